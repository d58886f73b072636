//! A process-wide request to give up long set-up work: what runs before a run's frames
//! flow, where the run's own stop flag (polled between frames) is not looked at, such
//! as `sample.val`'s radiance transfer precomputation (tens of seconds for a fine
//! mesh). The command line makes the request on the first interrupt (Ctrl-C, or the
//! one SIGTERM a scheduler sends before SIGKILL); the work checks [`requested`] as it
//! goes and returns [`Cancelled`].
//!
//! It never changes a result: work that is not cancelled computes the same bits.

use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

/// Asks every long set-up of this process to give up.
pub fn request() {
    REQUESTED.store(true, Ordering::SeqCst);
}

/// Whether [`request`] was called.
#[inline]
pub fn requested() -> bool {
    REQUESTED.load(Ordering::Relaxed)
}

/// Work given up at a [`request`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("interrupted")]
pub struct Cancelled;
