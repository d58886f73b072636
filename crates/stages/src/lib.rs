//! The stage families. Each module holds the math as plain functions over buffers
//! (`op(&src, &mut dst, params) -> Result`) and a thin [`Stage`](relume_graph::Stage)
//! type that the registry builds from config.
//!
//! | kind | module | what it does |
//! |---|---|---|
//! | `decode` | [`decode`] | decodes color, depth and pose from the recording's records |
//! | `pose.track` | [`track`] | camera pose from color and depth: frame-to-model ICP with a photometric term (KinectFusion, ElasticFusion) |
//! | `color.compensate` | [`compensate`] | color compensation c_t to the reference space, A_t / C_t of eq. (2) (paper 000 Sec. 4) |
//! | `depth.fuse` | [`fuse`] | warps the previous fused depth into the view and merges it with the new depth |
//! | `depth.to_points` | [`points`] | back-projects depth to a camera-space position map |
//! | `normals.cross` | [`normals`] | normals from the cross product of neighbouring positions |
//! | `normals.plane_fit` | [`plane_fit`] | normals and refined depth from per-pixel plane fits over disk neighbourhoods |
//! | `cloud.samples` | [`cloud`] | environment samples in a probabilistic hash grid, removed where the depth shows them gone |
//! | `gbuffer.splat` | [`gbuffer`] | splats the cloud into the view with a depth test, fills holes by push-pull |
//! | `light.envmap` | [`light::source`] | an HDR lat-long environment map from the recording's attachment or an EXR/.hdr file |
//! | `light.impostor` | [`light::impostor`] | a distance impostor splatted from the environment-sample cloud (paper 000 Sec. 6.1) |
//! | `light.importance` | [`light::importance`] | the table of environment importance samples (paper 001 Sec. 5.2) |
//! | `light.split` | [`light::split`] | direct and indirect parts of the environment light by an energy ratio per channel (paper 004 Sec. 4.2) |
//! | `light.val` | [`light::val`] | virtual area lights (importance samples + k-means + eq. 7) and SH9 of the indirect part (paper 004 Secs. 4.3-4.4) |
//! | `light.voxels` | [`light::voxels`] | a mip-mapped voxel volume of the environment-sample cloud, for cone tracing (paper 000 Sec. 6.1) |
//! | `sample.path` | [`sample::path`] | two-mode Monte Carlo estimates of E_R and E_RV, direct and indirect (paper 001 Sec. 5) |
//! | `sample.dir` | [`sample::instant_radiosity`] | E_R / E_RV from virtual point lights with real/virtual flags, imperfect shadow maps and interleaved sampling (paper 002 Sec. 3) |
//! | `sample.val` | [`sample::val`] | noise-free E_R / E_RV from the area lights with real and virtual shadow maps plus SH9 (paper 004 Sec. 5) |
//! | `temporal.accumulate` | [`temporal`] | a renderer's irradiance layers averaged over the frames that saw the same surface points (reprojection; issue 33's temporal reuse) |
//! | `filter.axis_aligned` | [`filter`] | axis-aligned world-space Gaussian of the four irradiance layers, bandwidths of eqs. 17-18, temporal reuse (paper 001 Secs. 6-7) |
//! | `composite.differential` | [`composite`] | the finished frame by the differential composite, back in the camera's colors (paper 001 eq. 2, paper 000 Sec. 6.6) |
//! | `material.estimate` | [`material`] | diffuse reflectance of real surfaces, rho = pi L / E_R (paper 000 eq. 5) |
//! | `write` | [`mod@write`] | saves chosen products per frame as PNG or EXR |
//! | `debug.noop`, `debug.sleep`, `debug.fail` | [`debug`] | runtime overhead, back-pressure and failure handling |
//!
//! # A stage of your own
//!
//! A stage is a [`Stage`](relume_graph::Stage) (one frame at a time, state of its own),
//! a [`StageInfo`] (its kind, parameters, ports and builder) and, when it makes
//! something new, a product kind declared beside the type it carries. This example is
//! written from outside the crate, as a user's would be: it adds a kind, registers the
//! stage beside the built-in ones, and runs it after `decode` over a small synthetic
//! recording.
//!
//! ```
//! use relume_base::payload::{Payload, ProductKind, Xxh3};
//! use relume_graph::config::SourceFile;
//! use relume_graph::{
//!     BuildContext, Frame, Pipeline, Port, Ports, Product, RunOptions, Stage, StageError,
//!     StageInfo, run,
//! };
//! use relume_recording::synth::{SynthConfig, generate};
//! use relume_recording::{Replay, ReplayOptions};
//! use relume_stages::kind;
//!
//! /// The mean of a frame's valid depth, in metres: a new product kind.
//! #[derive(Debug)]
//! struct MeanDepth(f32);
//!
//! impl Payload for MeanDepth {
//!     fn digest(&self, h: &mut Xxh3) {
//!         h.update(&self.0.to_bits().to_le_bytes());
//!     }
//! }
//!
//! const MEAN_DEPTH: ProductKind = ProductKind::of::<MeanDepth>("mean depth");
//!
//! /// The op: a plain function over its input.
//! fn mean_depth(depth: &[f32]) -> f32 {
//!     let valid: Vec<f32> = depth.iter().copied().filter(|z| *z > 0.0 && z.is_finite()).collect();
//!     valid.iter().sum::<f32>() / valid.len().max(1) as f32
//! }
//!
//! /// The thin stage around it.
//! struct MeanDepthStage;
//!
//! impl Stage for MeanDepthStage {
//!     fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
//!         let mean = mean_depth(&frame.depth("depth")?.data);
//!         frame.insert("mean_depth", Product::new(MEAN_DEPTH, MeanDepth(mean)));
//!         Ok(())
//!     }
//! }
//!
//! const INFO: StageInfo = StageInfo {
//!     kind: "example.mean_depth",
//!     summary: "the mean of the valid depth of each frame",
//!     params: &[],
//!     ports: |_| Ports {
//!         inputs: vec![Port::new("depth", "depth", &[kind::DEPTH])],
//!         outputs: vec![Port::new("mean_depth", "mean_depth", &[MEAN_DEPTH])],
//!     },
//!     build: |_: &BuildContext| Ok(Box::new(MeanDepthStage)),
//! };
//!
//! let mut registry = relume_stages::registry();
//! registry.register(INFO);
//! let config = "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"example.mean_depth\"\n";
//! let src = SourceFile { name: "example.toml".into(), text: config.into() };
//! let pipeline = Pipeline::parse(&src, &registry).expect("a valid pipeline");
//!
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("room.relume");
//! let synth = SynthConfig { frames: 2, width: 64, height: 48, ..Default::default() };
//! generate(&synth, &path).unwrap();
//! let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
//! let stages = pipeline
//!     .build(&registry, replay.recording.header(), dir.path(), 1)
//!     .expect("stages built");
//! let mut means = Vec::new();
//! run(&pipeline, stages, &replay, &RunOptions::default(), &mut |frame| {
//!     let product = frame.get("mean_depth").expect("the stage ran");
//!     means.push(product.get::<MeanDepth>(MEAN_DEPTH).expect("a mean depth").0);
//! })
//! .expect("the run finished");
//! // The synthetic room is a few metres across.
//! assert_eq!(means.len(), 2);
//! assert!(means.iter().all(|m| (0.5..8.0).contains(m)), "{means:?}");
//! ```

