//! `relume eval`: run a pipeline and score its stages against the recording's ground
//! truth (see `relume::eval` for every key).

use super::prepare;
use super::progress;
use super::replay::{Pacing, RunArgs, load, stop_on_interrupt};
use anyhow::bail;
use clap::Parser;
use relume::eval::{EvalOptions, Evaluator};
use serde_json::Value;
use std::path::PathBuf;

const SCORES: &str = "\
Scores (per stage, keyed by the stage's name):
  depth.fuse        rmse_raw_m, rmse_fused_m, holes_raw, holes_fused (fractions of pixels
                    the truth sees); without truth: warp_rmse_{raw,fused}_m,
                    warp_overlap_{raw,fused} (frame t-1 warped into frame t vs raw depth t)
  normals.*         mean_angle_deg, median_angle_deg, valid_fraction
  color.compensate  transform_rel_error_median (c_t vs the true map M_0 M_t^-1, relative
                    Frobenius), image_rel_error_median, gain_* (the same for A_t),
                    approximate_frames, pairs_kept_median
  gbuffer.splat     reference_psnr_db (reference vs compensated camera image), coverage
  light.importance  pdf_integral (1 for a correct pdf), irradiance_rel_error (the table's
                    irradiance vs brute force over the map, 26 normals)
  light.val         sh_irradiance_rel_error (SH9 vs brute force over the indirect part),
                    val_center_drift_m (light centres' movement per frame), environment_static
  sample.path       ratio_rmse (E_RV/E_R vs a 1024-samples-per-pixel reference where a path
                    met an object), ratio_rmse_alternative (the other scheme, object-aware
                    on/off), unbiased_p (z-test of 8 more seeds vs the reference); scored on
                    every 15th frame from 14, at most two (14 and 29 from the start;
                    a replay with none: its last frame), each costing about 70 runs
  sample.dir        ratio_rmse (as sample.path's, against the same references: the default
                    sample.path run with 1024 samples on sample.dir's inputs, same frames;
                    a pipeline that also has a sample.path: that stage's), ratio_rmse_all
                    (over every real pixel, not only near the objects)
  filter.axis_aligned
                    mse_unfiltered, mse_filtered, mse_gaussian_same_radius (a plain image
                    Gaussian over the same window) against the same references, on the
                    same frames; temporal_flicker, temporal_flicker_spatial_only (variance
                    per pixel over 4 re-sampled frames of a still camera, with and
                    without the temporal extension), flicker_as_configured (the one
                    the stage's `temporal` setting runs)
  composite.differential
                    psnr_db of the final image against the composite of the references;
                    psnr_db_unfiltered (the composite of the unfiltered layers);
                    psnr_db_by_frame (psnr_db of each scored frame); on recordings of
                    `relume synth`, against the true frame (the room with the objects,
                    and the virtual lamps, really in it, path traced): psnr_db_truth, psnr_db_truth_differential
                    (pixels off the objects the truth changes by more than one level:
                    shadows, bleeding), psnr_db_truth_objects, shadow_ratio_bias (the
                    composite's ratio to the camera frame minus the truth's, in its
                    shadows), truth_noise_psnr_db (the truth's own error),
                    differential_ratio_by_frame (per frame, the share of the truth's
                    shadows and bleeding the composite shows: the least-squares gain of
                    its differential on the truth's, off the objects); on a recording
                    whose light changes (relume synth --panel-off-at F), scored over the
                    change: change_frame, change_lag_frames (frames until that share
                    stays within 5 % of its final value), change_final_ratio,
                    change_ratio_before (the median share before the change); when
                    the pipeline's objects move (keyframes, velocity), the ghost they
                    leave where their shadows and light left, per age 1..5 (frames
                    since then): ghost_share_by_age (how much of what the truth lost
                    there the composite still shows, beyond its usual share of the
                    truth's differential: 0 none, below 0 too little),
                    ghost_psnr_db_by_age, ghost_pixels_by_age,
                    ghost_gone_after_frames (the age from which every share is within
                    5 % of 0) or ghost_unmeasured (why not)

The 1024-sample references and the true frame cost most of an eval at 640x480: about 30 s
each per scored frame on 2 cores (the default pipeline's eval of the built-in recording
takes 2.3 minutes, its replay 12 s). --reference-stride 4 computes them on every 4th
pixel in x and y, 16 times faster.

Examples:
  relume synth -o room.relume && relume eval room.relume -p pipelines/acquisition.toml
  relume eval room.relume -p pipelines/mixed-reality-sampling.toml --json
  relume eval room.relume --json                    the default (mixed-reality) pipeline
  relume eval room.relume --frames 0..15 --stage filter.axis_aligned --reference-stride 4
                                                    the filter's scores on frame 14, fast
  relume eval room60.relume -p pipelines/mixed-reality-moving.toml --score-frames 8..50 \
      --stage composite.differential --reference-stride 4
                                                    the composite frame by frame while
                                                    the torus slides";

#[derive(Parser, Debug)]
#[command(after_help = SCORES)]
pub struct EvalArgs {
    #[command(flatten)]
    run: RunArgs,
    /// Print the scores as JSON: {recording, pipeline, frames, interrupted,
    /// ground_truth, stages: {<stage name>: {kind, <score keys>}}, scoring_costs:
    /// {reference_render_s, truth_render_s} (seconds per scored frame; only with a
    /// scored composite)}.
    #[arg(long)]
    json: bool,
    /// Directory for files that `write` stages of the pipeline save (default: a temporary
    /// directory, removed afterwards).
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// Score only these stages (names from the pipeline file, comma-separated or the
    /// option repeated). The whole pipeline still runs; only the scoring is skipped.
    #[arg(long = "stage", value_delimiter = ',', value_name = "NAMES")]
    stages: Vec<String>,
    /// Compute the 1024-sample references (sample.path, filter, composite scores) only
    /// at pixels whose x and y are multiples of N: N^2 times less work for the
    /// slowest part of an eval; those scores then average over that pixel lattice
    /// (N must be smaller than the images' width and height).
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..))]
    reference_stride: u32,
    /// Score every frame of A..B (references and true frames on each) instead of frames
    /// 14 and 29: composite scores over time, e.g. while an object moves
    /// (psnr_db_by_frame and psnr_db_truth_by_frame then have one entry per frame,
    /// scored_frames says which). Each scored frame costs what one of the usual two does.
    #[arg(long, value_name = "A..B", value_parser = super::replay::parse_frames)]
    score_frames: Option<std::ops::Range<usize>>,
}

pub fn eval(a: EvalArgs) -> anyhow::Result<i32> {
    let loaded = load(&a.run)?;
    let header = loaded.replay.recording.header();
    let (w, h) = (
        header.depth_intrinsics.width,
        header.depth_intrinsics.height,
    );
    let stride = a.reference_stride;
    if stride > 1 && (stride >= w || stride >= h) {
        bail!(
            "--reference-stride {stride} leaves {}x{} pixels of the recording's {w}x{h} \
             images for the references: the scores would stand on a single row or \
             column; use a stride below {}",
            w.div_ceil(stride),
            h.div_ceil(stride),
            w.min(h)
        );
    }
    if let Some(score) = &a.score_frames {
        let run = &loaded.frames;
        if score.start >= run.end || score.end <= run.start || score.is_empty() {
            bail!(
                "--score-frames {}..{} has no frame of the replay ({}..{}): score frames the run replays",
                score.start,
                score.end,
                run.start,
                run.end
            );
        }
        if score.start < run.start || score.end > run.end {
            eprintln!(
                "warning: --score-frames {}..{} reaches past the replay ({}..{}): scoring frames {}..{}",
                score.start,
                score.end,
                run.start,
                run.end,
                score.start.max(run.start),
                score.end.min(run.end)
            );
        }
    }
    let options = EvalOptions {
        stages: a.stages.clone(),
        reference_stride: a.reference_stride,
        frames: Some(loaded.frames.clone()),
        score_frames: a.score_frames.clone(),
    };
    prepare::warn_every(&loaded.pipeline);
    let mut evaluator = Evaluator::new(&loaded.pipeline, header, a.run.seed, &options)
        .map_err(|e| anyhow::anyhow!("{}: {e}", loaded.pipeline.file))?;
    if evaluator.is_empty() {
        bail!(
            "pipeline `{}` ({}) has no stage that eval can score: it scores depth.fuse, \
             normals.*, color.compensate, gbuffer.splat, light.importance, light.val, \
             sample.path, filter.axis_aligned and composite.differential",
            loaded.pipeline.name,
            loaded.pipeline.file
        );
    }
    let scratch = std::env::temp_dir().join(format!("relume-eval-{}", std::process::id()));
    let out_dir = a.out.clone().unwrap_or_else(|| scratch.clone());
    let _lock = match &a.out {
        Some(out) => Some(super::lock::lock_output(out, "--out")?),
        None => None,
    };
    let stop = stop_on_interrupt();
    let bar = progress::bar(loaded.frames.len() as u64, "evaluating", "frames");
    let mut truth_error = None;
    let result = loaded.run_once(&out_dir, &a.run, Pacing::Pipelined, &stop, &mut |f| {
        bar.inc(1);
        if truth_error.is_none()
            && let Err(e) = evaluator.observe(&f)
        {
            truth_error = Some(e);
        }
    });
    bar.finish_and_clear();
    let _ = std::fs::remove_dir_all(&scratch);
    let path = loaded.replay.recording.path().display().to_string();
    let run = match result {
        Ok(run) => run,
        Err(f) => {
            return Err(
                anyhow::Error::new(f.error).context(format!("evaluation of {path} stopped"))
            );
        }
    };
    if let Some(e) = truth_error {
        bail!("{path}: {e}");
    }
    super::replay::some_frame_replayed(&loaded, &run)?;
    // Scores of an interrupted run cover the frames complete: printed, but the exit
    // status says they are partial (as replay's does).
    let status = if run.interrupted {
        eprintln!(
            "interrupted: the scores cover the {} frames complete",
            run.frames_out
        );
        130
    } else {
        0
    };
    let mut report = evaluator.report();
    let doc = report.as_object_mut().expect("an object");
    doc.insert("recording".into(), path.clone().into());
    doc.insert("pipeline".into(), loaded.pipeline.name.clone().into());
    doc.insert("interrupted".into(), run.interrupted.into());
    let costs = evaluator.scoring_costs();
    if let Some(costs) = &costs {
        doc.insert("scoring_costs".into(), costs.clone());
    }
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
        return Ok(status);
    }
    outln!(
        "{} on {path}: {} frames",
        loaded.pipeline.name,
        report["frames"]
    )?;
    if !evaluator.has_truth() {
        outln!(
            "{path} has no ground truth: the scores that need it are left out (depth.fuse \
             reports the previous frame's depth warped into the current view instead)"
        )?;
    }
    if let Some(Value::Object(stages)) = report.get("stages") {
        for (name, scores) in stages {
            let Value::Object(scores) = scores else {
                continue;
            };
            outln!("{name} ({})", scores["kind"].as_str().unwrap_or("?"))?;
            let mut any = false;
            for (key, value) in scores.iter().filter(|(k, _)| *k != "kind") {
                any = true;
                outln!("  {key:<34} {}", score_text(value))?;
            }
            if !any {
                outln!("  (nothing to score without ground truth)")?;
            }
        }
    }
    if let Some(costs) = costs {
        outln!(
            "scoring cost per scored frame: references {} s, truth {} s",
            score_text(&costs["reference_render_s"]),
            score_text(&costs["truth_render_s"])
        )?;
    }
    Ok(status)
}

/// A score as eval's text prints it: floats (alone or in a list) to 5 decimals, anything
/// else as JSON (null, integers, booleans).
fn score_text(value: &Value) -> String {
    match value {
        Value::Number(n) if n.is_f64() => format!("{:.5}", n.as_f64().unwrap_or(f64::NAN)),
        Value::Array(items) => {
            let items: Vec<String> = items.iter().map(score_text).collect();
            format!("[{}]", items.join(", "))
        }
        other => other.to_string(),
    }
}
