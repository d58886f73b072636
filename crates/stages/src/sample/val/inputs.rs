//! What `sample.val` is asked to shade: the settings ([`ValShadingParams`]) and one
//! frame's inputs ([`ValInputs`]), shared by the stage, the renderer and the pixels.

use glam::Affine3A;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Vec3Image};
use relume_scene::light::prt::Transfer;
use relume_scene::light::{AreaLights, SpotLight};
use relume_scene::objects::VirtualScene;

/// Settings of [`ValRenderer::render`](super::ValRenderer::render) (the stage's parameters).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValShadingParams {
    pub shadow_map_size: usize,
    pub virtual_bias: f32,
    pub real_bias: f32,
    pub slope_bias: f32,
    pub real_occluder_reach: f32,
    /// Lights whose shadow maps are rebuilt per frame, in turn; 0 = all.
    pub shadow_updates: usize,
    /// Light between the objects (paper 004 Sec. 4.4, `bounce.rs`), through the
    /// transfer's bounce part.
    pub object_bounce: bool,
}

impl Default for ValShadingParams {
    fn default() -> Self {
        ValShadingParams {
            shadow_map_size: 128,
            virtual_bias: 0.005,
            real_bias: 0.02,
            slope_bias: 1.5,
            real_occluder_reach: 1.0,
            shadow_updates: 0,
            object_bounce: true,
        }
    }
}

/// One frame's inputs.
#[derive(Clone, Copy)]
pub struct ValInputs<'a> {
    /// Metres, 0 or non-finite = missing.
    pub depth: &'a DepthImage,
    /// Camera-space unit normals facing the camera (zero = invalid), same size.
    pub normals: &'a Vec3Image,
    /// The camera of `depth` (rescaled to its size).
    pub camera: Pinhole,
    pub camera_to_world: Affine3A,
    pub lights: &'a AreaLights,
    pub objects: &'a VirtualScene,
    /// The objects' radiance transfer (paper 004 eq. 11) for their indirect light, or
    /// `None` for the unoccluded SH9 irradiance at the normal.
    pub transfer: Option<&'a Transfer>,
    /// The pipeline's spot lights (`[[light]]`, paper 002 Sec. 3.7), shaded after the
    /// area lights (`spots.rs`).
    pub spots: &'a [SpotLight],
}
