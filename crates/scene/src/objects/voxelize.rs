//! Solid voxelization of the virtual objects (paper 000 Sec. 6.2): the opacity tau of
//! the object volume that `sample.path`'s `vct` query marches its visibility cones
//! through. The paper voxelizes on the GPU (Eisemann and Décoret, ref. 8); here each
//! voxel centre is tested against the meshes by ray parity, on the CPU (a slice of
//! the volume per rayon task), once when the stage is built.

use super::VirtualScene;
use crate::light::voxels::{VoxelLevel, VoxelVolume};
use glam::{Vec3, Vec4};
use rayon::prelude::*;

/// Directions of the parity rays: off the axes, so that they rarely graze an edge or
/// run along a face of a box-like mesh.
const PARITY_DIRECTIONS: [Vec3; 3] = [
    Vec3::new(0.8, 0.36, 0.48),
    Vec3::new(-0.36, 0.8, -0.48),
    Vec3::new(0.48, -0.36, 0.8),
];
/// The most crossings counted along a parity ray (a bound for degenerate meshes).
const MAX_CROSSINGS: u32 = 64;

/// The objects' solid volume: `voxels` voxels along the longest side of their bounding
/// box (grown by one voxel on each side), tau = 1 where a voxel centre lies inside a
/// mesh and 0 elsewhere, with its mip levels (whose voxels hold the fraction inside).
/// Inside means an odd number of crossings along at least two of three rays (a mesh
/// that is not closed, the paper's limitation too, gives what the majority says). An
/// empty scene gives an empty volume.
pub fn solid_volume(scene: &VirtualScene, voxels: u32) -> VoxelVolume {
    let bounds = scene.bounds();
    if scene.is_empty() || !(bounds.min.is_finite() && bounds.max.is_finite()) {
        return VoxelVolume::empty();
    }
    let voxels = voxels.max(1);
    let extent = bounds.max - bounds.min;
    let voxel_size = (extent.max_element() / voxels as f32).max(1e-4);
    let dims = ((extent / voxel_size).ceil() + 2.0).as_uvec3().to_array();
    let size = glam::UVec3::from(dims).as_vec3() * voxel_size;
    let origin = (bounds.min + bounds.max) * 0.5 - size * 0.5;
    let n = dims.iter().map(|&d| d as usize).product();
    let mut voxels = vec![Vec4::ZERO; n];
    // A slice of constant z per task: each voxel is decided alone, so the volume does
    // not depend on the thread count.
    let slice = (dims[0] * dims[1]) as usize;
    voxels
        .par_chunks_mut(slice)
        .enumerate()
        .for_each(|(z, plane)| {
            for (i, voxel) in plane.iter_mut().enumerate() {
                let (x, y) = (i % dims[0] as usize, i / dims[0] as usize);
                let cell = Vec3::new(x as f32, y as f32, z as f32);
                if inside(scene, origin + (cell + 0.5) * voxel_size) {
                    *voxel = Vec4::W;
                }
            }
        });
    VoxelVolume::with_levels(origin, voxel_size, VoxelLevel::isotropic(dims, voxels))
}

/// True when `p` lies inside the meshes by a majority of parity rays.
fn inside(scene: &VirtualScene, p: Vec3) -> bool {
    let odd = PARITY_DIRECTIONS
        .iter()
        .filter(|d| crossings(scene, p, d.normalize()) % 2 == 1)
        .count();
    odd >= 2
}

/// Surfaces crossed by the ray from `p` along `dir`.
fn crossings(scene: &VirtualScene, p: Vec3, dir: Vec3) -> u32 {
    let mut t_min = 0.0;
    let mut count = 0;
    while count < MAX_CROSSINGS {
        match scene.intersect(p, dir, t_min, f32::INFINITY) {
            Some(hit) => {
                count += 1;
                t_min = hit.t + 1e-5 * (1.0 + hit.t);
            }
            None => break,
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::{Material, shapes};

    #[test]
    fn a_sphere_fills_its_share_of_the_box() {
        let material = Material {
            albedo: Vec3::splat(0.5),
            exponent: 0.0,
        };
        let scene = VirtualScene::new(shapes::sphere(0.5, 48), vec![material]);
        let volume = solid_volume(&scene, 32);
        let finest = &volume.levels[0];
        let inside: usize = finest.voxels.iter().filter(|v| v.w == 1.0).count();
        let v = volume.voxel_size;
        let filled = inside as f32 * v * v * v;
        let exact = 4.0 / 3.0 * std::f32::consts::PI * 0.125;
        assert!(
            (filled / exact - 1.0).abs() < 0.05,
            "filled {filled} m^3 against {exact} m^3"
        );
        // The centre is solid, a corner of the box empty.
        assert_eq!(volume.sample(Vec3::ZERO, 0.0, Vec3::X).w, 1.0);
        assert_eq!(volume.sample(Vec3::splat(0.49), 0.0, Vec3::X).w, 0.0);
    }

    #[test]
    fn no_objects_give_an_empty_volume() {
        assert!(solid_volume(&VirtualScene::default(), 32).is_empty());
    }
}
