//! `temporal.accumulate`: a renderer's irradiance layers averaged over the frames that
//! saw the same surface points (see [`mod@accumulate`] for the math), so that a renderer can
//! draw few samples per frame and the estimates still hold many.
//!
//! It reads a renderer's layers under the names `fresh_<role>` (a pipeline renames the
//! renderer's outputs, see `pipelines/default.toml`) and writes the accumulated layers
//! under the roles' own names, where `filter.axis_aligned` and `composite.differential`
//! read them unchanged. It also writes `history_frames`, the frames each pixel's estimate
//! holds (the warm-up, and where the camera uncovered new surfaces, can be seen there).
//!
//! The stage keeps the previous frame's output: frames are given to it in order, and
//! the first frame of a replay (for `--frames 10..20`, frame 10) starts without a
//! history, so its layers are that frame's estimates alone. When the pipeline's objects
//! move, the differential history (E_RV - E_R) near them moves with them (step 4 of
//! [`mod@accumulate`]); it then also reads the renderer's `mask`.

pub mod accumulate;
#[cfg(test)]
mod tests;

pub use accumulate::{
    AccumulateParams, Accumulated, ChangeLayers, FreshLayers, History, WorldChange, accumulate,
};

use crate::kind;
use glam::Affine3A;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{ScalarImage, Vec3Image};
use relume_graph::{
    Frame, ParamDefault, ParamSpec, Params, Port, Ports, Product, ProductKind, Stage, StageError,
    StageInfo,
};
use relume_recording::Intrinsics;
use std::sync::Arc;

const PARAMS: &[ParamSpec] = &[
    ParamSpec::new(
        "max_history",
        ParamDefault::Int(32),
        "frames an estimate averages at most: the plain mean of the frames so far up to this many, then an exponential average with this time constant (1 = off)",
    )
    .range(1.0, 4096.0),
    ParamSpec::new(
        "tolerance",
        ParamDefault::Float(2.0),
        "a previous frame's surface point is the same as this frame's within this many pixel footprints (the pixel's width at its distance, widened up to 4x at grazing angles)",
    )
    .range(0.0, 64.0),
    ParamSpec::new(
        "min_normal_cos",
        ParamDefault::Float(0.9),
        "and when the cosine between their normals is at least this",
    )
    .range(-1.0, 1.0),
];

/// (role, default product, kinds) of the inputs, in [`AccumulateStage::inputs`] order.
const INPUTS: [(&str, &str, &[ProductKind]); 10] = [
    ("e_r_dir", "fresh_e_r_dir", &[kind::RADIANCE]),
    ("e_r_ind", "fresh_e_r_ind", &[kind::RADIANCE]),
    ("e_rv_dir", "fresh_e_rv_dir", &[kind::RADIANCE]),
    ("e_rv_ind", "fresh_e_rv_ind", &[kind::RADIANCE]),
    (
        "direct_min_distance",
        "fresh_direct_min_distance",
        &[kind::SCALAR],
    ),
    (
        "indirect_min_distance",
        "fresh_indirect_min_distance",
        &[kind::SCALAR],
    ),
    ("touched", "fresh_touched", &[kind::LABELS]),
    ("world_position", "world_position", &[kind::POINTS]),
    ("world_normal", "world_normal", &[kind::NORMALS]),
    ("pose", "pose", &[kind::POSE]),
];

/// The output roles, in [`Accumulated`] order.
const OUTPUTS: [(&str, &[ProductKind]); 8] = [
    ("e_r_dir", &[kind::RADIANCE]),
    ("e_r_ind", &[kind::RADIANCE]),
    ("e_rv_dir", &[kind::RADIANCE]),
    ("e_rv_ind", &[kind::RADIANCE]),
    ("direct_min_distance", &[kind::SCALAR]),
    ("indirect_min_distance", &[kind::SCALAR]),
    ("touched", &[kind::LABELS]),
    ("history_frames", &[kind::SCALAR]),
];

pub const INFO: StageInfo = StageInfo {
    kind: "temporal.accumulate",
    summary: "a renderer's irradiance layers averaged over the frames that saw the same surface points (reprojection, differential irradiance caching)",
    params: PARAMS,
    ports: |_| Ports {
        inputs: INPUTS
            .iter()
            .map(|(role, product, kinds)| Port::new(role, product, kinds))
            // Which pixels show an object: read where the objects move (step 4), and
            // only where a stage makes it (a still pipeline need not).
            .chain([Port::new("mask", "mask", &[kind::SCALAR]).when_made()])
            .collect(),
        outputs: OUTPUTS
            .iter()
            .map(|(role, kinds)| Port::new(role, role, kinds))
            .collect(),
    },
    build: |ctx| {
        Ok(Box::new(AccumulateStage {
            inputs: INPUTS.map(|(role, _, _)| ctx.input(role)),
            outputs: OUTPUTS.map(|(role, _)| ctx.output(role)),
            params: params_from(ctx.params),
            intrinsics: ctx.header.depth_intrinsics,
            previous: None,
            moving: crate::world::object_world(ctx.world)
                .moves()
                .then(|| crate::world::object_world(ctx.world).clone()),
            mask: ctx.input("mask"),
        }))
    },
};

/// [`AccumulateParams`] from a stage's parameters.
pub fn params_from(p: &Params) -> AccumulateParams {
    AccumulateParams {
        max_history: p.int("max_history").clamp(1, u32::MAX as i64) as u32,
        tolerance: p.float("tolerance") as f32,
        min_normal_cos: p.float("min_normal_cos") as f32,
    }
}

