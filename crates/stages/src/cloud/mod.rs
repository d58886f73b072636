//! `cloud.samples` (paper 000 Sec. 5, last part): the environment samples of the
//! captured scene. Every frame first removes the samples that the current depth shows to
//! be gone (they project in front of it), then back-projects a subsampled set of valid
//! pixels with their compensated color and normal into the probabilistic hash grid
//! ([`grid`]), and outputs a snapshot of the cloud.

use crate::compensate::Compensation;
use crate::kind::FrameProducts;
use crate::{OpError, kind};
use glam::{Mat4, Vec3};
use rayon::prelude::*;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Rgb8Image, Vec3Image, depth_is_valid};
use relume_base::rng;
use relume_graph::{Frame, ParamDefault, ParamSpec, Ports, Product, Stage, StageError, StageInfo};
use relume_recording::{Intrinsics, Pose};
use relume_scene::light::EnvCloud;
use std::sync::Arc;

pub mod grid;

pub use grid::{HashGrid, Insertion, Sample};

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "capacity",
        ParamDefault::Int(4_194_304),
        "slots of the hash grid, the most samples the cloud holds (paper 000: 4M)",
    )
    .range(1.0, grid::MAX_CAPACITY as f64),
    ParamSpec::new(
        "cell_size",
        ParamDefault::Float(0.05),
        "edge of a virtual grid cell in metres; one sample per cell (paper 000: 0.05 m)",
    )
    .range(1e-4, 100.0),
    ParamSpec::new(
        "step",
        ParamDefault::Int(4),
        "pixel subsampling: one candidate per step x step block, the block offset drawn per frame",
    )
    .range(1.0, 64.0),
    ParamSpec::new(
        "removal_margin",
        ParamDefault::Float(0.05),
        "a sample is removed only when it lies this many metres (plus the relative part) in front of the current depth",
    )
    .range(0.0, 100.0),
    ParamSpec::new(
        "removal_margin_relative",
        ParamDefault::Float(0.02),
        "part of the removal margin proportional to the current depth (sensor noise grows with depth)",
    )
    .range(0.0, 10.0),
    ParamSpec::new(
        "skip_saturated",
        ParamDefault::Bool(true),
        "add no samples from pixels with a camera color channel at 255 (clipped)",
    ),
];

pub const INFO: StageInfo = StageInfo {
    kind: "cloud.samples",
    summary: "environment samples in a probabilistic hash grid, removed where the depth shows them gone (paper 000 Sec. 5)",
    params: PARAMS,
    ports: |_| {
        Ports::fixed(
            &[
                ("depth", &[kind::DEPTH]),
                ("normals", &[kind::NORMALS]),
                ("compensated", &[kind::RADIANCE]),
                ("color", &[kind::COLOR]),
                ("compensation", &[kind::COMPENSATION]),
                ("pose", &[kind::POSE]),
            ],
            &[("cloud", &[kind::CLOUD])],
        )
    },
    build: |ctx| {
        let p = ctx.params;
        let params = CloudParams {
            step: p.int("step") as usize,
            removal_margin: p.float("removal_margin") as f32,
            removal_margin_relative: p.float("removal_margin_relative") as f32,
            skip_saturated: p.bool("skip_saturated"),
        };
        Ok(Box::new(CloudSamples {
            inputs: [
                "depth",
                "normals",
                "compensated",
                "color",
                "compensation",
                "pose",
            ]
            .map(|r| ctx.input(r)),
            cloud: ctx.output("cloud"),
            cloud_builder: CloudBuilder::new(
                p.int("capacity") as usize,
                p.float("cell_size") as f32,
                params,
                ctx.seed,
            )?,
            intrinsics: ctx.header.depth_intrinsics,
        }))
    },
};

/// Parameters of [`CloudBuilder`] besides the grid's size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CloudParams {
    /// One candidate pixel per `step` x `step` block.
    pub step: usize,
    /// Absolute part of the removal margin (metres).
    pub removal_margin: f32,
    /// Part of the removal margin proportional to the current depth.
    pub removal_margin_relative: f32,
    /// Skip pixels whose camera color has a channel at 255.
    pub skip_saturated: bool,
}

impl Default for CloudParams {
    fn default() -> Self {
        CloudParams {
            step: 4,
            removal_margin: 0.05,
            removal_margin_relative: 0.02,
            skip_saturated: true,
        }
    }
}

