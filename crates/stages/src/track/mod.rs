//! `pose.track`: the camera pose of each frame from its color and depth, for recordings
//! without poses (or to refine theirs).
//!
//! Frame-to-model tracking as KinectFusion (Newcombe et al. 2011) and paper 001's
//! InfiniTAM do: each frame is aligned ([`mod@align`]) to a model, the fused depth of the
//! frames before it ([`crate::fuse::DepthFusion`], the same fusion as `depth.fuse`) in
//! the last tracked view, with its normals and the last frame's intensity, so that the
//! model's noise and holes shrink as frames are fused and drift grows more slowly than
//! frame to frame. The alignment is point-to-plane ICP with projective association plus
//! a photometric term, coarse to fine over a [`pyramid`], with Huber weights.
//!
//! With `model = "depth.fuse"` the stage reads that fused depth from the pipeline's
//! `depth.fuse` a frame back (its `fused` input, `fused_depth@prev`), as KinectFusion's
//! tracker reads the model its integration step built: the acquisition fuses each frame
//! anyway, with the tracked pose, and fusing twice costs the tracker a quarter of its
//! time. The map is the one the tracker's own fusion makes.
//!
//! The first frame takes the recording's pose when it has one (the tracked trajectory
//! then lies in the recording's world, where the pipeline's objects are placed), else
//! the identity. A frame whose alignment fails ([`Lost`]: too few correspondences, a
//! residual too high, a degenerate system, a jump beyond a physical bound) gets no pose;
//! the model stays as it was, and the next frame is aligned to it from the last good
//! pose, so tracking resumes without a pose being invented.

pub mod align;
pub mod pyramid;
pub mod source;

#[cfg(test)]
mod tests;

pub use align::{AlignParams, Alignment, align};
pub use pyramid::{Level, Pyramid};
pub use source::{PoseReader, reads_recorded_pose};

use crate::fuse::{DepthFusion, FuseParams};
use crate::{OpError, kind};
use glam::{DMat4, DQuat};
use relume_base::pinhole::Intrinsics;
use relume_base::raster::{DepthImage, Rgb8Image};
use relume_graph::{
    Frame, ParamDefault, ParamSpec, Port, Ports, Product, Stage, StageError, StageInfo,
};
use relume_recording::Pose;

/// Everything the tracker is set by.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackParams {
    pub align: AlignParams,
    /// Pyramid levels (KinectFusion: 3).
    pub levels: usize,
    /// Lost when fewer than this fraction of the frame's points find a model point.
    pub min_inlier_fraction: f64,
    /// Lost when the inliers' point-to-plane RMS exceeds this, metres.
    pub max_rmse_m: f64,
    /// Lost when the camera moved more than this between two tracked frames: metres,
    /// degrees (a hand-held camera at 30 frames/s: about 2 m/s, 300 deg/s).
    pub max_translation_m: f64,
    pub max_rotation_deg: f64,
    /// Align to the fused depth of the frames so far (frame to model) rather than the
    /// last frame's depth alone (frame to frame).
    pub fused_model: bool,
}

impl Default for TrackParams {
    fn default() -> Self {
        TrackParams {
            align: AlignParams::default(),
            levels: 3,
            min_inlier_fraction: 0.3,
            max_rmse_m: 0.02,
            max_translation_m: 0.15,
            max_rotation_deg: 15.0,
            fused_model: true,
        }
    }
}

/// Why a frame could not be tracked.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lost {
    /// Fewer correspondences than asked (`inliers` of `valid` frame points).
    TooFewInliers { inliers: usize, valid: usize },
    /// The inliers' residual is too high, metres.
    ResidualTooHigh(f64),
    /// The normal equations were singular: the scene does not fix every direction.
    Degenerate,
    /// A jump beyond the physical bound: metres, degrees.
    Jump {
        translation_m: f64,
        rotation_deg: f64,
    },
}

impl std::fmt::Display for Lost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Lost::TooFewInliers { inliers, valid } => {
                write!(f, "{inliers} of {valid} points matched the model")
            }
            Lost::ResidualTooHigh(r) => write!(f, "residual {:.1} mm", r * 1e3),
            Lost::Degenerate => write!(f, "the scene does not fix the motion"),
            Lost::Jump {
                translation_m,
                rotation_deg,
            } => write!(
                f,
                "a jump of {:.0} mm and {rotation_deg:.1} degrees",
                translation_m * 1e3
            ),
        }
    }
}

/// What the tracker made of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tracked {
    /// The first frame: its pose is the start pose.
    Started(Pose),
    /// A tracked frame, with its alignment.
    Pose(Pose, Alignment),
    /// No pose: why, and the alignment that was refused.
    Lost(Lost, Alignment),
}

