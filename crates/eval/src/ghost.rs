//! The ghost a moving object leaves (issue "things move"): how much of its old shadows and
//! bleeding a composite still shows in the region it left.
//!
//! At a scored frame t and an age k, the region left k frames ago is the set of real
//! points the camera sees at frame t (on the truth's pixel lattice, no object in front)
//! whose color the objects changed, at frame t-k, by more than [`LOST`] of the recorded
//! frame's value more than they change it at frame t, in some channel (in the camera's
//! linear values, as ratios: the exposure changes between frames): points the
//! objects' shadows or light left, wholly or in part (a shadow the torus drags along
//! the floor, the red glow it carries away). [`LOST`] is 10 %, well clear of the
//! truth's own noise (about a level: 2 % at level 128).
//!
//! A point is followed from frame t to frame t-k through the truth's depth and both
//! frames' poses, to the four pixels of the older truth's lattice around it, and kept
//! only where all four saw its surface (their depth is the point's: not behind
//! something) and all four lost the change (so that a point beside a shadow's edge is
//! not taken for one a lattice step away). Points an object hid at frame t-k, or that
//! lie within a lattice step of an object's outline at frame t-k or t, are left out:
//! the truth's outline pixels mix the object's color with the room's, and with a
//! moving camera the outline slides over the room behind (parallax), as most hidden
//! points are uncovered by the camera's own motion, not the object's (their error is
//! in the per-frame scores).
//!
//! Over the region, per age, two scores:
//! - the **ghost share**: the least-squares gain, on the differential the truth lost
//!   there, of what the composite shows beyond its usual share of today's:
//!   `sum((d - g d*) (d_old - d*)) / sum((d_old - d*)^2)`, where `d` and `d*` are the
//!   composite's and the truth's color at frame t as ratios to the recorded frame's,
//!   minus 1, `d_old` the same for the truth of frame t-k at the point (the bilinear mix
//!   of its four lattice pixels), all in the camera's linear values (ratios: the
//!   exposure may change between frames), and `g` the share of the truth's
//!   differential the composite shows over the whole frame (its
//!   `differential_ratio_by_frame`: a method that shows 80 % of every shadow is not
//!   charged for showing 80 % of what is left of this one). 0: the composite shows its
//!   usual share of today's shadows and light; `g`: it shows them as they stood k
//!   frames ago (a full ghost); below 0: less than today's (noise uncorrelated with
//!   what was lost adds nothing on average). Frames where the composite shows no share
//!   of the differential (g <= 0) are left out. Channels below level 16 or clipped are
//!   left out, as in `shadow_ratio_bias`;
//! - the composite's PSNR against the truth of frame t over the region.
//!
//! The ghost is gone after the fewest frames k from which on every measured age's share
//! is within [`GONE_SHARE`] of 0 (a negative share, the composite lighter than the truth
//! where a shadow was, is a ghost too).

use super::true_frame::{TrueComposite, linear_of_level};
use glam::Vec3;
use relume_base::pinhole::Pinhole;
use relume_base::raster::Rgb8Image;

/// Ages (frames since the object left a point) whose ghost is measured: 1 to this.
pub const GHOST_AGES: usize = 5;
/// A point was left when the objects changed one of its channels by more than this
/// share of the recorded (linear) value more than they change it now.
pub const LOST: f64 = 0.1;
/// A ghost share within this of 0 is gone (the 5 %, as for the lag).
pub const GONE_SHARE: f64 = 0.05;

/// The sums of one age's ghost over the frames scored.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GhostSums {
    /// Points in the region.
    pub pixels: u64,
    /// Squared 8-bit errors of the composite against the truth, and their channel count.
    pub squared: f64,
    pub values: u64,
    /// sum((d - g d*) (d_old - d*)).
    pub product: f64,
    /// sum((d_old - d*)^2).
    pub lost_squared: f64,
}

impl GhostSums {
    /// The ghost share, `None` where the region lost no differential.
    pub fn share(&self) -> Option<f64> {
        (self.lost_squared > 0.0).then(|| self.product / self.lost_squared)
    }

    /// The composite's mean squared 8-bit error against the truth over the region (its
    /// PSNR: [`super::composite::psnr_db`]), `None` where it is empty.
    pub fn mean_squared(&self) -> Option<f64> {
        (self.values > 0).then(|| self.squared / self.values as f64)
    }

