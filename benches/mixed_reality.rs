//! Per-frame cost of every stage of `pipelines/mixed-reality.toml` (the default
//! pipeline) at 640x480 on the synthetic recording, with the state (fused depth, cloud,
//! the filter's previous frame) built up over the preceding frames: `stage/<name>` is
//! that stage's `process` on a copy of the frame as it arrives there. The sum of the
//! medians bounds the pipeline's frame time from above on one core; `relume bench`
//! measures the pipelined throughput.
//!
//! `RELUME_BENCH_PIPELINE=FILE cargo bench --bench mixed_reality` measures another
//! pipeline.

mod common;

use criterion::{Criterion, criterion_group, criterion_main};

/// Frames replayed before the measured one.
const WARM_FRAMES: usize = 12;

fn bench_mixed_reality(c: &mut Criterion) {
    // The allocation policy the relume binary runs with (src/graph/memory.rs).
    relume::graph::memory::keep_freed_memory();
    let common::WarmedUp {
        pipeline,
        mut stages,
        arriving,
        _dir,
        ..
    } = common::warm_up("mixed-reality.toml", WARM_FRAMES + 1);
    let mut group = c.benchmark_group("mixed_reality_640x480");
    group.sample_size(10);
    common::bench_each_stage(&mut group, &pipeline, &mut stages, &arriving);
    group.finish();
}

criterion_group!(benches, bench_mixed_reality);
criterion_main!(benches);
