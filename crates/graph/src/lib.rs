//! Pipelines: config files, the registry of stage kinds, the threaded runtime and timing.

mod build;
pub mod config;
mod cycle;
mod error;
pub mod every;
pub mod frame;
pub mod lag;
pub mod memory;
pub mod overrides;
pub mod panics;
pub mod params;
pub mod pipeline;
pub mod product;
pub mod registry;
mod resolved;
pub mod runtime;
pub mod stage;
mod stage_checks;
pub mod timing;
pub mod tree;
pub mod world;

pub use config::{ConfigError, SourceFile};
pub use frame::Frame;
pub use overrides::ParamOverride;
pub use params::{ParamDefault, ParamSpec, ParamValue, Params};
pub use pipeline::{Feedback, Pipeline, ResolvedStage};
pub use product::{Payload, Product, ProductKind};
pub use registry::Registry;
pub use runtime::{Branch, FrameSource, PipelineError, RunFailure, RunOptions, run, run_graph};
pub use stage::{BuildContext, Port, Ports, Stage, StageError, StageInfo};
pub use timing::{FrameTiming, MAX_PARTS, Parts, RunReport, StageTimings, Stats};
pub use tree::{GraphFeedback, GraphNode, StageGraph};
pub use world::{EmptyWorld, World, WorldResolver};
