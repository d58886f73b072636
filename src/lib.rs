//! relume: replay recorded RGB-D sensor logs through configurable, timed pipelines.
//!
//! The crate is organised as the product is:
//! - [`recording`]: the `.relume` format, association of streams into frames, importers
//!   of common RGB-D dataset layouts, and the synthetic scene generator with ground truth.
//! - [`graph`]: pipeline configs, the stage registry, the threaded runtime and timing.
//! - [`stages`]: the stage families, each as plain functions over buffers plus a thin
//!   stage type the registry builds from config.
//! - [`light`]: environment maps, importance-sample tables, area lights and SH9.
//! - [`objects`]: virtual objects (meshes, primitives, materials) and ray queries.
//! - [`raster`] and [`rng`]: the image buffer type and counter-based random numbers.
//! - [`files`]: reading the files a user names, regular files only.
//! - [`batch`]: batch manifests, item ids, shards and completion markers.

pub mod batch;
pub mod eval;
pub mod files;
pub mod graph;
pub mod light;
pub mod objects;
pub mod pinhole;
pub mod raster;
pub mod recording;
pub mod rng;
pub mod simd;
pub mod stages;
