//! Stages that run behind the frames (paper 004 Sec. 3.2: the server computes the light
//! model asynchronously and the clients render with the last one they received): with
//! `lag = n` in a `[[stage]]` table, the stage runs on a thread of its own, and the
//! consumers of its products at the run's m-th frame read what it made from the
//! (m - n)-th frame's inputs; the first n frames read what it made from the first
//! frame. So from the first frame on, frame m hands its inputs to the stage's thread
//! and goes on with the products of frame m - n, which that thread finished while the
//! frames between were being processed: the stage overlaps later frames on another
//! core, and leaves their critical path unless it takes longer than n frames.
//!
//! Which product a frame receives depends only on its position in the run, never on
//! timing, channel capacity or thread count: the stage's thread processes the frames
//! in order, as the stage would without a lag, and the runtime's thread waits for the
//! one result it needs. So a run's products are as deterministic as with lag = 0, and
//! the stage's own products are bit for bit those it makes without a lag, n frames
//! later, unless it reads through `@prev` a product made from its own (then that
//! input, too, is n frames older than without a lag). Positions, not frame indices:
//! where a run skips frames (`--skip-corrupt`), n counts the frames the run processes.
//!
//! Only the stage's declared inputs travel to its thread, so the n + 1 frames it may
//! hold keep those products alive and no others.
//!
//! The time the runtime measures for such a stage is the wait for its result (what it
//! costs the frame), not the time its thread computes. At the end of a run its thread
//! finishes the frames it was handed (their products are no frame's, but a stage that
//! writes files writes them all), and a failure on any frame is the stage's failure.
//! With `every = k` as well, the stage runs on every k-th frame on its own thread.

use super::frame::{Frame, Product};
use super::panics::{in_stage, panic_message};
use super::stage::{Stage, StageError};
use crossbeam_channel::{Receiver, Sender, bounded, unbounded};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;
use std::thread::JoinHandle;

/// The largest `lag` a config may give.
pub const MAX_LAG: u32 = 64;

/// What the stage's thread made of one frame: its products by name, or why it failed.
type Made = Result<Vec<(String, Option<Arc<Product>>)>, StageError>;

/// `stage` run `lag` frames behind on its own thread; itself for lag 0. `inputs` are
/// the frame keys it reads (`name@prev` for a previous-frame input), `outputs` the
/// products it writes. Fails when the system refuses the thread.
pub fn lag_n(
    stage: Box<dyn Stage>,
    lag: u32,
    inputs: Vec<String>,
    outputs: Vec<String>,
) -> Result<Box<dyn Stage>, StageError> {
    if lag == 0 {
        return Ok(stage);
    }
    // Jobs are at most lag + 1 ahead of the results taken (the runtime's thread waits
    // for result m - n at frame m), so an unbounded channel stays that small.
    let (jobs, job_rx) = unbounded::<Frame>();
    let (made_tx, made) = bounded::<(usize, Made)>(lag as usize + 2);
    let worker = std::thread::Builder::new()
        .name("relume-lag".into())
        .spawn(move || work(stage, job_rx, made_tx, outputs))
        .map_err(|e| {
            StageError::Failed(format!("cannot start the thread of a lagged stage: {e}"))
        })?;
    Ok(Box::new(LagN {
        lag: lag as usize,
        inputs,
        jobs: Some(jobs),
        made,
        worker: Some(worker),
        position: 0,
        handed: 0,
        taken: 0,
        latest: None,
    }))
}

/// The stage's thread: processes the frames in order and sends what each made; stops
/// after a failure (a stage that failed or panicked is not called again) and when the
/// jobs end, handing the stage back for its `finish`.
fn work(
    mut stage: Box<dyn Stage>,
    jobs: Receiver<Frame>,
    made: Sender<(usize, Made)>,
    outputs: Vec<String>,
) -> Option<Box<dyn Stage>> {
    for mut frame in jobs {
        let index = frame.index;
        let result = catch_unwind(AssertUnwindSafe(|| in_stage(|| stage.process(&mut frame))));
        let outcome = match result {
            Ok(Ok(())) => Ok(outputs
                .iter()
                .map(|name| (name.clone(), frame.get_shared(name).cloned()))
                .collect()),
            Ok(Err(e)) => Err(e),
            Err(panic) => Err(StageError::Failed(format!(
                "panicked: {}",
                panic_message(panic)
            ))),
        };
        let failed = outcome.is_err();
        // The receiver is gone only when the run is over.
        if made.send((index, outcome)).is_err() || failed {
            return None;
        }
    }
    Some(stage)
}

struct LagN {
    lag: usize,
    /// The frame keys the stage reads: only those travel to its thread, so the frames
    /// it holds keep no other product alive.
    inputs: Vec<String>,
    /// Frames handed to the stage's thread (`None` once finished).
    jobs: Option<Sender<Frame>>,
    made: Receiver<(usize, Made)>,
    worker: Option<JoinHandle<Option<Box<dyn Stage>>>>,
    /// Frames seen, frames handed to the thread, and results taken.
    position: usize,
    handed: usize,
    taken: usize,
    /// The last result taken.
    latest: Option<Vec<(String, Option<Arc<Product>>)>>,
}

