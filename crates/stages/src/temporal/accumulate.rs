//! Temporal accumulation of the irradiance layers: each pixel's estimate of this frame
//! averaged with the estimates that earlier frames made of the same surface point.
//!
//! The real scene is static and the objects are placed once, so the irradiance at a
//! world point (E_R and E_RV, direct and indirect) does not change from frame to frame:
//! only the noise of its estimate does. This is the reuse that paper 000 cites as
//! differential irradiance caching (its ref. 23), kept in screen space: the previous
//! frame's accumulated layers are reprojected into the current view, as paper 001's
//! temporal filter does (eqs. 24-26), and averaged with the new estimate.
//!
//! Per pixel with a visible surface point p (`world_position`, normal n):
//! 1. **Reprojection**: p is projected into the previous camera. Of the four previous
//!    pixels around the projection, those whose surface point q lies within
//!    `tolerance` pixel footprints of p (the footprint is the pixel's width at p's
//!    distance, divided by the cosine between n and the view ray, at most 4x), whose
//!    normals agree (n . n_q >= `min_normal_cos`) and which have estimates of the same
//!    layers (E_R at both or at neither, E_RV likewise) are mixed bilinearly, their
//!    weights renormalized (so a history does not trail behind a slowly moving camera,
//!    as it would from the nearest pixel). When none qualifies (p beside a depth edge),
//!    the nearest qualifying point of the 3 x 3 window around the projected pixel is
//!    taken; when none there either, the pixel starts a new history.
//! 2. **Average**: with h frames of history, this frame's estimate gets weight 1 / n,
//!    n = min(h + 1, `max_history`): the plain mean of the last n frames while the
//!    history is shorter than `max_history`, then an exponential average of time
//!    constant `max_history` frames (so that the estimate follows a light table that
//!    changes as the camera sees more of the room).
//! 3. **Minimum distances** (the filter's nearest occluder and indirect hit) are the
//!    minimum of this frame's and the history's (of the heaviest bilinear tap): with a
//!    static scene, every earlier frame's samples saw the same occluders. `touched` is
//!    1 where this frame's or an earlier frame's paths met an object.
//!
//! E_RV == E_R holds bit for bit wherever it held in this frame's estimate and in the
//! history: both are averaged by the same operations with the same weight.
//!
//! Where it departs from a world-space cache: the bilinear mix blurs the history a
//! little each frame the camera moves (a fraction of a pixel; far below the filter's
//! widths), and on glossy objects it averages light that depends on the view over
//! the views of up to `max_history` frames. The mask, k_V, the exponent and the
//! surface positions are this frame's own (the accumulated estimates are of the
//! surface the pixel shows now).

use crate::OpError;
use glam::{Affine3A, Vec3};
use rayon::prelude::*;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{Image, LabelImage, ScalarImage, Vec3Image};

/// Half size of the reprojection's search window (1: 3 x 3).
pub const SEARCH_RADIUS: i32 = 1;

/// Largest factor by which a grazing view widens the position tolerance.
const MAX_GRAZING_FACTOR: f32 = 4.0;

/// Settings of [`accumulate`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccumulateParams {
    /// Frames an estimate averages at most before older frames fade (>= 1; 1 turns
    /// accumulation off).
    pub max_history: u32,
    /// Pixel footprints within which a previous surface point counts as the same.
    pub tolerance: f32,
    /// Smallest cosine between the normals of the same surface point in two frames.
    pub min_normal_cos: f32,
}

impl Default for AccumulateParams {
    fn default() -> Self {
        AccumulateParams {
            max_history: 32,
            tolerance: 2.0,
            min_normal_cos: 0.9,
        }
    }
}

/// One frame's estimates, as a renderer wrote them.
#[derive(Clone, Copy)]
pub struct FreshLayers<'a> {
    /// E_R^dir, E_R^ind, E_RV^dir, E_RV^ind (NaN: no estimate).
    pub irradiance: [&'a Vec3Image; 4],
    pub direct_min_distance: &'a ScalarImage,
    pub indirect_min_distance: &'a ScalarImage,
    pub touched: &'a LabelImage,
    /// The visible surface (world space; NaN / zero: none).
    pub world_position: &'a Vec3Image,
    pub world_normal: &'a Vec3Image,
}