/// One frame's inputs to [`CloudBuilder::update`], all in the current view: the depth
/// map, camera-space normals, compensated linear color and the camera's 8-bit color
/// (same size), the compensation and the camera-to-world pose.
#[derive(Clone, Copy)]
pub struct FrameView<'a> {
    pub index: u64,
    pub depth: &'a DepthImage,
    pub normals: &'a Vec3Image,
    pub compensated: &'a Vec3Image,
    pub color: &'a Rgb8Image,
    pub compensation: &'a Compensation,
    pub pose: &'a Pose,
    /// The camera of `depth` (rescaled to its size).
    pub camera: &'a Pinhole,
}

/// What one [`CloudBuilder::update`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UpdateCounts {
    pub removed: usize,
    pub candidates: usize,
    pub added: usize,
    pub replaced: usize,
}

/// A sample candidate of one pixel, gathered in parallel and inserted in pixel order.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    sample: Sample,
    /// `NO_SLOT` when the pixel gives no sample.
    slot: u32,
    draw: u64,
}

const NO_SLOT: u32 = u32::MAX;
/// Salts of this stage's random numbers.
const SALT_REPLACE: u64 = 0x636c_6f75_6401;
const SALT_OFFSET: u64 = 0x636c_6f75_6402;

/// The environment-sample cloud across frames: the hash grid plus reusable buffers.
pub struct CloudBuilder {
    grid: HashGrid,
    params: CloudParams,
    seed: u64,
    candidates: Vec<Candidate>,
}

impl CloudBuilder {
    pub fn new(
        capacity: usize,
        cell_size: f32,
        params: CloudParams,
        seed: u64,
    ) -> Result<CloudBuilder, OpError> {
        if params.step == 0 {
            return Err(OpError::BadParameter(
                "cloud step must be at least 1".into(),
            ));
        }
        Ok(CloudBuilder {
            grid: HashGrid::new(capacity, cell_size)?,
            params,
            seed,
            candidates: Vec::new(),
        })
    }

    pub fn grid(&self) -> &HashGrid {
        &self.grid
    }

    /// Updates the cloud with one frame (paper 000 Sec. 5): removal, then insertion
    /// (skipped when the compensation is approximate).
    ///
    /// Removal: a sample is transformed into the camera (pose^-1) and projected; it is
    /// removed when z < d - (margin + relative d), d being the smallest valid depth of
    /// the 2x2 pixels around its projection (the conservative reading of "a smaller
    /// depth than the current depth image at the same location": sub-pixel rounding and
    /// depth edges do not delete samples of the visible surface).
    ///
    /// Insertion: one pixel per step x step block (the block offset drawn per frame, so a
    /// still camera offers every pixel over time) with valid depth, a valid normal and a
    /// finite compensated color, and, with `skip_saturated`, no camera channel at 255;
    /// back-projected with its normal into world space, inserted in pixel order, the
    /// replacement drawn from `rng::hash(&[seed, frame, salt, pixel])`.
    pub fn update(&mut self, view: &FrameView) -> Result<UpdateCounts, OpError> {
        let depth = view.depth;
        let (w, h) = (depth.width, depth.height);
        for (name, (iw, ih)) in [
            ("normals", (view.normals.width, view.normals.height)),
            (
                "compensated",
                (view.compensated.width, view.compensated.height),
            ),
            ("color", (view.color.width, view.color.height)),
        ] {
            if (iw, ih) != (w, h) {
                return Err(OpError::SizeMismatch(format!(
                    "{name} is {iw}x{ih}, depth is {w}x{h}"
                )));
            }
        }
        if (view.camera.width, view.camera.height) != (w, h) {
            return Err(OpError::SizeMismatch(format!(
                "camera is {}x{}, depth is {w}x{h}",
                view.camera.width, view.camera.height
            )));
        }
        let camera_to_world = view.pose.matrix();
        let world_to_camera = camera_to_world.inverse().as_mat4();
        let camera_to_world = camera_to_world.as_mat4();

        let mut counts = UpdateCounts {
            removed: self.remove_in_front(depth, view.camera, &world_to_camera),
            ..Default::default()
        };
        if view.compensation.approximate {
            return Ok(counts);
        }
        self.gather(view, &camera_to_world);
        for c in &self.candidates {
            if c.slot == NO_SLOT {
                continue;
            }
            counts.candidates += 1;
            match self.grid.insert_at(c.slot, c.sample, c.draw) {
                Insertion::Added => counts.added += 1,
                Insertion::Replaced => counts.replaced += 1,
                Insertion::Rejected => {}
            }
        }
        Ok(counts)
    }

