//! Import speed: livingroom1 (211 frames, 640x480 JPEG color and 16-bit depth) from
//! its Redwood folder, and from MCAP (the file `relume export mcap` writes of it:
//! Foxglove JSON schemas, zstd chunks, depth as RawImage 16UC1). Issue 35 asks for
//! >= 200 frames/s from MCAP; frames/s = 211 / the median.
//!
//! Needs the shared data (`../shared/data` or `RELUME_DATA`).

use criterion::{Criterion, criterion_group, criterion_main};
use relume::recording::importers::redwood;
use relume::recording::mcap;
use std::path::PathBuf;

fn data_dir() -> PathBuf {
    let dir = match std::env::var_os("RELUME_DATA") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"),
    };
    assert!(
        dir.join("livingroom1").is_dir(),
        "benchmark data is missing: expected livingroom1 in {} (set RELUME_DATA)",
        dir.display()
    );
    dir
}

fn bench_import(c: &mut Criterion) {
    let tmp = tempfile::tempdir().unwrap();
    let folder = data_dir().join("livingroom1");
    let relume_file = tmp.path().join("lr.relume");
    let mcap_file = tmp.path().join("lr.mcap");
    redwood::import(&folder, &relume_file, &Default::default(), &mut |_, _| {}).unwrap();
    mcap::export(
        &relume_file,
        &mcap_file,
        &Default::default(),
        &mut |_, _| {},
    )
    .unwrap();
    let out = tmp.path().join("out.relume");

    let mut group = c.benchmark_group("import_livingroom1_211_frames");
    group.sample_size(10);
    group.bench_function("redwood", |b| {
        b.iter(|| redwood::import(&folder, &out, &Default::default(), &mut |_, _| {}).unwrap())
    });
    group.bench_function("mcap", |b| {
        b.iter(|| mcap::import(&mcap_file, &out, &Default::default(), &mut |_, _| {}).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench_import);
criterion_main!(benches);
