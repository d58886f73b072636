//! Ctrl-C, SIGTERM and SIGHUP (ctrlc's `termination` feature): one handler for the
//! whole process, since ctrlc takes only one, and a command can need two behaviours in
//! turn (`relume replay` first renders the built-in recording, then replays it).
//!
//! - While a recording is being written ([`PartialFile`]), its hidden temporary file is
//!   removed and the process exits with 130: the writer deletes it when it stops with an
//!   error, but a signal ends the process first.
//! - While a run is going ([`stop_flag`]), the first signal asks it to stop after the
//!   frames in flight; a second one exits with 130.
//! - Otherwise the process exits with 130.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

struct Watch {
    partial: Option<PathBuf>,
    stop: Option<Arc<AtomicBool>>,
}

static WATCH: Mutex<Watch> = Mutex::new(Watch {
    partial: None,
    stop: None,
});

/// Installs the handler (once, at start-up).
pub fn install() {
    let _ = ctrlc::set_handler(handle);
}

fn handle() {
    let watch = WATCH.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(partial) = &watch.partial {
        // Not there: not created yet, or already renamed to its final name.
        match std::fs::remove_file(partial) {
            Ok(()) => eprintln!("\ninterrupted: the unfinished output file was removed"),
            Err(_) => eprintln!("\ninterrupted"),
        }
        std::process::exit(130);
    }
    if let Some(stop) = &watch.stop {
        if stop.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        // Set-up work before the frames flow (a transfer precomputation) gives up too.
        relume::cancel::request();
        eprintln!("\nstopping after the frames in flight (interrupt again to abort) ...");
        return;
    }
    std::process::exit(130);
}

/// A recording being written: registered with the handler from creation until drop.
pub struct PartialFile;

impl PartialFile {
    /// Registers the temporary file that a recording written to `out` goes to first.
    pub fn watch(out: &std::path::Path) -> PartialFile {
        let partial = relume::recording::writer::output_paths(out)
            .ok()
            .map(|(_, temporary)| temporary);
        WATCH.lock().unwrap_or_else(|e| e.into_inner()).partial = partial;
        PartialFile
    }
}

impl Drop for PartialFile {
    fn drop(&mut self) {
        WATCH.lock().unwrap_or_else(|e| e.into_inner()).partial = None;
    }
}

/// A flag that the first signal sets: runs poll it and stop after the frames in flight.
pub fn stop_flag() -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    WATCH.lock().unwrap_or_else(|e| e.into_inner()).stop = Some(stop.clone());
    stop
}
