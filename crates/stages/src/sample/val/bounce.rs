//! Light between the virtual objects (paper 004 Sec. 4.4, Fig. 7 bottom): what the
//! other objects reflect onto an object, as nine SH coefficients per object.
//!
//! The paper renders, per object, a cube map from its centre holding the reconstructed
//! room and the other n - 1 objects (lit by their PRT, then a second map with their
//! direct light too: 2n cube maps) and projects it onto the SH basis. Here the room's
//! part is already in every vertex's transfer C_vk, which leaves out the directions an
//! object blocks; so the map from object i's centre holds only the other objects'
//! radiance, k_j / pi (E_RV^dir + E^ind) at the first point of another object each
//! direction meets (the area lights through their shadow maps, the spots through
//! theirs, the room's indirect light through that point's transfer), and zero where
//! no other object is met. Its SH coefficients reach object i's surface through the
//! bounce transfer B_vk ([`Transfer::bounce`]): the paper's V cos(theta), V the
//! object's occlusion of itself only. As in the paper the light is the one the centre
//! sees: a point on the side facing another object gets about (d / D)^2 of what its
//! own view would give it (d and D its distance and the centre's from the other
//! object's centre; 0.4 for a ball 0.1 m from a larger one), a point facing away a few
//! per cent of the brightest, of either sign (SH9 ringing).
//!
//! Where it departs: one bounce (the paper's b - 1 bounces over b static frames are
//! not accumulated); a lat-long map of [`MAP_WIDTH`] x [`MAP_WIDTH`] / 2 directions
//! (the paper's 6 x 32 x 32 cube); objects are diffuse here as everywhere in
//! `sample.val`; the real surfaces receive no light from the objects (as in the paper,
//! Sec. 7).

use super::ValInputs;
use super::pixel::PointArrays;
use super::shade::{Biases, Maps, PreparedLight};
use super::shade_lanes::shade_points;
use super::shadow::PointSampling;
use super::spots::SpotMaps;
use glam::{Vec3, Vec3A};
use rayon::prelude::*;
use relume_base::simd::{LANES, Portable};
use relume_scene::light::EnvMap;
use relume_scene::light::prt::{Transfer, barycentrics, object_count};
use relume_scene::light::sh::project_sh9;
use relume_scene::objects::{Aabb, VirtualHit, VirtualScene};
use std::f32::consts::FRAC_1_PI;

/// Columns of each object's map of the others (rows: half as many).
pub(super) const MAP_WIDTH: u32 = 64;

/// Own surfaces a direction may cross before it leaves its object (a torus: four).
const MAX_OWN_HITS: usize = 16;

/// What the bounce's shading reads: the frame's lights and their maps.
pub(super) struct BounceLights<'a> {
    pub lights: &'a [PreparedLight],
    pub maps: Maps<'a>,
    pub biases: Biases,
    /// The spots' maps, when the pipeline has spots.
    pub spot_maps: Option<&'a SpotMaps>,
    pub sampling: PointSampling,
}

/// Per object (material index), the radiance SH coefficients of the other objects as
/// seen from its centre; empty when the scene has fewer than two objects or
/// `transfer` has no bounce part.
pub(super) fn object_bounce(
    inputs: &ValInputs,
    transfer: &Transfer,
    light: &BounceLights,
) -> Vec<[Vec3; 9]> {
    let scene = inputs.objects;
    let n = object_count(scene);
    if n < 2 || transfer.bounce.is_empty() {
        return Vec::new();
    }
    let centres = object_centres(scene, n);
    let (width, height) = (MAP_WIDTH, MAP_WIDTH / 2);
    let texels = (width * height) as usize;
    (0..n)
        .map(|object| {
            let Some(centre) = centres[object] else {
                return [Vec3::ZERO; 9];
            };
            let hits: Vec<Option<VirtualHit>> = (0..texels)
                .into_par_iter()
                .map(|i| {
                    let (column, row) = ((i as u32 % width) as f32, (i as u32 / width) as f32);
                    let d = EnvMap::direction_at(column + 0.5, row + 0.5, width, height);
                    first_other_hit(scene, centre, d, object as u32)
                })
                .collect();
            let radiance: Vec<Vec3> = hits
                .par_chunks(LANES)
                .flat_map_iter(|chunk| radiance_of(chunk, inputs, transfer, light))
                .collect();
            project_sh9(&EnvMap::distant(width, height, radiance))
        })
        .collect()
}

/// Each object's bounding-box centre (`None` for an index no triangle has).
fn object_centres(scene: &VirtualScene, n: usize) -> Vec<Option<Vec3>> {
    let mut boxes = vec![Aabb::EMPTY; n];
    for t in &scene.triangles {
        for v in t.vertices {
            boxes[t.material as usize].grow(v);
        }
    }
    boxes
        .iter()
        .map(|b| (b.min.x <= b.max.x).then(|| (b.min + b.max) * 0.5))
        .collect()
}

/// The first point along `centre + t d` on an object other than `own`, crossing up
/// to [`MAX_OWN_HITS`] of `own`'s surfaces.
fn first_other_hit(scene: &VirtualScene, centre: Vec3, d: Vec3, own: u32) -> Option<VirtualHit> {
    let mut t_min = 0.0;
    for _ in 0..MAX_OWN_HITS {
        let hit = scene.intersect(centre, d, t_min, f32::INFINITY)?;
        if scene.triangles[hit.triangle as usize].material != own {
            return Some(hit);
        }
        t_min = hit.t * (1.0 + 1e-5) + 1e-6;
    }
    None
}

/// The radiance k / pi (E_RV^dir + E^ind) each hit of `chunk` (at most [`LANES`])
/// sends back along its ray; zero where there is no hit.
fn radiance_of(
    chunk: &[Option<VirtualHit>],
    inputs: &ValInputs,
    transfer: &Transfer,
    light: &BounceLights,
) -> Vec<Vec3> {
    let mut points = PointArrays::default();
    for (l, hit) in chunk.iter().enumerate() {
        if let Some(hit) = hit {
            let p = Vec3A::from(hit.position);
            points.set(l, p, hit.normal.into(), light.sampling.footprint(p));
        }
    }
    let direct = shade_points(
        &points.points::<Portable>(),
        u64::MAX,
        light.lights,
        light.maps,
        light.biases,
    );
    chunk
        .iter()
        .enumerate()
        .map(|(l, hit)| {
            let Some(hit) = hit else {
                return Vec3::ZERO;
            };
            let corners = &inputs.objects.triangles[hit.triangle as usize].vertices;
            let (u, v) = barycentrics(corners, hit.position);
            let indirect =
                Transfer::irradiance(&transfer.at(hit.triangle, u, v), &inputs.lights.sh9);
            let spots = light.spot_maps.map_or(Vec3::ZERO, |maps| {
                let patch = light.sampling.footprint(hit.position.into());
                let (_, e_rv, _) =
                    maps.light_at(inputs.spots, hit.position, hit.normal, patch, light.biases);
                e_rv
            });
            hit.material.albedo * FRAC_1_PI * (direct.lane(l).e_rv + spots + indirect)
        })
        .collect()
}
