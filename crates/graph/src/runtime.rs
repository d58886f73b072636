//! The threaded runtime: a source thread reads frames, each stage runs on its own
//! thread, bounded crossbeam channels connect them (a slow stage holds back its
//! producers; nothing is dropped), and the calling thread receives finished frames in
//! order. Feedback edges carry a product of frame t-1 to a stage processing frame t.
//!
//! The stages form a [`StageGraph`]: a chain for a lone pipeline, a tree when several
//! pipelines share their first stages. A stage with several children sends each a copy
//! of the frame's product map; the products themselves are shared (`Arc`), never
//! copied. The calling thread takes one finished frame from each branch per frame, so
//! a slow branch holds back the shared stages, and through them every other branch:
//! memory stays bounded by the channels.
//!
//! Failure: the first error or panic of any stage is recorded with the stage, frame
//! and cause; that stage drops its channels, which stops its producers (their sends
//! fail) and lets its consumers finish the frames already passed on. Nothing blocks
//! forever: every wait is on a channel whose other end is dropped when its thread ends.

use super::frame::{Frame, Product};
use super::panics::panic_message;
use super::pipeline::Pipeline;
use super::resolved::{PREVIOUS_SUFFIX, SOURCE_PRODUCT};
use super::stage::{Stage, StageError};
use super::timing::{FrameTiming, RunReport, StageTimings};
use super::tree::StageGraph;
use crossbeam_channel::{Receiver, Sender, bounded};
use relume_recording::{RecordingError, Replay};
use std::ops::Range;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Where frames come from.
pub trait FrameSource: Sync {
    /// Number of frames.
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Reads frame `n` with its source products.
    fn read(&self, n: usize) -> Result<Frame, RecordingError>;
    /// [`FrameSource::read`], also checking what a stage would find unreadable (images
    /// that do not decode), so that `skip_corrupt` can skip such frames too.
    fn read_checked(&self, n: usize) -> Result<Frame, RecordingError> {
        self.read(n)
    }
}

impl FrameSource for Replay {
    fn len(&self) -> usize {
        Replay::len(self)
    }

    fn read(&self, n: usize) -> Result<Frame, RecordingError> {
        Ok(source_frame(n, self.read_frame(n)?))
    }

    fn read_checked(&self, n: usize) -> Result<Frame, RecordingError> {
        let records = self.read_frame(n)?;
        self.check_images(n, &records)?;
        Ok(source_frame(n, records))
    }
}

/// Frame `n` holding its records as the source product.
fn source_frame(n: usize, records: relume_recording::FrameRecords) -> Frame {
    let mut frame = Frame::new(n, records.stamp_ns);
    frame.insert(
        SOURCE_PRODUCT,
        Product::new(relume_recording::RECORD, Arc::new(records)),
    );
    frame
}

/// The branch a failing stage runs in, as errors print it: nothing for a stage every
/// branch runs (and in a lone pipeline), else "branch `label`: " (`a+b` for a stage
/// that some branches share).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Branch(pub Option<String>);

impl std::fmt::Display for Branch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.0 {
            Some(label) => write!(f, "branch `{label}`: "),
            None => Ok(()),
        }
    }
}

/// Why a run stopped early.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("{at}: stage `{stage}` could not be set up: {source}")]
    Build {
        /// The stage's place in its pipeline file, `file:line`.
        at: String,
        stage: String,
        #[source]
        source: StageError,
    },
    #[error("{branch}stage `{stage}` ({kind}) failed at frame {frame}: {source}")]
    Stage {
        branch: Branch,
        stage: String,
        kind: String,
        frame: usize,
        #[source]
        source: StageError,
    },
    #[error("{branch}stage `{stage}` ({kind}) panicked at frame {frame}: {message}")]
    Panic {
        branch: Branch,
        stage: String,
        kind: String,
        frame: usize,
        message: String,
    },
    #[error("{branch}stage `{stage}` ({kind}) failed while finishing: {source}")]
    Finish {
        branch: Branch,
        stage: String,
        kind: String,
        #[source]
        source: StageError,
    },
    #[error(
        "cannot start the thread of {what} (each stage runs on a thread of its own: a \
         pipeline this large needs a higher thread or memory limit, or fewer stages): {source}"
    )]
    Thread {
        /// "stage `name`" or "the recording's reader".
        what: String,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot read frame {frame}: {source}")]
    Source {
        frame: usize,
        #[source]
        source: RecordingError,
    },
}

