//! What `sample.path`'s estimator draws and sums at one pixel, as plain records: the
//! real shading point, the samples drawn before a span's rays are traced (each with its
//! ray's index in the span's batch), and the running sums of the estimates. The span
//! (`span.rs`) fills them; the estimator (`kernel.rs`) reads them.

use super::bounds::Cone;
use super::parts::PartTicks;
use super::sampling::Basis;
use crate::sample::ssrt::RayOrigin;
use glam::Vec3;
use relume_scene::objects::VirtualHit;

/// Offset (metres) of rays leaving a virtual surface along its normal.
pub(super) const SURFACE_OFFSET: f32 = 1e-4;

/// A real shading point: the pixel's depth-map point and normal.
pub(super) struct RealPoint {
    /// The ray origin, raised off the surface along the normal (world space, and
    /// projected for the screen-space tracer: `None` when it leaves the image), and
    /// the surface point itself (world).
    pub(super) world: Vec3,
    /// Where the world-space query's rays start: `world`, but raised a voxel
    /// further under `vct`.
    pub(super) query_origin: Vec3,
    pub(super) origin: Option<RayOrigin>,
    pub(super) surface: Vec3,
    pub(super) normal_world: Vec3,
    /// Basis about the camera-space normal (indirect directions are drawn in camera
    /// space, where the screen-space tracer works).
    pub(super) basis_camera: Basis,
    /// The objects' cone from this point, in world and in camera space.
    pub(super) cone_world: Cone,
    pub(super) cone_camera: Cone,
}

/// Sums of one pixel's estimates while its samples are drawn.
pub(super) struct Acc {
    pub(super) r_dir: Vec3,
    pub(super) r_ind: Vec3,
    pub(super) rv_dir: Vec3,
    pub(super) rv_ind: Vec3,
    pub(super) rv_dir_n: u32,
    pub(super) rv_ind_n: u32,
    /// Indirect / direct samples of E_RV taken at the real point.
    pub(super) rv_ind_real_n: u32,
    pub(super) rv_dir_real_n: u32,
    pub(super) direct_min: f32,
    pub(super) indirect_min: f32,
    pub(super) touched: bool,
    /// Draws taken from the bounce stream so far.
    pub(super) bounces: u64,
    /// Clock ticks spent on the object and on the differential (see `parts.rs`).
    pub(super) ticks: PartTicks,
}

/// A direct sample whose ray is traced: its table sample, the cosine of its direction
/// to the normal, and its ray in the batch.
#[derive(Clone, Copy, Debug)]
pub(super) struct DirectRay {
    pub(super) sample: usize,
    pub(super) cos: f32,
    pub(super) ray: usize,
}

/// An indirect sample: its camera-space direction and its ray in the batch.
#[derive(Clone, Copy, Debug)]
pub(super) struct IndirectRay {
    pub(super) dir_camera: Vec3,
    pub(super) ray: usize,
}

/// One real point's samples: per direct sample s (primary j has
/// `j * direct .. (j + 1) * direct`) its ray, `None` where it is not traced (the table
/// is empty, or the direction is below the surface or has no density); per indirect
/// sample likewise, always traced.
pub(super) struct RealSamples<'a> {
    pub(super) direct: &'a [Option<DirectRay>],
    pub(super) indirect: &'a [IndirectRay],
}

/// The samples drawn at one pixel's virtual primaries, in primary order: `direct`
/// per direct sample of each virtual primary, `indirect` per indirect sample.
pub(super) struct VirtualSamples<'a> {
    pub(super) direct: &'a [VirtualDirect],
    pub(super) indirect: &'a [VirtualIndirect],
}

/// What was drawn at one pixel before its span's rays were traced: its real point, if
/// any, with its samples; per primary its virtual hit and view direction, if any; and
/// the samples of those virtual hits.
pub(super) struct Drawn<'a> {
    pub(super) real: Option<&'a RealPoint>,
    pub(super) real_samples: RealSamples<'a>,
    pub(super) primaries: &'a [Option<(VirtualHit, Vec3)>],
    pub(super) virtual_samples: VirtualSamples<'a>,
}

/// A direct sample at a virtual primary, as drawn before the span's rays are traced.
#[derive(Clone, Copy, Debug)]
pub(super) enum VirtualDirect {
    /// No light: the table is empty, or the sample lies below the surface or has no
    /// density.
    Unlit,
    /// Table sample `sample` at cosine `cos` to the normal, blocked by a virtual surface
    /// at distance `t`.
    Blocked { sample: usize, cos: f32, t: f32 },
    /// Table sample `sample` at cosine `cos`, whose ray is `ray` in the span's batch,
    /// `visible` the share of its light the objects let through (1 but under `vct`,
    /// whose cones are partly blocked).
    Open {
        sample: usize,
        cos: f32,
        ray: usize,
        visible: f32,
    },
}

/// An indirect sample at a virtual primary: its world direction and weight, and its
/// ray in the span's batch (none where the weight is 0: the direction lies below the
/// surface, and the sample brings nothing).
#[derive(Clone, Copy, Debug)]
pub(super) struct VirtualIndirect {
    pub(super) dir: Vec3,
    pub(super) weight: f32,
    pub(super) ray: Option<usize>,
}

/// Where a virtual primary's rays leave its surface (raised off it), and the mirror
/// direction of its view.
pub(super) struct Surface {
    pub(super) origin: Vec3,
    pub(super) mirror: Vec3,
    pub(super) glossy: bool,
}

impl Surface {
    pub(super) fn new(hit: &VirtualHit, to_viewer: Vec3) -> Surface {
        let n = hit.normal;
        Surface {
            origin: hit.position + n * SURFACE_OFFSET,
            mirror: 2.0 * n.dot(to_viewer) * n - to_viewer,
            glossy: hit.material.is_glossy(),
        }
    }
}
