//! The seam every renderer plugs into: the [`Renderer`] trait, the one stage wrapper
//! that runs any renderer ([`RendererStage`], made into a registry entry by [`info`]),
//! and [`RendererKind`], how the registry and `relume eval` find a renderer (in
//! [`super::RENDERERS`]).
//!
//! A renderer computes the irradiance layers of a frame (paper 001 eq. 2's E_R and
//! E_RV, split into direct and indirect light, with the mask, k_V and what the filter
//! needs): by Monte Carlo paths (`sample.path`, paper 001 Sec. 5), from virtual area
//! lights (`sample.val`, paper 004 Sec. 5) or from virtual point lights (`sample.dir`,
//! paper 002 Sec. 3). What they share is here once: the frame's depth map, pose and
//! camera, the output roles ([`LAYER_OUTPUTS`]), the layers' allocation and their way
//! into the frame. A renderer says what else it reads and how it computes.
//!
//! A new renderer is its folder (the math as plain functions over buffers, and a type
//! implementing [`Renderer`]), one line in [`super::RENDERERS`], and one line in the contract
//! test (`contract_tests.rs`).

use super::layers::{IrradianceLayers, LAYER_OUTPUTS};
use crate::kind::FrameProducts;
use glam::Affine3A;
use relume_base::pinhole::Pinhole;
use relume_base::raster::{DepthImage, Vec3Image};
use relume_graph::{
    BuildContext, Frame, ParamSpec, Params, Parts, Port, Ports, ProductKind, Stage, StageError,
    StageInfo,
};
use relume_recording::Intrinsics;
use relume_scene::light::voxels::VoxelVolume;
use relume_scene::light::{AreaLights, EnvMap, LightTable};

/// The input role of the depth map every renderer reads (the real geometry; the
/// layers are its size).
pub const DEPTH_ROLE: &str = "depth";
/// The input role of the camera pose every renderer reads.
pub const POSE_ROLE: &str = "pose";

/// A way to compute a frame's irradiance layers. Implemented by `sample.path`'s
/// [`SamplePath`](super::path::SamplePath), `sample.val`'s
/// [`SampleVal`](super::val::SampleVal) and `sample.dir`'s
/// [`SampleDir`](super::instant_radiosity::SampleDir); run by [`RendererStage`].
///
/// Contract (tested for every renderer in `contract_tests.rs`): under a constant
/// environment L over a floor, E_R^dir + E_R^ind = pi L; with no objects E_RV == E_R
/// bit for bit; the same bits at any thread count and on every SIMD path.
pub trait Renderer: Send + Sized + 'static {
    /// The stage kind users write in a pipeline, e.g. `sample.path`.
    const KIND: &'static str;
    /// One line for `relume stages`.
    const SUMMARY: &'static str;
    const PARAMS: &'static [ParamSpec];
    /// The layers it writes, in [`LAYER_OUTPUTS`] order: all of them, or all but
    /// `touched` for a renderer that cannot tell which pixels its objects touched.
    const OUTPUTS: &'static [(&'static str, &'static [ProductKind])] = &LAYER_OUTPUTS;
    /// True when `relume eval` can score it against its own estimator run with many
    /// samples (`sample.path`); otherwise it is scored against the default
    /// `sample.path`'s references on its inputs.
    const REFERENCES_ITSELF: bool = false;

    /// Its input ports given its parameters; [`DEPTH_ROLE`] and [`POSE_ROLE`] among
    /// them, which the wrapper reads for it.
    fn inputs(params: &Params) -> Vec<Port>;

    /// The renderer for a run: its parameters checked, what it builds once (the
    /// objects' points, volume or transfer) built.
    fn build(ctx: &BuildContext) -> Result<Self, StageError>;

    /// The layers a frame starts from before [`Renderer::render`] writes them
    /// (default: irradiance NaN, "nothing there" elsewhere; see
    /// [`IrradianceLayers::new`]).
    fn layers(width: u32, height: u32) -> IrradianceLayers {
        IrradianceLayers::new(width, height)
    }

    /// Estimates the layers of one frame into `out` (the depth map's size).
    fn render(
        &mut self,
        frame: &RenderFrame<'_>,
        out: &mut IrradianceLayers,
    ) -> Result<(), StageError>;

    /// How the last [`Renderer::render`] call's time split into parts, for a renderer
    /// that times them ([`Stage::parts`]).
    fn parts(&self) -> Option<Parts> {
        None
    }
}

/// One frame as a renderer sees it: the depth map, the camera at its size and pose,
/// the frame's index, and its other inputs by role.
pub struct RenderFrame<'f> {
    frame: &'f Frame,
    /// (role, product name) of every input.
    inputs: &'f [(String, String)],
    pub depth: &'f DepthImage,
    /// The depth camera, at the depth map's size.
    pub camera: Pinhole,
    pub camera_to_world: Affine3A,
    /// The frame's index (a key of the random numbers).
    pub index: u64,
}