    /// Adds the region of frame `now` that the objects left since frame `before`, with
    /// `own` the composite of frame `now` and `gain` the share of the truth's
    /// differential it shows over the whole frame (`differential_ratio_by_frame`); a
    /// frame whose gain is not positive adds nothing.
    pub fn observe(
        &mut self,
        own: &Rgb8Image,
        now: &TrueComposite,
        before: &TrueComposite,
        gain: f64,
    ) {
        let (w, h) = (now.image.width, now.image.height);
        let sizes = [
            (before.image.width, before.image.height),
            (own.width, own.height),
        ];
        if sizes.iter().any(|&size| size != (w, h)) || !(gain > 0.0 && gain.is_finite()) {
            return;
        }
        let camera_now = Pinhole::new(&now.view.intrinsics, w, h);
        let usable = |level: u8| (16..255).contains(&level);
        for i in (0..own.data.len()).filter(|&i| now.has_pixel(i)) {
            let z = now.depth[i];
            let (truth, camera) = (now.image.data[i], now.camera.data[i]);
            if z <= 0.0 || beside_object(now, i) {
                continue;
            }
            let (x, y) = ((i % w as usize) as f32, (i / w as usize) as f32);
            let world = now.view.rotation * camera_now.back_project(x, y, z) + now.view.position;
            let Some(old) = lattice_corners(before, world) else {
                continue;
            };
            let change_now = |c: usize| ratio(truth[c], camera[c], now.contrast).abs();
            let lost = old.iter().all(|&(j, _)| {
                let (t, base) = (before.image.data[j], before.camera.data[j]);
                let change_then = |c: usize| ratio(t[c], base[c], before.contrast).abs();
                let usable_then = |c: usize| usable(camera[c]) && usable(base[c]);
                !beside_object(before, j)
                    && (0..3).any(|c| usable_then(c) && change_then(c) > change_now(c) + LOST)
            });
            if !lost {
                continue;
            }
            self.pixels += 1;
            self.squared += (0..3)
                .map(|c| (own.data[i][c] as f64 - truth[c] as f64).powi(2))
                .sum::<f64>();
            self.values += 3;
            for c in 0..3 {
                let old_usable = old.iter().all(|&(j, _)| usable(before.camera.data[j][c]));
                if !(usable(camera[c]) && old_usable) {
                    continue;
                }
                let d = ratio(own.data[i][c], camera[c], now.contrast);
                let d_true = ratio(truth[c], camera[c], now.contrast);
                let d_old: f64 = old
                    .iter()
                    .map(|&(j, weight)| {
                        let (t, base) = (before.image.data[j][c], before.camera.data[j][c]);
                        weight as f64 * ratio(t, base, before.contrast)
                    })
                    .sum();
                let lost = d_old - d_true;
                self.product += (d - gain * d_true) * lost;
                self.lost_squared += lost * lost;
            }
        }
    }
}

/// Linear `level` as a ratio to linear `base`, minus 1.
fn ratio(level: u8, base: u8, contrast: f32) -> f64 {
    linear_of_level(level, contrast) as f64 / linear_of_level(base, contrast) as f64 - 1.0
}

/// Whether lattice pixel `i` of `t`, or one of its eight lattice neighbours, shows an
/// object: the truth's pixels along an outline mix the object's color with the room's,
/// and the camera's motion moves the outline over the room behind (parallax), so the
/// outline's band is no region an object's light left.
fn beside_object(t: &TrueComposite, i: usize) -> bool {
    let (w, h) = (t.image.width as i64, t.image.height as i64);
    let s = t.stride.max(1) as i64;
    let (x, y) = (i as i64 % w, i as i64 / w);
    (-1..=1).any(|dy| {
        (-1..=1).any(|dx| {
            let (u, v) = (x + dx * s, y + dy * s);
            (0..w).contains(&u) && (0..h).contains(&v) && t.object[(v * w + u) as usize]
        })
    })
}

/// The four pixels of `t`'s lattice around where its camera saw world point `p`, with
/// their bilinear weights, when each saw `p`'s surface (its depth there is `p`'s: the
/// point was in view, not behind something).
fn lattice_corners(t: &TrueComposite, p: Vec3) -> Option<[(usize, f32); 4]> {
    let (w, h) = (t.image.width as usize, t.image.height as usize);
    let seen = t.view.rotation.transpose() * (p - t.view.position);
    let uv = Pinhole::new(&t.view.intrinsics, w as u32, h as u32).project(seen)?
        / t.stride.max(1) as f32;
    let (u0, v0) = (uv.x.floor(), uv.y.floor());
    let (fu, fv) = (uv.x - u0, uv.y - v0);
    let s = t.stride.max(1) as usize;
    let mut corners = [(0, 0.0); 4];
    for (k, corner) in corners.iter_mut().enumerate() {
        let (du, dv) = (k % 2, k / 2);
        let (u, v) = (u0 + du as f32, v0 + dv as f32);
        if u < 0.0 || v < 0.0 {
            return None;
        }
        let (x, y) = (u as usize * s, v as usize * s);
        if x >= w || y >= h {
            return None;
        }
        let j = y * w + x;
        if (t.depth[j] - seen.z).abs() > 0.03 * seen.z + 0.01 {
            return None;
        }
        let weight = if du == 0 { 1.0 - fu } else { fu } * if dv == 0 { 1.0 - fv } else { fv };
        *corner = (j, weight);
    }
    Some(corners)
}