/// The accumulated layers of one frame: the stage's outputs, and the next frame's
/// history.
#[derive(Clone, Debug, PartialEq)]
pub struct Accumulated {
    /// E_R^dir, E_R^ind, E_RV^dir, E_RV^ind.
    pub irradiance: [Vec3Image; 4],
    pub direct_min_distance: ScalarImage,
    pub indirect_min_distance: ScalarImage,
    pub touched: LabelImage,
    /// Frames each pixel's estimate holds (this one included; the weight of the
    /// newest is 1 / min(frames, max_history)).
    pub frames: ScalarImage,
}

/// The previous frame as [`accumulate`] reads it: its accumulated layers (as in
/// [`Accumulated`]) and the surface they describe.
#[derive(Clone, Copy)]
pub struct History<'a> {
    /// E_R^dir, E_R^ind, E_RV^dir, E_RV^ind.
    pub irradiance: [&'a Vec3Image; 4],
    pub direct_min_distance: &'a ScalarImage,
    pub indirect_min_distance: &'a ScalarImage,
    pub touched: &'a LabelImage,
    pub frames: &'a ScalarImage,
    /// The previous frame's visible surface.
    pub world_position: &'a Vec3Image,
    pub world_normal: &'a Vec3Image,
    /// World to the previous camera.
    pub world_to_camera: Affine3A,
    /// The previous camera (its image the layers' size).
    pub camera: Pinhole,
}

impl<'a> History<'a> {
    /// `layers` as the history of a frame that showed `world_position` and
    /// `world_normal` through `camera` at `world_to_camera`.
    pub fn of(
        layers: &'a Accumulated,
        world_position: &'a Vec3Image,
        world_normal: &'a Vec3Image,
        world_to_camera: Affine3A,
        camera: Pinhole,
    ) -> History<'a> {
        History {
            irradiance: [0, 1, 2, 3].map(|k| &layers.irradiance[k]),
            direct_min_distance: &layers.direct_min_distance,
            indirect_min_distance: &layers.indirect_min_distance,
            touched: &layers.touched,
            frames: &layers.frames,
            world_position,
            world_normal,
            world_to_camera,
            camera,
        }
    }

    /// Whether every layer is `w` x `h`.
    fn has_size(&self, w: u32, h: u32) -> bool {
        let frames = self.frames;
        (frames.width, frames.height) == (w, h)
            && (self.camera.width, self.camera.height) == (w, h)
            && self.irradiance.iter().all(|image| image.same_size(frames))
            && self.direct_min_distance.same_size(frames)
            && self.indirect_min_distance.same_size(frames)
            && self.touched.same_size(frames)
            && self.world_position.same_size(frames)
            && self.world_normal.same_size(frames)
    }
}

/// What one pixel ends up with.
#[derive(Clone, Copy)]
struct Pixel {
    irradiance: [Vec3; 4],
    direct_min: f32,
    indirect_min: f32,
    touched: u8,
    frames: f32,
}

