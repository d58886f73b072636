//! Where `sample.path`'s time goes, in paper 000 Table 2's rows: the material
//! estimation (E_R at the real points: their samples, rays and sums), the virtual object
//! (the primaries that meet it: finding them, their samples, rays and sums), the
//! differential background (what the objects change at the real points: the tests of
//! their samples against the objects, the object-aware candidates) and the setup (the
//! depth pyramid, the kernel's tables and, for voxel visibility, the objects' volume).
//!
//! The parts interleave pixel by pixel (E_RV at a real point reuses E_R's paths), so they
//! are timed where they run with [`relume_base::ticks`] (a few nanoseconds a reading):
//! each span reads the clock around its phases, and around the object tests and
//! candidates of its pixels. The ticks are summed over the threads, and the wall time of
//! the rows is split in their proportion.

use relume_base::ticks;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// The parts' names, in [`PathTimes::ns`] order.
pub const PART_NAMES: &[&str] = &["material", "object", "differential", "setup"];

/// Ticks of one span (or pixel) spent on the object and on the differential; the rest
/// of its total is the material estimation's.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct PartTicks {
    pub(super) object: u64,
    pub(super) differential: u64,
}

/// The ticks since `start` (a reading of [`ticks::now`]); 0 if the clock reads
/// earlier (a thread moved to a core whose counter lags).
#[inline]
pub(super) fn since(start: u64) -> u64 {
    ticks::now().saturating_sub(start)
}

/// The ticks of every span of a call, summed over the threads.
#[derive(Debug, Default)]
pub(super) struct PartClock {
    total: AtomicU64,
    object: AtomicU64,
    differential: AtomicU64,
}

impl PartClock {
    /// Adds a span's `total` ticks, of which `parts` went to the object and the
    /// differential.
    pub(super) fn add(&self, total: u64, parts: PartTicks) {
        self.total.fetch_add(total, Ordering::Relaxed);
        self.object.fetch_add(parts.object, Ordering::Relaxed);
        self.differential
            .fetch_add(parts.differential, Ordering::Relaxed);
    }

    /// The parts of a call whose rows took `rows` and the rest of which took `setup`.
    pub(super) fn times(&self, rows: Duration, setup: Duration) -> PathTimes {
        let total = self.total.load(Ordering::Relaxed);
        let object = self.object.load(Ordering::Relaxed).min(total);
        let differential = self
            .differential
            .load(Ordering::Relaxed)
            .min(total - object);
        let rows_ns = rows.as_nanos() as f64;
        let share = |t: u64| match total {
            0 => 0,
            _ => (rows_ns * t as f64 / total as f64).round() as u64,
        };
        let (object_ns, differential_ns) = (share(object), share(differential));
        PathTimes {
            ns: [
                (rows.as_nanos() as u64).saturating_sub(object_ns + differential_ns),
                object_ns,
                differential_ns,
                setup.as_nanos() as u64,
            ],
        }
    }
}

/// The wall time of one `sample.path` call split into [`PART_NAMES`]' parts
/// (nanoseconds; they add up to the call's time).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PathTimes {
    pub ns: [u64; 4],
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rows_wall_time_is_split_in_the_ticks_proportion() {
        let clock = PartClock::default();
        let span = |object, differential| PartTicks {
            object,
            differential,
        };
        clock.add(600, span(100, 50));
        clock.add(400, span(100, 150));
        // 1000 ticks: 200 object, 200 differential, 600 material.
        let times = clock.times(Duration::from_millis(10), Duration::from_millis(3));
        assert_eq!(times.ns, [6_000_000, 2_000_000, 2_000_000, 3_000_000]);
        // Nothing timed: the rows are all material.
        let empty = PartClock::default().times(Duration::from_millis(10), Duration::ZERO);
        assert_eq!(empty.ns, [10_000_000, 0, 0, 0]);
    }

    #[test]
    fn a_part_is_timed_around_its_work() {
        let start = ticks::now();
        std::thread::sleep(Duration::from_millis(2));
        assert!(since(start) > 0);
    }
}
