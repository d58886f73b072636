//! relume: replay recorded RGB-D sensor logs through configurable, timed pipelines.
//!
//! This crate is the `relume` command line; its library is a facade over the workspace's
//! crates, so that benches, tests and the command line name every part by one path
//! (`relume::graph::Pipeline`). The crates, bottom to top (`ARCHITECTURE.md`):
//! - [`relume_base`]: [`raster`], [`rng`], [`pinhole`], [`simd`], [`threads`], [`files`],
//!   [`cancel`].
//! - [`relume_recording`] as [`recording`]: the `.relume` format, importers, `relume synth`.
//! - [`relume_scene`]: virtual [`objects`] and [`light`] models.
//! - [`relume_graph`] as [`graph`]: pipeline configs, the registry, the runtime, timing.
//! - [`relume_stages`] as [`stages`]: the stage families and the built-in registry.
//! - [`relume_eval`] as [`eval`] and [`batch`]: scores, reports, diff and batch runs.

pub use relume_base::{cancel, files, pinhole, raster, rng, simd, threads};
pub use relume_eval as eval;
pub use relume_eval::batch;
pub use relume_graph as graph;
pub use relume_recording as recording;
pub use relume_scene::{light, objects};
pub use relume_stages as stages;
