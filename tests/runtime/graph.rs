//! Several pipelines in one run: their identical first stages run once and fan out;
//! products are shared, not copied; every branch's frames come back in order; a failing
//! branch stops the run naming branch, stage and frame; a slow branch keeps memory
//! bounded.

use super::stages::{CountingSource, header, pipeline, registry};
use relume::graph::{Frame, Pipeline, RunOptions, StageGraph, run_graph};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::time::Duration;

/// Shared: `test.index` then a no-op; then each branch its own tail.
const TRUNK: &str = r#"
[pipeline]
channel_capacity = 2
[[stage]]
kind = "test.index"
outputs = { value = "input" }
[[stage]]
kind = "debug.noop"
"#;

fn variant(tail: &str) -> Pipeline {
    pipeline(&format!("{TRUNK}{tail}"))
}

const COPY: &str = r#"
[[stage]]
kind = "test.copy"
"#;

const SLOW_COPY: &str = r#"
[[stage]]
kind = "test.copy"
params = { sleep_ms = 3.0 }
"#;

struct Outcome {
    frames: Vec<Vec<Frame>>,
    result: Result<relume::graph::RunReport, Box<relume::graph::RunFailure>>,
    max_in_flight: usize,
}

/// Runs `pipelines` as one graph (branches `a`, `b`, ...) on another thread, failing the
/// test if it hangs.
fn run_branches(pipelines: Vec<Pipeline>, frames: usize) -> (StageGraph, Outcome) {
    let labels = ["a", "b", "c", "d"];
    let branches: Vec<(String, &Pipeline)> = pipelines
        .iter()
        .enumerate()
        .map(|(i, p)| (labels[i].to_string(), p))
        .collect();
    let graph = StageGraph::shared(&branches);
    let (tx, rx) = mpsc::channel();
    let g = graph.clone();
    std::thread::spawn(move || {
        let dirs = vec![std::env::temp_dir(); g.branch_count()];
        let stages = g
            .build(&registry(), &header(), &dirs, 1)
            .unwrap_or_else(|(n, e)| panic!("node {n}: {e}"));
        let source = CountingSource::new(frames);
        let mut out = Vec::new();
        let mut max_in_flight = 0;
        let result = run_graph(&g, stages, &source, &RunOptions::default(), &mut |f| {
            out.push(f);
            max_in_flight = max_in_flight.max(source.read.load(Ordering::SeqCst) - out.len());
        });
        let _ = tx.send(Outcome {
            frames: out,
            result,
            max_in_flight,
        });
    });
    let outcome = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("the graph finished without hanging");
    (graph, outcome)
}

#[test]
fn identical_first_stages_run_once_and_fan_out() {
    let a = variant(COPY);
    let b = variant(SLOW_COPY);
    let (graph, out) = run_branches(vec![a, b], 6);
    // Nodes: index, noop (shared), then one copy per branch.
    assert_eq!(graph.nodes.len(), 4);
    assert_eq!(graph.branch_nodes, vec![vec![0, 1, 2], vec![0, 1, 3]]);
    let report = out.result.expect("the run succeeds");
    let rows: Vec<&str> = report.stages.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(
        rows,
        [
            "source",
            "test.index",
            "debug.noop",
            "a/test.copy",
            "b/test.copy"
        ]
    );
    assert!(report.stages.iter().all(|s| s.frames.len() == 6));
}

#[test]
fn shared_products_are_not_copied_and_every_branch_comes_back_in_order() {
    let (_, out) = run_branches(vec![variant(COPY), variant(COPY), variant(SLOW_COPY)], 20);
    let report = out.result.expect("the run succeeds");
    let rows: Vec<&str> = report.stages.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(
        rows,
        [
            "source",
            "test.index",
            "debug.noop",
            "a+b/test.copy",
            "c/test.copy"
        ],
        "a stage some branches share is named after them"
    );
    assert_eq!(out.frames.len(), 20);
    for (i, per_branch) in out.frames.iter().enumerate() {
        assert_eq!(per_branch.len(), 3, "one frame per branch");
        assert!(
            per_branch.iter().all(|f| f.index == i),
            "frame {i} in order"
        );
        let trunk: Vec<_> = per_branch
            .iter()
            .map(|f| f.get_shared("input").expect("the shared product"))
            .collect();
        assert!(
            trunk.iter().all(|p| Arc::ptr_eq(p, trunk[0])),
            "frame {i}: the shared stage's product is one allocation in every branch"
        );
        let own: Vec<_> = per_branch
            .iter()
            .map(|f| f.get_shared("output").expect("the branch's product"))
            .collect();
        // a and b are the same pipeline: all of it is shared; c copies on its own.
        assert!(
            Arc::ptr_eq(own[0], own[1]),
            "identical pipelines share every stage"
        );
        assert!(
            !Arc::ptr_eq(own[0], own[2]),
            "a branch's own stage writes its own"
        );
        assert_eq!(own[0].digest(), own[2].digest());
    }
}

