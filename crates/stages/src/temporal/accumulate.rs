//! Temporal accumulation of the irradiance layers: each pixel's estimate of this frame
//! averaged with the estimates that earlier frames made of the same surface point.
//!
//! The real scene is static, so while the objects stand still the irradiance at a
//! world point (E_R and E_RV, direct and indirect) does not change from frame to frame:
//! only the noise of its estimate does. Where objects move, see step 4. This is the reuse that paper 000 cites as
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
//! 4. **Objects that move** (when the caller passes how each object moved since the
//!    previous frame, [`WorldChange`]): each pixel also keeps how many frames its
//!    differential E_RV - E_R holds, and whether it showed an object. E_R always
//!    averages as above (the objects do not change it); the differential's history
//!    follows the objects:
//!    - a pixel of an object that moved this frame takes, whole, the history of the same
//!      point of the object where it stood a frame ago (its world position carried back
//!      by the object's rigid move, then step 1 there), or starts anew when the
//!      previous frame did not see that point;
//!    - a real surface point whose paths met an object (now or in its history), or that
//!      an object covered a frame ago, and whose nearest object moved this frame, takes
//!      its differential from the history of the point that stood where it does
//!      relative to that object a frame ago: a shadow or a glow that travels with its
//!      object travels with its history. Where that point was not seen, the
//!      differential starts anew (this frame's E_RV - E_R over the averaged E_R).
//!      A point the previous frame did not see itself (the object's motion uncovered
//!      it: the floor seen through a moving torus's hole, or just below its outline)
//!      is carried too when its paths met the object this frame, and takes the carried
//!      point's E_R history as well (a point one object step away on the same surface:
//!      E_R there is nearly its own, and an E_R of this frame alone, divided into a
//!      carried differential, is noisier than the fresh estimates it replaces, whose
//!      E_RV and E_R share their samples);
//!    - elsewhere (no object moved, or the nearest one did not) the history is kept.
//!
//!    The carried differential averages its own frames (weight 1 / min(its frames + 1,
//!    `max_history`)); the minimum distances and `touched` are this frame's and the
//!    carried point's. Nothing is left where an object was (no trailing shadow); the
//!    approximation is that a shadow moves rigidly with its object, exact for a
//!    translation along a plane under distant light. Where the differential holds as
//!    many frames as E_R (everywhere in a still scene) the arithmetic is the plain one,
//!    bit for bit. Reprojection-based denoisers reject such history by comparing noisy
//!    estimates or re-shading a few pixels (temporal gradients); here what moved, and
//!    how, is known.
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
use relume_scene::objects::ObjectMove;

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
    /// What step 4 keeps per pixel, when the objects move (`None` otherwise).
    pub change: Option<ChangeLayers>,
}

/// Per pixel, what step 4 keeps beside the layers when objects move.
#[derive(Clone, Debug, PartialEq)]
pub struct ChangeLayers {
    /// Frames the differential E_RV - E_R holds: as `frames` until an object moved
    /// near the pixel, its own count from then on.
    pub differential_frames: ScalarImage,
    /// 1 where the pixel showed a virtual object (mask below 1/2).
    pub object: LabelImage,
}

/// What step 4 needs of this frame: the renderer's mask (1 on real surfaces, 0 on
/// objects), which tells a pixel that shows an object from one that shows the real
/// surface, and how each object moved since the previous frame.
#[derive(Clone, Copy)]
pub struct WorldChange<'a> {
    pub mask: &'a ScalarImage,
    /// Every object, in the scene's order.
    pub objects: &'a [ObjectMove],
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
    /// Step 4's layers of the previous frame (`None`: nothing moved there, every
    /// differential holds as many frames as E_R).
    pub change: Option<&'a ChangeLayers>,
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
            change: layers.change.as_ref(),
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
            && self.change.is_none_or(|c| {
                c.differential_frames.same_size(frames) && c.object.same_size(frames)
            })
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
    /// Step 4: the frames the differential holds.
    differential_frames: f32,
    /// Whether the pixel shows a virtual object (step 4).
    object: bool,
}