/// The model frames are aligned to.
struct Model {
    pyramid: Pyramid,
    /// World from model camera.
    pose: DMat4,
}

/// The last tracked frame, from which the next frame's model is made when that frame
/// comes: with the pipeline's fused depth where it gives it, else with the tracker's own
/// fusion (or the frame's depth alone, frame to frame).
struct LastFrame {
    pyramid: Pyramid,
    /// Its depth, for the tracker's own fusion (`None` frame to frame, which fuses
    /// nothing).
    depth: Option<DepthImage>,
    pose: Pose,
}

/// What the tracker holds between frames.
enum State {
    /// No frame yet.
    Empty,
    /// A frame was tracked: the model for the next is made from it.
    Tracked(LastFrame),
    /// The model, kept while frames are lost.
    Model(Model),
}

/// Frame-to-model tracking that keeps its model between frames; the stage's core,
/// also usable without a pipeline.
pub struct Tracker {
    intrinsics: Intrinsics,
    params: TrackParams,
    fusion: DepthFusion,
    state: State,
    /// Frames tracked and lost so far.
    pub tracked: usize,
    pub lost: usize,
}

impl Tracker {
    /// A tracker for a camera with `intrinsics` (color and depth registered).
    pub fn new(intrinsics: Intrinsics, params: TrackParams) -> Tracker {
        Tracker {
            intrinsics,
            params,
            fusion: DepthFusion::new(intrinsics, FuseParams::default()),
            state: State::Empty,
            tracked: 0,
            lost: 0,
        }
    }

    /// Tracks the next frame. `start` is the pose of the first frame (the identity when
    /// `None`); `guess`, when given, is the frame's pose to start the alignment from
    /// (refinement of a recorded pose), else the last tracked pose. `fused`, when given,
    /// is the depth fused up to the last tracked frame, in its view (the pipeline's
    /// `depth.fuse`, a frame back): the fused model is made from it instead of by the
    /// tracker's own fusion, which gives the same map where depth.fuse has its default
    /// settings.
    pub fn track(
        &mut self,
        color: &Rgb8Image,
        depth: &DepthImage,
        start: Option<&Pose>,
        guess: Option<&Pose>,
        fused: Option<&DepthImage>,
    ) -> Result<Tracked, OpError> {
        if !color.same_size(depth) {
            return Err(OpError::SizeMismatch(format!(
                "pose.track: color {}x{} and depth {}x{} differ (depth must be registered \
                 to color)",
                color.width, color.height, depth.width, depth.height
            )));
        }
        // Frame to frame, this frame's pyramid is the next model, whose normals are
        // looked up anywhere; with the fused model, only the aligned pixels need them.
        let normal_stride = match self.params.fused_model {
            true => self.params.align.fine_stride,
            false => 1,
        };
        let frame = Pyramid::build(
            &self.intrinsics,
            color,
            depth,
            self.params.levels,
            normal_stride,
        );
        let model = match std::mem::replace(&mut self.state, State::Empty) {
            State::Empty => {
                let pose = start.copied().unwrap_or(Pose::IDENTITY);
                self.keep(frame, depth, pose);
                return Ok(Tracked::Started(pose));
            }
            State::Tracked(last) => self.model_of(last, fused)?,
            State::Model(model) => model,
        };
        let initial = match guess {
            Some(g) => model.pose.inverse() * g.matrix(),
            None => DMat4::IDENTITY,
        };
        let alignment = align(&model.pyramid, &frame, initial, &self.params.align);
        if let Some(lost) = self.refuse(&alignment) {
            self.lost += 1;
            self.state = State::Model(model);
            return Ok(Tracked::Lost(lost, alignment));
        }
        let pose = pose_of(&(model.pose * alignment.model_from_frame));
        self.keep(frame, depth, pose);
        Ok(Tracked::Pose(pose, alignment))
    }

    /// Keeps a tracked frame for the next frame's model.
    fn keep(&mut self, pyramid: Pyramid, depth: &DepthImage, pose: Pose) {
        self.tracked += 1;
        self.state = State::Tracked(LastFrame {
            pyramid,
            depth: self.params.fused_model.then(|| depth.clone()),
            pose,
        });
    }

    /// The model made from the last tracked frame: its pyramid as it is (frame to
    /// frame), or with the fused map seen from it, the pipeline's (`fused`) or the
    /// tracker's own fusion's (with the frame's intensity, which fusion does not change).
    fn model_of(&mut self, last: LastFrame, fused: Option<&DepthImage>) -> Result<Model, OpError> {
        let pose = last.pose.matrix();
        // Frame to frame keeps no depth: the frame's own pyramid is the model.
        let Some(depth) = &last.depth else {
            return Ok(Model {
                pyramid: last.pyramid,
                pose,
            });
        };
        let pyramid = match fused {
            Some(fused) if fused.same_size(depth) => last.pyramid.with_depth(fused),
            _ => {
                let (own, _) = self.fusion.push(depth, &last.pose)?;
                let own = own
                    .get::<DepthImage>(kind::DEPTH)
                    .expect("the fusion returns depth");
                last.pyramid.with_depth(own)
            }
        };
        Ok(Model { pyramid, pose })
    }

