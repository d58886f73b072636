//! `relume compare`: several pipelines replayed together over one recording, their
//! shared first stages run once, each scored as `relume eval` scores it alone, and one
//! report (see `relume::eval::report`).

use super::prepare::{self, place_objects};
use super::progress;
use super::replay::{RunArgs, open_recording, stop_on_interrupt};
use anyhow::{Context, bail};
use clap::Parser;
use relume::eval::report::{self, Comparison, FrameImages, StageRun, Variant, VariantImages};
use relume::eval::sampling::ReferenceCache;
use relume::eval::{EvalOptions, Evaluator};
use relume::graph::{Frame, Pipeline, PipelineError, StageGraph, run_graph};
use relume::raster::Rgb8Image;
use relume::recording::writer::write_file_atomic;
use relume::stages::world::{ObjectWorld, PipelineObjects, object_world};
use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

const ABOUT: &str = "\
What it does:
  The pipelines run in one replay. Their longest run of identical leading stages (same
  name, kind, parameters, products and objects: usually the whole acquisition) runs
  once and fans out into one branch per pipeline, so the timing table shows one set of
  shared rows and a LABEL/stage row per branch stage. Each pipeline is scored as
  `relume eval` scores it alone (same keys, same references, same numbers); the
  1024-sample references are computed once for every pipeline whose renderer reads the
  same products with the same settings.

What it writes into --out DIR:
  report.json     everything: per variant its scores, per stage its times per frame
  report.md       a table per scored stage and one of stage times, best in bold
  index.html      open it in a browser (no network needed): the scored frames'
                  composites beside the reference with false-colour differences,
                  per-frame curves, quality against cost
  frames/         the images the page shows
  runs/LABEL/     what each pipeline's `write` stages save (compare two of them with
                  `relume diff`)

A variant's label is its pipeline's name (`[pipeline] name`), made unique.

Time: as `relume eval` for each pipeline, less the shared stages and references. The
references cost about 25 s per scored frame at 640x480 on 2 cores; --reference-stride 4
makes that 16 times less.

Examples:
  relume compare -p pipelines/default.toml -p pipelines/mixed-reality-fast.toml \\
      -p pipelines/mixed-reality-dir.toml --frames 0..30 --reference-stride 4 --out cmp
  relume compare lr.relume -p pipelines/mixed-reality-livingroom1.toml \\
      -p pipelines/mixed-reality-dir-livingroom1.toml --out cmp-lr --no-scores";

#[derive(Parser, Debug)]
#[command(after_help = ABOUT)]
pub struct CompareArgs {
    /// The recording (.relume). Default: the built-in synthetic recording.
    recording: Option<PathBuf>,
    /// A pipeline file (TOML) to compare; give -p once per pipeline.
    #[arg(short, long = "pipeline", value_name = "FILE", required = true)]
    pipelines: Vec<PathBuf>,
    /// Folder for the report (created if missing).
    #[arg(short, long, value_name = "DIR")]
    out: PathBuf,
    /// Frames to replay: A..B (B excluded), A.., ..B or a single index N.
    #[arg(long, value_parser = super::replay::parse_frames)]
    frames: Option<Range<usize>>,
    /// Seed for stages that draw random numbers (the same for every pipeline).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Skip (and count) frames with corrupt records instead of stopping.
    #[arg(long)]
    skip_corrupt: bool,
    /// Compute the references only at pixels whose x and y are multiples of N (as
    /// `relume eval --reference-stride`).
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..))]
    reference_stride: u32,
    /// Time the pipelines without scoring them (no references: the report holds
    /// stage times only).
    #[arg(long)]
    no_scores: bool,
    /// Print one line per frame and pipeline, `LABEL FRAME STAMP product=digest ...`:
    /// without the label, the line `relume replay --hash` prints for that pipeline alone.
    #[arg(long)]
    hash: bool,
}

