//! A lone pipeline: failures stop cleanly with the stage and frame named, frames leave
//! in order and none is lost, channel bounds hold under a slow stage, feedback edges
//! deliver the previous frame's product, and a stop request ends after frames in flight.

use super::stages::{CountingSource, header, pipeline, registry};
use relume::graph::{Frame, Pipeline, PipelineError, RunOptions, run};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

struct Outcome {
    frames: Vec<Frame>,
    result: Result<relume::graph::RunReport, Box<relume::graph::RunFailure>>,
    max_in_flight: usize,
}

/// Runs `pipeline` over `source` on another thread, failing the test if it hangs.
fn run_with_timeout(
    p: Pipeline,
    source: Arc<CountingSource>,
    options: RunOptions,
    stop_after: Option<usize>,
) -> Outcome {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let dir = std::env::temp_dir();
        let stages = p
            .build(&registry(), &header(), &dir, 1)
            .unwrap_or_else(|(s, e)| panic!("{s}: {e}"));
        let mut frames = Vec::new();
        let mut max_in_flight = 0;
        let stop = options.stop.clone();
        let result = run(&p, stages, source.as_ref(), &options, &mut |f| {
            frames.push(f);
            max_in_flight = max_in_flight.max(source.read.load(Ordering::SeqCst) - frames.len());
            if stop_after == Some(frames.len()) {
                stop.store(true, Ordering::SeqCst);
            }
        });
        let _ = tx.send(Outcome {
            frames,
            result,
            max_in_flight,
        });
    });
    rx.recv_timeout(Duration::from_secs(60))
        .expect("the pipeline finished without hanging")
}

const FOUR_STAGES_FAILING_AT_5: &str = r#"
[[stage]]
kind = "test.index"
outputs = { value = "input" }
[[stage]]
kind = "debug.noop"
[[stage]]
name = "fail"
kind = "debug.fail"
params = { frame = 5, mode = "MODE" }
[[stage]]
kind = "test.copy"
"#;

#[test]
fn an_error_at_frame_5_stops_cleanly_and_names_stage_and_frame() {
    let p = pipeline(&FOUR_STAGES_FAILING_AT_5.replace("MODE", "error"));
    let out = run_with_timeout(
        p,
        Arc::new(CountingSource::new(40)),
        RunOptions::default(),
        None,
    );
    let failure = out.result.expect_err("the run fails");
    assert_eq!(
        failure.to_string(),
        "stage `fail` (debug.fail) failed at frame 5: debug.fail was asked to fail at frame 5"
    );
    assert!(
        matches!(failure.error, PipelineError::Stage { frame: 5, ref stage, .. } if stage == "fail")
    );
    let indices: Vec<usize> = out.frames.iter().map(|f| f.index).collect();
    assert_eq!(
        indices,
        vec![0, 1, 2, 3, 4],
        "frames before the failure complete, in order"
    );
    assert_eq!(failure.report.frames_out, 5);
}

#[test]
fn a_panic_at_frame_5_is_caught_and_reported() {
    let p = pipeline(&FOUR_STAGES_FAILING_AT_5.replace("MODE", "panic"));
    let out = run_with_timeout(
        p,
        Arc::new(CountingSource::new(40)),
        RunOptions::default(),
        None,
    );
    let failure = out.result.expect_err("the run fails");
    assert_eq!(
        failure.to_string(),
        "stage `fail` (debug.fail) panicked at frame 5: debug.fail was asked to panic at frame 5"
    );
    assert_eq!(out.frames.len(), 5);
}