/// The previous frame's output (in [`OUTPUTS`] order, shared with the frame it was
/// written into) and the surface it describes.
struct Previous {
    layers: [Arc<Product>; 8],
    world_position: Arc<Product>,
    world_normal: Arc<Product>,
    world_to_camera: Affine3A,
    camera: Pinhole,
    /// The frame it was, and step 4's layers when the objects move.
    index: u64,
    change: Option<ChangeLayers>,
}

impl Previous {
    /// The history [`accumulate()`] reads; `None` if a product is not of its kind.
    fn history(&self) -> Option<History<'_>> {
        fn radiance(p: &Product) -> Option<&Vec3Image> {
            p.get(kind::RADIANCE)
        }
        fn scalar(p: &Product) -> Option<&ScalarImage> {
            p.get(kind::SCALAR)
        }
        let [
            r_dir,
            r_ind,
            rv_dir,
            rv_ind,
            direct_min,
            indirect_min,
            touched,
            frames,
        ] = &self.layers;
        Some(History {
            irradiance: [
                radiance(r_dir)?,
                radiance(r_ind)?,
                radiance(rv_dir)?,
                radiance(rv_ind)?,
            ],
            direct_min_distance: scalar(direct_min)?,
            indirect_min_distance: scalar(indirect_min)?,
            touched: touched.get(kind::LABELS)?,
            frames: scalar(frames)?,
            world_position: vec3_image(&self.world_position)?,
            world_normal: vec3_image(&self.world_normal)?,
            world_to_camera: self.world_to_camera,
            camera: self.camera,
            change: self.change.as_ref(),
        })
    }
}

/// The stage: the math of [`accumulate()`] and the previous frame's state.
pub struct AccumulateStage {
    inputs: [String; 10],
    outputs: [String; 8],
    params: AccumulateParams,
    intrinsics: Intrinsics,
    previous: Option<Previous>,
    /// The pipeline's objects, when they move.
    moving: Option<crate::world::ObjectWorld>,
    /// The renderer's mask (read only when the objects move).
    mask: String,
}

/// The image inside a shared points or normals product.
fn vec3_image(product: &Product) -> Option<&Vec3Image> {
    if product.is(kind::POINTS) || product.is(kind::NORMALS) {
        product.value()
    } else {
        None
    }
}

impl Stage for AccumulateStage {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let [
            r_dir,
            r_ind,
            rv_dir,
            rv_ind,
            direct_min,
            indirect_min,
            touched,
            position,
            normal,
            pose,
        ] = &self.inputs;
        let world_position = frame.points(position)?;
        let (w, h) = (world_position.width, world_position.height);
        let fresh = FreshLayers {
            irradiance: [
                frame.radiance(r_dir)?,
                frame.radiance(r_ind)?,
                frame.radiance(rv_dir)?,
                frame.radiance(rv_ind)?,
            ],
            direct_min_distance: frame.scalar(direct_min)?,
            indirect_min_distance: frame.scalar(indirect_min)?,
            touched: frame.labels(touched)?,
            world_position,
            world_normal: frame.normals(normal)?,
        };
        let camera_to_world = Affine3A::from_mat4(frame.pose(pose)?.matrix().as_mat4());
        if !camera_to_world.is_finite() {
            return Err(StageError::Failed(
                "temporal.accumulate: the camera pose is not finite".into(),
            ));
        }
        let camera = Pinhole::new(&self.intrinsics, w, h);
        let index = frame.index as u64;
        let mut objects = Vec::new();
        if let Some(world) = &self.moving {
            let earlier = self.previous.as_ref().map_or(index, |p| p.index);
            objects = world
                .moves_between(earlier, index)
                .map_err(|e| StageError::Failed(e.to_string()))?;
        }
        let history = self.previous.as_ref().and_then(Previous::history);
        let change = match &self.moving {
            Some(_) => Some(WorldChange {
                mask: frame.scalar(&self.mask).map_err(|_| {
                    StageError::Failed(format!(
                        "the pipeline's objects move and no `{}` (the renderer's mask, which tells the pixels of objects) reaches temporal.accumulate: bind its `mask` input to the renderer's mask output, e.g. inputs = {{ mask = \"val_mask\" }}",
                        self.mask
                    ))
                })?,
                objects: &objects,
            }),
            None => None,
        };
        let layers = accumulate(
            &fresh,
            history.as_ref(),
            camera,
            camera_to_world,
            &self.params,
            change,
        )?;
        let shared = |name: &str| frame.get_shared(name).cloned();
        let (Some(world_position), Some(world_normal)) = (shared(position), shared(normal)) else {
            return Err(StageError::MissingInput(position.clone()));
        };
        let Accumulated {
            irradiance: [e_r_dir, e_r_ind, e_rv_dir, e_rv_ind],
            direct_min_distance,
            indirect_min_distance,
            touched,
            frames,
            change,
        } = layers;
        let products = [
            Product::new(kind::RADIANCE, e_r_dir),
            Product::new(kind::RADIANCE, e_r_ind),
            Product::new(kind::RADIANCE, e_rv_dir),
            Product::new(kind::RADIANCE, e_rv_ind),
            Product::new(kind::SCALAR, direct_min_distance),
            Product::new(kind::SCALAR, indirect_min_distance),
            Product::new(kind::LABELS, touched),
            Product::new(kind::SCALAR, frames),
        ]
        .map(Arc::new);
        for (name, product) in self.outputs.iter().zip(&products) {
            frame.insert_shared(name, Arc::clone(product));
        }
        self.previous = Some(Previous {
            layers: products,
            world_position,
            world_normal,
            world_to_camera: camera_to_world.inverse(),
            camera,
            index,
            change,
        });
        Ok(())
    }
}