/// Labels from the pipelines' names: file-name safe, unique (a repeat gets `-2`, ...).
fn labels(pipelines: &[Pipeline]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for p in pipelines {
        let base: String = p
            .name
            .chars()
            .map(|c| match c {
                'a'..='z' | 'A'..='Z' | '0'..='9' | '.' | '_' | '-' => c,
                _ => '-',
            })
            .collect();
        // Not `.` or `..`, nor hidden: the label names a folder under runs/.
        let base = base.trim_start_matches('.');
        let base = if base.trim_matches('-').is_empty() {
            "pipeline".to_string()
        } else {
            base.to_string()
        };
        let mut label = base.clone();
        let mut n = 2;
        while out.contains(&label) {
            label = format!("{base}-{n}");
            n += 1;
        }
        out.push(label);
    }
    out
}

pub fn compare(a: CompareArgs) -> anyhow::Result<i32> {
    let started = Instant::now();
    let registry = relume::stages::registry();
    let mut pipelines = Vec::new();
    for path in &a.pipelines {
        let pipeline = Pipeline::load(path, &registry)?;
        super::prepare::announce_programs(&pipeline);
        pipelines.push(pipeline);
    }
    let labels = labels(&pipelines);
    if a.out.exists() && !a.out.is_dir() {
        bail!("--out {}: not a folder", a.out.display());
    }
    let run_args = RunArgs {
        recording: a.recording.clone(),
        pipeline: None,
        frames: a.frames.clone(),
        skip_corrupt: a.skip_corrupt,
        seed: a.seed,
        overrides: Vec::new(),
        max_pose_gap: None,
    };
    let (replay, frames) = open_recording(&run_args)?;
    for pipeline in &mut pipelines {
        let prefix = format!("{}: ", pipeline.file);
        place_objects(pipeline, &replay, frames.start, &prefix)?;
        if !a.no_scores {
            prepare::warn_every(pipeline);
        }
    }
    // Equal objects (and equal motions) become one allocation, so that references can
    // be shared.
    for i in 1..pipelines.len() {
        let world = |k: usize| object_world(&pipelines[k].world);
        let same =
            |j: usize| world(j).scene == world(i).scene && world(j).moving == world(i).moving;
        if let Some(j) = (0..i).find(|&j| same(j)) {
            pipelines[i].world = Arc::new(ObjectWorld {
                declared: pipelines[i].declared_objects().to_vec(),
                scene: world(j).scene.clone(),
                moving: world(j).moving.clone(),
                lights: world(i).lights.clone(),
            });
        }
    }
    let header = replay.recording.header();
    let stride = a.reference_stride;
    let (w, h) = (
        header.depth_intrinsics.width,
        header.depth_intrinsics.height,
    );
    if stride > 1 && (stride >= w || stride >= h) {
        bail!("--reference-stride {stride} is not below the images' size {w}x{h}");
    }
    let cache = ReferenceCache::default();
    let mut evaluators = Vec::new();
    if !a.no_scores {
        let options = EvalOptions {
            stages: Vec::new(),
            reference_stride: stride,
            frames: Some(frames.clone()),
            score_frames: None,
        };
        for p in &pipelines {
            let mut e = Evaluator::new(p, header, a.seed, &options)
                .map_err(|e| anyhow::anyhow!("{}: {e}", p.file))?;
            e.share_references(cache.clone());
            evaluators.push(e);
        }
    }
    let branches: Vec<(String, &Pipeline)> = labels.iter().cloned().zip(&pipelines).collect();
    let graph = StageGraph::shared(&branches);
    let out_dirs: Vec<PathBuf> = labels.iter().map(|l| a.out.join("runs").join(l)).collect();
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let _lock = super::lock::lock_output(&a.out, "--out")?;
    super::out_dir::remove_stale_partials(&a.out, 5);
    let stages = graph
        .build(&registry, header, &out_dirs, a.seed)
        .map_err(|(node, source)| {
            let (b, stage) = (graph.nodes[node].branches[0], &graph.nodes[node].stage);
            PipelineError::Build {
                at: format!("{}:{}", pipelines[b].file, stage.line),
                stage: stage.name.clone(),
                source,
            }
        })?;

    let stop = stop_on_interrupt();
    let bar = progress::bar(frames.len() as u64, "comparing", "frames");
    let mut images: Vec<FrameImages> = Vec::new();
    let (mut saved_references, mut saved_truths) = (SavedImages::new(), SavedImages::new());
    let mut sink_error: Option<anyhow::Error> = None;
    let stdout = std::io::stdout();
    let options = relume::graph::RunOptions {
        frames: frames.clone(),
        skip_corrupt: a.skip_corrupt,
        stop: stop.clone(),
        lockstep: false,
    };
    let result = run_graph(&graph, stages, &replay, &options, &mut |done: Vec<
        Frame,
    >| {
        bar.inc(1);
        if sink_error.is_some() {
            return;
        }
        let mut step = || -> anyhow::Result<()> {
            if a.hash {
                let mut lock = stdout.lock();
                for (label, frame) in labels.iter().zip(&done) {
                    writeln!(lock, "{label} {}", hash_line(frame))?;
                }
            }
            for (b, (e, frame)) in evaluators.iter_mut().zip(&done).enumerate() {
                e.observe(frame).map_err(|e| anyhow::anyhow!("{e}"))?;
                save_images(
                    &a.out,
                    &labels[b],
                    &pipelines[b],
                    e,
                    frame,
                    stride,
                    (&mut images, &mut saved_references, &mut saved_truths),
                )?;
            }
            Ok(())
        };
        if let Err(e) = step() {
            sink_error = Some(e);
            stop.store(true, std::sync::atomic::Ordering::SeqCst);
        }
        cache.clear();
    });
    bar.finish_and_clear();
    let path = replay.recording.path().display().to_string();
    let run = match result {
        Ok(run) => run,
        Err(f) => {
            return Err(
                anyhow::Error::new(f.error).context(format!("comparison on {path} stopped"))
            );
        }
    };
    if let Some(e) = sink_error {
        return Err(e.context(format!("comparison on {path} stopped")));
    }

    // Stages: node n is timed in run.stages[n + 1] (the source is first).
    let stage_runs: Vec<StageRun> = graph
        .nodes
        .iter()
        .enumerate()
        .map(|(n, node)| {
            let t = &run.stages[n + 1];
            let stats = t.process();
            StageRun {
                name: node.stage.name.clone(),
                kind: node.stage.kind.to_string(),
                variants: node.branches.iter().map(|&b| labels[b].clone()).collect(),
                median_ms: stats.median_ms,
                p95_ms: stats.p95_ms,
                frame_ms: t
                    .frames
                    .iter()
                    .map(|f| f.process_ns as f64 * 1e-6)
                    .collect(),
            }
        })
        .collect();
    let mut comparison = Comparison {
        recording: path.clone(),
        frames: [frames.start, frames.end],
        reference_stride: stride,
        seed: a.seed,
        wall_s: 0.0,
        variants: Vec::new(),
        stages: stage_runs,
        images,
    };
    for (b, p) in pipelines.iter().enumerate() {
        let nodes = &graph.branch_nodes[b];
        let cost_ms = nodes.iter().map(|&n| comparison.stages[n].median_ms).sum();
        let mut frame_ms: Vec<(usize, f64)> = Vec::new();
        for &n in nodes {
            for f in &run.stages[n + 1].frames {
                let ms = f.process_ns as f64 * 1e-6;
                match frame_ms.iter_mut().find(|(i, _)| *i == f.frame) {
                    Some(entry) => entry.1 += ms,
                    None => frame_ms.push((f.frame, ms)),
                }
            }
        }
        frame_ms.sort_by_key(|e| e.0);
        let scores = match evaluators.get(b) {
            Some(e) => e.report()["stages"].clone(),
            None => serde_json::json!({}),
        };
        comparison.variants.push(Variant {
            composite_stage: composite_stage(p).map(|s| s.name.clone()),
            label: labels[b].clone(),
            pipeline: p.name.clone(),
            file: p.file.clone(),
            scores,
            stages: nodes.clone(),
            cost_ms,
            frame_ms,
        });
    }
    // Each image's PSNR, from the scores.
    for f in &mut comparison.images {
        for v in &mut f.variants {
            let b = labels.iter().position(|l| *l == v.label).unwrap_or(0);
            v.psnr_db = scored_psnr(&comparison.variants[b], f.frame, "psnr_db_by_frame");
            v.psnr_db_truth =
                scored_psnr(&comparison.variants[b], f.frame, "psnr_db_truth_by_frame");
        }
    }
    comparison.wall_s = started.elapsed().as_secs_f64();
    let files = [
        (
            "report.json",
            serde_json::to_string_pretty(&comparison)? + "\n",
        ),
        ("report.md", report::markdown::render(&comparison)),
        ("index.html", report::html::render(&comparison)),
    ];
    for (name, text) in &files {
        let target = a.out.join(name);
        write_file_atomic(&target, text.as_bytes())
            .with_context(|| format!("cannot write {}", target.display()))?;
    }

    let table = format!("{} on {path}:\n{}", labels.join(", "), run.table());
    if a.hash {
        eprint!("{table}");
    } else {
        out!("{table}")?;
    }
    for (frame, cause) in &run.skipped_corrupt {
        eprintln!("skipped corrupt frame {frame}: {cause}");
    }
    let mut summary = String::from("\nvariant                       psnr_db   cost ms/frame\n");
    for (v, variant) in comparison.variants.iter().enumerate() {
        let psnr = comparison
            .composite_psnr(v)
            .map_or("–".to_string(), |p| format!("{p:.2}"));
        summary.push_str(&format!(
            "{:<28} {psnr:>8} {:>15.1}\n",
            variant.label, variant.cost_ms
        ));
    }
    summary.push_str(&format!(
        "\nwrote {}/report.json, report.md and index.html ({:.1} s)\n",
        a.out.display(),
        comparison.wall_s
    ));
    if a.hash {
        eprint!("{summary}");
    } else {
        out!("{summary}")?;
    }
    if run.interrupted {
        eprintln!(
            "interrupted: the report covers the {} frames complete",
            run.frames_out
        );
        return Ok(130);
    }
    Ok(0)
}

