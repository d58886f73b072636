//! The runtime's own cost: frames with no products through chains of `debug.noop`
//! stages. The difference between a chain of 9 and of 1 no-op stage, divided by 8, is
//! the overhead of one stage hop (channel send and receive, timing, thread hand-off).
//! `runtime/parse` times reading a generated pipeline of thousands of stages, each
//! writing a product of its own (what `relume validate` does): linear since issue 59
//! (16,000 stages took 55 s and 18 GB, now under 0.1 s).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use relume::graph::{Frame, FrameSource, Pipeline, RunOptions, SourceFile, run};
use relume::recording::{Header, Intrinsics, RecordingError};
use std::hint::black_box;

struct EmptyFrames(usize);

impl FrameSource for EmptyFrames {
    fn len(&self) -> usize {
        self.0
    }
    fn read(&self, n: usize) -> Result<Frame, RecordingError> {
        Ok(Frame::new(n, n as i64))
    }
}

fn header() -> Header {
    Header::new("bench", Intrinsics::PRIMESENSE, 0.001)
}

fn noop_chain(stages: usize, capacity: usize) -> Pipeline {
    let mut text = format!("[pipeline]\nchannel_capacity = {capacity}\n");
    for i in 0..stages {
        text.push_str(&format!(
            "[[stage]]\nname = \"noop{i}\"\nkind = \"debug.noop\"\n"
        ));
    }
    Pipeline::parse(
        &SourceFile {
            name: "bench".into(),
            text,
        },
        &relume::stages::registry(),
    )
    .expect("valid pipeline")
}

fn bench_hops(c: &mut Criterion) {
    // The allocation policy the relume binary runs with (crates/graph/src/memory.rs).
    relume::graph::memory::keep_freed_memory();
    let registry = relume::stages::registry();
    let frames = 2000;
    let mut group = c.benchmark_group("runtime/noop_chain");
    group.throughput(Throughput::Elements(frames as u64));
    group.sample_size(20);
    for stages in [1, 9] {
        for capacity in [2, 16] {
            let pipeline = noop_chain(stages, capacity);
            let id = BenchmarkId::new(format!("capacity{capacity}"), format!("{stages}stages"));
            group.bench_with_input(id, &pipeline, |b, p| {
                b.iter(|| {
                    let built = p
                        .build(&registry, &header(), std::path::Path::new("."), 1)
                        .expect("build");
                    let mut n = 0usize;
                    run(
                        p,
                        built,
                        &EmptyFrames(frames),
                        &RunOptions::default(),
                        &mut |f| n += black_box(f.index),
                    )
                    .expect("run");
                    n
                })
            });
        }
    }
    group.finish();
}

/// `stages` `depth.to_points` stages after a decode, each writing its own product.
fn wide_pipeline_text(stages: usize) -> String {
    let mut text = String::from("[[stage]]\nkind = \"decode\"\n");
    for i in 0..stages {
        text.push_str(&format!(
            "[[stage]]\nkind = \"depth.to_points\"\nname = \"p{i}\"\n\
             outputs = {{ points = \"points{i}\" }}\n"
        ));
    }
    text
}

fn bench_parse(c: &mut Criterion) {
    let registry = relume::stages::registry();
    let mut group = c.benchmark_group("runtime/parse");
    group.sample_size(10);
    for stages in [1000, 4000, 16000] {
        let source = SourceFile {
            name: "bench".into(),
            text: wide_pipeline_text(stages),
        };
        group.throughput(Throughput::Elements(stages as u64));
        group.bench_with_input(BenchmarkId::from_parameter(stages), &source, |b, s| {
            b.iter(|| Pipeline::parse(s, &registry).expect("valid pipeline"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_hops, bench_parse);
criterion_main!(benches);
