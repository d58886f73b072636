//! relume's scene layer: what is rendered and what lights it.
//!
//! - [`objects`]: virtual objects (meshes, primitives, materials), their BVH and voxels.
//! - [`light`]: environment maps, importance-sample tables, area lights, SH9, impostors,
//!   voxel volumes and precomputed transfer.

pub mod light;
pub mod objects;
