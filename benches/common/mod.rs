//! Shared set-up of the per-stage benchmarks: a synthetic recording, a pipeline, and its
//! stages replayed up to a frame so that their state (fused depth, cloud, lights) is
//! built up.

// Each bench binary compiles this module and uses a part of it.
#![allow(dead_code)]

use relume::graph::{Frame, FrameSource, Pipeline, Product, Stage};
use relume::recording::synth::{SynthConfig, generate};
use relume::recording::{Header, Replay, ReplayOptions};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// A pipeline replayed over `frames` synthetic 640x480 frames.
pub struct WarmedUp {
    pub pipeline: Pipeline,
    pub header: Header,
    pub stages: Vec<Box<dyn Stage>>,
    /// The last frame as each stage received it (index = stage).
    pub arriving: Vec<Frame>,
    /// The frame before it as each stage received it (empty after one frame).
    pub arriving_before: Vec<Frame>,
    /// The last frame after every stage.
    pub done: Frame,
    /// Keeps the recording and the stages' output directory alive.
    pub _dir: tempfile::TempDir,
}

/// Generates the default synthetic recording with `frames` frames, loads the pipeline
/// named by `RELUME_BENCH_PIPELINE` or else `pipelines/<default_pipeline>`, and replays
/// every frame in this thread, stage after stage, feeding `product@prev` inputs from
/// the previous frame.
pub fn warm_up(default_pipeline: &str, frames: usize) -> WarmedUp {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("synth.relume");
    let config = SynthConfig {
        frames,
        ..SynthConfig::default()
    };
    generate(&config, &path).unwrap();
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let registry = relume::stages::registry();
    let pipeline_path = std::env::var_os("RELUME_BENCH_PIPELINE")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("pipelines")
                .join(default_pipeline)
        });
    let pipeline = Pipeline::load(&pipeline_path, &registry).unwrap();
    let header = replay.recording.header().clone();
    let mut stages = pipeline
        .build(&registry, &header, dir.path(), 1)
        .map_err(|(s, e)| format!("{s}: {e}"))
        .unwrap();
    let mut previous: BTreeMap<String, Arc<Product>> = BTreeMap::new();
    let mut arriving = Vec::new();
    let mut arriving_before = Vec::new();
    let mut done = None;
    for n in 0..frames {
        let mut frame = replay.read(n).unwrap();
        for (name, product) in &previous {
            frame.insert_shared(&format!("{name}@prev"), product.clone());
        }
        arriving_before = std::mem::take(&mut arriving);
        for stage in stages.iter_mut() {
            arriving.push(frame.clone());
            stage.process(&mut frame).unwrap();
        }
        previous = pipeline
            .feedback
            .iter()
            .filter_map(|f| Some((f.product.clone(), frame.get_shared(&f.product)?.clone())))
            .collect();
        done = Some(frame);
    }
    WarmedUp {
        pipeline,
        header,
        stages,
        arriving,
        arriving_before,
        done: done.expect("at least one frame"),
        _dir: dir,
    }
}

/// `stage/<name>`: every stage's `process` on a copy of the frame as it arrived there;
/// with frames in `before` (the frame before, as it arrived at each stage), on the two
/// frames in turn, so that a stage keeping state from frame to frame (a previous frame,
/// a warm start) always meets a frame other than the one it saw last, as in a replay.
pub fn bench_each_stage(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    pipeline: &Pipeline,
    stages: &mut [Box<dyn Stage>],
    arriving: &[Frame],
    before: &[Frame],
) {
    for (i, stage) in stages.iter_mut().enumerate() {
        let spec = &pipeline.stages[i];
        let frames: Vec<&Frame> = std::iter::once(&arriving[i]).chain(before.get(i)).collect();
        // The stage saw `arriving` last (in `warm_up`), so the first run takes the
        // frame before.
        let mut turn = 0;
        group.bench_function(format!("stage/{}", spec.name), |b| {
            b.iter(|| {
                turn = (turn + 1) % frames.len();
                let mut frame: Frame = frames[turn].clone();
                stage.process(&mut frame).unwrap();
                frame
            })
        });
    }
}