    /// Why `a` is not to be trusted, if it is not.
    fn refuse(&self, a: &Alignment) -> Option<Lost> {
        let p = &self.params;
        if a.valid == 0 || (a.inliers as f64) < p.min_inlier_fraction * a.valid as f64 {
            return Some(Lost::TooFewInliers {
                inliers: a.inliers,
                valid: a.valid,
            });
        }
        if !a.solvable {
            return Some(Lost::Degenerate);
        }
        if a.rmse_m > p.max_rmse_m {
            return Some(Lost::ResidualTooHigh(a.rmse_m));
        }
        let m = &a.model_from_frame;
        let translation_m = m.w_axis.truncate().length();
        let rotation_deg = DQuat::from_mat4(m)
            .angle_between(DQuat::IDENTITY)
            .to_degrees();
        if translation_m > p.max_translation_m || rotation_deg > p.max_rotation_deg {
            return Some(Lost::Jump {
                translation_m,
                rotation_deg,
            });
        }
        None
    }
}

/// The pose of a camera-to-world matrix (its rotation made a unit quaternion).
fn pose_of(m: &DMat4) -> Pose {
    Pose::from_parts(m.w_axis.truncate(), DQuat::from_mat4(m).normalize())
}

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "levels",
        ParamDefault::Int(3),
        "pyramid levels, each half the size of the one below (KinectFusion: 3)",
    )
    .range(1.0, 6.0),
    ParamSpec::new(
        "iterations",
        ParamDefault::Str("1,1,4"),
        "Gauss-Newton iterations per level, finest first, comma-separated; a level beyond \
         the list takes its last count. KinectFusion's 4,5,10 scored no better at twice \
         the time: ATE on livingroom1 11.51 mm against 11.48, on the built-in recording \
         1.16 against 0.86 (the coarsest level takes the motion, a step on each finer \
         level refines it)",
    ),
    ParamSpec::new(
        "fine_stride",
        ParamDefault::Int(2),
        "use every n-th pixel in x and y at the finest level (2: a third of the time of 1, \
         ATE 11.5 against 11.3 mm on livingroom1)",
    )
    .range(1.0, 16.0),
    ParamSpec::new(
        "max_distance_m",
        ParamDefault::Float(0.1),
        "a frame point farther than this from its model point is no correspondence \
         (KinectFusion's distance threshold)",
    )
    .range(0.001, 10.0),
    ParamSpec::new(
        "max_angle_deg",
        ParamDefault::Float(80.0),
        "normals further apart than this are no correspondence; KinectFusion's 20 suits \
         depth smoothed first, and on raw Kinect-like depth (the synthetic room) the \
         frame's normals are too noisy for it: 45 loses 29 of 30 frames there, 80 none",
    )
    .range(0.0, 180.0),
    ParamSpec::new(
        "photometric_weight",
        ParamDefault::Float(0.1),
        "weight of the photometric term against the point-to-plane term (residuals in \
         intensity 0..1 and metres; ElasticFusion weighs ICP 10 to 1 against RGB); 0 is \
         ICP alone",
    )
    .range(0.0, 1000.0),
    ParamSpec::new(
        "huber_m",
        ParamDefault::Float(0.01),
        "Huber threshold of the point-to-plane residual, metres",
    )
    .range(1e-6, 1.0),
    ParamSpec::new(
        "huber_intensity",
        ParamDefault::Float(0.05),
        "Huber threshold of the photometric residual (intensity 0..1)",
    )
    .range(1e-6, 1.0),
    ParamSpec::new(
        "min_inlier_fraction",
        ParamDefault::Float(0.3),
        "lost when fewer than this fraction of the frame's points match the model",
    )
    .range(0.0, 1.0),
    ParamSpec::new(
        "max_rmse_m",
        ParamDefault::Float(0.02),
        "lost when the matched points' point-to-plane RMS exceeds this, metres",
    )
    .range(0.0, 10.0),
    ParamSpec::new(
        "max_translation_m",
        ParamDefault::Float(0.15),
        "lost when the camera moved more than this from the last tracked frame, metres",
    )
    .range(0.0, 100.0),
    ParamSpec::new(
        "max_rotation_deg",
        ParamDefault::Float(15.0),
        "lost when the camera turned more than this from the last tracked frame, degrees",
    )
    .range(0.0, 180.0),
    ParamSpec::new(
        "model",
        ParamDefault::Str("fused"),
        "what frames are aligned to: `fused`, the depth fused over the frames so far by \
         the tracker's own fusion (frame to model, as KinectFusion); `depth.fuse`, the \
         same map from the pipeline's `depth.fuse` a frame back (input `fused`, product \
         `fused_depth@prev`), where the pipeline fuses with the tracked poses anyway: the \
         tracker then skips its own fusion (4-5 of its 18-19 ms a frame on livingroom1), \
         but a lost frame stops the run there, since depth.fuse needs its pose; or \
         `frame`, the last frame's depth",
    )
    .choices(&["fused", "depth.fuse", "frame"]),
    ParamSpec::new(
        "refine",
        ParamDefault::Bool(false),
        "start each alignment from the recording's pose (refinement) instead of the last \
         tracked one",
    ),
];

