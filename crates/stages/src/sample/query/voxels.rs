//! `vct`: Voxel Cone Tracing (paper 000 Secs. 6.1 and 6.5, after Crassin et al.): the
//! ray's cone marched through the scene volume of `light.voxels`.

use super::interface::{Hit, RadianceQuery, Ray, Source};
use relume_scene::light::voxels::VoxelVolume;

/// Below this opacity a cone is taken to have met nothing (the environment at
/// infinity answers): the radiance of a nearly clear cone, divided by its opacity,
/// would stand on a few stray voxels.
pub const MIN_OPACITY: f32 = 0.05;

/// The scene volume answering cones. A cone starts `start` metres along its axis (a
/// finest voxel: the voxel of the surface it leaves is not its own occluder). Its
/// answer is the radiance it gathered divided by its opacity (the part of the cone
/// the volume left clear, the volume's holes and what lies beyond it, is taken to see
/// what the rest saw), from the distance where it became half opaque, as
/// [`Source::Environment`]: the volume holds the room's light itself.
pub struct VoxelQuery<'a> {
    pub volume: &'a VoxelVolume,
    pub start: f32,
}

impl<'a> VoxelQuery<'a> {
    /// The query over `volume`, starting cones a finest voxel out.
    pub fn new(volume: &'a VoxelVolume) -> VoxelQuery<'a> {
        VoxelQuery {
            volume,
            start: volume.voxel_size,
        }
    }
}

impl RadianceQuery for VoxelQuery<'_> {
    fn query(&self, ray: &Ray) -> Option<Hit> {
        let m = self
            .volume
            .march(ray.origin, ray.dir, ray.spread, self.start, ray.t_max);
        (m.opacity >= MIN_OPACITY).then(|| Hit {
            t: m.t_half,
            radiance: m.radiance / m.opacity,
            source: Source::Environment,
        })
    }
}

/// The spread (tangent of the half aperture) of each of `samples` cones sharing a
/// hemisphere: the cone whose solid angle is 2 pi / samples (cos = 1 - 1 / samples),
/// narrowed to a Phong lobe's half width at half maximum (cos^exponent = 1/2) when
/// `exponent` > 0, at most [`MAX_SPREAD`]. This is how a cone's aperture follows the
/// BRDF lobe (Sec. 6.5).
pub fn cone_spread(samples: u32, exponent: f32) -> f32 {
    let cos_share = 1.0 - 1.0 / samples.max(1) as f32;
    let cos_lobe = if exponent > 0.0 {
        0.5f32.powf(1.0 / exponent)
    } else {
        0.0
    };
    let cos = cos_share.max(cos_lobe).clamp(0.0, 1.0);
    ((1.0 - cos * cos).sqrt() / cos.max(1e-3)).min(MAX_SPREAD)
}

/// The widest cone: 60 degrees half aperture (one cone for a whole hemisphere).
pub const MAX_SPREAD: f32 = 1.732_050_8;