/// A run that stopped on an error, with what it measured up to then.
#[derive(Debug)]
pub struct RunFailure {
    pub error: PipelineError,
    pub report: RunReport,
}

impl std::fmt::Display for RunFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.error.fmt(f)
    }
}

impl std::error::Error for RunFailure {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.error)
    }
}

/// How to run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Frames to replay (clamped to the source).
    pub frames: Range<usize>,
    /// Skip and count frames whose records are corrupt instead of stopping.
    pub skip_corrupt: bool,
    /// Set to stop after the frames in flight (Ctrl-C).
    pub stop: Arc<AtomicBool>,
    /// One frame in the pipeline at a time: the source reads the next frame only after
    /// the sink has the last one, so no two stages run at once and each stage's
    /// `process_ns` is its own work, not time spent waiting for cores that other stages
    /// hold. Throughput drops to one over the sum of the stages.
    pub lockstep: bool,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            frames: 0..usize::MAX,
            skip_corrupt: false,
            stop: Arc::new(AtomicBool::new(false)),
            lockstep: false,
        }
    }
}

type FeedbackValue = Option<Arc<Product>>;

/// The channels one stage thread owns.
struct StageWiring {
    input: Receiver<Frame>,
    /// Its children's inputs, then the sinks of the branches it ends: each gets the
    /// frame (a copy of the product map, the products themselves shared).
    outputs: Vec<Sender<Frame>>,
    /// (frame key `product@prev`, receiver) for previous-frame inputs.
    feedback_in: Vec<(String, Receiver<FeedbackValue>)>,
    /// (product, sender) for products this stage feeds back.
    feedback_out: Vec<(String, Sender<FeedbackValue>)>,
}

/// Sends `frame` to every output, moving it into the last; false when one of them is
/// closed (its side of the run stopped on an error).
fn send_all(outputs: &[Sender<Frame>], frame: Frame) -> bool {
    let Some((last, rest)) = outputs.split_last() else {
        return true;
    };
    rest.iter().all(|o| o.send(frame.clone()).is_ok()) && last.send(frame).is_ok()
}

/// Runs `stages` (built from `pipeline`) over `source`, handing each finished frame to
/// `sink` in order on the calling thread.
pub fn run(
    pipeline: &Pipeline,
    stages: Vec<Box<dyn Stage>>,
    source: &dyn FrameSource,
    options: &RunOptions,
    sink: &mut dyn FnMut(Frame),
) -> Result<RunReport, Box<RunFailure>> {
    assert_eq!(
        stages.len(),
        pipeline.stages.len(),
        "one built stage per config stage"
    );
    let graph = StageGraph::linear(pipeline);
    run_graph(&graph, stages, source, options, &mut |mut frames| {
        sink(frames.pop().expect("one branch"))
    })
}