impl<'f> RenderFrame<'f> {
    /// Reads the depth map and pose of `frame` (bound to `inputs`' roles) and puts the
    /// camera `intrinsics` at the depth map's size.
    pub fn new(
        frame: &'f Frame,
        inputs: &'f [(String, String)],
        intrinsics: &Intrinsics,
    ) -> Result<RenderFrame<'f>, StageError> {
        let product = |role| bound(inputs, role);
        let depth = frame.depth(product(DEPTH_ROLE))?;
        let pose = frame.pose(product(POSE_ROLE))?;
        Ok(RenderFrame {
            frame,
            inputs,
            depth,
            camera: Pinhole::new(intrinsics, depth.width, depth.height),
            camera_to_world: Affine3A::from_mat4(pose.matrix().as_mat4()),
            index: frame.index as u64,
        })
    }

    /// The product bound to input `role`.
    pub fn product<'a>(&'a self, role: &'a str) -> &'a str {
        bound(self.inputs, role)
    }

    pub fn normals(&self, role: &str) -> Result<&'f Vec3Image, StageError> {
        self.frame.normals(self.product(role))
    }

    pub fn radiance(&self, role: &str) -> Result<&'f Vec3Image, StageError> {
        self.frame.radiance(self.product(role))
    }

    pub fn light_table(&self, role: &str) -> Result<&'f LightTable, StageError> {
        self.frame.light_table(self.product(role)).map(|p| &**p)
    }

    pub fn area_lights(&self, role: &str) -> Result<&'f AreaLights, StageError> {
        self.frame.area_lights(self.product(role)).map(|p| &**p)
    }

    pub fn environment(&self, role: &str) -> Result<&'f EnvMap, StageError> {
        self.frame.environment(self.product(role)).map(|p| &**p)
    }

    pub fn voxels(&self, role: &str) -> Result<&'f VoxelVolume, StageError> {
        self.frame.voxels(self.product(role)).map(|p| &**p)
    }
}

/// The product bound to `role` in `inputs` (the role's own name when unbound, as the
/// graph's `BuildContext::input` does).
fn bound<'a>(inputs: &'a [(String, String)], role: &'a str) -> &'a str {
    inputs
        .iter()
        .find(|(r, _)| r == role)
        .map_or(role, |(_, product)| product)
}

/// The stage that runs renderer `R`: reads the depth map and pose, hands the frame to
/// the renderer, and puts the layers into the frame under its output names.
pub struct RendererStage<R> {
    renderer: R,
    /// (role, product name) of every input port.
    inputs: Vec<(String, String)>,
    /// The product names of `R::OUTPUTS`, in order.
    outputs: Vec<String>,
    intrinsics: Intrinsics,
}

impl<R: Renderer> Stage for RendererStage<R> {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let view = RenderFrame::new(frame, &self.inputs, &self.intrinsics)?;
        let mut out = R::layers(view.depth.width, view.depth.height);
        self.renderer.render(&view, &mut out)?;
        out.insert_into(frame, &self.outputs);
        Ok(())
    }

    fn parts(&self) -> Option<Parts> {
        self.renderer.parts()
    }
}

/// The registry entry of renderer `R`: its kind, parameters, ports (its inputs and
/// the layers of `R::OUTPUTS`, each under its role's name) and a builder of
/// [`RendererStage<R>`].
pub const fn info<R: Renderer>() -> StageInfo {
    StageInfo {
        kind: R::KIND,
        summary: R::SUMMARY,
        params: R::PARAMS,
        ports: ports::<R>,
        build: build::<R>,
    }
}

fn ports<R: Renderer>(params: &Params) -> Ports {
    Ports {
        inputs: R::inputs(params),
        outputs: R::OUTPUTS
            .iter()
            .map(|(role, kinds)| Port::new(role, role, kinds))
            .collect(),
    }
}

fn build<R: Renderer>(ctx: &BuildContext) -> Result<Box<dyn Stage>, StageError> {
    let renderer = R::build(ctx)?;
    let inputs = R::inputs(ctx.params)
        .into_iter()
        .map(|port| {
            let product = ctx.input(&port.role);
            (port.role.to_string(), product)
        })
        .collect();
    Ok(Box::new(RendererStage {
        renderer,
        inputs,
        outputs: R::OUTPUTS
            .iter()
            .map(|(role, _)| ctx.output(role))
            .collect(),
        intrinsics: ctx.header.depth_intrinsics,
    }))
}

/// A renderer kind as the rest of relume finds it: its registry entry, and how
/// `relume eval` scores it.
#[derive(Clone, Copy)]
pub struct RendererKind {
    pub info: StageInfo,
    /// See [`Renderer::REFERENCES_ITSELF`].
    pub references_itself: bool,
}

