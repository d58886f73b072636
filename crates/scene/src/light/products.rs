//! The light models as pipeline products ([`relume_base::payload`]): their kinds and
//! digests.

use super::voxels::VoxelVolume;
use super::{AreaLights, EnvCloud, EnvMap, LightTable};
use relume_base::payload::{Payload, ProductKind, digest};
use std::sync::Arc;
use xxhash_rust::xxh3::Xxh3;

/// The world-space cloud of environment samples ([`EnvCloud`]).
pub const CLOUD: ProductKind = ProductKind::of::<Arc<EnvCloud>>("environment-sample cloud");
/// An HDR lat-long environment map ([`EnvMap`]).
pub const ENVIRONMENT: ProductKind = ProductKind::of::<Arc<EnvMap>>("environment map");
/// Importance samples of an environment map ([`LightTable`]).
pub const LIGHT_TABLE: ProductKind = ProductKind::of::<Arc<LightTable>>("light sample table");
/// Virtual area lights and SH9 indirect light ([`AreaLights`]).
pub const AREA_LIGHTS: ProductKind = ProductKind::of::<Arc<AreaLights>>("set of area lights");
/// A mip-mapped voxel volume of the scene ([`VoxelVolume`]).
pub const VOXELS: ProductKind = ProductKind::of::<Arc<VoxelVolume>>("voxel volume");

impl Payload for EnvCloud {
    fn digest(&self, h: &mut Xxh3) {
        h.update(&(self.len() as u64).to_le_bytes());
        digest::vec3s(h, &self.positions);
        digest::vec3s(h, &self.colors);
        digest::vec3s(h, &self.normals);
    }
}

impl Payload for EnvMap {
    fn digest(&self, h: &mut Xxh3) {
        digest::dims(h, self.width, self.height);
        digest::vec3s(h, &self.radiance);
        digest::floats(h, &self.distance);
        digest::floats(h, &self.center.to_array());
    }
}

impl Payload for LightTable {
    fn digest(&self, h: &mut Xxh3) {
        h.update(&(self.samples.len() as u64).to_le_bytes());
        for s in &self.samples {
            digest::floats(h, &s.direction.to_array());
            digest::floats(h, &s.radiance.to_array());
            digest::floats(h, &[s.pdf]);
        }
    }
}

impl Payload for AreaLights {
    fn digest(&self, h: &mut Xxh3) {
        h.update(&(self.lights.len() as u64).to_le_bytes());
        for l in &self.lights {
            digest::floats(h, &l.position.to_array());
            digest::floats(h, &l.normal.to_array());
            digest::floats(h, &l.intensity.to_array());
            digest::floats(h, &[l.area]);
        }
        digest::vec3s(h, &self.sh9);
    }
}

impl Payload for VoxelVolume {
    fn digest(&self, h: &mut Xxh3) {
        digest::floats(h, &self.origin.to_array());
        digest::floats(h, &[self.voxel_size]);
        for level in &self.levels {
            digest::dims(h, level.dims[0], level.dims[1]);
            h.update(&level.dims[2].to_le_bytes());
            for v in &level.voxels {
                digest::floats(h, &v.to_array());
            }
        }
    }
}