/// Runs the stages of `graph` (one built stage per node) over `source`. For each frame,
/// `sink` gets every branch's finished frame, in branch order, on the calling thread;
/// frames come in order. A branch that fails stops the run: the sink gets no frame
/// that some branch did not finish.
pub fn run_graph(
    graph: &StageGraph,
    stages: Vec<Box<dyn Stage>>,
    source: &dyn FrameSource,
    options: &RunOptions,
    sink: &mut dyn FnMut(Vec<Frame>),
) -> Result<RunReport, Box<RunFailure>> {
    assert_eq!(stages.len(), graph.nodes.len(), "one built stage per node");
    assert!(graph.branch_count() > 0, "a graph has a branch");
    let capacity = graph.channel_capacity;
    let frames = options.frames.start.min(source.len())..options.frames.end.min(source.len());
    let first_error: Mutex<Option<PipelineError>> = Mutex::new(None);
    let record_error = |e: PipelineError| {
        let mut slot = first_error.lock().unwrap_or_else(|p| p.into_inner());
        slot.get_or_insert(e);
    };
    let skipped: Mutex<Vec<(usize, String)>> = Mutex::new(Vec::new());

    // Channels: one into each node, one out of each branch to the sink.
    let (mut node_tx, mut node_rx) = (Vec::new(), Vec::new());
    for _ in &graph.nodes {
        let (tx, rx) = bounded::<Frame>(capacity);
        node_tx.push(tx);
        node_rx.push(rx);
    }
    let (mut sink_tx, mut sink_rx) = (Vec::new(), Vec::new());
    for _ in 0..graph.branch_count() {
        let (tx, rx) = bounded::<Frame>(capacity);
        sink_tx.push(tx);
        sink_rx.push(rx);
    }
    let outputs_of = |parent: Option<usize>| -> Vec<Sender<Frame>> {
        let children = graph.children(parent).map(|c| node_tx[c].clone());
        let sinks = (0..graph.branch_count())
            .filter(|&b| graph.branch_end(b) == parent)
            .map(|b| sink_tx[b].clone());
        children.chain(sinks).collect()
    };
    let source_outputs = outputs_of(None);
    let mut wiring: Vec<StageWiring> = node_rx
        .drain(..)
        .enumerate()
        .map(|(n, input)| StageWiring {
            input,
            outputs: outputs_of(Some(n)),
            feedback_in: Vec::new(),
            feedback_out: Vec::new(),
        })
        .collect();
    // Only the threads hold senders: a channel closes when its writer ends.
    node_tx.clear();
    sink_tx.clear();
    // A producer can run ahead of its consumer by every buffered frame: size the
    // feedback channel so that sending never waits on the consumer.
    let feedback_capacity = capacity * (stages.len() + 2) + 2;
    for fb in &graph.feedback {
        let (tx, rx) = bounded::<FeedbackValue>(feedback_capacity);
        wiring[fb.producer]
            .feedback_out
            .push((fb.product.clone(), tx));
        wiring[fb.consumer]
            .feedback_in
            .push((format!("{}{PREVIOUS_SUFFIX}", fb.product), rx));
    }

    // Lockstep: the source takes a token before each frame it sends; the sink gives one
    // back for each frame it gets. Dropping the sender (when the sink is done) frees a
    // source that waits.
    let (token_tx, token_rx) = match options.lockstep {
        true => {
            let (tx, rx) = bounded::<()>(1);
            tx.send(()).expect("the receiver is alive");
            (Some(tx), Some(rx))
        }
        false => (None, None),
    };

    let t0 = Instant::now();
    let mut report = RunReport::default();
    let mut latencies = Vec::new();
    let mut interrupted = false;
    let stage_timings = std::thread::scope(|scope| {
        // A thread the system refuses is an error of the run: what was not started is
        // dropped with its channels, so the threads that did start see their inputs end.
        let source_handle = std::thread::Builder::new()
            .name("relume-source".into())
            .spawn_scoped(scope, || {
                source_loop(
                    source,
                    frames,
                    options,
                    (source_outputs, token_rx),
                    t0,
                    &record_error,
                    &skipped,
                )
            })
            .map_err(|source| {
                record_error(PipelineError::Thread {
                    what: "the recording's reader".into(),
                    source,
                })
            })
            .ok();
        let mut handles = Vec::new();
        for (n, (stage, wires)) in stages.into_iter().zip(wiring).enumerate() {
            if source_handle.is_none() {
                break;
            }
            let record_error = &record_error;
            let node = StageNode {
                name: &graph.nodes[n].stage.name,
                kind: graph.nodes[n].stage.kind,
                branch: graph.branch_label(n),
                measure_allocations: options.lockstep,
            };
            let what = format!("stage `{}`", node.name);
            let spawned = std::thread::Builder::new()
                .name(format!("relume-{}", node.name))
                .spawn_scoped(scope, move || {
                    stage_loop(stage, wires, &node, t0, record_error)
                });
            match spawned {
                Ok(handle) => handles.push(handle),
                Err(source) => {
                    record_error(PipelineError::Thread { what, source });
                    break;
                }
            }
        }
        let mut last_index = None;
        'frames: loop {
            let mut done = Vec::with_capacity(sink_rx.len());
            for rx in &sink_rx {
                match rx.recv() {
                    Ok(frame) => done.push(frame),
                    // That branch ended: after its last frame, or on an error.
                    Err(_) => break 'frames,
                }
            }
            let index = done[0].index;
            debug_assert!(
                last_index.is_none_or(|l| index > l) && done.iter().all(|f| f.index == index),
                "frames leave in order, one per branch"
            );
            last_index = Some(index);
            let latency = done.iter().map(|f| f.entered.elapsed()).max();
            latencies.push(latency.unwrap_or_default().as_nanos() as u64);
            sink(done);
            if let Some(tokens) = &token_tx {
                // Fails only when the source has ended.
                let _ = tokens.send(());
            }
        }
        // Branches still running stop at their next send.
        drop(sink_rx);
        drop(token_tx);
        let (source_timing, was_interrupted) = match source_handle {
            Some(h) => h.join().expect("the source thread catches its panics"),
            None => (StageTimings::new("source", "read"), false),
        };
        interrupted = was_interrupted;
        let mut all = vec![source_timing];
        all.extend(handles.into_iter().enumerate().map(|(n, h)| {
            let mut timings = h
                .join()
                .expect("stage threads catch their panics")
                .unwrap_or_else(|| StageTimings::new("", graph.nodes[n].stage.kind));
            timings.name = graph.row_name(n);
            timings
        }));
        all
    });
    report.wall_ns = t0.elapsed().as_nanos() as u64;
    report.stages = stage_timings;
    report.frames_out = latencies.len();
    report.latencies_ns = latencies;
    report.skipped_corrupt = skipped.into_inner().unwrap_or_else(|p| p.into_inner());
    report.interrupted = interrupted;
    match first_error.into_inner().unwrap_or_else(|p| p.into_inner()) {
        Some(error) => Err(Box::new(RunFailure { error, report })),
        None => Ok(report),
    }
}

