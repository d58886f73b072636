//! Per-frame cost of the shipped stages at 640x480 on a real frame (livingroom1 frame
//! 100 from `../shared/data` or `$RELUME_DATA`): decode (JPEG color + PNG16 depth),
//! back-projection, cross-product normals, and writing PNGs.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use relume::graph::Product;
use relume::raster::Image;
use relume::recording::codec::{decode_color, decode_depth, wrap_image_file};
use relume::recording::{Intrinsics, importers::redwood::REDWOOD_DEPTH_UNIT_M};
use relume::stages::kind;
use relume::stages::{normals, points, write};
use std::hint::black_box;
use std::path::PathBuf;

fn data_dir() -> PathBuf {
    let dir = std::env::var_os("RELUME_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    assert!(
        dir.join("livingroom1").is_dir(),
        "benchmark data missing: expected livingroom1 under {} (set RELUME_DATA)",
        dir.display()
    );
    dir
}

fn bench_stages(c: &mut Criterion) {
    // The allocation policy the relume binary runs with (crates/graph/src/memory.rs).
    relume::graph::memory::keep_freed_memory();
    let lr = data_dir().join("livingroom1");
    let (color, _) = wrap_image_file(std::fs::read(lr.join("color/00100.jpg")).unwrap()).unwrap();
    let (depth, _) = wrap_image_file(std::fs::read(lr.join("depth/00100.png")).unwrap()).unwrap();
    let mut group = c.benchmark_group("stages_640x480");
    group.sample_size(30);
    group.bench_function("decode/color_jpeg", |b| {
        b.iter(|| decode_color(black_box(&color)).unwrap())
    });
    group.bench_function("decode/depth_png16", |b| {
        b.iter(|| decode_depth(black_box(&depth), REDWOOD_DEPTH_UNIT_M).unwrap())
    });
    group.bench_function("decode/both_parallel", |b| {
        b.iter(|| {
            rayon::join(
                || decode_color(&color).unwrap(),
                || decode_depth(&depth, REDWOOD_DEPTH_UNIT_M).unwrap(),
            )
        })
    });
    let depth_m = decode_depth(&depth, REDWOOD_DEPTH_UNIT_M).unwrap();
    let mut pts = Image::filled(640, 480, Vec3::ZERO);
    group.bench_function("depth.to_points", |b| {
        b.iter(|| points::depth_to_points(&depth_m, &Intrinsics::PRIMESENSE, &mut pts).unwrap())
    });
    let mut nrm = Image::filled(640, 480, Vec3::ZERO);
    group.bench_function("normals.cross", |b| {
        b.iter(|| normals::cross_normals(&pts, &normals::CrossParams::default(), &mut nrm).unwrap())
    });
    let dir = tempfile::tempdir().unwrap();
    let normals_product = Product::new(kind::NORMALS, nrm.clone());
    let depth_product = Product::new(kind::DEPTH, depth_m.clone());
    group.bench_function("write/normals_png", |b| {
        b.iter(|| write::write_png(&normals_product, &dir.path().join("n.png")).unwrap())
    });
    group.bench_function("write/depth_png16", |b| {
        b.iter(|| write::write_png(&depth_product, &dir.path().join("d.png")).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench_stages);
criterion_main!(benches);
