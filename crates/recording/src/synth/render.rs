//! Rendering of the synthetic room: HDR radiance of the first hit with soft shadows from
//! both area lights, the ground-truth maps of a camera view (radiance, depth, normals),
//! and the lat-long environment map seen from the object position.
//!
//! Every random number is drawn from [`relume_base::rng::Counter`] keyed by (seed, frame,
//! purpose, pixel), so the images are the same for any number of threads.

use super::scene::{Hit, OBJECT_POSITION, Ray, Scene, direct_irradiance};
use crate::types::Intrinsics;
use glam::{Mat3, Vec3};
use rayon::prelude::*;
use relume_base::rng::Counter;
use std::f32::consts::PI;

/// Purpose keys of the counter-based random numbers.
pub mod purpose {
    /// Shadow-ray positions on the lights, per camera pixel.
    pub const SHADOW: u64 = 1;
    /// Sub-texel positions and shadow rays of the environment map.
    pub const ENVIRONMENT: u64 = 2;
    /// Gaussian depth noise, per pixel.
    pub const DEPTH_NOISE: u64 = 3;
    /// Hole decisions at grazing angles and depth discontinuities, per pixel.
    pub const DEPTH_HOLES: u64 = 4;
    /// Dropout blobs, per cell of the blob grid.
    pub const DEPTH_DROPOUT: u64 = 5;
}

/// Stratified shadow rays per light and camera pixel: a 4 x 2 grid with one jittered
/// sample per cell.
pub const SHADOW_GRID: (u32, u32) = (4, 2);

/// The frame number that keys the environment map's random numbers (it belongs to no frame).
pub const ENVIRONMENT_FRAME: u64 = u64::MAX;

/// Radiance leaving `hit` back along the ray: an emitter's radiance, or for diffuse
/// surfaces albedo / pi times the irradiance: the direct light of both rectangles
/// (`grid` stratified shadow rays each, [`direct_irradiance`]) plus the light the room
/// reflects onto the point ([`Scene::indirect_irradiance`], solved by [`super::interreflection`]).
pub fn shade(scene: &Scene, hit: &Hit, rng: &mut Counter, grid: (u32, u32)) -> Vec3 {
    let material = scene.material(hit);
    if material.emission != Vec3::ZERO {
        return material.emission;
    }
    let direct = direct_irradiance(scene, hit.position, hit.normal, rng, grid);
    material.albedo * ((direct + scene.indirect_irradiance(hit)) / PI)
}

/// A pinhole view: camera-to-world rotation (camera x right, y down, z forward) and
/// position, with the intrinsics that map pixels to rays.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub rotation: Mat3,
    pub position: Vec3,
    pub intrinsics: Intrinsics,
}

/// The camera-space direction through the centre of pixel (x, y), scaled to z = 1.
#[inline]
pub fn pixel_direction(k: &Intrinsics, x: u32, y: u32) -> Vec3 {
    Vec3::new(
        ((x as f64 - k.cx) / k.fx) as f32,
        ((y as f64 - k.cy) / k.fy) as f32,
        1.0,
    )
}

/// Ground truth of one view, row-major, `width * height` entries each.
#[derive(Clone, Debug, PartialEq)]
pub struct TruthMaps {
    pub width: u32,
    pub height: u32,
    /// HDR linear RGB radiance reaching each pixel.
    pub radiance: Vec<Vec3>,
    /// Camera-space z in metres (0 where nothing was hit).
    pub depth: Vec<f32>,
    /// Camera-space unit normals facing the camera (zero where nothing was hit).
    pub normals: Vec<Vec3>,
}

/// Renders the ground truth of `view`: one ray through each pixel centre.
pub fn render_view(scene: &Scene, view: &View, seed: u64, frame: u64) -> TruthMaps {
    let k = view.intrinsics;
    let width = k.width as usize;
    let world_to_camera = view.rotation.transpose();
    let mut pixels = vec![(Vec3::ZERO, 0.0f32, Vec3::ZERO); width * k.height as usize];
    pixels
        .par_chunks_mut(width.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let d_cam = pixel_direction(&k, x as u32, y as u32);
                let ray = Ray {
                    origin: view.position,
                    direction: view.rotation * d_cam,
                };
                let Some(hit) = scene.intersect(&ray, 0.0) else {
                    continue;
                };
                let pixel = (y * width + x) as u64;
                let mut rng = Counter::new(&[seed, frame, purpose::SHADOW, pixel]);
                let radiance = shade(scene, &hit, &mut rng, SHADOW_GRID);
                let mut normal = (world_to_camera * hit.normal).normalize_or_zero();
                if normal.dot(d_cam) > 0.0 {
                    normal = -normal;
                }
                // d_cam has z = 1 and the rotation is orthonormal, so t is the depth.
                *out = (radiance, hit.t, normal);
            }
        });
    TruthMaps {
        width: k.width,
        height: k.height,
        radiance: pixels.iter().map(|p| p.0).collect(),
        depth: pixels.iter().map(|p| p.1).collect(),
        normals: pixels.iter().map(|p| p.2).collect(),
    }
}