/// What a stage thread says about itself in errors.
struct StageNode<'a> {
    name: &'a str,
    kind: &'static str,
    /// The branches that run it, when not all of them do.
    branch: Option<String>,
    /// Measure the stage's allocation high-water mark per frame: in a lockstep run, where
    /// no other stage allocates meanwhile.
    measure_allocations: bool,
}

/// Reads frames and sends them on; returns its timings and whether it was interrupted.
fn source_loop(
    source: &dyn FrameSource,
    frames: Range<usize>,
    options: &RunOptions,
    (outputs, tokens): (Vec<Sender<Frame>>, Option<Receiver<()>>),
    t0: Instant,
    record_error: &dyn Fn(PipelineError),
    skipped: &Mutex<Vec<(usize, String)>>,
) -> (StageTimings, bool) {
    let mut timings = StageTimings::new("source", "read");
    // In lockstep, whether the source holds the token for its next frame (it keeps it
    // over a skipped frame).
    let mut holding = false;
    for n in frames {
        if let Some(tokens) = &tokens
            && !holding
        {
            if tokens.recv().is_err() {
                break; // the sink is done: downstream stopped on an error
            }
            holding = true;
        }
        if options.stop.load(Ordering::Relaxed) {
            return (timings, true);
        }
        let start = Instant::now();
        // Skipping corrupt frames means checking their images here, before a stage
        // fails on them (a second decode, in this recovery mode only).
        let read = || {
            if options.skip_corrupt {
                source.read_checked(n)
            } else {
                source.read(n)
            }
        };
        let frame = match catch_unwind(AssertUnwindSafe(read)) {
            Ok(Ok(mut frame)) => {
                frame.entered = start;
                frame
            }
            Ok(Err(e)) if options.skip_corrupt => {
                skipped
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .push((n, e.to_string()));
                continue;
            }
            Ok(Err(source)) => {
                record_error(PipelineError::Source { frame: n, source });
                break;
            }
            Err(panic) => {
                record_error(PipelineError::Panic {
                    branch: Branch::default(),
                    stage: "source".into(),
                    kind: "read".into(),
                    frame: n,
                    message: panic_message(panic),
                });
                break;
            }
        };
        let processed = Instant::now();
        holding = false;
        if !send_all(&outputs, frame) {
            break; // downstream stopped on an error
        }
        let sent = Instant::now();
        timings.frames.push(FrameTiming {
            frame: n,
            start_ns: (start - t0).as_nanos() as u64,
            wait_in_ns: 0,
            process_ns: (processed - start).as_nanos() as u64,
            wait_out_ns: (sent - processed).as_nanos() as u64,
            program_ns: None,
            alloc_peak_bytes: None,
            parts: None,
        });
    }
    (timings, false)
}

