//! `depth.fuse` (paper 002, Sec. 4.2): temporal fusion of sensor depth. Each frame the
//! previous fused depth and weight map is warped into the current view by forward
//! projection of a triangle mesh with a z-test ([`warp`]), then merged with the new
//! depth per pixel ([`merge`]): a capped running average where the two agree, the new
//! depth where they disagree, the warped depth where the new one has a hole and the
//! warped weight is high enough. The result has less noise and fewer holes than the raw
//! depth; the weight map says how many agreeing measurements stand behind each pixel.
//!
//! The stage keeps the fused map and its pose between frames. The first frame, and any
//! frame whose size differs from the previous one, starts over: fused = raw depth,
//! weight 1 where valid and 0 elsewhere.
//!
//! Cost per 640x480 frame: the warp transforms 307k vertices (a few multiply-adds and
//! one division each) and bounds 614k triangles, most of which hold no pixel centre;
//! each of the about 307k covered pixels costs two divisions and one atomic
//! `fetch_min` (skipped when a nearer value is already there). The triangles go eight
//! quads at a time through the CPU's AVX2 lanes (`mesh_lanes.rs`, the same bits as
//! one at a time), which took the stage from 28 to 9-11 ms of one core on livingroom1
//! (the warp's rasterization was most of it).
//! The merge is one pass, plus a small window at the holes it fills. No per-pixel
//! allocation.

pub mod merge;
mod mesh;
mod mesh_lanes;
pub mod warp;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod warp_tests;

pub use merge::{MergeParams, merge_depth};
pub use warp::{WarpParams, WarpedDepth, previous_to_current, warp_depth};

use crate::{OpError, kind};
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Image, ScalarImage};
use relume_graph::{Frame, ParamDefault, ParamSpec, Ports, Product, Stage, StageError, StageInfo};
use relume_recording::{Intrinsics, Pose};
use std::sync::Arc;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "agreement",
        ParamDefault::Float(0.05),
        "new and warped depth are the same surface when they differ by at most this \
         fraction of the new depth (Kinect noise plus disparity quantization: about 3% \
         at 5 m, 4% at 7 m, at three sigma)",
    )
    .range(0.0, 1.0),
    ParamSpec::new(
        "max_weight",
        ParamDefault::Float(20.0),
        "cap of the running average's weight: noise falls about 6x, and the map follows \
         changes within about 20 frames",
    )
    .range(1.0, 10000.0),
    ParamSpec::new(
        "min_fill_weight",
        ParamDefault::Float(2.0),
        "a hole in the new depth is filled from the warped map only where its weight is at \
         least this (2: confirmed by a second measurement)",
    )
    .range(0.0, 10000.0),
    ParamSpec::new(
        "fill_decay",
        ParamDefault::Float(0.9),
        "factor on the weight of a warped value kept over a hole, so unconfirmed values \
         fade out",
    )
    .range(0.0, 1.0),
    ParamSpec::new(
        "occlusion_radius",
        ParamDefault::Int(2),
        "do not fill a hole from the warped map where new depth within this many pixels \
         lies in front of the warped depth (a nearer object's unmeasured rim); 2 suits \
         640x480, 1 320x240; 0 fills every hole as paper 002 does",
    )
    .range(0.0, 16.0),
    ParamSpec::new(
        "max_stretch",
        ParamDefault::Float(0.05),
        "warped triangles whose vertex depths differ by more than this fraction of the \
         nearest are dropped (depth discontinuities: no skin between surfaces)",
    )
    .range(0.0, 100.0),
];

pub const INFO: StageInfo = StageInfo {
    kind: "depth.fuse",
    summary: "warp the previous fused depth into the view and merge it with the new depth \
              (paper 002 Sec. 4.2)",
    params: PARAMS,
    ports: |_| {
        Ports::fixed(
            &[("depth", &[kind::DEPTH]), ("pose", &[kind::POSE])],
            &[
                ("fused_depth", &[kind::DEPTH]),
                ("fuse_weight", &[kind::SCALAR]),
            ],
        )
    },
    build: |ctx| {
        let p = ctx.params;
        Ok(Box::new(DepthFuse {
            depth: ctx.input("depth"),
            pose: ctx.input("pose"),
            fused_depth: ctx.output("fused_depth"),
            fuse_weight: ctx.output("fuse_weight"),
            fusion: DepthFusion::new(
                ctx.header.depth_intrinsics,
                FuseParams {
                    warp: WarpParams {
                        max_stretch: p.float("max_stretch") as f32,
                    },
                    merge: MergeParams {
                        agreement: p.float("agreement") as f32,
                        max_weight: p.float("max_weight") as f32,
                        min_fill_weight: p.float("min_fill_weight") as f32,
                        fill_decay: p.float("fill_decay") as f32,
                        occlusion_radius: p.int("occlusion_radius") as usize,
                    },
                },
            ),
        }))
    },
};