/// Averages `fresh` with `history` (see the module docs) into a new [`Accumulated`].
/// `camera` and `camera_to_world` are this frame's camera; all images must be its
/// size. Without a history (the first frame, or after a cut) the result is `fresh`
/// with one frame everywhere.
pub fn accumulate(
    fresh: &FreshLayers,
    history: Option<&History>,
    camera: Pinhole,
    camera_to_world: Affine3A,
    params: &AccumulateParams,
) -> Result<Accumulated, OpError> {
    let (w, h) = (camera.width, camera.height);
    let mut sizes = vec![
        (
            "world_position",
            fresh.world_position.width,
            fresh.world_position.height,
        ),
        (
            "world_normal",
            fresh.world_normal.width,
            fresh.world_normal.height,
        ),
        ("touched", fresh.touched.width, fresh.touched.height),
        (
            "direct_min_distance",
            fresh.direct_min_distance.width,
            fresh.direct_min_distance.height,
        ),
        (
            "indirect_min_distance",
            fresh.indirect_min_distance.width,
            fresh.indirect_min_distance.height,
        ),
    ];
    for (name, image) in ["e_r_dir", "e_r_ind", "e_rv_dir", "e_rv_ind"]
        .into_iter()
        .zip(fresh.irradiance)
    {
        sizes.push((name, image.width, image.height));
    }
    if let Some((what, ww, hh)) = sizes.into_iter().find(|&(_, ww, hh)| (ww, hh) != (w, h)) {
        return Err(OpError::SizeMismatch(format!(
            "temporal.accumulate: {what} is {ww}x{hh}, the camera's image is {w}x{h}"
        )));
    }
    // A history of another size (the recording changed size) is no history.
    let history = history.filter(|hist| hist.has_size(w, h));
    let eye = camera_to_world.translation.into();
    let max_history = params.max_history.max(1) as f32;
    let mut out = Accumulated::zeroed(w, h);
    let width = w as usize;
    out.rows(width).into_par_iter().for_each(|(y, mut row)| {
        for x in 0..width {
            let i = y * width + x;
            let fresh_pixel = fresh_pixel(fresh, i);
            let pixel = match history.and_then(|hist| previous(fresh, i, hist, camera, eye, params))
            {
                Some(previous) => blend(&fresh_pixel, &previous, max_history),
                None => fresh_pixel,
            };
            row.set(x, &pixel);
        }
    });
    Ok(out)
}

impl Accumulated {
    /// Layers of `width` x `height` zeros.
    pub fn zeroed(width: u32, height: u32) -> Accumulated {
        let v = || Image::zeroed(width, height);
        Accumulated {
            irradiance: [v(), v(), v(), v()],
            direct_min_distance: Image::zeroed(width, height),
            indirect_min_distance: Image::zeroed(width, height),
            touched: Image::zeroed(width, height),
            frames: Image::zeroed(width, height),
        }
    }

    /// (y, row of every layer) for each row of `width` pixels.
    fn rows(&mut self, width: usize) -> Vec<(usize, Row<'_>)> {
        let [r_dir, r_ind, rv_dir, rv_ind] = &mut self.irradiance;
        let mut r_dir = r_dir.data.chunks_mut(width);
        let mut r_ind = r_ind.data.chunks_mut(width);
        let mut rv_dir = rv_dir.data.chunks_mut(width);
        let mut rv_ind = rv_ind.data.chunks_mut(width);
        let mut direct_min = self.direct_min_distance.data.chunks_mut(width);
        let mut indirect_min = self.indirect_min_distance.data.chunks_mut(width);
        let mut touched = self.touched.data.chunks_mut(width);
        let mut frames = self.frames.data.chunks_mut(width);
        let mut rows = Vec::new();
        while let (Some(a), Some(b), Some(c), Some(d), Some(e), Some(f), Some(g), Some(h)) = (
            r_dir.next(),
            r_ind.next(),
            rv_dir.next(),
            rv_ind.next(),
            direct_min.next(),
            indirect_min.next(),
            touched.next(),
            frames.next(),
        ) {
            let row = Row {
                irradiance: [a, b, c, d],
                direct_min: e,
                indirect_min: f,
                touched: g,
                frames: h,
            };
            rows.push((rows.len(), row));
        }
        rows
    }
}

/// One row of every accumulated layer.
struct Row<'a> {
    irradiance: [&'a mut [Vec3]; 4],
    direct_min: &'a mut [f32],
    indirect_min: &'a mut [f32],
    touched: &'a mut [u8],
    frames: &'a mut [f32],
}

impl Row<'_> {
    #[inline]
    fn set(&mut self, x: usize, p: &Pixel) {
        for (layer, value) in self.irradiance.iter_mut().zip(p.irradiance) {
            layer[x] = value;
        }
        self.direct_min[x] = p.direct_min;
        self.indirect_min[x] = p.indirect_min;
        self.touched[x] = p.touched;
        self.frames[x] = p.frames;
    }
}

