//! `external/...`: the cost of an external stage's transport, the default's four RGB
//! f32 irradiance layers at 640x480 (14.7 MB) to a Python identity stage and back, per
//! frame (issue 54's budget: 10 ms). The program returns its inputs as they came, so
//! the time is transport and the protocol's handling on both sides.
//!
//! Needs Python 3 with numpy and msgpack (`pip install ./python`); `RELUME_PYTHON`
//! names the interpreter (default `python3`). Without them the bench says so and
//! measures nothing.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use relume::graph::{BuildContext, Frame, Params, Product, world::EmptyWorld};
use relume::raster::Vec3Image;
use relume::recording::synth::{SynthConfig, generate};
use relume::recording::{Replay, ReplayOptions};
use relume::stages::{external, kind};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

const LAYERS: [&str; 4] = ["e_r_direct", "e_r_indirect", "e_rv_direct", "e_rv_indirect"];

const IDENTITY: &str = "import sys, relume_stage\n\
    sys.exit(relume_stage.run(lambda frame, settings: dict(frame.inputs)))\n";

fn bench(c: &mut Criterion) {
    let python = std::env::var("RELUME_PYTHON").unwrap_or_else(|_| "python3".into());
    let package = Path::new(env!("CARGO_MANIFEST_DIR")).join("python");
    let usable = std::process::Command::new(&python)
        .args(["-c", "import numpy, msgpack, relume_stage"])
        .env("PYTHONPATH", &package)
        .output()
        .is_ok_and(|o| o.status.success());
    if !usable {
        eprintln!(
            "external: skipped: {python} cannot import numpy, msgpack and relume_stage \
             (pip install ./python, or set RELUME_PYTHON)"
        );
        return;
    }
    // SAFETY of the environment: set before any thread of this process starts one.
    unsafe { std::env::set_var("PYTHONPATH", &package) };
    let dir = tempfile::tempdir().unwrap();
    let recording = dir.path().join("room.relume");
    generate(
        &SynthConfig {
            frames: 1,
            ..SynthConfig::default()
        },
        &recording,
    )
    .unwrap();
    let replay = Replay::open(&recording, ReplayOptions::default()).unwrap();
    let header = replay.recording.header();
    let (w, h) = (
        header.color_intrinsics.width,
        header.color_intrinsics.height,
    );
    std::fs::write(dir.path().join("identity.py"), IDENTITY).unwrap();

    let mut frame = Frame::new(0, 0);
    for (i, layer) in LAYERS.iter().enumerate() {
        let data = (0..w * h)
            .map(|p| Vec3::splat((p as f32 + i as f32) * 1e-3))
            .collect();
        let image = Vec3Image::from_vec(w, h, data).unwrap();
        frame.insert(layer, Product::new(kind::RADIANCE, image));
    }
    let mut group = c.benchmark_group("external");
    group.sample_size(30);
    // `auto`: shared memory (relume_stage maps it); `pipe`: every byte over the pipe.
    for transport in ["auto", "pipe"] {
        let mut params = Params::defaults(external::INFO.params);
        let text = |s: &str| relume::graph::ParamValue::Str(s.to_string());
        let list = |v: Vec<String>| relume::graph::ParamValue::StrList(v);
        params.set("interpreter", text(&python));
        params.set(
            "program",
            text(dir.path().join("identity.py").to_str().unwrap()),
        );
        params.set("transport", text(transport));
        let ports: Vec<String> = LAYERS.iter().map(|l| format!("{l}=radiance")).collect();
        params.set("input_kinds", list(ports.clone()));
        params.set("output_kinds", list(ports));
        let roles: BTreeMap<String, String> = LAYERS
            .iter()
            .map(|l| (l.to_string(), l.to_string()))
            .collect();
        let world: Arc<dyn relume::graph::world::World> = Arc::new(EmptyWorld);
        let ctx = BuildContext {
            stage_name: "identity",
            params: &params,
            inputs: &roles,
            outputs: &roles,
            header,
            out_dir: dir.path(),
            seed: 1,
            world: &world,
        };
        let mut stage = (external::INFO.build)(&ctx).expect("the identity program starts");
        group.bench_function(format!("identity_4_radiance_640x480/{transport}"), |b| {
            b.iter(|| {
                let mut f = frame.clone();
                stage.process(&mut f).unwrap();
                f
            })
        });
        stage.finish().unwrap();
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
