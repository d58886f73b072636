//! MCAP logs in and out.
//!
//! - [`import()`]: ROS 2 (`cdr`) and Foxglove (`json`) messages to a recording: color and
//!   depth images by their header stamps, intrinsics from the camera info, camera poses
//!   from the TF tree or a pose topic ([`messages`] lists the types).
//! - [`export()`]: a recording, and the products a replay saved, to Foxglove's well-known
//!   schemas in JSON, so that Foxglove and Lichtblick open it without a plug-in; it
//!   imports back to the same frames.

pub mod cdr;
mod choose;
mod chunk;
pub mod export;
mod export_products;
mod export_writer;
mod failure;
pub mod import;
mod lengths;
pub mod messages;
mod options;
pub mod pixels;
pub mod read;
pub mod scan;
pub mod tf;

pub use export::{ExportOptions, ExportSummary, export};
pub use import::import;
pub use options::McapOptions;
pub use scan::Scan;