impl LagN {
    /// The next result, in order; an error names the frame it failed on.
    fn take(&mut self) -> Result<(), StageError> {
        let (index, made) = self.made.recv().map_err(|_| {
            StageError::Failed("the lagged stage's thread stopped without a result".into())
        })?;
        self.taken += 1;
        let products = made.map_err(|e| {
            StageError::Failed(format!(
                "on frame {index}, which this stage runs behind (lag): {e}"
            ))
        })?;
        self.latest = Some(products);
        Ok(())
    }
}

impl Stage for LagN {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let position = self.position;
        self.position += 1;
        let jobs = self.jobs.as_ref().expect("not finished");
        // The thread stops after a failure, and its result says so when it is due: a
        // frame handed after it would wait for nothing, so it is not counted.
        let mut job = Frame::new(frame.index, frame.stamp_ns);
        job.entered = frame.entered;
        for key in &self.inputs {
            if let Some(product) = frame.get_shared(key) {
                job.insert_shared(key, Arc::clone(product));
            }
        }
        if jobs.send(job).is_ok() {
            self.handed += 1;
        }
        // This frame reads the result of position max(m - n, 0).
        let wanted = position.saturating_sub(self.lag);
        while self.taken <= wanted {
            self.take()?;
        }
        for (name, product) in self.latest.iter().flatten() {
            if let Some(product) = product {
                frame.insert_shared(name, Arc::clone(product));
            }
        }
        Ok(())
    }

    fn finish(&mut self) -> Result<(), StageError> {
        // Let the thread finish its frames and report a failure among them.
        drop(self.jobs.take());
        while self.taken < self.handed {
            self.take()?;
        }
        let stage = self.worker.take().and_then(|w| w.join().ok().flatten());
        match stage {
            Some(mut stage) => stage.finish(),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes `count` = the number of frames it has seen, as a scalar-free product: a
    /// pose whose x is that count (any product kind works).
    struct Counter {
        seen: usize,
        fail_on: Option<usize>,
    }

    impl Stage for Counter {
        fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
            if self.fail_on == Some(frame.index) {
                return Err(StageError::Failed("no light".into()));
            }
            self.seen += 1;
            let input = frame.index as f64;
            let mut pose = relume_recording::Pose::IDENTITY;
            pose.translation = [self.seen as f64, input, 0.0];
            frame.insert("count", Product::new(relume_recording::POSE, pose));
            Ok(())
        }
    }

    fn run(lag: u32, frames: usize, fail_on: Option<usize>) -> Result<Vec<(f64, f64)>, StageError> {
        let stage = Box::new(Counter { seen: 0, fail_on });
        let mut stage = lag_n(stage, lag, Vec::new(), vec!["count".into()]).unwrap();
        let mut out = Vec::new();
        for index in 10..10 + frames {
            let mut frame = Frame::new(index, 0);
            stage.process(&mut frame)?;
            let pose = frame.pose("count")?;
            assert_eq!(frame.get("count").unwrap().kind(), relume_recording::POSE);
            out.push((pose.translation[0], pose.translation[1]));
        }
        stage.finish()?;
        Ok(out)
    }

    #[test]
    fn frame_m_reads_what_the_stage_made_of_frame_m_minus_n() {
        // (frames the stage had seen, the frame its product was made from).
        let lagged = run(2, 6, None).unwrap();
        assert_eq!(
            lagged,
            [
                (1.0, 10.0),
                (1.0, 10.0),
                (1.0, 10.0),
                (2.0, 11.0),
                (3.0, 12.0),
                (4.0, 13.0)
            ]
        );
        // Lag 0 is the stage itself.
        let plain = run(0, 6, None).unwrap();
        assert_eq!(plain[3], (4.0, 13.0));
        // The stage itself made the same products, n frames earlier.
        assert_eq!(lagged[5], plain[3]);
    }

    /// Panics on frame 12 instead of failing.
    struct Panics;

    impl Stage for Panics {
        fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
            assert!(frame.index != 12, "the lamp fell");
            Ok(())
        }
    }

    #[test]
    fn a_panic_on_the_stage_thread_is_the_stage_failing_on_its_frame() {
        let mut stage = lag_n(Box::new(Panics), 1, Vec::new(), Vec::new()).unwrap();
        let mut outcome = Ok(());
        for index in 10..16 {
            outcome = stage.process(&mut Frame::new(index, 0));
            if outcome.is_err() {
                break;
            }
        }
        let e = outcome.unwrap_err().to_string();
        assert!(
            e.starts_with(
                "on frame 12, which this stage runs behind (lag): panicked: the lamp fell"
            ),
            "{e}"
        );
    }

    #[test]
    fn a_failure_is_reported_when_its_frame_is_due_or_at_the_end() {
        let e = run(2, 6, Some(12)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "on frame 12, which this stage runs behind (lag): no light"
        );
        // Frame 14 is handed last; no frame reads its product, but finish says it failed.
        let e = run(2, 5, Some(14)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "on frame 14, which this stage runs behind (lag): no light"
        );
    }
}