/// All parameters of the fusion.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FuseParams {
    pub warp: WarpParams,
    pub merge: MergeParams,
}

/// The fused map of the previous frame, shared with the frame it was output in.
struct FusedState {
    depth: Arc<Product>,
    weight: Arc<Product>,
    pose: Pose,
}

/// Temporal depth fusion that keeps its state between frames; the stage's core, also
/// usable without a pipeline.
pub struct DepthFusion {
    intrinsics: Intrinsics,
    params: FuseParams,
    state: Option<FusedState>,
    warped: WarpedDepth,
}

impl DepthFusion {
    /// A fusion for a depth camera with `intrinsics` (rescaled to each frame's size).
    pub fn new(intrinsics: Intrinsics, params: FuseParams) -> DepthFusion {
        DepthFusion {
            intrinsics,
            params,
            state: None,
            warped: WarpedDepth::new(0, 0),
        }
    }

    /// Fuses the next frame's sensor `depth` seen from `pose`; returns the fused depth
    /// and weight (as [`kind::DEPTH`] and [`kind::SCALAR`] products, shared with the state).
    pub fn push(
        &mut self,
        depth: &DepthImage,
        pose: &Pose,
    ) -> Result<(Arc<Product>, Arc<Product>), OpError> {
        let (w, h) = (depth.width, depth.height);
        let previous = match &self.state {
            Some(s) => match (
                s.depth.get::<DepthImage>(kind::DEPTH),
                s.weight.get::<ScalarImage>(kind::SCALAR),
            ) {
                (Some(d), Some(wt)) if d.same_size(depth) => Some((d, wt, &s.pose)),
                _ => None,
            },
            None => None,
        };
        match previous {
            Some((prev_depth, prev_weight, prev_pose)) => {
                if !self.warped.depth.same_size(depth) {
                    self.warped = WarpedDepth::new(w, h);
                }
                let camera = Pinhole::new(&self.intrinsics, w, h);
                warp_depth(
                    prev_depth,
                    prev_weight,
                    prev_pose,
                    pose,
                    &camera,
                    &self.params.warp,
                    &mut self.warped,
                )?;
            }
            // Start over: merging with an empty warped map gives raw depth, weight 1.
            None => self.warped = WarpedDepth::new(w, h),
        }
        // The previous map has been warped: reuse its buffers when no frame holds them
        // any more (merge_depth overwrites every pixel), saving two zeroed allocations.
        let (mut fused, mut weight): (DepthImage, ScalarImage) = match self.state.take() {
            Some(s) => (reuse_or_new(s.depth, w, h), reuse_or_new(s.weight, w, h)),
            None => (Image::filled(w, h, 0.0), Image::filled(w, h, 0.0)),
        };
        merge_depth(
            &self.warped.depth,
            &self.warped.weight,
            depth,
            &self.params.merge,
            &mut fused,
            &mut weight,
        )?;
        let state = FusedState {
            depth: Arc::new(Product::new(kind::DEPTH, fused)),
            weight: Arc::new(Product::new(kind::SCALAR, weight)),
            pose: *pose,
        };
        let out = (state.depth.clone(), state.weight.clone());
        self.state = Some(state);
        Ok(out)
    }
}

/// The image inside `product` when it is unshared and `w` x `h` (depth or scalar), else
/// a new zeroed one.
fn reuse_or_new(product: Arc<Product>, w: u32, h: u32) -> Image<f32> {
    match Arc::try_unwrap(product).map(Product::into_value::<Image<f32>>) {
        Ok(Ok(img)) if img.width == w && img.height == h => img,
        _ => Image::filled(w, h, 0.0),
    }
}

struct DepthFuse {
    depth: String,
    pose: String,
    fused_depth: String,
    fuse_weight: String,
    fusion: DepthFusion,
}

impl Stage for DepthFuse {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let pose = *frame.pose(&self.pose)?;
        let (depth, weight) = self.fusion.push(frame.depth(&self.depth)?, &pose)?;
        frame.insert_shared(&self.fused_depth, depth);
        frame.insert_shared(&self.fuse_weight, weight);
        Ok(())
    }
}
