//! The environment-sample cloud (paper 000 Sec. 5): what `cloud.samples` keeps of the
//! real room, and what impostors, voxel volumes and the G-buffer splat are made from.

use glam::Vec3;

/// Environment samples (paper 000 Sec. 5) as they stand after a frame: world positions
/// (metres), compensated linear colors and unit world normals, in a deterministic order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EnvCloud {
    pub positions: Vec<Vec3>,
    pub colors: Vec<Vec3>,
    pub normals: Vec<Vec3>,
}

impl EnvCloud {
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}
