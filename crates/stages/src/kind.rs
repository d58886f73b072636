//! Every built-in product kind in one place, for stage authors: the images of
//! `relume_base::raster`, the record and pose of `relume_recording`, the light models of
//! `relume_scene::light` and the compensation of [`crate::compensate`]. A stage crate
//! declares a new kind beside its type ([`relume_base::payload::ProductKind::of`]) and
//! uses it in its ports like these.
//!
//! [`FrameProducts`] reads the kinds above the runtime from a frame, as
//! [`Frame::depth`] and its siblings read those below it.

use relume_graph::{Frame, StageError};
use relume_scene::light::voxels::VoxelVolume;
use relume_scene::light::{AreaLights, EnvCloud, EnvMap, LightTable};
use std::sync::Arc;

pub use crate::compensate::{COMPENSATION, Compensation};
pub use relume_base::raster::{COLOR, DEPTH, LABELS, NORMALS, POINTS, RADIANCE, SCALAR};
pub use relume_recording::{POSE, RECORD};
pub use relume_scene::light::{AREA_LIGHTS, CLOUD, ENVIRONMENT, LIGHT_TABLE, VOXELS};

/// The kinds that are images and can be written to image files.
pub const IMAGES: &[relume_graph::ProductKind] =
    &[COLOR, DEPTH, POINTS, NORMALS, RADIANCE, SCALAR, LABELS];

/// The kinds the `write` stage can save: the images first, then compensation (JSON),
/// the cloud (PLY), the light model (`relume_scene::light::record`) and the camera pose
/// (a line of a TUM trajectory file).
pub const WRITABLE: &[relume_graph::ProductKind] = &[
    COLOR,
    DEPTH,
    POINTS,
    NORMALS,
    RADIANCE,
    SCALAR,
    LABELS,
    COMPENSATION,
    CLOUD,
    AREA_LIGHTS,
    POSE,
];

/// True for the kinds in [`IMAGES`].
pub fn is_image(kind: relume_graph::ProductKind) -> bool {
    IMAGES.contains(&kind)
}

/// True for the kinds in [`WRITABLE`].
pub fn is_writable(kind: relume_graph::ProductKind) -> bool {
    WRITABLE.contains(&kind)
}

/// Typed access to a frame's products of the kinds above the runtime; errors name the
/// product and what was expected.
pub trait FrameProducts {
    fn compensation(&self, name: &str) -> Result<&Compensation, StageError>;
    fn cloud(&self, name: &str) -> Result<&Arc<EnvCloud>, StageError>;
    fn environment(&self, name: &str) -> Result<&Arc<EnvMap>, StageError>;
    fn light_table(&self, name: &str) -> Result<&Arc<LightTable>, StageError>;
    fn area_lights(&self, name: &str) -> Result<&Arc<AreaLights>, StageError>;
    fn voxels(&self, name: &str) -> Result<&Arc<VoxelVolume>, StageError>;
}

impl FrameProducts for Frame {
    fn compensation(&self, name: &str) -> Result<&Compensation, StageError> {
        self.get_as(name, COMPENSATION)
    }

    fn cloud(&self, name: &str) -> Result<&Arc<EnvCloud>, StageError> {
        self.get_as(name, CLOUD)
    }

    fn environment(&self, name: &str) -> Result<&Arc<EnvMap>, StageError> {
        self.get_as(name, ENVIRONMENT)
    }

    fn light_table(&self, name: &str) -> Result<&Arc<LightTable>, StageError> {
        self.get_as(name, LIGHT_TABLE)
    }

    fn area_lights(&self, name: &str) -> Result<&Arc<AreaLights>, StageError> {
        self.get_as(name, AREA_LIGHTS)
    }

    fn voxels(&self, name: &str) -> Result<&Arc<VoxelVolume>, StageError> {
        self.get_as(name, VOXELS)
    }
}
