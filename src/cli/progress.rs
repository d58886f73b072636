//! Progress of long runs: a bar on a terminal (drawn on stderr, so piped stdout stays
//! clean), and otherwise a line on stderr every [`LINE_EVERY`] (or every
//! `RELUME_PROGRESS_SECONDS` seconds), so that a run in a log or a CI job is not silent
//! for minutes.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::cell::Cell;
use std::io::IsTerminal;
use std::time::{Duration, Instant};

/// How often a run without a terminal says how far it is.
pub const LINE_EVERY: Duration = Duration::from_secs(5);

/// Progress over a known number of items.
pub struct Progress {
    bar: ProgressBar,
    /// `None` on a terminal (the bar draws itself).
    lines: Option<Lines>,
}

struct Lines {
    every: Duration,
    what: String,
    unit: &'static str,
    started: Instant,
    last: Cell<Instant>,
}

/// A progress bar over `len` items of `unit` ("frames"), doing `what` ("replaying").
pub fn bar(len: u64, what: &str, unit: &'static str) -> Progress {
    // The bar draws on stderr: a terminal there gets the bar, a log the lines.
    let terminal = std::io::stderr().is_terminal();
    let target = if terminal {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(len), target);
    let template =
        format!("{{msg:>10}} [{{bar:40}}] {{pos}}/{{len}} {unit} {{per_sec}} eta {{eta}}");
    if let Ok(style) = ProgressStyle::with_template(&template).map(|s| s.progress_chars("=> ")) {
        bar.set_style(style);
    }
    bar.set_message(what.to_string());
    let now = Instant::now();
    let every = std::env::var("RELUME_PROGRESS_SECONDS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .and_then(|s| Duration::try_from_secs_f64(s).ok())
        .unwrap_or(LINE_EVERY);
    let lines = (!terminal).then(|| Lines {
        every,
        what: what.to_string(),
        unit,
        started: now,
        last: Cell::new(now),
    });
    Progress { bar, lines }
}

impl Progress {
    pub fn inc(&self, n: u64) {
        self.bar.inc(n);
        self.maybe_line();
    }

    pub fn set_position(&self, pos: u64) {
        self.bar.set_position(pos);
        self.maybe_line();
    }

    pub fn set_length(&self, len: u64) {
        self.bar.set_length(len);
    }

    pub fn finish_and_clear(&self) {
        self.bar.finish_and_clear();
    }

    /// Without a terminal: a line when [`LINE_EVERY`] has passed since the last.
    fn maybe_line(&self) {
        let Some(lines) = &self.lines else { return };
        if lines.last.get().elapsed() < lines.every {
            return;
        }
        lines.last.set(Instant::now());
        let (done, len) = (self.bar.position(), self.bar.length().unwrap_or(0));
        eprintln!(
            "{}",
            line(&lines.what, lines.unit, done, len, lines.started.elapsed())
        );
    }
}

/// "replaying: 12/30 frames, 1.9 frames/s, about 9 s left".
fn line(what: &str, unit: &str, done: u64, len: u64, elapsed: Duration) -> String {
    let rate = done as f64 / elapsed.as_secs_f64().max(1e-9);
    let left = match (rate > 0.0, len > done) {
        (true, true) => format!(", about {:.0} s left", (len - done) as f64 / rate),
        _ => String::new(),
    };
    format!("{what}: {done}/{len} {unit}, {rate:.2} {unit}/s{left}")
}

#[cfg(test)]
mod tests {
    use super::line;
    use std::time::Duration;

    #[test]
    fn a_progress_line_says_how_far_how_fast_and_how_long() {
        assert_eq!(
            line("replaying", "frames", 12, 30, Duration::from_secs(6)),
            "replaying: 12/30 frames, 2.00 frames/s, about 9 s left"
        );
        assert_eq!(
            line("bench", "runs", 3, 3, Duration::from_secs(6)),
            "bench: 3/3 runs, 0.50 runs/s"
        );
    }
}
