//! Running work on a rayon pool of a given size.

/// Runs `f` on a rayon pool of `threads` threads: determinism tests compare 1 and 3.
pub fn with_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool")
        .install(f)
}
