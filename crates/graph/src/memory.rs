//! The process's allocation policy for per-frame images.
//!
//! Every stage writes its products into fresh images that travel downstream with the
//! frame and are freed when the frame leaves the pipeline, about 80 MB per 640x480
//! frame of the mixed-reality pipeline in buffers of 1-4 MB. glibc's allocator serves
//! buffers that large with `mmap` and returns them with `munmap` (or trims them off the
//! heap), so each frame's products can land on fresh pages: a page fault and a kernel
//! zeroing per 4 KiB. [`keep_freed_memory`] makes the allocator keep freed memory for
//! the next frame's buffers instead. Measured: a caller that allocates per call, as
//! `benches/composite.rs` does, went from 8.3 to 3.8 ms at 640x480 (on that bench's
//! first inputs, where most pixels took the composite's fast path); an 8-frame replay
//! of the default pipeline from 158k to 105k page faults and 0.61 to 0.38 s of system
//! time (about 1 % of its CPU time), for 9 % more peak memory (363 -> 396 MB).
//!
//! It also measures memory: [`CountingAllocator`] counts the bytes allocated, for each
//! stage's allocation high-water mark in a lockstep run, and [`peak_resident_bytes`]
//! reads the process's peak resident memory.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Keeps freed memory of up to 32 MB buffers in the process for reuse (glibc: heap
/// allocation up to 32 MB, no trimming below 1 GiB of free heap), in as many heaps
/// (arenas) as the machine has cores. Call it once at startup, before any threads; a
/// no-op on other platforms and allocators. The memory a replay holds stays bounded by
/// what its frames in flight need.
///
/// The arena cap: glibc gives threads up to eight heaps per core, and every stage runs
/// on a thread of its own, so the freed frames were kept in up to 16 heaps on two cores,
/// each holding its own stock; `relume bench`, which starts the stages' threads anew
/// for every run, peaked at 675 MB over four runs of the default against 407 MB with
/// the cap, and a replay at 385 against 350 MB, at the same CPU time (20.0 and 19.6 s
/// user for 30 frames, alternating runs). At most as many threads allocate at once as
/// there are cores to run them.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let arenas = cores.clamp(1, 64) as libc::c_int;
        // SAFETY: mallopt only changes allocator thresholds; glibc accepts these values
        // (the mmap threshold's maximum is 32 MB on 64-bit targets; any positive arena
        // count). Failure (0) leaves the defaults, which are correct, only slower or
        // larger.
        unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
            libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
            libc::mallopt(libc::M_ARENA_MAX, arenas);
        }
    }
}

/// The system allocator, counting the bytes it holds for the program and their high-water
/// mark, so that `relume bench --isolated` can say how much each stage allocates at its
/// peak (SLAMBench2 reports memory beside speed and accuracy). The binary installs it
/// (`#[global_allocator]`) and calls [`CountingAllocator::installed`]; a library user's
/// program without it reports no allocation figures. The cost is two relaxed atomic
/// updates per allocation.
pub struct CountingAllocator;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static INSTALLED: AtomicBool = AtomicBool::new(false);

// SAFETY: every call is passed on to the system allocator unchanged; the counters only
// observe the sizes.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract for `alloc` is the system allocator's.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: as `alloc`.
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from this allocator, which is the system's.
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: as `dealloc` and `alloc`.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            if new_size >= layout.size() {
                grew(new_size - layout.size());
            } else {
                LIVE.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
            }
        }
        p
    }
}

fn grew(bytes: usize) {
    let live = LIVE.fetch_add(bytes, Ordering::Relaxed) + bytes;
    PEAK.fetch_max(live, Ordering::Relaxed);
}

impl CountingAllocator {
    /// Says that this allocator is the program's: [`allocation_peak`] measures from now.
    pub fn installed() {
        INSTALLED.store(true, Ordering::Relaxed);
    }
}

/// Starts a measurement of the allocation high-water mark: the bytes held now, from
/// which [`allocation_peak`] counts. `None` where [`CountingAllocator`] is not installed.
pub fn allocation_mark() -> Option<usize> {
    if !INSTALLED.load(Ordering::Relaxed) {
        return None;
    }
    let live = LIVE.load(Ordering::Relaxed);
    PEAK.store(live, Ordering::Relaxed);
    Some(live)
}

/// The most bytes held at once since `mark` ([`allocation_mark`]) beyond those held
/// then: what the code in between allocated at its peak, on every thread (the figure is
/// one stage's only where nothing else runs meanwhile, as in a lockstep run).
pub fn allocation_peak(mark: usize) -> usize {
    PEAK.load(Ordering::Relaxed).saturating_sub(mark)
}

/// The process's peak resident memory (`VmHWM`), bytes; `None` where the system does
/// not say (outside Linux).
pub fn peak_resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
