//! A loaded pipeline made ready for a recording: refused when it needs poses the
//! recording lacks, its anchored objects placed (saying where), the programs it will
//! start named, and a warning before scores of stages that run at their own rate.

use relume::stages::world::PipelineObjects;

/// Makes `pipeline` ready for `replay`: refuses it when a stage needs the recording's
/// poses and the recording has none ([`check_poses`]), then places its objects
/// anchored to the scene for a run from `first_frame`, saying where (each line after
/// `prefix`, which names the pipeline where several run).
pub(crate) fn place_objects(
    pipeline: &mut relume::graph::Pipeline,
    replay: &relume::recording::Replay,
    first_frame: usize,
    prefix: &str,
) -> anyhow::Result<()> {
    check_poses(pipeline, replay)?;
    for placed in pipeline.place_objects_from(replay, first_frame)? {
        eprintln!("{prefix}{placed}");
    }
    Ok(())
}

/// Refuses `pipeline` on `replay` when none of the recording's frames has a pose and a
/// stage reads `decode`'s: every frame would stop at that stage. The hint names the
/// tracker, which gives poses from color and depth.
pub(crate) fn check_poses(
    pipeline: &relume::graph::Pipeline,
    replay: &relume::recording::Replay,
) -> anyhow::Result<()> {
    if replay.stats.frames_with_pose > 0 {
        return Ok(());
    }
    let registry = relume::stages::registry();
    let Some(reader) = relume::stages::track::reads_recorded_pose(&pipeline.stages, &registry)
    else {
        return Ok(());
    };
    anyhow::bail!(
        "{}: the recording has no camera poses, and stage `{}` ({}:{}) needs them: its input \
         `{}` reads `{}`, which `decode` takes from the recording\n\
         hint: track the poses from color and depth with a `pose.track` stage after decode \
         (decode's `outputs = {{ pose = \"recorded_pose\" }}`, then `[[stage]] kind = \
         \"pose.track\"`), as pipelines/acquisition-tracked.toml and \
         pipelines/mixed-reality-tracked.toml do",
        replay.recording.path().display(),
        reader.stage,
        pipeline.file,
        reader.line,
        reader.role,
        reader.product,
    )
}

/// Names the programs `pipeline`'s external stages start, before anything runs: a
/// pipeline file from someone else can run programs, and the user should see which.
pub(crate) fn announce_programs(pipeline: &relume::graph::Pipeline) {
    let programs = relume::stages::external::programs(&pipeline.stages);
    if programs.is_empty() {
        return;
    }
    let list: Vec<String> = programs
        .iter()
        .map(|(stage, command)| format!("stage `{stage}` runs `{command}`"))
        .collect();
    eprintln!(
        "pipeline `{}` starts programs: {}",
        pipeline.name,
        list.join("; ")
    );
}

/// A warning before scores of a pipeline with stages at their own rate (`every = k`,
/// `lag = n`): on the frames between their runs, or always when they run behind, they
/// and the stages after them hand on products of an earlier frame, which eval compares
/// with the current frame's truth and references.
pub(crate) fn warn_every(pipeline: &relume::graph::Pipeline) {
    let slow: Vec<String> = pipeline
        .stages
        .iter()
        .filter(|s| s.every > 1 || s.lag > 0)
        .map(|s| match (s.every, s.lag) {
            (1, lag) => format!("`{}` (lag {lag})", s.name),
            (every, 0) => format!("`{}` (every {every})", s.name),
            (every, lag) => format!("`{}` (every {every}, lag {lag})", s.name),
        })
        .collect();
    if !slow.is_empty() {
        let one = slow.len() == 1;
        eprintln!(
            "warning: {} of `{}` {} at {} own rate (every k: on every k-th frame; lag n: n frames behind): on the frames between, or behind, {} and the stages after {} are scored with products of an earlier frame against the current frame's truth and references",
            slow.join(", "),
            pipeline.file,
            if one { "runs" } else { "run" },
            if one { "its" } else { "their" },
            if one { "it" } else { "they" },
            if one { "it" } else { "them" },
        );
    }
}
