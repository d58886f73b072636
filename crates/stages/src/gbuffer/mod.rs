//! `gbuffer.splat` (paper 000 Sec. 3, "G-Buffer as AR basis", and Fig. 2): the
//! environment-sample cloud rendered into the current view, the reference image of
//! `color.compensate` (Sec. 4) and the real geometry for AR rendering. The cloud is
//! splatted with a depth test ([`splat()`]), then holes are filled by push-pull
//! ([`push_pull()`]).
//!
//! The `cloud` input defaults to `cloud@prev`, the cloud as it stood after the previous
//! frame; on the first frame it is absent and every output is empty.

use crate::kind::FrameProducts;
use crate::{OpError, kind};
use relume_base::pinhole::Pinhole;
use relume_graph::{
    Frame, ParamDefault, ParamSpec, Port, Ports, Product, Stage, StageError, StageInfo,
};
use relume_scene::light::EnvCloud;

mod buffer;
pub mod push_pull;
pub mod splat;

pub use buffer::{COVERAGE_FILLED, COVERAGE_NONE, COVERAGE_SPLAT, GBuffer};
pub use push_pull::{Pyramid, push_pull};
pub use splat::{SplatBuffer, SplatParams, splat};

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "splat_radius",
        ParamDefault::Float(0.035),
        "world radius of a sample's disk in metres (about 0.7 x the cloud's 5 cm cells: neighbouring disks meet)",
    )
    .range(0.0, 10.0),
    ParamSpec::new(
        "max_splat_radius_px",
        ParamDefault::Float(64.0),
        "upper bound of a splat's screen radius in pixels (bounds the cost of samples very near the camera)",
    )
    .range(0.75, 4096.0),
    ParamSpec::new(
        "occlusion_margin",
        ParamDefault::Float(splat::DEFAULT_OCCLUSION_MARGIN),
        "a sample whose centre lies this many metres behind the nearest sample centre of the 3x3 pixels around it is not splatted (occluded layers cost one projection)",
    )
    .range(0.0, 1e9),
    ParamSpec::new(
        "push_pull",
        ParamDefault::Bool(true),
        "fill holes by push-pull (paper 000 Sec. 3)",
    ),
    ParamSpec::new(
        "max_fill_levels",
        ParamDefault::Int(5),
        "coarser levels push-pull may use: holes wider than about 2^levels pixels stay empty",
    )
    .range(0.0, 16.0),
];

pub const INFO: StageInfo = StageInfo {
    kind: "gbuffer.splat",
    summary: "splat the environment-sample cloud into the view with a depth test and fill holes by push-pull (paper 000 Sec. 3)",
    params: PARAMS,
    ports: |_| Ports {
        inputs: vec![
            Port::new("cloud", "cloud@prev", &[kind::CLOUD]).optional(),
            Port::new("pose", "pose", &[kind::POSE]),
        ],
        outputs: vec![
            Port::new("reference", "reference", &[kind::RADIANCE]),
            Port::new("reference_depth", "reference_depth", &[kind::DEPTH]),
            Port::new("reference_normals", "reference_normals", &[kind::NORMALS]),
            Port::new("reference_coverage", "reference_coverage", &[kind::LABELS]),
        ],
    },
    build: |ctx| {
        let p = ctx.params;
        let k = ctx.header.color_intrinsics;
        Ok(Box::new(GBufferSplat {
            cloud: ctx.input("cloud"),
            pose: ctx.input("pose"),
            outputs: [
                "reference",
                "reference_depth",
                "reference_normals",
                "reference_coverage",
            ]
            .map(|r| ctx.output(r)),
            camera: Pinhole::new(&k, k.width, k.height),
            splat: SplatParams {
                radius: p.float("splat_radius") as f32,
                max_radius_px: p.float("max_splat_radius_px") as f32,
                occlusion_margin: p.float("occlusion_margin") as f32,
            },
            fill_levels: if p.bool("push_pull") {
                p.int("max_fill_levels") as usize
            } else {
                0
            },
            splat_buffer: SplatBuffer::default(),
            pyramid: Pyramid::default(),
        }))
    },
};

struct GBufferSplat {
    cloud: String,
    pose: String,
    /// reference, reference_depth, reference_normals, reference_coverage.
    outputs: [String; 4],
    camera: Pinhole,
    splat: SplatParams,
    /// 0 = no push-pull.
    fill_levels: usize,
    splat_buffer: SplatBuffer,
    pyramid: Pyramid,
}

impl GBufferSplat {
    /// Splats `cloud` (None on the first frame) and fills holes.
    fn render(
        &mut self,
        cloud: Option<&EnvCloud>,
        pose: &relume_recording::Pose,
    ) -> Result<GBuffer, OpError> {
        let mut g = GBuffer::new(self.camera.width, self.camera.height);
        if let Some(cloud) = cloud.filter(|c| !c.is_empty()) {
            splat(
                cloud,
                pose,
                &self.camera,
                &self.splat,
                &mut self.splat_buffer,
                &mut g,
            )?;
            push_pull(&mut g, &self.camera, self.fill_levels, &mut self.pyramid)?;
        }
        Ok(g)
    }
}

impl Stage for GBufferSplat {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let pose = *frame.pose(&self.pose)?;
        // Absent on the first frame (a feedback edge has no value yet).
        let cloud = match frame.get(&self.cloud) {
            None => None,
            Some(_) => Some(frame.cloud(&self.cloud)?.clone()),
        };
        let g = self.render(cloud.as_deref(), &pose)?;
        let [color, depth, normals, coverage] = &self.outputs;
        frame.insert(color, Product::new(kind::RADIANCE, g.color));
        frame.insert(depth, Product::new(kind::DEPTH, g.depth));
        frame.insert(normals, Product::new(kind::NORMALS, g.normals));
        frame.insert(coverage, Product::new(kind::LABELS, g.coverage));
        Ok(())
    }
}

#[cfg(test)]
mod tests;
