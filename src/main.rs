//! The `relume` command line.

mod cli;

/// Counts allocations, for `relume bench --isolated`'s per-stage allocation peaks.
#[global_allocator]
static ALLOCATOR: relume::graph::memory::CountingAllocator =
    relume::graph::memory::CountingAllocator;

fn main() {
    relume::graph::memory::keep_freed_memory();
    relume::graph::memory::CountingAllocator::installed();
    relume::graph::panics::quiet_in_stages();
    match cli::main() {
        Ok(code) => std::process::exit(code),
        Err(e) if cli::is_broken_pipe(&e) => std::process::exit(0),
        Err(e) => {
            eprintln!("error: {}", cli::report(&e));
            // A failure caused by an interrupt (set-up work that gave up) is the
            // interrupt's exit status.
            std::process::exit(if relume::cancel::requested() { 130 } else { 1 });
        }
    }
}
