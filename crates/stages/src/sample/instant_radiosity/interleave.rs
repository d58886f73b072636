//! The interleaved gather of a frame (paper 002 Sec. 3.2, step 4 of the module docs):
//! row by row, and within a row class by class (the paper's split G-buffer: a class's
//! VPLs and their maps stay in cache over its pixels). Per class of a row, the real
//! points gather as real receivers and the objects' points the view rays meet gather
//! as virtual ones, eight at a time where lanes run (`gather_lanes.rs`, the same
//! bits as one at a time).

use super::gather_lanes::gather_each;
use super::params::DirInputs;
use super::points::RealSurface;
use super::shade::{Gathered, LightSet, Receiver};
use crate::sample::layers::{LayerRow, PixelLayers};
use glam::Vec3;
use relume_base::simd::Kernel;
use relume_scene::objects::VirtualHit;

/// What the gather of a frame reads.
pub(super) struct Interleaved<'a> {
    pub inputs: &'a DirInputs<'a>,
    pub lights: &'a LightSet<'a>,
    pub real: &'a RealSurface,
    /// Per class, its VPLs.
    pub members: &'a [Vec<u32>],
    /// The tiles' side (k x k classes).
    pub k: usize,
    /// The lanes, or one receiver at a time (`None`).
    pub kernel: Option<Kernel>,
    /// `[x0, y0, x1, y1)`: no view ray outside it meets an object ([`object_rect`]).
    pub object_rect: [usize; 4],
}

/// A row's buffers, reused from row to row.
#[derive(Default)]
pub(super) struct RowScratch {
    /// The class's pixels (columns).
    xs: Vec<usize>,
    /// Per pixel: what its real point gathers (none without a real point).
    real: Vec<Option<Gathered>>,
    /// Per pixel: the object its view ray meets in front of the real point.
    hits: Vec<Option<VirtualHit>>,
    /// The pixels (indices into `xs`) with a hit, and what their hits gather.
    hit_pixels: Vec<usize>,
    at_hits: Vec<Gathered>,
}

impl Interleaved<'_> {
    /// Gathers row `y` into `row` (the un-blurred layers, times the interleaving scale).
    pub fn shade_row(&self, y: usize, row: &mut LayerRow<'_>, scratch: &mut RowScratch) {
        let w = self.inputs.depth.width as usize;
        let k = self.k;
        let scale = (k * k) as f32;
        let in_rect_row = (self.object_rect[1]..self.object_rect[3]).contains(&y);
        for cx in 0..k.min(w) {
            let members = &self.members[(y % k) * k + cx];
            let RowScratch {
                xs,
                real,
                hits,
                hit_pixels,
                at_hits,
            } = scratch;
            xs.clear();
            xs.extend((cx..w).step_by(k));
            // A pixel has a real point where it has a normal.
            let real_point = |x: &usize| {
                let i = y * w + x;
                let (p, n) = (self.real.position[i], self.real.normal[i]);
                (n != Vec3::ZERO).then_some((p, n))
            };
            real.clear();
            gather_each(
                self.kernel,
                self.lights,
                members,
                Receiver::Real,
                xs,
                real_point,
                |g| real.push(g),
            );
            hits.clear();
            hits.extend(xs.iter().map(|&x| {
                let inside = in_rect_row && (self.object_rect[0]..self.object_rect[2]).contains(&x);
                if inside {
                    let real_point = real_point(&x).map(|(p, _)| p);
                    primary_hit(self.inputs, x, y, real_point)
                } else {
                    None
                }
            }));
            hit_pixels.clear();
            hit_pixels.extend(hits.iter().enumerate().filter_map(|(j, h)| h.map(|_| j)));
            at_hits.clear();
            let hit_points = |&j: &usize| hits[j].map(|hit| (hit.position, hit.normal));
            gather_each(
                self.kernel,
                self.lights,
                members,
                Receiver::Virtual,
                hit_pixels,
                hit_points,
                |g| at_hits.push(g.expect("a gather")),
            );
            let mut at_hit = at_hits.iter();
            for ((&x, r), hit) in xs.iter().zip(real.iter()).zip(hits.iter()) {
                let i = y * w + x;
                let out = match (hit, r) {
                    (Some(hit), r) => {
                        let v = *at_hit.next().expect("a gather per hit");
                        pixel(Some(hit), r.unwrap_or(NO_LIGHT), v, scale)
                    }
                    (None, Some(r)) => pixel(None, *r, *r, scale),
                    (None, None) => {
                        row.set(x, &NOTHING);
                        continue;
                    }
                };
                row.set(x, &out);
                if r.is_none() {
                    // No real point behind the object: E_R has no estimate.
                    row.e_r_dir[x] = Vec3::NAN;
                    row.e_r_ind[x] = Vec3::NAN;
                }
                if hit.is_none() {
                    row.world_position[x] = self.real.position[i];
                    row.world_normal[x] = self.real.normal[i];
                }
            }
        }
    }
}