    /// Removes the samples in front of the current depth (see [`CloudBuilder::update`]).
    fn remove_in_front(
        &mut self,
        depth: &DepthImage,
        camera: &Pinhole,
        world_to_camera: &Mat4,
    ) -> usize {
        let (w, h) = (depth.width as i64, depth.height as i64);
        let (abs, rel) = (
            self.params.removal_margin,
            self.params.removal_margin_relative,
        );
        self.grid.remove_where(|world| {
            let p = world_to_camera.transform_point3(world);
            let Some(uv) = camera.project(p) else {
                return false;
            };
            if !(uv.x > -1.0 && uv.y > -1.0 && uv.x < w as f32 && uv.y < h as f32) {
                return false;
            }
            let (x0, y0) = (uv.x.floor() as i64, uv.y.floor() as i64);
            let mut nearest = f32::INFINITY;
            for y in y0.max(0)..(y0 + 2).min(h) {
                for x in x0.max(0)..(x0 + 2).min(w) {
                    let d = depth.data[(y * w + x) as usize];
                    if depth_is_valid(d) {
                        nearest = nearest.min(d);
                    }
                }
            }
            nearest.is_finite() && p.z < nearest - (abs + rel * nearest)
        })
    }

    /// Fills `self.candidates` with one candidate per step x step block, in parallel.
    fn gather(&mut self, view: &FrameView, camera_to_world: &Mat4) {
        let step = self.params.step;
        let (w, h) = (view.depth.width as usize, view.depth.height as usize);
        let offset = rng::hash(&[self.seed, view.index, SALT_OFFSET]);
        let (ox, oy) = (
            (offset % step as u64) as usize,
            ((offset >> 32) % step as u64) as usize,
        );
        let cols = w.saturating_sub(ox).div_ceil(step);
        let rows = h.saturating_sub(oy).div_ceil(step);
        let empty = Candidate {
            sample: Sample {
                position: Vec3::ZERO,
                color: Vec3::ZERO,
                normal: Vec3::ZERO,
            },
            slot: NO_SLOT,
            draw: 0,
        };
        self.candidates.clear();
        self.candidates.resize(cols * rows, empty);
        if cols == 0 {
            return;
        }
        let grid = &self.grid;
        let (seed, frame) = (self.seed, view.index);
        let skip_saturated = self.params.skip_saturated;
        self.candidates
            .par_chunks_mut(cols)
            .enumerate()
            .for_each(|(row, out)| {
                let y = oy + row * step;
                for (col, c) in out.iter_mut().enumerate() {
                    let x = ox + col * step;
                    let i = y * w + x;
                    let z = view.depth.data[i];
                    let normal = view.normals.data[i];
                    let color = view.compensated.data[i];
                    if !depth_is_valid(z)
                        || normal == Vec3::ZERO
                        || !normal.is_finite()
                        || !color.is_finite()
                        || (skip_saturated && view.color.data[i].contains(&255))
                    {
                        continue;
                    }
                    let camera_point = view.camera.back_project(x as f32, y as f32, z);
                    let position = camera_to_world.transform_point3(camera_point);
                    let sample = Sample {
                        position,
                        color,
                        normal: camera_to_world.transform_vector3(normal).normalize(),
                    };
                    *c = Candidate {
                        sample,
                        slot: grid.slot_for(position),
                        draw: rng::hash(&[seed, frame, SALT_REPLACE, i as u64]),
                    };
                }
            });
    }

    /// The cloud as it stands, in storage order.
    pub fn snapshot(&self) -> EnvCloud {
        self.grid.snapshot()
    }
}

struct CloudSamples {
    /// depth, normals, compensated, color, compensation, pose.
    inputs: [String; 6],
    cloud: String,
    cloud_builder: CloudBuilder,
    intrinsics: Intrinsics,
}

impl Stage for CloudSamples {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let [depth, normals, compensated, color, compensation, pose] = &self.inputs;
        let depth = frame.depth(depth)?;
        let camera = Pinhole::new(&self.intrinsics, depth.width, depth.height);
        let view = FrameView {
            index: frame.index as u64,
            depth,
            normals: frame.normals(normals)?,
            compensated: frame.radiance(compensated)?,
            color: frame.color(color)?,
            compensation: frame.compensation(compensation)?,
            pose: frame.pose(pose)?,
            camera: &camera,
        };
        self.cloud_builder.update(&view)?;
        let cloud = Arc::new(self.cloud_builder.snapshot());
        frame.insert(&self.cloud, Product::new(kind::CLOUD, cloud));
        Ok(())
    }
}

#[cfg(test)]
mod tests;
