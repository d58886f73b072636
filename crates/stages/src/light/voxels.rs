//! `light.voxels` (paper 000 Sec. 6.1, "(Scene) Voxel Volume"): the environment-sample
//! cloud voxelized into a mip-mapped volume of radiance and opacity, which
//! `sample.path`'s `query = "vct"` marches cones through. The math is
//! [`relume_scene::light::voxels`].
//!
//! The cloud already holds the current frame's fused depth (`cloud.samples` adds it),
//! so the volume is the whole reconstructed room. It is rebuilt only when the cloud
//! changes (a new `Arc`); a frame without the cloud (the first frame when reading
//! `cloud@prev`) gets an empty volume, through which every cone stays clear.

use super::per_cloud::PerCloud;
use crate::kind;
use relume_graph::{
    Frame, ParamDefault, ParamSpec, Port, Ports, Product, Stage, StageError, StageInfo,
};
use relume_scene::light::voxels::VoxelVolume;

const PARAMS: &[ParamSpec] = &[ParamSpec::new(
    "voxel_size",
    ParamDefault::Float(0.04),
    "edge of the finest voxels in metres (two of the cloud's 2 cm cells; grown where the cloud's extent would need more than 256 a side)",
)
.range(1e-4, 100.0)];

pub const INFO: StageInfo = StageInfo {
    kind: "light.voxels",
    summary: "a mip-mapped voxel volume of the environment-sample cloud, for voxel cone tracing (paper 000 Sec. 6.1)",
    params: PARAMS,
    ports: |_| Ports {
        // Without a cloud (the first frame under `cloud@prev`) the volume is empty.
        inputs: vec![Port::new("cloud", "cloud", &[kind::CLOUD]).optional()],
        outputs: vec![Port::new("voxels", "voxels", &[kind::VOXELS])],
    },
    build: |ctx| {
        Ok(Box::new(Voxels {
            cloud: ctx.input("cloud"),
            voxels: ctx.output("voxels"),
            voxel_size: ctx.params.float("voxel_size") as f32,
            volumes: PerCloud::new(),
        }))
    },
};

struct Voxels {
    cloud: String,
    voxels: String,
    voxel_size: f32,
    volumes: PerCloud<VoxelVolume>,
}

impl Stage for Voxels {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let (voxel_size, name) = (self.voxel_size, &self.cloud);
        let volume = self.volumes.get(frame, &self.cloud, |cloud| match cloud {
            Some(c) => VoxelVolume::from_points(&c.positions, &c.colors, voxel_size)
                .map_err(|e| StageError::Failed(format!("cloud `{name}`: {e}"))),
            None => Ok(VoxelVolume::empty()),
        })?;
        frame.insert(&self.voxels, Product::new(kind::VOXELS, volume));
        Ok(())
    }
}