fn fresh_pixel(fresh: &FreshLayers, i: usize) -> Pixel {
    Pixel {
        irradiance: fresh.irradiance.map(|image| image.data[i]),
        direct_min: fresh.direct_min_distance.data[i],
        indirect_min: fresh.indirect_min_distance.data[i],
        touched: fresh.touched.data[i].min(1),
        frames: 1.0,
    }
}

fn history_pixel(history: &History, j: usize) -> Pixel {
    Pixel {
        irradiance: history.irradiance.map(|image| image.data[j]),
        direct_min: history.direct_min_distance.data[j],
        indirect_min: history.indirect_min_distance.data[j],
        touched: history.touched.data[j],
        frames: history.frames.data[j],
    }
}

/// The bilinear mix of previous pixels `taps` (index, weight > 0): the same weights for
/// every irradiance layer (so equal E_R and E_RV stay equal bit for bit) and the frame
/// counts; `touched` where any tap is; the minimum distances of the heaviest tap (a
/// minimum over all four would spread an occluder a pixel further every frame).
fn mixed_history(history: &History, taps: &[(usize, f32)]) -> Pixel {
    let total: f32 = taps.iter().map(|&(_, w)| w).sum();
    let heaviest = taps
        .iter()
        .fold(taps[0], |a, &b| if b.1 > a.1 { b } else { a })
        .0;
    let mut mixed = Pixel {
        irradiance: [Vec3::ZERO; 4],
        direct_min: history.direct_min_distance.data[heaviest],
        indirect_min: history.indirect_min_distance.data[heaviest],
        touched: 0,
        frames: 0.0,
    };
    for &(j, w) in taps {
        let w = w / total;
        for (sum, layer) in mixed.irradiance.iter_mut().zip(history.irradiance) {
            *sum += layer.data[j] * w;
        }
        mixed.frames += history.frames.data[j] * w;
        mixed.touched |= history.touched.data[j];
    }
    mixed
}

/// The running average of step 2 and the minima of step 3.
#[inline]
fn blend(fresh: &Pixel, previous: &Pixel, max_history: f32) -> Pixel {
    let n = (previous.frames + 1.0).min(max_history);
    if n <= 1.0 {
        return *fresh;
    }
    let weight = 1.0 / n;
    Pixel {
        irradiance: [0, 1, 2, 3].map(|k| {
            let (new, old) = (fresh.irradiance[k], previous.irradiance[k]);
            old + (new - old) * weight
        }),
        direct_min: fresh.direct_min.min(previous.direct_min),
        indirect_min: fresh.indirect_min.min(previous.indirect_min),
        touched: fresh.touched | previous.touched,
        frames: n,
    }
}

/// Previous pixel `j` of `history` when it may show the same surface point as `p`
/// (normal `n`, layers `fresh_has`: E_R^dir and E_RV^dir present): its squared
/// distance to `p`.
#[inline(always)]
fn candidate(
    history: &History,
    j: usize,
    p: Vec3,
    n: Vec3,
    fresh_has: [bool; 2],
    tolerance2: f32,
    min_normal_cos: f32,
) -> Option<f32> {
    // NaN frame counts and distances (no previous surface) fail here too.
    let frames = history.frames.data[j];
    let d2 = (history.world_position.data[j] - p).length_squared();
    if frames.is_nan() || frames <= 0.0 || d2.is_nan() || d2 > tolerance2 {
        return None;
    }
    let m = history.world_normal.data[j];
    let normals_agree = match (n == Vec3::ZERO, m == Vec3::ZERO) {
        (false, false) => n.dot(m) >= min_normal_cos,
        (zero_n, zero_m) => zero_n == zero_m,
    };
    let same_layers = history.irradiance[0].data[j].is_finite() == fresh_has[0]
        && history.irradiance[2].data[j].is_finite() == fresh_has[1];
    (normals_agree && same_layers).then_some(d2)
}

/// `x.floor()` as an integer for |x| < 2^31 (beyond, and for infinities, it saturates
/// at `i32::MIN` or `i32::MAX`; NaN gives 0: no pixel is indexed either way), without
/// the library call `floor` is without SSE4.1.
#[inline(always)]
fn floor_i32(x: f32) -> i32 {
    let t = x as i32;
    t.saturating_sub((x < t as f32) as i32)
}

