//! Import speed: livingroom1 (211 frames, 640x480 JPEG color and 16-bit depth) from
//! its Redwood folder, from MCAP (the file `relume export mcap` writes of it:
//! Foxglove JSON schemas, zstd chunks, depth as RawImage 16UC1), and from a ROS 1 bag in
//! a RealSense recording's layout whose depth camera has other intrinsics and sits 1.5 cm
//! from the color camera, so that every frame is registered (raw rgb8 and mono16 images,
//! uncompressed chunks). Issue 35 asks for >= 200 frames/s from MCAP, issue 55 for >= 150
//! frames/s with registration; frames/s = 211 / the median.
//!
//! Needs the shared data (`../shared/data` or `RELUME_DATA`).

use criterion::{Criterion, criterion_group, criterion_main};
use relume::recording::importers::redwood;
use relume::recording::mcap;
use std::path::{Path, PathBuf};

#[path = "rosbag_writer.rs"]
mod rosbag_writer;
use rosbag_writer::{BagWriter, Msg};

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
    let bag_file = tmp.path().join("lr-realsense.bag");
    write_realsense_bag(&relume_file, &bag_file);
    let out = tmp.path().join("out.relume");

    let mut group = c.benchmark_group("import_livingroom1_211_frames");
    group.sample_size(10);
    group.bench_function("redwood", |b| {
        b.iter(|| redwood::import(&folder, &out, &Default::default(), &mut |_, _| {}).unwrap())
    });
    group.bench_function("mcap", |b| {
        b.iter(|| mcap::import(&mcap_file, &out, &Default::default(), &mut |_, _| {}).unwrap())
    });
    group.bench_function("rosbag_realsense_registered", |b| {
        b.iter(|| mcap::import(&bag_file, &out, &Default::default(), &mut |_, _| {}).unwrap())
    });
    group.finish();
}

/// livingroom1 as a RealSense recording: rgb8 color with the dataset's intrinsics, mono16
/// depth from a camera with fx = fy = 500, 1.5 cm to the side (the images are the
/// dataset's; only the cost of registering them is measured).
fn write_realsense_bag(recording: &Path, bag: &Path) {
    use relume::recording::{Replay, ReplayOptions, codec};
    let replay = Replay::open(recording, ReplayOptions::default()).unwrap();
    let k = replay.recording.header().color_intrinsics;
    let mut w = BagWriter::create(bag);
    let info = |stamp: i64, fx: f64, fy: f64, cx: f64, cy: f64| {
        Msg::header(stamp, "0")
            .u32(k.height)
            .u32(k.width)
            .string("plumb_bob")
            .u32(0)
            .f64s(&[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0])
    };
    let (d, c) = ("/device_0/sensor_0/Depth_0", "/device_0/sensor_1/Color_0");
    let (info_ty, tf_ty) = ("sensor_msgs/CameraInfo", "geometry_msgs/Transform");
    w.put(
        &format!("{d}/info/camera_info"),
        info_ty,
        0,
        info(0, 500.0, 500.0, 320.0, 240.0),
    );
    w.put(
        &format!("{c}/info/camera_info"),
        info_ty,
        0,
        info(0, k.fx, k.fy, k.cx, k.cy),
    );
    let units = "/device_0/sensor_0/option/Depth Units/value";
    w.put(units, "std_msgs/Float32", 0, Msg(Vec::new()).f32(0.001));
    let identity = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    w.put(
        &format!("{d}/tf/0"),
        tf_ty,
        0,
        Msg(Vec::new()).f64s(&identity),
    );
    let beside = [0.015, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    w.put(
        &format!("{c}/tf/0"),
        tf_ty,
        0,
        Msg(Vec::new()).f64s(&beside),
    );
    for i in 0..replay.stats.frames {
        let f = replay.read_frame(i).unwrap();
        let stamp = f.color.stamp_ns;
        let rgb = codec::decode_color(&f.color.image).unwrap();
        let rgb: Vec<u8> = rgb.data.iter().flatten().copied().collect();
        let depth = codec::decode_depth_units(&f.depth.unwrap().image).unwrap();
        let depth: Vec<u8> = depth.data.iter().flat_map(|u| u.to_le_bytes()).collect();
        let image = |encoding: &str, step: u32, data: &[u8]| {
            Msg::header(stamp, "0")
                .u32(k.height)
                .u32(k.width)
                .string(encoding)
                .u8(0)
                .u32(step)
                .bytes(data)
        };
        let color_msg = image("rgb8", k.width * 3, &rgb);
        w.put(
            &format!("{c}/image/data"),
            "sensor_msgs/Image",
            stamp,
            color_msg,
        );
        let depth_msg = image("mono16", k.width * 2, &depth);
        w.put(
            &format!("{d}/image/data"),
            "sensor_msgs/Image",
            stamp,
            depth_msg,
        );
        w.flush_chunk();
    }
    w.finish();
}

/// One livingroom1 frame registered as the RealSense bag above registers it (depth camera
/// fx = fy = 500, 1.5 cm to the side): the part of that import that registration costs,
/// on one core.
fn bench_register(c: &mut Criterion) {
    use relume::recording::register::{Extrinsic, Registration, Scratch, register_depth};
    use relume::recording::{Replay, ReplayOptions, codec};
    let tmp = tempfile::tempdir().unwrap();
    let recording = tmp.path().join("lr.relume");
    let folder = data_dir().join("livingroom1");
    redwood::import(&folder, &recording, &Default::default(), &mut |_, _| {}).unwrap();
    let replay = Replay::open(&recording, ReplayOptions::default()).unwrap();
    let color = replay.recording.header().color_intrinsics;
    let mut depth_k = color;
    (depth_k.fx, depth_k.fy, depth_k.cx, depth_k.cy) = (500.0, 500.0, 320.0, 240.0);
    let beside = Extrinsic {
        rotation: glam::DQuat::IDENTITY,
        translation: glam::DVec3::new(0.015, 0.0, 0.0),
    };
    let registration = Registration::new(depth_k, color, beside);
    let frame = replay.read_frame(0).unwrap();
    let depth = codec::decode_depth_units(&frame.depth.unwrap().image).unwrap();
    let (mut out, mut scratch) = (Vec::new(), Scratch::default());
    // RELUME_DUMP_REGISTERED=FILE: every frame registered, written to FILE (u16 LE), to
    // compare two versions of the registration byte for byte.
    if let Some(dump) = std::env::var_os("RELUME_DUMP_REGISTERED") {
        let mut all = Vec::new();
        for i in 0..replay.stats.frames {
            let f = replay.read_frame(i).unwrap();
            let d = codec::decode_depth_units(&f.depth.unwrap().image).unwrap();
            register_depth(&d.data, 0.001, &registration, &mut out, &mut scratch).unwrap();
            all.extend(out.iter().flat_map(|u| u.to_le_bytes()));
        }
        std::fs::write(dump, all).unwrap();
    }
    c.bench_function("register_livingroom1_frame0", |b| {
        b.iter(|| {
            register_depth(&depth.data, 0.001, &registration, &mut out, &mut scratch).unwrap()
        })
    });
}

criterion_group!(benches, bench_import, bench_register);
criterion_main!(benches);
