//! The pipeline's spot lights (`[[light]]`, paper 002 Sec. 3.7) in `sample.path`: a
//! point source's direct light is exact with one shadow ray, so it is added to the
//! layers after the Monte Carlo estimate, deterministically, with the flags of paper
//! 002 eqs. 4-5: a real spot adds its light to E_R with the real visibility and to
//! E_RV with the real and the virtual; a virtual spot adds to E_RV only, real points
//! included.
//!
//! Per pixel: at its real point (raised as the estimator's rays are) the real
//! visibility is the query's screen-space march towards the lamp within
//! `max_distance` (`ssrt`; the world-space queries model no real geometry near the
//! points, so nothing real blocks a spot there), the virtual one a ray through the
//! objects' BVH. Where the pixel shows an object (mask M < 1), E_RV mixes the real
//! point's light (weight M) with that at the object the pixel centre's view ray meets
//! (weight 1 - M), tested the same way from there, itself included.
//!
//! Where it departs: one point per pixel (the centre) where the estimator draws
//! sub-pixel primaries, so the objects' edges take the spot's light at the centre's
//! surface; the mesh always gives the objects' shadows (`object_visibility` and
//! `visibility` do not apply).

use super::kernel::Kernel;
use crate::sample::layers::{IrradianceLayers, LayerRow, shade_rows};
use glam::{Vec3, Vec3A};
use relume_scene::light::{LightWorld, SpotLight};

/// The spots' light at one point: E_R's and E_RV's shares, whether they differ, and
/// the nearest blocker over the cosine.
#[derive(Clone, Copy, Default)]
struct Lit {
    r: Vec3,
    rv: Vec3,
    touched: bool,
    nearest: Option<f32>,
}

/// Adds the spots' direct light to the pixels the estimator shaded (rows and columns
/// `stride` apart).
pub(super) fn add_spots(
    kernel: &Kernel,
    spots: &[SpotLight],
    stride: usize,
    out: &mut IrradianceLayers,
) {
    let w = kernel.inputs.depth.width as usize;
    shade_rows(
        out,
        w,
        stride,
        || (),
        |_, y, mut row| {
            for x in 0..w {
                add_pixel(kernel, spots, x, y, &mut row);
            }
        },
    );
}

fn add_pixel(kernel: &Kernel, spots: &[SpotLight], x: usize, y: usize, row: &mut LayerRow<'_>) {
    let inputs = kernel.inputs;
    let i = y * inputs.depth.width as usize + x;
    let (z, n) = (inputs.depth.data[i], inputs.normals.data[i]);
    let real = kernel.real_point(x as u32, y as u32, z, n);
    let at_real = real
        .as_ref()
        .map(|p| lit(kernel, spots, p.surface, p.world, p.normal_world, true));
    let mask = row.mask[x];
    let at_object = (mask < 1.0)
        .then(|| object_at_centre(kernel, x, y, real.as_ref().map(|p| p.surface)))
        .flatten()
        .map(|(p, n)| lit(kernel, spots, p, p + n * 1e-4, n, false));
    let rv = match (at_real, at_object) {
        (Some(r), Some(o)) => r.rv * mask + o.rv * (1.0 - mask),
        (None, Some(o)) => o.rv,
        (Some(r), None) => r.rv,
        (None, None) => return,
    };
    if let Some(r) = at_real {
        row.e_r_dir[x] += r.r;
    }
    row.e_rv_dir[x] += rv;
    for l in [at_real, at_object].into_iter().flatten() {
        if l.touched {
            row.touched[x] = 1;
        }
        if let Some(d) = l.nearest {
            row.direct_min_distance[x] = row.direct_min_distance[x].min(d);
        }
    }
}

/// The spots' light at `surface` with unit normal `normal`, shadow rays leaving from
/// `origin` (raised off it); `real_point`: a real point (it has an E_R).
fn lit(
    kernel: &Kernel,
    spots: &[SpotLight],
    surface: Vec3,
    origin: Vec3,
    normal: Vec3,
    real_point: bool,
) -> Lit {
    let mut lit = Lit::default();
    for spot in spots {
        let Some(arrival) = spot.arrival(surface, normal) else {
            continue;
        };
        let (to_light, d) = (arrival.to_light, arrival.distance);
        let real_blocker = match kernel.query.world_query {
            Some(_) => None,
            None => kernel
                .query
                .tracer
                .trace(origin, to_light, d.min(kernel.query.max_distance))
                .map(|hit| hit.t),
        };
        let virtual_blocker = kernel
            .inputs
            .objects
            .intersect(origin, to_light, 0.0, d * (1.0 - 1e-3))
            .map(|hit| hit.t);
        let (st_r, st_v) = (
            real_blocker.map_or(1.0, |_| 0.0),
            virtual_blocker.map_or(1.0, |_| 0.0),
        );
        let light = arrival.irradiance;
        let real_light = spot.world == LightWorld::Real;
        if real_light && real_point {
            lit.r += light * st_r;
        }
        lit.rv += light * (st_r * st_v);
        if !(real_light && real_point) || st_v < st_r {
            lit.touched = true;
        }
        if let Some(t) = real_blocker
            .into_iter()
            .chain(virtual_blocker)
            .reduce(f32::min)
        {
            let over_cos = t / arrival.cos.max(1e-3);
            lit.nearest = Some(lit.nearest.map_or(over_cos, |n| n.min(over_cos)));
        }
    }
    lit
}

/// The object the view ray through pixel (x, y)'s centre meets in front of the real
/// point `real` (if any): its position and unit normal.
fn object_at_centre(
    kernel: &Kernel,
    x: usize,
    y: usize,
    real: Option<Vec3>,
) -> Option<(Vec3, Vec3)> {
    let inputs = kernel.inputs;
    if inputs.objects.is_empty() {
        return None;
    }
    let origin = kernel.camera_position;
    let dir = Vec3::from(kernel.to_world * Vec3A::from(inputs.camera.ray(x as f32, y as f32)))
        .normalize();
    let t_max = real.map_or(f32::INFINITY, |p| p.distance(origin));
    inputs
        .objects
        .intersect(origin, dir, 0.0, t_max)
        .map(|hit| (hit.position, hit.normal))
}