impl RendererKind {
    pub const fn of<R: Renderer>() -> RendererKind {
        RendererKind {
            info: info::<R>(),
            references_itself: R::REFERENCES_ITSELF,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kind;
    use glam::{DQuat, DVec3, Vec3};
    use relume_base::raster::Image;
    use relume_graph::Product;
    use relume_recording::{Header, Pose};
    use relume_scene::objects::VirtualScene;
    use std::collections::BTreeMap;
    use std::sync::Arc;

    /// A renderer that writes its camera's fx into `e_r_dir` and the frame index into
    /// `mask`, and reads a `radiance` it adds to `e_rv_dir`: enough to see what the
    /// wrapper hands it and where the layers land.
    struct Probe {
        frames: u32,
    }

    impl Renderer for Probe {
        const KIND: &'static str = "test.probe";
        const SUMMARY: &'static str = "a probe";
        const PARAMS: &'static [ParamSpec] = &[];
        const OUTPUTS: &'static [(&'static str, &'static [ProductKind])] =
            LAYER_OUTPUTS.split_at(5).0;

        fn inputs(_: &Params) -> Vec<Port> {
            vec![
                Port::new(DEPTH_ROLE, "refined_depth", &[kind::DEPTH]),
                Port::new(POSE_ROLE, "pose", &[kind::POSE]),
                Port::new("radiance", "compensated", &[kind::RADIANCE]),
            ]
        }

        fn build(_: &BuildContext) -> Result<Probe, StageError> {
            Ok(Probe { frames: 0 })
        }

        fn layers(width: u32, height: u32) -> IrradianceLayers {
            IrradianceLayers::filled(width, height, Vec3::ONE)
        }

        fn render(
            &mut self,
            frame: &RenderFrame<'_>,
            out: &mut IrradianceLayers,
        ) -> Result<(), StageError> {
            self.frames += 1;
            let radiance = frame.radiance("radiance")?;
            out.e_r_dir.data.fill(Vec3::splat(frame.camera.fx));
            out.mask
                .data
                .fill(frame.index as f32 + self.frames as f32 / 10.0);
            out.e_rv_dir.data[0] += radiance.data[0];
            out.e_r_ind.data[0] = frame.camera_to_world.translation.into();
            Ok(())
        }
    }

    #[test]
    fn the_wrapper_hands_a_renderer_its_frame_and_writes_its_layers_under_their_names() {
        const INFO: StageInfo = info::<Probe>();
        let params = Params::defaults(INFO.params);
        let ports = (INFO.ports)(&params);
        let roles: Vec<&str> = ports.outputs.iter().map(|p| p.role.as_str()).collect();
        assert_eq!(
            roles,
            ["e_r_dir", "e_r_ind", "e_rv_dir", "e_rv_ind", "mask"]
        );
        let header = Header::new("t", relume_recording::Intrinsics::PRIMESENSE, 0.001);
        let inputs: BTreeMap<String, String> = [
            ("depth", "d"),
            ("pose", "pose"),
            ("radiance", "my_radiance"),
        ]
        .map(|(r, p)| (r.to_string(), p.to_string()))
        .into();
        let outputs: BTreeMap<String, String> =
            [("mask".to_string(), "coverage".to_string())].into();
        let ctx = BuildContext {
            stage_name: "probe",
            params: &params,
            inputs: &inputs,
            outputs: &outputs,
            header: &header,
            out_dir: std::path::Path::new("."),
            seed: 1,
            world: &crate::world::world_of(Arc::new(VirtualScene::default())),
        };
        let mut stage = (INFO.build)(&ctx).unwrap();
        let mut frame = Frame::new(4, 0);
        frame.insert(
            "d",
            Product::new(kind::DEPTH, Image::filled(320, 240, 1.5f32)),
        );
        let pose = Pose::from_parts(DVec3::new(1.0, 2.0, 3.0), DQuat::IDENTITY);
        frame.insert("pose", Product::new(kind::POSE, pose));
        // Without its radiance the renderer's own read fails, naming the product.
        let missing = stage.process(&mut frame).unwrap_err().to_string();
        assert_eq!(
            missing,
            "input product `my_radiance` is missing from the frame"
        );
        let radiance = Image::filled(320, 240, Vec3::new(0.5, 0.25, 0.125));
        frame.insert("my_radiance", Product::new(kind::RADIANCE, radiance));
        stage.process(&mut frame).unwrap();
        // The camera at the depth map's size (PrimeSense is 640x480: half of 525).
        let e_r_dir = frame.radiance("e_r_dir").unwrap();
        assert_eq!((e_r_dir.width, e_r_dir.height), (320, 240));
        assert_eq!(e_r_dir.data[0], Vec3::splat(262.5));
        assert_eq!(
            frame.radiance("e_r_ind").unwrap().data[0],
            Vec3::new(1.0, 2.0, 3.0)
        );
        assert_eq!(
            frame.radiance("e_rv_dir").unwrap().data[0],
            Vec3::new(1.5, 1.25, 1.125)
        );
        // The second call of this stage, on frame 4; `mask` under its bound name.
        assert_eq!(frame.scalar("coverage").unwrap().data[0], 4.2);
        assert!(frame.get("mask").is_none() && frame.get("k_v").is_none());
    }
}
