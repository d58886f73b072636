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

/// Keeps freed memory of up to 32 MB buffers in the process for reuse (glibc: heap
/// allocation up to 32 MB, no trimming below 1 GiB of free heap). Call it once at
/// startup, before any threads; a no-op on other platforms and allocators. The memory a
/// replay holds stays bounded by what its frames in flight need.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only changes allocator thresholds; glibc accepts these values
        // (the mmap threshold's maximum is 32 MB on 64-bit targets). Failure (0) leaves
        // the defaults, which are correct, only slower.
        unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
            libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
        }
    }
}