/// Averages `fresh` with `history` (see the module docs) into a new [`Accumulated`].
/// `camera` and `camera_to_world` are this frame's camera; all images must be its
/// size. Without a history (the first frame, or after a cut) the result is `fresh`
/// with one frame everywhere.
///
/// `change` is given when the pipeline's objects move (step 4), `None` when they stand
/// still (the result then has no [`ChangeLayers`]).
pub fn accumulate(
    fresh: &FreshLayers,
    history: Option<&History>,
    camera: Pinhole,
    camera_to_world: Affine3A,
    params: &AccumulateParams,
    change: Option<WorldChange>,
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
    if let Some(c) = change {
        sizes.push(("mask", c.mask.width, c.mask.height));
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
    if change.is_some() {
        out.change = Some(ChangeLayers {
            differential_frames: Image::zeroed(w, h),
            object: Image::zeroed(w, h),
        });
    }
    let width = w as usize;
    out.rows(width).into_par_iter().for_each(|(y, mut row)| {
        for x in 0..width {
            let i = y * width + x;
            let mut fresh_pixel = fresh_pixel(fresh, i);
            let found = history.and_then(|hist| previous(fresh, i, hist, camera, eye, params));
            let pixel = match (found, change) {
                (None, None) => fresh_pixel,
                (Some(previous), None) => blend(&fresh_pixel, &previous, max_history),
                (found, Some(c)) => {
                    fresh_pixel.object = c.mask.data[i] < 0.5;
                    let source = match history {
                        Some(hist) => differential_source(
                            &fresh_pixel,
                            found.as_ref(),
                            fresh,
                            i,
                            hist,
                            (camera, camera_to_world),
                            params,
                            c,
                        ),
                        None => Differential::Kept,
                    };
                    match (found, source) {
                        (_, Differential::Restart) => fresh_pixel,
                        // The whole pixel, its frame counts included.
                        (_, Differential::Whole(source)) => {
                            blend(&fresh_pixel, &source, max_history)
                        }
                        (Some(previous), source) => {
                            blend_changing(&fresh_pixel, &previous, source, max_history)
                        }
                        // A point the previous frame did not see (the object's motion
                        // uncovered it): E_R and the differential from the carried point.
                        (None, source @ Differential::Carried(carried)) => {
                            blend_changing(&fresh_pixel, &carried, source, max_history)
                        }
                        (None, _) => fresh_pixel,
                    }
                }
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
            change: None,
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
        let (mut differential_frames, mut object) = match &mut self.change {
            Some(c) => (
                Some(c.differential_frames.data.chunks_mut(width)),
                Some(c.object.data.chunks_mut(width)),
            ),
            None => (None, None),
        };
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
                differential_frames: differential_frames.as_mut().and_then(|c| c.next()),
                object: object.as_mut().and_then(|c| c.next()),
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
    differential_frames: Option<&'a mut [f32]>,
    object: Option<&'a mut [u8]>,
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
        if let Some(d) = &mut self.differential_frames {
            d[x] = p.differential_frames;
        }
        if let Some(o) = &mut self.object {
            o[x] = p.object as u8;
        }
    }
}

fn fresh_pixel(fresh: &FreshLayers, i: usize) -> Pixel {
    Pixel {
        irradiance: fresh.irradiance.map(|image| image.data[i]),
        direct_min: fresh.direct_min_distance.data[i],
        indirect_min: fresh.indirect_min_distance.data[i],
        touched: fresh.touched.data[i].min(1),
        frames: 1.0,
        differential_frames: 1.0,
        object: false,
    }
}

fn history_pixel(history: &History, j: usize) -> Pixel {
    Pixel {
        irradiance: history.irradiance.map(|image| image.data[j]),
        direct_min: history.direct_min_distance.data[j],
        indirect_min: history.indirect_min_distance.data[j],
        touched: history.touched.data[j],
        frames: history.frames.data[j],
        differential_frames: match history.change {
            Some(c) => c.differential_frames.data[j],
            None => history.frames.data[j],
        },
        object: history.change.is_some_and(|c| c.object.data[j] != 0),
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
        differential_frames: 0.0,
        object: history.change.is_some_and(|c| c.object.data[heaviest] != 0),
    };
    for &(j, w) in taps {
        let w = w / total;
        for (sum, layer) in mixed.irradiance.iter_mut().zip(history.irradiance) {
            *sum += layer.data[j] * w;
        }
        mixed.frames += history.frames.data[j] * w;
        mixed.touched |= history.touched.data[j];
    }
    // Step 4's count, by the same operations as `frames` (equal counts mix to equal
    // counts); without step 4's layers it is `frames` itself.
    mixed.differential_frames = match history.change {
        Some(c) => taps
            .iter()
            .map(|&(j, w)| c.differential_frames.data[j] * (w / total))
            .fold(0.0, |sum, x| sum + x),
        None => mixed.frames,
    };
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
        differential_frames: n,
        object: fresh.object,
    }
}

/// Where step 4 takes a pixel's differential history from.
#[derive(Clone, Copy)]
enum Differential {
    /// From the pixel's own history, as for E_R.
    Kept,
    /// Nowhere: this frame's differential alone.
    Dropped,
    /// From the history of the point that stood where this one does relative to the
    /// object that moved (its layers as a [`Pixel`]).
    Carried(Pixel),
    /// The whole pixel from the history of the same point of a moved object.
    Whole(Pixel),
    /// The whole pixel starts anew.
    Restart,
}

/// Step 4's choice for pixel `i` with history `previous` (`None`: the previous frame
/// did not see its point).
#[allow(clippy::too_many_arguments)]
#[inline]
fn differential_source(
    fresh_pixel: &Pixel,
    previous: Option<&Pixel>,
    fresh: &FreshLayers,
    i: usize,
    history: &History,
    (camera, camera_to_world): (Pinhole, Affine3A),
    params: &AccumulateParams,
    change: WorldChange,
) -> Differential {
    let eye: Vec3 = camera_to_world.translation.into();
    let p = fresh.world_position.data[i];
    let n = fresh.world_normal.data[i];
    let fresh_has = [0, 2].map(|k| fresh.irradiance[k].data[i].is_finite());
    // The object nearest the pixel's point (on it, for a pixel of an object), if it
    // moved this frame: by the distance to its box, and among boxes that hold the
    // point (overlapping objects), by the distance to the box's centre in units of its
    // half diagonal (the point lies deeper in the box of the object it is on).
    let distance = |m: &ObjectMove| {
        let outside = (p.clamp(m.bounds.min, m.bounds.max) - p).length_squared();
        let half = (m.bounds.max - m.bounds.min)
            .length()
            .max(f32::MIN_POSITIVE)
            * 0.5;
        (outside, (p - m.bounds.center()).length() / half)
    };
    let nearest_moved = change
        .objects
        .iter()
        .min_by(|a, b| {
            let (da, db) = (distance(a), distance(b));
            da.0.total_cmp(&db.0).then(da.1.total_cmp(&db.1))
        })
        .filter(|m| m.moved);
    if fresh_pixel.object {
        // A pixel of a moved object takes the history of the same point of the object
        // where it stood; a still object's shading changes little when another moves.
        return match nearest_moved {
            Some(m) => {
                let q = m.to_earlier.transform_point3(p);
                let n = m.to_earlier.transform_vector3(n).normalize_or_zero();
                match previous_at(q, n, fresh_has, history, camera, eye, params) {
                    Some(source) if source.object => Differential::Whole(source),
                    _ => Differential::Restart,
                }
            }
            None => Differential::Kept,
        };
    }
    // A real surface point: its differential changes where an object that moved this
    // frame is the nearest one and reached it, now or before (or stood on it).
    let reached = fresh_pixel.touched != 0 || previous.is_some_and(|p| p.touched != 0 || p.object);
    match nearest_moved {
        Some(m) if reached => {
            let q = m.to_earlier.transform_point3(p);
            match previous_at(q, n, fresh_has, history, camera, eye, params) {
                Some(source) if !source.object => Differential::Carried(source),
                _ => Differential::Dropped,
            }
        }
        _ => Differential::Kept,
    }
}

/// Step 4: [`blend`] for E_R and the rest, the differential from `source`.
#[inline]
fn blend_changing(
    fresh: &Pixel,
    previous: &Pixel,
    source: Differential,
    max_history: f32,
) -> Pixel {
    let mut out = blend(fresh, previous, max_history);
    let (from, frames) = match source {
        Differential::Kept => {
            if previous.differential_frames == previous.frames {
                // Every frame of the history is of the objects where they stand now.
                return out;
            }
            (*previous, previous.differential_frames)
        }
        Differential::Dropped | Differential::Restart | Differential::Whole(_) => (*previous, 0.0),
        Differential::Carried(source) => (source, source.differential_frames),
    };
    if !matches!(source, Differential::Kept) {
        // The nearest occluders and the paths that met objects: this frame's, and
        // those the carried history saw of the object where it stood.
        (out.direct_min, out.indirect_min, out.touched) = match source {
            Differential::Carried(s) => (
                fresh.direct_min.min(s.direct_min),
                fresh.indirect_min.min(s.indirect_min),
                fresh.touched | s.touched,
            ),
            _ => (fresh.direct_min, fresh.indirect_min, fresh.touched),
        };
    }
    let m = (frames + 1.0).min(max_history);
    let weight = 1.0 / m;
    for (r, rv) in [(0, 2), (1, 3)] {
        let (new_rv, old_rv) = (fresh.irradiance[rv], from.irradiance[rv]);
        let (new_r, old_r) = (fresh.irradiance[r], from.irradiance[r]);
        out.irradiance[rv] = if new_r.is_finite() && old_r.is_finite() {
            // E_R from the whole history, the differential from its own frames.
            let (new_d, old_d) = (new_rv - new_r, old_rv - old_r);
            out.irradiance[r] + (old_d + (new_d - old_d) * weight)
        } else {
            // No real surface (a pixel of an object): E_RV alone, over its own frames.
            old_rv + (new_rv - old_rv) * weight
        };
    }
    out.differential_frames = m;
    out
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
    // Which layers this pixel has (E_R^dir, E_RV^dir stand for their pairs), once.
    let fresh_has = [0, 2].map(|k| fresh.irradiance[k].data[i].is_finite());
    previous_at(p, n, fresh_has, history, camera, eye, params)
}

/// The history of the surface point `p` (normal `n`, with the layers `fresh_has`), if
/// the previous frame saw it: step 1 for any point.
#[inline(always)]
fn previous_at(
    p: Vec3,
    n: Vec3,
    fresh_has: [bool; 2],
    history: &History,
    camera: Pinhole,
    eye: Vec3,
    params: &AccumulateParams,
) -> Option<Pixel> {
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