/// The fewest frames after which the ghost is gone: every age from it on with a share
/// has one within [`GONE_SHARE`] of 0; an error saying why not.
pub fn gone_after(ages: &[GhostSums]) -> Result<usize, String> {
    let shares: Vec<(usize, f64)> = ages
        .iter()
        .enumerate()
        .filter_map(|(k, a)| a.share().map(|s| (k + 1, s)))
        .collect();
    let Some(&(oldest, last)) = shares.last() else {
        return Err(
            "no scored frame shows a point the objects' shadows or light left (the objects did not move in the scored frames, or --score-frames skips the frames before)"
                .into(),
        );
    };
    if last.abs() > GONE_SHARE {
        return Err(format!(
            "the ghost share is {last:.3} at age {oldest}, the oldest measured (beyond {GONE_SHARE} of 0)"
        ));
    }
    let lingering = shares.iter().rposition(|(_, s)| s.abs() > GONE_SHARE);
    Ok(lingering.map_or(shares[0].0, |i| shares[i + 1].0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Mat3;
    use relume_recording::Intrinsics;
    use relume_recording::synth::render::View;

    const W: u32 = 16;
    const H: u32 = 12;

    /// A truth of a flat gray wall (level 120) 2 m in front of a camera that stands
    /// 0.06 m down and left for each of `frames_ago`: the wall moves 0.3 pixels right and
    /// down per frame ago in its image (f = 10).
    fn wall(frames_ago: u32) -> TrueComposite {
        let n = (W * H) as usize;
        let camera = Rgb8Image::from_vec(W, H, vec![[120; 3]; n]).unwrap();
        let back = -0.06 * frames_ago as f32;
        TrueComposite {
            frame: 10 - frames_ago as usize,
            stride: 1,
            image: camera.clone(),
            camera,
            noise_levels: vec![0.0; n],
            object: vec![false; n],
            contrast: 1.0,
            render_s: 0.0,
            depth: vec![2.0; n],
            view: View {
                rotation: Mat3::IDENTITY,
                position: Vec3::new(back, back, 0.0),
                intrinsics: Intrinsics {
                    width: W,
                    height: H,
                    fx: 10.0,
                    fy: 10.0,
                    cx: 7.5,
                    cy: 5.5,
                },
            },
        }
    }

    /// The pixels of columns `xs` and rows `ys`.
    fn block(
        xs: std::ops::RangeInclusive<usize>,
        ys: std::ops::RangeInclusive<usize>,
    ) -> Vec<usize> {
        ys.flat_map(|y| xs.clone().map(move |x| y * W as usize + x))
            .collect()
    }

    /// Darkens `pixels` of the truth by `levels`.
    fn shadow(t: &mut TrueComposite, pixels: &[usize], levels: u8) {
        for &i in pixels {
            t.image.data[i] = [120 - levels; 3];
        }
    }

    #[test]
    fn half_the_old_shadow_left_is_a_share_of_a_half_and_the_camera_motion_is_followed() {
        let mut before = wall(1);
        shadow(&mut before, &block(4..=9, 3..=7), 20);
        let now = wall(0);
        // Pixel (x, y) now is (x + 0.3, y + 0.3) a frame ago: the points whose four
        // lattice neighbours a frame ago were all in the shadow are x 4..=8, y 3..=6.
        let mut own = now.camera.clone();
        for i in block(4..=8, 3..=6) {
            own.data[i] = [110; 3];
        }
        let mut sums = GhostSums::default();
        sums.observe(&own, &now, &before, 1.0);
        assert_eq!(sums.pixels, 20);
        let share = sums.share().unwrap();
        // Linear ratios: level 110 against 120 over level 100 against 120.
        let ratio = |l: f64| (l / 120.0f64).powf(2.2) - 1.0;
        assert!(
            (share - ratio(110.0) / ratio(100.0)).abs() < 1e-5,
            "{share}"
        );
        assert!((0.45..0.55).contains(&share), "{share}");
        // 10 levels off in 3 channels of each point.
        assert_eq!(sums.mean_squared(), Some(100.0));
    }

    #[test]
    fn a_shadow_that_lightened_is_measured_on_what_it_lost() {
        // 20 levels darker a frame ago, 10 now: a composite still 20 darker shows all of
        // the loss, one 10 darker none of it.
        let mut before = wall(1);
        shadow(&mut before, &block(2..=13, 2..=9), 20);
        let mut now = wall(0);
        shadow(&mut now, &block(0..=15, 0..=11), 10);
        let mut stale = now.image.clone();
        stale.data.iter_mut().for_each(|p| *p = [100; 3]);
        let mut ghost = GhostSums::default();
        ghost.observe(&stale, &now, &before, 1.0);
        assert!((ghost.share().unwrap() - 1.0).abs() < 1e-5, "{ghost:?}");
        let mut followed = GhostSums::default();
        followed.observe(&now.image, &now, &before, 1.0);
        assert_eq!(followed.share(), Some(0.0));
        assert_eq!(ghost.pixels, followed.pixels);
        assert!(ghost.pixels > 0);
        // A composite that shows half of every shadow, measured against its half: at
        // half the old shadow it is a full ghost (a share of a half), at half today's
        // none (within the 8-bit rounding of a 9-level shadow).
        let half = |levels: f64| {
            let linear = 1.0 + 0.5 * ((levels / 120.0f64).powf(2.2) - 1.0);
            let level = (linear.powf(1.0 / 2.2) * 120.0).round() as u8;
            let mut image = now.camera.clone();
            image.data.iter_mut().for_each(|p| *p = [level; 3]);
            image
        };
        let mut halved = GhostSums::default();
        halved.observe(&half(100.0), &now, &before, 0.5);
        assert!((halved.share().unwrap() - 0.5).abs() < 0.06, "{halved:?}");
        let mut halved = GhostSums::default();
        halved.observe(&half(110.0), &now, &before, 0.5);
        assert!(halved.share().unwrap().abs() < 0.06, "{halved:?}");
        // No share to measure against: nothing is added.
        let mut none = GhostSums::default();
        none.observe(&stale, &now, &before, 0.0);
        assert_eq!(none, GhostSums::default());
    }

    #[test]
    fn what_the_truth_still_changes_hidden_points_objects_and_faint_losses_are_not_ghosts() {
        let mut before = wall(1);
        // Still as dark now.
        shadow(&mut before, &block(2..=5, 2..=5), 20);
        // Lost only 4 levels.
        shadow(&mut before, &block(9..=12, 2..=5), 4);
        // Out of view a frame ago (1 m nearer).
        shadow(&mut before, &block(9..=12, 7..=10), 20);
        for i in block(9..=12, 7..=10) {
            before.depth[i] = 1.0;
        }
        // An object in front (the camera's motion uncovers what was behind it).
        for i in block(2..=5, 7..=10) {
            before.object[i] = true;
        }
        let mut now = wall(0);
        shadow(&mut now, &block(1..=5, 1..=5), 20);
        let mut own = now.image.clone();
        own.data.iter_mut().for_each(|p| *p = [90; 3]);
        let mut sums = GhostSums::default();
        sums.observe(&own, &now, &before, 1.0);
        assert_eq!(sums, GhostSums::default());
        assert_eq!((sums.share(), sums.mean_squared()), (None, None));
        // The same loss beside a shadow's edge: the lattice neighbours disagree.
        let mut edge = wall(1);
        shadow(&mut edge, &block(4..=4, 0..=11), 20);
        sums.observe(&now.camera, &wall(0), &edge, 1.0);
        assert_eq!(sums.pixels, 0);
    }

    #[test]
    fn the_ghost_is_gone_from_the_first_age_after_which_every_share_is_small() {
        let age = |share: f64| GhostSums {
            product: share,
            lost_squared: 1.0,
            ..GhostSums::default()
        };
        let ages = [age(0.6), age(0.2), age(0.04), age(0.01), age(-0.02)];
        assert_eq!(gone_after(&ages), Ok(3));
        let ages = [
            age(0.01),
            age(0.2),
            age(0.04),
            GhostSums::default(),
            age(0.0),
        ];
        assert_eq!(gone_after(&ages), Ok(3));
        assert_eq!(gone_after(&[age(0.0), age(0.01)]), Ok(1));
        assert_eq!(
            gone_after(&[age(-0.2), age(0.01), age(-0.06), age(0.0)]),
            Ok(4)
        );
        assert_eq!(
            gone_after(&[age(0.0), age(0.3)]),
            Err("the ghost share is 0.300 at age 2, the oldest measured (beyond 0.05 of 0)".into())
        );
        assert!(
            gone_after(&[GhostSums::default()])
                .unwrap_err()
                .starts_with("no scored frame")
        );
    }
}