/// Runs one stage until its input closes or something fails.
fn stage_loop(
    mut stage: Box<dyn Stage>,
    wires: StageWiring,
    node: &StageNode,
    t0: Instant,
    record_error: &dyn Fn(PipelineError),
) -> Option<StageTimings> {
    let (name, kind) = (node.name, node.kind);
    let branch = Branch(node.branch.clone());
    let mut timings = StageTimings::new(name, kind);
    let mut first = true;
    let mut failed = false;
    'frames: loop {
        let wait_start = Instant::now();
        let Ok(mut frame) = wires.input.recv() else {
            break;
        };
        if !first {
            for (key, rx) in &wires.feedback_in {
                match rx.recv() {
                    Ok(Some(product)) => frame.insert_shared(key, product),
                    Ok(None) => {}
                    Err(_) => break 'frames, // the producer stopped on an error
                }
            }
        }
        first = false;
        let mark = match node.measure_allocations {
            true => super::memory::allocation_mark(),
            false => None,
        };
        let start = Instant::now();
        let index = frame.index;
        let result = catch_unwind(AssertUnwindSafe(|| {
            super::panics::in_stage(|| stage.process(&mut frame))
        }));
        let processed = Instant::now();
        let alloc_peak_bytes = mark.map(|m| super::memory::allocation_peak(m) as u64);
        let program_ns = stage.program_ns();
        let parts = stage.parts();
        let error = match result {
            Ok(Ok(())) => None,
            Ok(Err(source)) => Some(PipelineError::Stage {
                branch: branch.clone(),
                stage: name.into(),
                kind: kind.into(),
                frame: index,
                source,
            }),
            Err(panic) => Some(PipelineError::Panic {
                branch: branch.clone(),
                stage: name.into(),
                kind: kind.into(),
                frame: index,
                message: panic_message(panic),
            }),
        };
        if let Some(e) = error {
            record_error(e);
            failed = true;
            break;
        }
        for (key, _) in &wires.feedback_in {
            frame.remove(key);
        }
        for (product, tx) in &wires.feedback_out {
            // A send fails only when the consumer has stopped; the run is ending then.
            let _ = tx.send(frame.get_shared(product).cloned());
        }
        if !send_all(&wires.outputs, frame) {
            break;
        }
        let sent = Instant::now();
        timings.frames.push(FrameTiming {
            frame: index,
            start_ns: (start - t0).as_nanos() as u64,
            wait_in_ns: (start - wait_start).as_nanos() as u64,
            process_ns: (processed - start).as_nanos() as u64,
            wait_out_ns: (sent - processed).as_nanos() as u64,
            program_ns,
            alloc_peak_bytes,
            parts,
        });
    }
    // Close our channels before finishing, so neighbours are never held up by `finish`.
    drop(wires);
    if !failed {
        match catch_unwind(AssertUnwindSafe(|| stage.finish())) {
            Ok(Ok(())) => {}
            Ok(Err(source)) => record_error(PipelineError::Finish {
                branch: branch.clone(),
                stage: name.into(),
                kind: kind.into(),
                source,
            }),
            Err(panic) => record_error(PipelineError::Finish {
                branch: branch.clone(),
                stage: name.into(),
                kind: kind.into(),
                source: StageError::Failed(format!("panicked: {}", panic_message(panic))),
            }),
        }
    }
    Some(timings)
}
