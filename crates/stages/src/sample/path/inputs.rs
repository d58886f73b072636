//! What `sample.path`'s estimator reads for one frame: [`PathInputs`].

use glam::Affine3A;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Vec3Image};
use relume_scene::light::voxels::VoxelVolume;
use relume_scene::light::{EnvMap, LightTable, SpotLight};
use relume_scene::objects::VirtualScene;

/// What [`sample_path`](super::sample_path) reads for one frame.
#[derive(Clone, Copy)]
pub struct PathInputs<'a> {
    /// Depth in metres (0 or non-finite = missing): the real geometry.
    pub depth: &'a DepthImage,
    /// Camera-space unit normals facing the camera, zero = invalid.
    pub normals: &'a Vec3Image,
    /// Compensated linear camera radiance: what an indirect ray brings from a real hit.
    pub radiance: &'a Vec3Image,
    /// The depth camera, at the depth map's size.
    pub camera: Pinhole,
    pub camera_to_world: Affine3A,
    /// Importance samples of the environment, in stratified order.
    pub table: &'a LightTable,
    /// The distance impostor the `em` and `dit` queries read (unused by the others).
    pub environment: Option<&'a EnvMap>,
    /// The scene's voxel volume the `vct` query reads (unused by the others).
    pub voxels: Option<&'a VoxelVolume>,
    pub objects: &'a VirtualScene,
    /// With `object_visibility` voxels: the objects' solid volume
    /// ([`PathParams::object_volume`](super::PathParams::object_volume)); built for the
    /// call when `None`.
    pub object_voxels: Option<&'a VoxelVolume>,
    /// The pipeline's spot lights (`[[light]]`), real and virtual.
    pub spots: &'a [SpotLight],
    /// The frame index (a key of the random numbers).
    pub frame: u64,
}