#[test]
fn a_slow_stage_holds_back_producers_within_the_channel_bounds() {
    let p = pipeline(
        r#"
[pipeline]
channel_capacity = 2
[[stage]]
kind = "test.index"
outputs = { value = "input" }
[[stage]]
kind = "debug.noop"
[[stage]]
kind = "test.copy"
params = { sleep_ms = 3.0 }
[[stage]]
name = "after"
kind = "debug.noop"
"#,
    );
    let frames = 60;
    let source = Arc::new(CountingSource::new(frames));
    let out = run_with_timeout(p, source, RunOptions::default(), None);
    let report = out.result.expect("the run succeeds");
    let indices: Vec<usize> = out.frames.iter().map(|f| f.index).collect();
    assert_eq!(
        indices,
        (0..frames).collect::<Vec<_>>(),
        "lossless and in order"
    );
    // In flight at most: one frame held by the source and by each of the 4 stages,
    // plus 2 per channel on the 5 channels.
    let bound = 1 + 4 + 2 * 5;
    assert!(
        out.max_in_flight <= bound,
        "{} frames in flight, bound {bound}",
        out.max_in_flight
    );
    assert!(
        out.max_in_flight >= 4,
        "the slow stage should fill the queues ({} in flight)",
        out.max_in_flight
    );
    // Back-pressure shows as waiting on output upstream of the slow stage.
    let noop = &report.stages[2];
    assert_eq!(noop.kind, "debug.noop");
    let waited_ms: f64 = noop
        .frames
        .iter()
        .map(|f| f.wait_out_ns as f64 * 1e-6)
        .sum();
    assert!(
        waited_ms > 0.5 * 3.0 * frames as f64 * 0.5,
        "upstream waited only {waited_ms:.1} ms"
    );
    assert_eq!(
        report.stages.len(),
        5,
        "the source and four stages are timed"
    );
    assert!(report.stages.iter().all(|s| s.frames.len() == frames));
}

#[test]
fn feedback_edges_deliver_the_previous_frame_in_either_direction() {
    // Downstream producer: `late` makes `value`; `early` reads value@prev before it.
    let backward = pipeline(
        r#"
[[stage]]
name = "early"
kind = "test.copy"
inputs = { input = "value@prev" }
outputs = { output = "seen" }
[[stage]]
name = "late"
kind = "test.index"
"#,
    );
    assert_eq!(backward.feedback.len(), 1);
    // Upstream producer: read by a later stage one frame late.
    let forward = pipeline(
        r#"
[pipeline]
channel_capacity = 1
[[stage]]
kind = "test.index"
[[stage]]
kind = "debug.noop"
[[stage]]
kind = "test.copy"
inputs = { input = "value@prev" }
outputs = { output = "seen" }
params = { sleep_ms = 1.0 }
"#,
    );
    for p in [backward, forward] {
        let out = run_with_timeout(
            p,
            Arc::new(CountingSource::new(25)),
            RunOptions::default(),
            None,
        );
        out.result.expect("no deadlock, no error");
        assert_eq!(out.frames.len(), 25);
        for f in &out.frames {
            let seen = f.depth("seen").unwrap().data[0];
            let expected = if f.index == 0 {
                -1.0
            } else {
                (f.index - 1) as f32
            };
            assert_eq!(seen, expected, "frame {}", f.index);
            assert!(
                f.get("value@prev").is_none(),
                "feedback inputs are removed after use"
            );
        }
    }
}

#[test]
fn a_failing_feedback_producer_does_not_deadlock_its_consumer() {
    let p = pipeline(
        r#"
[[stage]]
name = "early"
kind = "test.copy"
inputs = { input = "value@prev" }
outputs = { output = "seen" }
[[stage]]
kind = "test.index"
[[stage]]
name = "fail"
kind = "debug.fail"
params = { frame = 3 }
"#,
    );
    let out = run_with_timeout(
        p,
        Arc::new(CountingSource::new(30)),
        RunOptions::default(),
        None,
    );
    let failure = out.result.expect_err("the run fails");
    assert!(
        failure
            .to_string()
            .starts_with("stage `fail` (debug.fail) failed at frame 3"),
        "{failure}"
    );
    assert_eq!(out.frames.len(), 3);
}

