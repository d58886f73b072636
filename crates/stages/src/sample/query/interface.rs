//! What a radiance query is, apart from its implementations: the [`Ray`] in, the [`Hit`]
//! out, the [`RadianceQuery`] trait and the [`QueryKind`] a config names (see the
//! module docs of [`super`]).

use glam::Vec3;

/// A ray or a cone of the query: `origin + t dir` for 0 <= t <= `t_max` (world space,
/// metres; `dir` unit), `spread` the tangent of the cone's half aperture (0: a ray).
/// Only [`VoxelQuery`](super::VoxelQuery) reads `spread`; the others answer the cone's axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub t_max: f32,
    pub spread: f32,
}

impl Ray {
    /// The ray `origin + t dir` for every t >= 0.
    #[inline]
    pub fn unbounded(origin: Vec3, dir: Vec3) -> Ray {
        Ray::cone(origin, dir, 0.0)
    }

    /// The cone about `origin + t dir` for every t >= 0 whose half aperture has tangent
    /// `spread`.
    #[inline]
    pub fn cone(origin: Vec3, dir: Vec3, spread: f32) -> Ray {
        Ray {
            origin,
            dir,
            t_max: f32::INFINITY,
            spread,
        }
    }
}

/// What sent the radiance of a [`Hit`] (see the module docs for what each means to a
/// renderer).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// Real geometry near the shading point: it occludes the environment behind it.
    Surface,
    /// The environment light, at a finite or infinite distance.
    Environment,
}

/// The answer of a query: radiance arriving along the ray from distance `t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub radiance: Vec3,
    pub source: Source,
}

/// The name of an implementation, as the `query` parameter of the sampling stage takes
/// it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum QueryKind {
    /// Screen-space ray marching over the depth map (paper 001's sampler as relume ran
    /// it before the query existed).
    #[default]
    Ssrt,
    /// Environment Mapping: a direction lookup into the distance impostor.
    Em,
    /// Distance Impostor Tracing.
    Dit,
    /// Voxel Cone Tracing.
    Vct,
}

impl QueryKind {
    /// Every kind, in the order of [`QueryKind::NAMES`].
    const ALL: [QueryKind; 4] = [
        QueryKind::Ssrt,
        QueryKind::Em,
        QueryKind::Dit,
        QueryKind::Vct,
    ];
    /// The parameter values, in the order of the variants.
    pub const NAMES: &'static [&'static str] = &["ssrt", "em", "dit", "vct"];

    /// The kind named `name` (one of [`QueryKind::NAMES`]).
    pub fn from_name(name: &str) -> Option<QueryKind> {
        let i = Self::NAMES.iter().position(|&n| n == name)?;
        Some(Self::ALL[i])
    }

    /// The parameter value of this kind.
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// Whether the implementation reads the distance impostor (an environment map with
    /// distances).
    pub fn needs_environment(self) -> bool {
        matches!(self, QueryKind::Em | QueryKind::Dit)
    }

    /// Whether the implementation reads the scene's voxel volume (`light.voxels`).
    pub fn needs_voxels(self) -> bool {
        self == QueryKind::Vct
    }
}

/// A representation of the real scene that answers rays (paper 000 Fig. 5). An
/// implementation must be deterministic: the same ray gives the same bits.
/// `sample.path` marches its screen-space rays in lane batches of its own
/// (`path/rays.rs`), with the answers [`ScreenQuery`](super::ScreenQuery) gives ray by ray.
pub trait RadianceQuery: Sync {
    /// The radiance arriving at `ray.origin` from `ray.dir`, or `None` when nothing
    /// this representation holds lies within `ray.t_max` (the environment at infinity).
    fn query(&self, ray: &Ray) -> Option<Hit>;
}