pub const INFO: StageInfo = StageInfo {
    kind: "pose.track",
    summary: "camera pose from color and depth: frame-to-model ICP with a photometric term \
              (KinectFusion, ElasticFusion)",
    params: PARAMS,
    ports: |params| {
        let mut inputs = vec![
            Port::new("color", "color", &[kind::COLOR]),
            Port::new("depth", "depth", &[kind::DEPTH]),
            Port::new("recorded", "recorded_pose", &[kind::POSE]).optional(),
        ];
        if params.str("model") == "depth.fuse" {
            inputs.push(Port::new("fused", "fused_depth@prev", &[kind::DEPTH]).optional());
        }
        Ports {
            inputs,
            outputs: vec![Port::new("pose", "pose", &[kind::POSE])],
        }
    },
    build: |ctx| {
        let p = ctx.params;
        let mut iterations = Vec::new();
        for s in p.str("iterations").split(',') {
            match s.trim().parse::<usize>() {
                Ok(n) if n <= 1000 => iterations.push(n),
                _ => {
                    return Err(StageError::Failed(format!(
                        "pose.track: iterations: {s:?} is not a count from 0 to 1000"
                    )));
                }
            }
        }
        let params = TrackParams {
            align: AlignParams {
                iterations,
                fine_stride: p.int("fine_stride") as usize,
                max_distance_m: p.float("max_distance_m") as f32,
                max_angle_deg: p.float("max_angle_deg") as f32,
                photometric_weight: p.float("photometric_weight"),
                huber_m: p.float("huber_m") as f32,
                huber_intensity: p.float("huber_intensity") as f32,
            },
            levels: p.int("levels") as usize,
            min_inlier_fraction: p.float("min_inlier_fraction"),
            max_rmse_m: p.float("max_rmse_m"),
            max_translation_m: p.float("max_translation_m"),
            max_rotation_deg: p.float("max_rotation_deg"),
            fused_model: p.str("model") != "frame",
        };
        Ok(Box::new(TrackStage {
            color: ctx.input("color"),
            depth: ctx.input("depth"),
            recorded: ctx.input("recorded"),
            fused: (p.str("model") == "depth.fuse").then(|| ctx.input("fused")),
            pose: ctx.output("pose"),
            name: ctx.stage_name.to_string(),
            first_lost: None,
            refine: p.bool("refine"),
            tracker: Tracker::new(ctx.header.color_intrinsics, params),
        }))
    },
};

struct TrackStage {
    color: String,
    depth: String,
    recorded: String,
    /// The last tracked frame's fused depth (`depth.fuse`'s, a frame back), where the
    /// pipeline fuses with the tracked poses.
    fused: Option<String>,
    pose: String,
    name: String,
    /// The first lost frame and why.
    first_lost: Option<(usize, Lost)>,
    refine: bool,
    tracker: Tracker,
}

impl Stage for TrackStage {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let recorded = frame.pose(&self.recorded).ok().copied();
        let guess = if self.refine { recorded.as_ref() } else { None };
        let outcome = self.tracker.track(
            frame.color(&self.color)?,
            frame.depth(&self.depth)?,
            recorded.as_ref(),
            guess,
            self.fused.as_ref().and_then(|f| frame.depth(f).ok()),
        )?;
        match outcome {
            Tracked::Started(pose) | Tracked::Pose(pose, _) => {
                frame.insert(&self.pose, Product::new(kind::POSE, pose));
            }
            Tracked::Lost(why, _) => {
                self.first_lost.get_or_insert((frame.index, why));
            }
        }
        Ok(())
    }

    /// Says how many frames were lost, and why the first was: lost frames have no pose,
    /// so a stage after this one that needs it stops there.
    fn finish(&mut self) -> Result<(), StageError> {
        if let Some((index, why)) = self.first_lost {
            eprintln!(
                "{}: {} of {} frames lost (no pose), the first at frame {index}: {why}",
                self.name,
                self.tracker.lost,
                self.tracker.lost + self.tracker.tracked
            );
        }
        Ok(())
    }
}