/// The world direction of lat-long texel (`column`, `row`) of a `width` x `height` map:
/// theta = (row + 0.5) / height * pi from world +y, phi = (column + 0.5) / width * 2 pi
/// from +x towards +z, d = (sin theta cos phi, cos theta, sin theta sin phi). Fractional
/// texel coordinates give directions inside the texel.
pub fn latlong_direction(column: f32, row: f32, width: u32, height: u32) -> Vec3 {
    let theta = row / height as f32 * PI;
    let phi = column / width as f32 * 2.0 * PI;
    Vec3::new(
        theta.sin() * phi.cos(),
        theta.cos(),
        theta.sin() * phi.sin(),
    )
}

/// Sub-texel samples per environment-map texel (a jittered 2 x 2 grid).
const ENVIRONMENT_SUBSAMPLES: u32 = 2;

/// Renders the HDR lat-long environment map seen from [`OBJECT_POSITION`]: `width` x
/// `height` texels of linear RGB, interleaved, row 0 towards world +y (see
/// [`latlong_direction`]). Each texel averages a jittered 2 x 2 grid of rays.
pub fn render_environment(scene: &Scene, seed: u64, width: u32, height: u32) -> Vec<f32> {
    let w = width as usize;
    let mut texels = vec![0.0f32; w * height as usize * 3];
    texels
        .par_chunks_mut((w * 3).max(1))
        .enumerate()
        .for_each(|(row, out)| {
            for (column, rgb) in out.chunks_exact_mut(3).enumerate() {
                let texel = (row * w + column) as u64;
                let mut rng = Counter::new(&[seed, ENVIRONMENT_FRAME, purpose::ENVIRONMENT, texel]);
                let mut sum = Vec3::ZERO;
                let n = ENVIRONMENT_SUBSAMPLES;
                for sy in 0..n {
                    for sx in 0..n {
                        let c = column as f32 + (sx as f32 + rng.next_f32()) / n as f32;
                        let r = row as f32 + (sy as f32 + rng.next_f32()) / n as f32;
                        let ray = Ray {
                            origin: OBJECT_POSITION,
                            direction: latlong_direction(c, r, width, height),
                        };
                        if let Some(hit) = scene.intersect(&ray, 0.0) {
                            sum += shade(scene, &hit, &mut rng, SHADOW_GRID);
                        }
                    }
                }
                let mean = sum / (n * n) as f32;
                rgb.copy_from_slice(&mean.to_array());
            }
        });
    texels
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latlong_convention_puts_up_at_the_top_and_phi_zero_at_plus_x() {
        let up = latlong_direction(0.0, 0.0, 256, 128);
        assert!((up - Vec3::Y).length() < 1e-6);
        let x = latlong_direction(0.0, 64.0, 256, 128);
        assert!((x - Vec3::X).length() < 1e-6);
        let z = latlong_direction(64.0, 64.0, 256, 128);
        assert!((z - Vec3::Z).length() < 1e-6);
    }

    #[test]
    fn lit_floor_is_brighter_than_shadowed_floor_and_emitters_return_their_radiance() {
        let scene = crate::synth::interreflection::room();
        let down = |x: f32, z: f32| Ray {
            origin: Vec3::new(x, 2.0, z),
            direction: Vec3::NEG_Y,
        };
        let mut rng = Counter::new(&[1]);
        let open = scene.intersect(&down(0.0, 0.0), 0.0).unwrap();
        let lit = shade(&scene, &open, &mut rng, (8, 8));
        // Right beside the ball on the side away from both lights: partly shadowed.
        let c = scene.ball.center;
        let under = scene.intersect(&down(c.x - 0.36, c.z - 0.2), 0.0).unwrap();
        let shadowed = shade(&scene, &under, &mut rng, (8, 8));
        assert!(lit.y > 1.5 * shadowed.y, "lit {lit} shadowed {shadowed}");
        let up = scene
            .intersect(
                &Ray {
                    origin: Vec3::new(0.0, 1.0, 0.0),
                    direction: Vec3::Y,
                },
                0.0,
            )
            .unwrap();
        assert_eq!(
            shade(&scene, &up, &mut rng, SHADOW_GRID),
            scene.lights[0].radiance
        );
    }

    #[test]
    fn depth_is_camera_z_and_normals_face_the_camera() {
        let scene = crate::synth::interreflection::room();
        let intrinsics = Intrinsics::PRIMESENSE.scaled_to(32, 24);
        // Camera at the room centre looking down +x (world): camera z = world +x,
        // camera x = world +z, camera y = world -y.
        let rotation = Mat3::from_cols(Vec3::Z, Vec3::NEG_Y, Vec3::X);
        let view = View {
            rotation,
            position: Vec3::new(0.0, 1.3, 0.0),
            intrinsics,
        };
        let maps = render_view(&scene, &view, 1, 0);
        for (i, (&z, n)) in maps.depth.iter().zip(&maps.normals).enumerate() {
            let d = pixel_direction(&intrinsics, (i % 32) as u32, (i / 32) as u32);
            assert!(z > 0.0);
            assert!((n.length() - 1.0).abs() < 1e-5 && n.dot(d) < 0.0);
        }
        // The centre pixel sees the east wall 2.5 m away, straight on.
        let centre = 12 * 32 + 16;
        assert!(
            (maps.depth[centre] - 2.5).abs() < 1e-4,
            "{}",
            maps.depth[centre]
        );
    }
}
