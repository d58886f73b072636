//! A cheap clock for splitting a stage's time into parts: reading it costs a few
//! nanoseconds (the CPU's time-stamp counter on x86_64, a monotonic clock elsewhere),
//! so a kernel can read it per pixel. Its unit is not fixed (the counter runs at the
//! CPU's nominal frequency): callers compare ticks with ticks, the shares of a time
//! measured with [`std::time::Instant`].

/// The clock now, in ticks.
#[inline]
pub fn now() -> u64 {
    #[cfg(target_arch = "x86_64")]
    {
        // SAFETY: RDTSC has no preconditions; every x86_64 CPU has it.
        #[allow(unused_unsafe)]
        unsafe {
            core::arch::x86_64::_rdtsc()
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        static EPOCH: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
        EPOCH
            .get_or_init(std::time::Instant::now)
            .elapsed()
            .as_nanos() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    /// Spins for `d`, returning the ticks it took.
    fn spin(d: Duration) -> u64 {
        let (instant, start) = (Instant::now(), now());
        while instant.elapsed() < d {
            std::hint::spin_loop();
        }
        now().saturating_sub(start)
    }

    #[test]
    fn ticks_grow_with_the_time_spent() {
        let short = spin(Duration::from_millis(5));
        let long = spin(Duration::from_millis(20));
        assert!(short > 0);
        // Four times the time is about four times the ticks (a loose bound: this
        // machine's scheduler may pause either spin).
        let ratio = long as f64 / short as f64;
        assert!(
            (2.0..8.0).contains(&ratio),
            "{ratio}: {short} then {long} ticks"
        );
    }
}
