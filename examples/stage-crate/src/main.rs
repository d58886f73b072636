//! Runs a pipeline that uses this crate's stage over a recording, with relume's
//! library: `relume-stage-example PIPELINE RECORDING` prints each frame's share of
//! edge pixels and the digest of every product (as `relume replay --hash` does).
//! Without arguments it makes a small synthetic recording and runs `depth-edges.toml`.

use anyhow::Context;
use relume::graph::{Pipeline, RunOptions, run};
use relume::recording::{Replay, ReplayOptions};
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let demo = tempfile_dir()?;
    let result = replay(&demo);
    let _ = std::fs::remove_dir_all(&demo);
    result
}

fn replay(demo: &std::path::Path) -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (pipeline, recording) = match args.as_slice() {
        [pipeline, recording] => (PathBuf::from(pipeline), PathBuf::from(recording)),
        [] => {
            let recording = demo.join("room.relume");
            let synth = relume::recording::synth::SynthConfig {
                frames: 3,
                width: 160,
                height: 120,
                ..Default::default()
            };
            relume::recording::synth::generate(&synth, &recording)
                .context("making the demo recording")?;
            let pipeline = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("depth-edges.toml");
            (pipeline, recording)
        }
        _ => anyhow::bail!("usage: relume-stage-example [PIPELINE RECORDING]"),
    };
    let registry = relume_stage_example::registry();
    let pipeline = Pipeline::load(&pipeline, &registry)?;
    let replay = Replay::open(&recording, ReplayOptions::default())
        .with_context(|| format!("opening {}", recording.display()))?;
    let stages = pipeline
        .build(&registry, replay.recording.header(), demo, 1)
        .map_err(|(stage, e)| anyhow::anyhow!("stage `{stage}` could not be set up: {e}"))?;
    run(
        &pipeline,
        stages,
        &replay,
        &RunOptions::default(),
        &mut |frame| {
            let mut line = format!("{:06}", frame.index);
            if let Ok(edges) = frame.labels("edges") {
                let share = edges.data.iter().filter(|&&l| l > 0).count() as f64
                    / edges.data.len().max(1) as f64;
                line.push_str(&format!(" edges={:.2}%", share * 100.0));
            }
            for (name, product) in frame.products() {
                line.push_str(&format!(" {name}={:016x}", product.digest()));
            }
            println!("{line}");
        },
    )?;
    Ok(())
}

/// A fresh folder for the demo recording and anything the stages write.
fn tempfile_dir() -> anyhow::Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("relume-stage-example-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}
