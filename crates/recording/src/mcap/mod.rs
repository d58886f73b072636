//! Robotics logs in and out: MCAP files and ROS 1 bags.
//!
//! - [`import()`]: ROS 2 (`cdr`), ROS 1 (`ros1`) and Foxglove (`json`) messages to a
//!   recording, from an MCAP file or a ROS 1 bag ([`container`]): color and depth images
//!   by their header stamps, intrinsics from the camera info, camera poses from the TF
//!   tree or a pose topic ([`messages`] lists the types), depth from a camera of its own
//!   registered to the color view ([`crate::register`]; RealSense recordings'
//!   extrinsics and depth unit: [`realsense`]).
//! - [`export()`]: a recording, and the products a replay saved, to Foxglove's well-known
//!   schemas in JSON, so that Foxglove and Lichtblick open it without a plug-in; it
//!   imports back to the same frames.

mod bag;
mod choose;
mod chunk;
pub mod container;
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
pub mod realsense;
pub mod scan;
pub mod tf;
pub mod wire;

pub use export::{ExportOptions, ExportSummary, export};
pub use import::import;
pub use options::McapOptions;
pub use scan::Scan;