/// The rectangle `[x0, y0, x1, y1)` of pixels whose view rays may meet the objects:
/// the box of the projections of their bounding box's corners, two pixels wider on
/// each side; the whole image when a corner is not in front of the camera; empty
/// without objects.
pub(super) fn object_rect(inputs: &DirInputs) -> [usize; 4] {
    let (w, h) = (inputs.depth.width as usize, inputs.depth.height as usize);
    if inputs.objects.is_empty() {
        return [0; 4];
    }
    let b = inputs.objects.bounds();
    let world_to_camera = inputs.camera_to_world.inverse();
    let (mut lo, mut hi) = (glam::Vec2::INFINITY, glam::Vec2::NEG_INFINITY);
    for corner in 0..8 {
        let pick = |bit: usize, min: f32, max: f32| if corner & bit == 0 { min } else { max };
        let p = Vec3::new(
            pick(1, b.min.x, b.max.x),
            pick(2, b.min.y, b.max.y),
            pick(4, b.min.z, b.max.z),
        );
        let Some(uv) = inputs
            .camera
            .project(world_to_camera.transform_point3(p))
            .filter(|uv| uv.is_finite())
        else {
            return [0, 0, w, h];
        };
        lo = lo.min(uv);
        hi = hi.max(uv);
    }
    let clamp = |v: f32, size: usize| v.clamp(0.0, size as f32) as usize;
    [
        clamp(lo.x.floor() - 2.0, w),
        clamp(lo.y.floor() - 2.0, h),
        clamp(hi.x.ceil() + 3.0, w),
        clamp(hi.y.ceil() + 3.0, h),
    ]
}

/// The object the view ray through pixel (x, y) meets in front of the real point
/// `real` (if any).
pub(super) fn primary_hit(
    inputs: &DirInputs,
    x: usize,
    y: usize,
    real: Option<Vec3>,
) -> Option<VirtualHit> {
    if inputs.objects.is_empty() {
        return None;
    }
    let origin: Vec3 = inputs.camera_to_world.translation.into();
    let dir = inputs
        .camera_to_world
        .transform_vector3(inputs.camera.ray(x as f32, y as f32))
        .normalize();
    let t_max = real.map_or(f32::INFINITY, |p| p.distance(origin));
    let (t0, t1) = inputs
        .objects
        .bounds()
        .ray_span(origin, dir.recip(), 0.0, t_max)?;
    inputs
        .objects
        .intersect(origin, dir, (t0 - 1e-4).max(0.0), t1 + 1e-4)
}

/// A pixel with neither a real point nor an object.
const NOTHING: PixelLayers = PixelLayers {
    e_r_dir: Vec3::NAN,
    e_r_ind: Vec3::NAN,
    e_rv_dir: Vec3::NAN,
    e_rv_ind: Vec3::NAN,
    mask: 1.0,
    k_v: Vec3::ZERO,
    exponent: 0.0,
    world_position: Vec3::NAN,
    world_normal: Vec3::ZERO,
    direct_min_distance: f32::INFINITY,
    indirect_min_distance: f32::INFINITY,
    touched: false,
};

const NO_LIGHT: Gathered = Gathered {
    r_dir: Vec3::NAN,
    r_ind: Vec3::NAN,
    rv_dir: Vec3::ZERO,
    rv_ind: Vec3::ZERO,
    touched: true,
    direct_min_distance: f32::INFINITY,
    indirect_min_distance: f32::INFINITY,
};

/// One pixel's un-blurred layers: E_R from the real point `r`, E_RV from `v` (the
/// object's point where `hit`, else the same real point), both times the interleaving
/// `scale`.
fn pixel(hit: Option<&VirtualHit>, r: Gathered, v: Gathered, scale: f32) -> PixelLayers {
    PixelLayers {
        e_r_dir: r.r_dir * scale,
        e_r_ind: r.r_ind * scale,
        e_rv_dir: v.rv_dir * scale,
        e_rv_ind: v.rv_ind * scale,
        mask: if hit.is_some() { 0.0 } else { 1.0 },
        k_v: hit.map_or(Vec3::ZERO, |h| h.material.albedo),
        exponent: 0.0,
        world_position: hit.map_or(Vec3::NAN, |h| h.position),
        world_normal: hit.map_or(Vec3::ZERO, |h| h.normal),
        direct_min_distance: r.direct_min_distance.min(v.direct_min_distance),
        indirect_min_distance: r.indirect_min_distance.min(v.indirect_min_distance),
        touched: hit.is_some() || r.touched,
    }
}
