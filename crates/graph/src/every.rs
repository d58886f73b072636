//! Stages at their own rate (paper 004 Sec. 3.2: the light model is computed at a lower
//! rate than the frames): `every = k` in a `[[stage]]` table runs the stage on the
//! frames whose index is a multiple of k, and on the first frame of a run whatever its
//! index (it has no products to lend before it); every other frame receives the
//! products of its last run, the same shared allocations, unchanged.
//!
//! Which frames run depends only on the frame indices of the run, never on timing,
//! channel capacity or thread count, so a run's products are as deterministic as with
//! k = 1. For a stage without state across frames whose inputs do not change between
//! its runs (a light probe's importance table, the light model of a static scene), its
//! products are bit for bit those of running it on every frame. A stage that builds up
//! state on each call (depth.fuse's weights, color.compensate's chain, the filter's
//! temporal reuse, light.val's warm start) sees fewer calls and gives other products.
//! The frames between runs see the stage's last run, as the paper's client sees the
//! server's last light model; `relume eval` warns that its scores then compare those
//! products with the current frame.
//!
//! A stage's own time on a frame it skips is the copy of a few pointers; `relume bench`
//! reports such a stage's mean over all frames, its amortized cost.

use super::frame::Frame;
use super::product::Product;
use super::resolved::ResolvedStage;
use super::stage::{Stage, StageError};
use super::timing::Parts;
use std::sync::Arc;

/// The largest `every` a config may give.
pub const MAX_EVERY: u32 = 100_000;

/// `stage` as `resolved` says: itself for `every = 1`, else wrapped to run on every
/// `every`-th frame.
pub fn every_k(stage: Box<dyn Stage>, resolved: &ResolvedStage) -> Box<dyn Stage> {
    if resolved.every <= 1 {
        return stage;
    }
    Box::new(EveryK {
        inner: stage,
        every: resolved.every as usize,
        outputs: resolved.outputs.values().cloned().collect(),
        last: None,
        ran: false,
    })
}

/// True when a stage with `every` = k runs on frame `index`, given whether it has run
/// before in this run.
pub fn runs_on(index: usize, every: usize, has_run: bool) -> bool {
    !has_run || index.is_multiple_of(every.max(1))
}

struct EveryK {
    inner: Box<dyn Stage>,
    every: usize,
    /// The products the stage writes.
    outputs: Vec<String>,
    /// Its products of its last run (`None` for a product it did not write then).
    last: Option<Vec<(String, Option<Arc<Product>>)>>,
    /// Whether the last frame ran the stage (its program time is then the stage's).
    ran: bool,
}

impl Stage for EveryK {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        match &self.last {
            Some(last) if !runs_on(frame.index, self.every, true) => {
                self.ran = false;
                for (name, product) in last {
                    if let Some(product) = product {
                        frame.insert_shared(name, Arc::clone(product));
                    }
                }
                Ok(())
            }
            _ => {
                self.ran = true;
                self.inner.process(frame)?;
                let kept = self
                    .outputs
                    .iter()
                    .map(|name| (name.clone(), frame.get_shared(name).cloned()))
                    .collect();
                self.last = Some(kept);
                Ok(())
            }
        }
    }

    fn program_ns(&self) -> Option<u64> {
        self.ran.then(|| self.inner.program_ns()).flatten()
    }

    fn parts(&self) -> Option<Parts> {
        self.ran.then(|| self.inner.parts()).flatten()
    }

    fn finish(&mut self) -> Result<(), StageError> {
        self.inner.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stage_runs_on_its_first_frame_and_on_multiples_of_k() {
        let ran: Vec<usize> = {
            let mut has_run = false;
            (5..30)
                .filter(|&i| {
                    let run = runs_on(i, 8, has_run);
                    has_run |= run;
                    run
                })
                .collect()
        };
        assert_eq!(ran, [5, 8, 16, 24]);
        assert!((0..10).all(|i| runs_on(i, 1, true)));
    }
}