/// The reference or true images saved so far: (frame, path in the report, image).
type SavedImages = Vec<(usize, String, Rgb8Image)>;

/// `relume replay --hash`'s line for a frame.
pub(super) fn hash_line(frame: &Frame) -> String {
    let mut line = format!("{:06} {}", frame.index, frame.stamp_ns);
    for (name, product) in frame.products() {
        line.push_str(&format!(" {name}={:016x}", product.digest()));
    }
    line
}

/// The first `composite.differential` stage of `pipeline`: the one whose image the
/// report shows and whose scores it plots (eval scores it first too).
fn composite_stage(pipeline: &Pipeline) -> Option<&relume::graph::ResolvedStage> {
    pipeline
        .stages
        .iter()
        .find(|s| s.kind == "composite.differential")
}

/// The composite PSNR that a variant's scores hold for `frame` under `key` (one value
/// per scored frame).
fn scored_psnr(variant: &Variant, frame: usize, key: &str) -> Option<f64> {
    let composite = &variant.scores[variant.composite_stage.as_deref()?];
    let frames = composite["scored_frames"].as_array()?;
    let at = frames
        .iter()
        .position(|f| f.as_u64() == Some(frame as u64))?;
    composite[key][at].as_f64()
}

/// On a frame the evaluator just scored against a reference composite: saves the
/// reference and the true frame (each once per frame and distinct image), the
/// variant's composite and its differences from them, on the reference's pixel
/// lattice, and lists them in `images`.
fn save_images(
    out: &Path,
    label: &str,
    pipeline: &Pipeline,
    evaluator: &Evaluator,
    frame: &Frame,
    stride: u32,
    (images, saved_references, saved_truths): (
        &mut Vec<FrameImages>,
        &mut SavedImages,
        &mut SavedImages,
    ),
) -> anyhow::Result<()> {
    let references = evaluator.reference_composites();
    let Some((_, reference)) = references.iter().find(|(f, _)| *f == frame.index) else {
        return Ok(());
    };
    let Some(composite) = composite_stage(pipeline) else {
        return Ok(());
    };
    let final_name = composite
        .outputs
        .get("final")
        .map_or("final", |s| s.as_str());
    let Ok(own) = frame.color(final_name) else {
        return Ok(());
    };
    let folder = format!("frames/{:06}", frame.index);
    std::fs::create_dir_all(out.join(&folder))
        .with_context(|| format!("cannot create {}", out.join(&folder).display()))?;
    let save = |name: &str, image: &Rgb8Image| -> anyhow::Result<String> {
        let relative = format!("{folder}/{name}.png");
        let bytes = report::images::png_bytes(image).map_err(anyhow::Error::msg)?;
        write_file_atomic(&out.join(&relative), &bytes)
            .with_context(|| format!("cannot write {}", out.join(&relative).display()))?;
        Ok(relative)
    };
    let reference = report::images::on_lattice(reference, stride);
    let own = report::images::on_lattice(own, stride);
    // Variants whose renderers read other products have other references: each is
    // saved once, the first as `reference.png`.
    let entry = match images.iter().position(|f| f.frame == frame.index) {
        Some(i) => i,
        None => {
            images.push(FrameImages {
                frame: frame.index,
                reference: save("reference", &reference)?,
                truth: None,
                variants: Vec::new(),
            });
            let path = images[images.len() - 1].reference.clone();
            saved_references.push((frame.index, path, reference.clone()));
            images.len() - 1
        }
    };
    let reference_path = match saved_references
        .iter()
        .find(|(f, _, image)| *f == frame.index && image.data == reference.data)
    {
        Some((_, path, _)) => path.clone(),
        None => {
            let path = save(&format!("{label}.reference"), &reference)?;
            saved_references.push((frame.index, path.clone(), reference.clone()));
            path
        }
    };
    let composite = save(&format!("{label}.composite"), &own)?;
    let difference = save(
        &format!("{label}.difference"),
        &report::images::difference(&own, &reference),
    )?;
    // The true frame: saved once per frame and objects (pipelines with other objects or
    // virtual lamps have other truths), the first as `truth.png`.
    let truths = evaluator.true_composites();
    let (truth_path, truth_difference) = match truths.iter().find(|t| t.frame == frame.index) {
        Some(t) => {
            let truth = report::images::on_lattice(&t.image, stride);
            let path = match saved_truths
                .iter()
                .find(|(f, _, image)| *f == frame.index && image.data == truth.data)
            {
                Some((_, path, _)) => path.clone(),
                None => {
                    let name = match images[entry].truth.is_none() {
                        true => "truth".to_string(),
                        false => format!("{label}.truth"),
                    };
                    let path = save(&name, &truth)?;
                    images[entry].truth.get_or_insert_with(|| path.clone());
                    saved_truths.push((frame.index, path.clone(), truth.clone()));
                    path
                }
            };
            let difference = save(
                &format!("{label}.truth_difference"),
                &report::images::difference(&own, &truth),
            )?;
            (Some(path), Some(difference))
        }
        None => (None, None),
    };
    images[entry].variants.push(VariantImages {
        label: label.to_string(),
        reference: reference_path,
        composite,
        difference,
        psnr_db: None,
        truth: truth_path,
        truth_difference,
        psnr_db_truth: None,
    });
    Ok(())
}