pub mod cloud;
pub mod compensate;
pub mod composite;
pub mod debug;
pub mod decode;
pub mod error;
pub mod external;
pub mod filter;
pub mod fuse;
pub mod gbuffer;
pub mod kind;
pub mod light;
pub mod material;
pub mod normals;
pub mod plane_fit;
pub mod points;
pub mod sample;
pub mod temporal;
pub mod track;
pub mod world;
pub mod write;

pub use error::OpError;
use relume_graph::{Registry, StageInfo};

/// The built-in registry: every stage kind of [`builtin`], and [`world::resolve`] for
/// the configs' `[[object]]` tables.
pub fn registry() -> Registry {
    let mut r = Registry::empty();
    for info in builtin() {
        r.register(info);
    }
    r.set_world_resolver(world::resolve);
    r
}

/// Every built-in stage kind (the renderers from [`sample::RENDERERS`]).
pub fn builtin() -> Vec<StageInfo> {
    let mut all = vec![
        decode::INFO,
        track::INFO,
        compensate::INFO,
        fuse::INFO,
        points::INFO,
        normals::CROSS_INFO,
        plane_fit::INFO,
        cloud::INFO,
        gbuffer::INFO,
        light::source::INFO,
        light::impostor::INFO,
        light::importance::INFO,
        light::split::INFO,
        light::val::INFO,
        light::voxels::INFO,
    ];
    all.extend(sample::RENDERERS.iter().map(|r| r.info));
    all.extend([
        temporal::INFO,
        filter::INFO,
        material::INFO,
        composite::INFO,
        write::INFO,
        debug::NOOP_INFO,
        debug::SLEEP_INFO,
        debug::FAIL_INFO,
        external::INFO,
    ]);
    all
}

#[cfg(test)]
mod tests {
    /// The registry holds every renderer, under its own kind, in [`super::builtin`]'s
    /// place for them (between the light stages and `temporal.accumulate`).
    #[test]
    fn the_registry_holds_every_renderer_in_its_place() {
        let kinds: Vec<&str> = super::builtin().iter().map(|i| i.kind).collect();
        let at = kinds.iter().position(|k| *k == "light.voxels").unwrap();
        assert_eq!(
            kinds[at + 1..at + 5],
            [
                "sample.path",
                "sample.val",
                "sample.dir",
                "temporal.accumulate"
            ]
        );
        let registry = super::registry();
        for r in super::sample::RENDERERS {
            assert!(registry.get(r.info.kind).is_some(), "{}", r.info.kind);
        }
    }
}
