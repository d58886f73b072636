//! relume's base layer: the types and helpers every other crate builds on, and nothing
//! that knows about recordings, scenes, pipelines or stages.
//!
//! - [`raster`]: the image buffer type and its pixel formats.
//! - [`rng`]: counter-based random numbers (hashes of seed, frame, stage, pixel, sample).
//! - [`pinhole`]: the pinhole camera model and a sensor's intrinsics.
//! - [`simd`]: eight-wide lanes with a portable twin, and the one CPU probe.
//! - [`threads`]: running work on a rayon pool of a given size.
//! - [`ticks`]: a clock cheap enough to read per pixel, for splitting a stage's time.
//! - [`payload`]: what a pipeline product holds: the [`payload::Payload`] trait and kinds.
//! - [`files`]: reading the files a user names, regular files only.
//! - [`spot`]: a spot light's cone (Mitsuba 3's profile), shared by the synthetic room's
//!   lamp and the spot lights pipelines declare.

pub mod cancel;
pub mod files;
pub mod payload;
pub mod pinhole;
pub mod raster;
pub mod rng;
pub mod simd;
pub mod spot;
pub mod threads;
pub mod ticks;