#[test]
fn a_failing_branch_stops_the_run_naming_branch_stage_and_frame() {
    let failing = variant(
        r#"
[[stage]]
name = "fail"
kind = "debug.fail"
params = { frame = 5, mode = "error" }
"#,
    );
    let (_, out) = run_branches(vec![variant(SLOW_COPY), failing], 40);
    let failure = out.result.expect_err("the run fails");
    assert_eq!(
        failure.to_string(),
        "branch `b`: stage `fail` (debug.fail) failed at frame 5: debug.fail was asked to \
         fail at frame 5"
    );
    let indices: Vec<usize> = out.frames.iter().map(|f| f[0].index).collect();
    assert_eq!(indices, [0, 1, 2, 3, 4], "the frames every branch finished");
}

#[test]
fn a_slow_branch_keeps_memory_bounded() {
    let frames = 60;
    let (graph, out) = run_branches(vec![variant(COPY), variant(SLOW_COPY)], frames);
    out.result.expect("the run succeeds");
    assert_eq!(out.frames.len(), frames);
    // In flight at most: the source's frame, one per node, two per channel (one into
    // each node, one out of each branch).
    let channels = graph.nodes.len() + graph.branch_count();
    let bound = 1 + graph.nodes.len() + 2 * channels;
    assert!(
        out.max_in_flight <= bound,
        "{} frames in flight, bound {bound}",
        out.max_in_flight
    );
    assert!(
        out.max_in_flight >= 4,
        "the slow branch should fill the queues ({} in flight)",
        out.max_in_flight
    );
}

#[test]
fn a_stage_fed_back_from_a_branch_stage_is_not_shared() {
    // `early` reads `late`'s product of the previous frame; the branches differ in
    // `late`, so `early` cannot be one stage for both.
    let with_late = |sleep: f64| {
        pipeline(&format!(
            r#"
[[stage]]
kind = "test.index"
outputs = {{ value = "input" }}
[[stage]]
name = "early"
kind = "test.copy"
inputs = {{ input = "late_value@prev" }}
outputs = {{ output = "early_value" }}
[[stage]]
name = "late"
kind = "test.copy"
params = {{ sleep_ms = {sleep:?} }}
outputs = {{ output = "late_value" }}
"#
        ))
    };
    let (graph, out) = run_branches(vec![with_late(0.0), with_late(1.0)], 5);
    assert_eq!(graph.branch_nodes, vec![vec![0, 1, 2], vec![0, 3, 4]]);
    out.result.expect("the run succeeds");
    for per_branch in &out.frames {
        let early: Vec<f32> = per_branch
            .iter()
            .map(|f| f.depth("early_value").unwrap().data[0])
            .collect();
        let want = per_branch[0].index as f32 - 1.0;
        assert_eq!(early, [want.max(-1.0); 2], "the previous frame's index");
    }
}

#[test]
fn a_feedback_chain_through_an_unshared_stage_cuts_the_sharing_back() {
    // s0 reads y@prev (from s2), s1 reads z@prev (from s3); the pipelines differ only
    // in s3. s1 cannot be shared (its producer is not), so s2 is not, so s0 is not.
    let chain = |sleep: f64| {
        pipeline(&format!(
            r#"
[[stage]]
name = "s0"
kind = "test.copy"
inputs = {{ input = "y@prev" }}
outputs = {{ output = "x" }}
[[stage]]
name = "s1"
kind = "test.copy"
inputs = {{ input = "z@prev" }}
outputs = {{ output = "a" }}
[[stage]]
name = "s2"
kind = "test.copy"
inputs = {{ input = "a" }}
outputs = {{ output = "y" }}
[[stage]]
name = "s3"
kind = "test.copy"
inputs = {{ input = "x" }}
params = {{ sleep_ms = {sleep:?} }}
outputs = {{ output = "z" }}
"#
        ))
    };
    let (graph, out) = run_branches(vec![chain(0.0), chain(0.5)], 4);
    assert_eq!(
        graph.branch_nodes,
        vec![vec![0, 1, 2, 3], vec![4, 5, 6, 7]],
        "nothing shared"
    );
    out.result.expect("the run succeeds");
    // Identical up to s2, with no feedback: s0..s2 shared.
    let plain = |sleep: f64| {
        variant(&format!(
            "[[stage]]\nname = \"tail\"\nkind = \"test.copy\"\nparams = {{ sleep_ms = {sleep:?} }}\n"
        ))
    };
    let (graph, _) = run_branches(vec![plain(0.0), plain(0.5)], 1);
    assert_eq!(graph.branch_nodes, vec![vec![0, 1, 2], vec![0, 1, 3]]);
}
