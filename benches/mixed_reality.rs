//! Per-frame cost of every stage of `pipelines/mixed-reality.toml` (the default
//! pipeline) at 640x480 on the synthetic recording, with the state (fused depth, cloud,
//! the accumulator's history) built up over the preceding frames: `stage/<name>` is
//! that stage's `process` on copies of the last two frames as they arrive there, in
//! turn. Each run thus meets a frame other than the one the stage saw last, as in a
//! replay (one step forward, one back): the accumulator (and, in a pipeline whose
//! filter has `temporal = true`, the filter's temporal taps) reprojects a frame that
//! moved, as on real frames. (Re-running one frame would reproject it onto
//! itself, every lane at offset 0, the cheapest case.) The sum of the medians bounds
//! the pipeline's frame time from above on one core; `relume bench` measures the
//! pipelined throughput.
//!
//! `RELUME_BENCH_PIPELINE=FILE cargo bench --bench mixed_reality` measures another
//! pipeline.

mod common;

use criterion::{Criterion, criterion_group, criterion_main};

/// Frames replayed before the measured one.
const WARM_FRAMES: usize = 12;

fn bench_mixed_reality(c: &mut Criterion) {
    // The allocation policy the relume binary runs with (crates/graph/src/memory.rs).
    relume::graph::memory::keep_freed_memory();
    let common::WarmedUp {
        pipeline,
        mut stages,
        arriving,
        arriving_before,
        _dir,
        ..
    } = common::warm_up("mixed-reality.toml", WARM_FRAMES + 1);
    let mut group = c.benchmark_group("mixed_reality_640x480");
    group.sample_size(10);
    common::bench_each_stage(
        &mut group,
        &pipeline,
        &mut stages,
        &arriving,
        &arriving_before,
    );
    group.finish();
}

criterion_group!(benches, bench_mixed_reality);
criterion_main!(benches);
