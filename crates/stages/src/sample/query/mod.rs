//! The radiance query (paper 000 Sec. 6, Fig. 5: "an interface to query radiance from
//! the scene"): a ray in; the radiance arriving along it, how far away it comes from,
//! and what sent it, out. The renderers ask it both when they shade a virtual object
//! (paper 000 eq. 3) and when they estimate the differential background (eqs. 4, 8),
//! and each implementation is one way of representing the real scene:
//!
//! | `query` | implementation | the real scene is |
//! |---|---|---|
//! | `ssrt` | [`ScreenQuery`] | the fused depth map, marched in screen space within `max_distance`; beyond it the environment map stands, looked up by direction |
//! | `em` | [`ImpostorQuery`] with 0 iterations | the distance impostor looked up by direction alone (Environment Mapping, Sec. 6.1) |
//! | `dit` | [`ImpostorQuery`] | the distance impostor traced: the lookup refined from its stored distances until the ray crosses the stored surface (Distance Impostor Tracing, Sec. 6.1, after Szirmay-Kalos et al.) |
//! | `vct` | [`VoxelQuery`] | the environment cloud voxelized into a mip-mapped volume, marched by cones (Voxel Cone Tracing, Secs. 6.1 and 6.5, after Crassin et al.) |
//!
//! This module is a leaf: it knows rays, maps and depth images, not stages.
//!
//! What a [`Hit`] means to a renderer (paper 001's two-mode split of the same
//! integral): a [`Source::Surface`] is real geometry near the shading point; it blocks
//! the environment light behind it and reflects `radiance` (the camera's light of the
//! room) as indirect light. A [`Source::Environment`] is the environment light itself,
//! arriving from distance `t` with `radiance`: direct light, and the distance up to
//! which a virtual object can stand in front of it (the "ray 3" early occlusion of
//! Sec. 6.4 is an object farther than `t`). No hit (`None`) is the environment at
//! infinity, whose radiance the renderer takes from its importance table.

mod impostor;
mod interface;
mod screen;
mod voxels;

pub use impostor::{ImpostorQuery, MAX_FACE_SIZE, MAX_ITERATIONS, START_DISTANCE, TracedImpostor};
pub use interface::{Hit, QueryKind, RadianceQuery, Ray, Source};
pub use screen::ScreenQuery;
pub use voxels::{MAX_SPREAD, MIN_OPACITY, VoxelQuery, cone_spread};

#[cfg(test)]
mod tests;
