//! The light stages: where the environment light comes from and how it is prepared
//! for sampling.
//!
//! | kind | module | what it does |
//! |---|---|---|
//! | `light.envmap` | [`source`] | an HDR lat-long map from a file or the recording's attachment |
//! | `light.impostor` | [`impostor`] | a distance impostor splatted from the environment-sample cloud (paper 000 Sec. 6.1) |
//! | `light.importance` | [`importance`] | the table of environment importance samples (paper 001 Sec. 5.2) |
//! | `light.split` | [`split`] | direct and indirect parts by an energy ratio (paper 004 Sec. 4.2) |
//! | `light.val` | [`val`] | virtual area lights and SH9 indirect light (paper 004 Secs. 4.3-4.4) |
//! | `light.voxels` | [`voxels`] | a mip-mapped voxel volume of the environment-sample cloud (paper 000 Sec. 6.1) |

pub mod importance;
pub mod impostor;
mod per_cloud;
pub mod source;
pub mod split;
pub mod val;
pub mod voxels;