/// Step 1: the history of the surface point of pixel `i`, if the previous frame saw it.
fn previous(
    fresh: &FreshLayers,
    i: usize,
    history: &History,
    camera: Pinhole,
    eye: Vec3,
    params: &AccumulateParams,
) -> Option<Pixel> {
    let p = fresh.world_position.data[i];
    let n = fresh.world_normal.data[i];
    if !p.is_finite() {
        return None;
    }
    let distance = (p - eye).length();
    let cos = if n == Vec3::ZERO {
        1.0
    } else {
        n.dot((eye - p) / distance).abs()
    };
    let footprint = distance / camera.fx.abs().max(f32::MIN_POSITIVE);
    let grazing = (1.0 / cos.max(1.0 / MAX_GRAZING_FACTOR)).min(MAX_GRAZING_FACTOR);
    let tolerance = params.tolerance * footprint * grazing;
    let in_previous = history.world_to_camera.transform_point3(p);
    let (width, height) = (history.camera.width as i32, history.camera.height as i32);
    // Which layers this pixel has (E_R^dir, E_RV^dir stand for their pairs), once.
    let fresh_has = [0, 2].map(|k| fresh.irradiance[k].data[i].is_finite());
    let tolerance2 = tolerance * tolerance;
    let same_point = |j: usize| {
        candidate(
            history,
            j,
            p,
            n,
            fresh_has,
            tolerance2,
            params.min_normal_cos,
        )
    };
    // The bilinear taps around p's projection that show p.
    let uv = history.camera.project(in_previous)?;
    let (u0, v0) = (floor_i32(uv.x), floor_i32(uv.y));
    let (fx, fy) = (uv.x - u0 as f32, uv.y - v0 as f32);
    let mut taps = [(0usize, 0.0f32); 4];
    let mut count = 0;
    for (dx, dy, w) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        let (x, y) = (u0.saturating_add(dx), v0.saturating_add(dy));
        if w <= 0.0 || x < 0 || y < 0 || x >= width || y >= height {
            continue;
        }
        let j = y as usize * width as usize + x as usize;
        if same_point(j).is_some() {
            taps[count] = (j, w);
            count += 1;
        }
    }
    if count > 0 {
        return Some(mixed_history(history, &taps[..count]));
    }
    // None of them (p lies on a depth edge, or beyond the bilinear cell): the
    // nearest point of the 3 x 3 window around the projected pixel.
    let (u, v) = history.camera.pixel_of(in_previous)?;
    let mut best: Option<(f32, usize)> = None;
    for dy in -SEARCH_RADIUS..=SEARCH_RADIUS {
        for dx in -SEARCH_RADIUS..=SEARCH_RADIUS {
            let (x, y) = (u as i32 + dx, v as i32 + dy);
            if x < 0 || y < 0 || x >= width || y >= height {
                continue;
            }
            let j = y as usize * width as usize + x as usize;
            if let Some(d2) = same_point(j)
                && best.is_none_or(|(best_d2, _)| d2 < best_d2)
            {
                best = Some((d2, j));
            }
        }
    }
    best.map(|(_, j)| history_pixel(history, j))
}

#[cfg(test)]
mod floor_tests {
    use super::floor_i32;

    #[test]
    fn floor_i32_is_floor_in_range_and_saturates_beyond() {
        for x in [
            0.0f32, -0.0, 0.5, -0.5, -1.0, -1.5, 1.0, 639.999, 2.0e9, -2.0e9,
        ] {
            assert_eq!(floor_i32(x), x.floor() as i32, "{x}");
        }
        // Points just in front of the previous camera's plane project this far out;
        // neither end may overflow (a panic in debug builds).
        assert_eq!(floor_i32(-1.0e30), i32::MIN);
        assert_eq!(floor_i32(f32::NEG_INFINITY), i32::MIN);
        assert_eq!(floor_i32(1.0e30), i32::MAX);
        assert_eq!(floor_i32(f32::INFINITY), i32::MAX);
        assert_eq!(floor_i32(f32::NAN), 0);
    }
}