#[test]
fn a_stop_request_ends_after_the_frames_in_flight() {
    let p = pipeline("[[stage]]\nkind = \"debug.sleep\"\nparams = { ms = 2.0 }\n");
    let options = RunOptions {
        stop: Arc::new(AtomicBool::new(false)),
        ..Default::default()
    };
    let out = run_with_timeout(p, Arc::new(CountingSource::new(200)), options, Some(3));
    let report = out.result.expect("a stopped run is not an error");
    assert!(report.interrupted);
    let n = out.frames.len();
    assert!((3..20).contains(&n), "{n} frames after stopping at 3");
    let indices: Vec<usize> = out.frames.iter().map(|f| f.index).collect();
    assert_eq!(
        indices,
        (0..n).collect::<Vec<_>>(),
        "complete frames only, in order"
    );
}

const THREE_STAGES: &str = r#"
[[stage]]
kind = "test.index"
outputs = { value = "input" }
[[stage]]
kind = "test.copy"
params = { sleep_ms = 1.0 }
[[stage]]
kind = "debug.noop"
"#;

/// Lockstep: one frame in the pipeline at a time, so no two stages (nor the source)
/// ever process at once, and every frame still arrives, in order.
#[test]
fn lockstep_runs_one_frame_at_a_time() {
    let frames = 20;
    let options = RunOptions {
        lockstep: true,
        ..Default::default()
    };
    let out = run_with_timeout(
        pipeline(THREE_STAGES),
        Arc::new(CountingSource::new(frames)),
        options,
        None,
    );
    let report = out.result.expect("the run succeeds");
    let indices: Vec<usize> = out.frames.iter().map(|f| f.index).collect();
    assert_eq!(indices, (0..frames).collect::<Vec<_>>());
    assert_eq!(out.max_in_flight, 0, "read only after the last frame left");
    let mut intervals: Vec<(u64, u64, &str)> = report
        .stages
        .iter()
        .flat_map(|s| {
            let name = s.name.as_str();
            s.frames
                .iter()
                .map(move |f| (f.start_ns, f.start_ns + f.process_ns, name))
        })
        .collect();
    assert_eq!(intervals.len(), 4 * frames, "the source and three stages");
    intervals.sort();
    for pair in intervals.windows(2) {
        assert!(pair[1].0 >= pair[0].1, "{pair:?} overlap");
    }
}

/// Lockstep ends cleanly when frames are skipped (the source keeps its turn) and when a
/// stage fails (the source waiting for its turn is let go).
#[test]
fn lockstep_survives_skipped_frames_and_failures() {
    let options = || RunOptions {
        lockstep: true,
        skip_corrupt: true,
        ..Default::default()
    };
    let source = CountingSource {
        corrupt: vec![3, 4, 9],
        ..CountingSource::new(10)
    };
    let out = run_with_timeout(pipeline(THREE_STAGES), Arc::new(source), options(), None);
    let report = out.result.expect("the run succeeds");
    let indices: Vec<usize> = out.frames.iter().map(|f| f.index).collect();
    assert_eq!(indices, vec![0, 1, 2, 5, 6, 7, 8]);
    assert_eq!(report.skipped_corrupt.len(), 3);
    let p = pipeline(&FOUR_STAGES_FAILING_AT_5.replace("MODE", "error"));
    let out = run_with_timeout(p, Arc::new(CountingSource::new(40)), options(), None);
    let failure = out.result.expect_err("the run fails");
    assert!(matches!(
        failure.error,
        PipelineError::Stage { frame: 5, .. }
    ));
    assert_eq!(out.frames.len(), 5);
}

#[test]
fn frame_ranges_select_frames() {
    let p = pipeline("[[stage]]\nkind = \"test.index\"\n");
    let options = RunOptions {
        frames: 7..12,
        ..Default::default()
    };
    let out = run_with_timeout(p, Arc::new(CountingSource::new(20)), options, None);
    out.result.unwrap();
    let values: Vec<f32> = out
        .frames
        .iter()
        .map(|f| f.depth("value").unwrap().data[0])
        .collect();
    assert_eq!(values, vec![7.0, 8.0, 9.0, 10.0, 11.0]);
}
