//! ROS 1 bags written by an independent writer, Python's `rosbags` (tests/writers/rosbag.py,
//! in a virtual environment under the target folder), imported with `relume import bag`:
//! pixels, stamps, intrinsics, depth scale and poses come back exactly, in a camera
//! driver's layout and in librealsense's; damaged bags give clear errors and no file.

mod common;

use common::{ok, relume, stderr};
use glam::{DQuat, DVec3};
use relume::recording::{Pose, Replay, ReplayOptions, codec};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// tests/writers/rosbag.py's formulas.
const WIDTH: usize = 16;
const HEIGHT: usize = 12;

fn stamp_ns(k: usize) -> i64 {
    1_000_000_000_000 + k as i64 * 33_333_333 + 1_000
}

fn color(k: usize) -> Vec<u8> {
    let mut out = Vec::new();
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            for c in 0..3 {
                out.push(((k * 31 + x * 7 + y * 13 + c * 50) % 256) as u8);
            }
        }
    }
    out
}

fn depth(k: usize) -> Vec<u16> {
    (0..HEIGHT)
        .flat_map(|y| (0..WIDTH).map(move |x| (1000 + k * 10 + x + y * 3) as u16))
        .collect()
}

fn pose(k: usize) -> Pose {
    let half = 0.05 * k as f64 / 2.0;
    Pose::from_parts(
        DVec3::new(0.1 * k as f64, 0.2, -0.05 * k as f64),
        DQuat::from_xyzw(0.0, half.sin(), 0.0, half.cos()),
    )
}

fn python() -> &'static Path {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    common::venv::python(
        &PYTHON,
        "rosbags-venv",
        &["rosbags==0.11.9"],
        "import rosbags.rosbag1",
    )
}

/// Writes a bag with tests/writers/rosbag.py.
fn write_bag(path: &Path, layout: &str, compression: &str, frames: usize, extra: &[&str]) {
    let frames = frames.to_string();
    let args = [
        path.as_os_str(),
        layout.as_ref(),
        compression.as_ref(),
        frames.as_ref(),
    ]
    .into_iter()
    .chain(extra.iter().map(|a| a.as_ref()));
    common::venv::run_writer(python(), "rosbag.py", &args.collect::<Vec<_>>());
}

fn import(bag: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    relume()
        .args(["import", "bag"])
        .arg(bag)
        .arg("-o")
        .arg(out)
        .args(extra)
        .output()
        .expect("run relume")
}

#[test]
fn a_camera_drivers_bag_imports_exactly_whatever_its_compression() {
    let dir = tempfile::tempdir().unwrap();
    for compression in ["none", "lz4", "bz2"] {
        let bag = dir.path().join(format!("{compression}.bag"));
        let out = dir.path().join(format!("{compression}.relume"));
        write_bag(&bag, "ros", compression, 5, &[]);
        let o = ok(import(&bag, &out, &[]));
        assert!(
            String::from_utf8_lossy(&o.stdout).contains("5 color, 5 depth, 5 poses"),
            "{compression}: {}",
            String::from_utf8_lossy(&o.stdout)
        );
        let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
        let header = replay.recording.header();
        assert_eq!(header.provenance.tool, "relume import rosbag");
        let k = header.color_intrinsics;
        assert_eq!(
            (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
            (16, 12, 20.5, 21.0, 7.5, 5.75)
        );
        assert_eq!(header.depth_unit_m, 0.001);
        assert_eq!(replay.stats.frames, 5);
        for i in 0..5 {
            let rec = replay.read_frame(i).unwrap();
            assert_eq!(rec.color.stamp_ns, stamp_ns(i), "{compression} frame {i}");
            let rgb = codec::decode_color(&rec.color.image).unwrap();
            let flat: Vec<u8> = rgb.data.iter().flatten().copied().collect();
            assert_eq!(flat, color(i), "{compression} frame {i} color");
            let d = rec.depth.unwrap();
            assert_eq!(d.stamp_ns, stamp_ns(i) + 1_000_000);
            assert_eq!(
                codec::decode_depth_units(&d.image).unwrap().data,
                depth(i),
                "{compression} frame {i} depth"
            );
            let (got, want) = (rec.pose.unwrap(), pose(i));
            let dt = (got.translation() - want.translation()).length();
            let dq = got.rotation().angle_between(want.rotation());
            assert!(dt < 1e-12 && dq < 1e-7, "frame {i}: {got:?} vs {want:?}");
        }
    }
}

#[test]
fn a_realsense_recording_gives_its_depth_unit_and_registers_its_depth_camera() {
    let dir = tempfile::tempdir().unwrap();
    // The two streams coincide: nothing to register, pixels exact.
    let bag = dir.path().join("rs.bag");
    let out = dir.path().join("rs.relume");
    write_bag(&bag, "realsense", "lz4", 4, &[]);
    let listing = ok(relume()
        .args(["import", "rosbag"])
        .arg(&bag)
        .arg("--list")
        .output()
        .unwrap());
    let listing = String::from_utf8_lossy(&listing.stdout).into_owned();
    assert!(
        listing.contains("/device_0/sensor_0/option/Depth Units/value")
            && listing.contains("value 0.00025"),
        "{listing}"
    );
    ok(import(&bag, &out, &[]));
    let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
    let header = replay.recording.header();
    assert_eq!(header.depth_unit_m, 0.00025);
    assert!(!header.provenance.settings.contains_key("registered"));
    assert_eq!(replay.stats.frames, 4);
    for i in 0..4 {
        let rec = replay.read_frame(i).unwrap();
        assert_eq!(rec.color.stamp_ns, stamp_ns(i));
        assert!(rec.pose.is_none());
        let units = codec::decode_depth_units(&rec.depth.unwrap().image).unwrap();
        assert_eq!(units.data, depth(i), "frame {i}");
    }

    // The depth camera 1.5 cm beside the color camera and turned by a degree: the depth
    // is registered into the color view, the header says so.
    let bag = dir.path().join("rs-extrinsic.bag");
    let out = dir.path().join("rs-extrinsic.relume");
    write_bag(&bag, "realsense", "none", 2, &["0.015,0,0,1"]);
    ok(import(&bag, &out, &[]));
    let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
    let header = replay.recording.header();
    assert_eq!(header.depth_intrinsics, header.color_intrinsics);
    let registered = &header.provenance.settings["registered"];
    assert!(
        registered.starts_with(
            "depth 16x12 to color, depth camera at (0.0150, 0.0000, 0.0000) m in the color \
             camera, turned 1.000 degrees"
        ),
        "{registered}"
    );
    let units =
        codec::decode_depth_units(&replay.read_frame(0).unwrap().depth.unwrap().image).unwrap();
    let seen: Vec<u16> = units.data.iter().copied().filter(|&d| d > 0).collect();
    // The fixture's depth is a ramp, not a surface: its registration keeps its range.
    let (lo, hi) = (
        *depth(0).iter().min().unwrap(),
        *depth(0).iter().max().unwrap(),
    );
    assert!(
        seen.len() > WIDTH * HEIGHT / 2,
        "{} pixels registered",
        seen.len()
    );
    assert!(
        seen.iter().all(|&d| d >= lo - 20 && d <= hi + 20),
        "{seen:?}"
    );
}

#[test]
fn damaged_bags_name_the_chunk_or_byte_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("good.bag");
    write_bag(&bag, "ros", "lz4", 6, &[]);
    let bytes = std::fs::read(&bag).unwrap();
    let out = dir.path().join("out.relume");
    let write = |name: &str, bytes: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    // The chunks: each record's op and offset, walked from the bag header.
    let chunks = chunk_offsets(&bytes);
    assert!(chunks.len() >= 3, "{chunks:?}");

    // Cut inside the last chunk: what precedes imports, with a warning.
    let cut = write("cut.bag", &bytes[..chunks[chunks.len() - 1] + 60]);
    let o = ok(import(&cut, &out, &[]));
    assert!(
        stderr(&o).contains("the file ends inside chunk"),
        "{}",
        stderr(&o)
    );
    std::fs::remove_file(&out).unwrap();

    // Cut inside the first chunk of an uncompressed bag (a short recording stopped
    // early; the RealSense layout's first chunk holds the file version, options and
    // extrinsics): the chunk's complete messages are read, with a warning.
    let plain = dir.path().join("plain.bag");
    write_bag(&plain, "realsense", "none", 6, &[]);
    let plain_bytes = std::fs::read(&plain).unwrap();
    let plain_chunks = chunk_offsets(&plain_bytes);
    let u32_at = |at: usize| u32::from_le_bytes(plain_bytes[at..at + 4].try_into().unwrap());
    let header_len = u32_at(plain_chunks[0]) as usize;
    let data_len = u32_at(plain_chunks[0] + 4 + header_len) as usize;
    let first_end = plain_chunks[0] + 8 + header_len + data_len;
    let cut_first = write("cut-first.bag", &plain_bytes[..first_end - 10]);
    let o = ok(relume()
        .args(["import", "bag", "--list"])
        .arg(&cut_first)
        .output()
        .unwrap());
    let listing = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        listing.contains("warning: the file ends inside chunk 1")
            && listing
                .lines()
                .any(|l| l.contains("/file_version ") && l.contains(" 1 ")),
        "{listing}"
    );
    // Cut inside a record's header: a cut too, not damage.
    let in_header = write("in-header.bag", &plain_bytes[..plain_chunks[2] + 10]);
    let o = ok(import(&in_header, &out, &[]));
    assert!(
        stderr(&o).contains("the file ends inside a record's header"),
        "{}",
        stderr(&o)
    );
    std::fs::remove_file(&out).unwrap();

    // Cut before any message: an error, no file.
    let early = write("early.bag", &bytes[..4200]);
    let o = import(&early, &out, &[]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("early.bag: the file ends inside"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());

    // A chunk's compressed data damaged: named, and passed over with --skip-corrupt.
    let mut damaged = bytes.clone();
    let second = chunks[1];
    for b in &mut damaged[second + 80..second + 120] {
        *b ^= 0x5a;
    }
    let damaged = write("damaged.bag", &damaged);
    let o = import(&damaged, &out, &[]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains(&format!("damaged.bag: chunk 2 at byte {second}"))
            && e.contains("--skip-corrupt"),
        "{e}"
    );
    assert!(!out.exists());
    let o = ok(import(&damaged, &out, &["--skip-corrupt"]));
    assert!(
        stderr(&o).contains("skipped 1 damaged chunk"),
        "{}",
        stderr(&o)
    );
    std::fs::remove_file(&out).unwrap();

    // A record header claiming more than the file holds.
    let mut long = bytes.clone();
    long[chunks[1]..chunks[1] + 4].copy_from_slice(&0x00ff_ffffu32.to_le_bytes());
    let long = write("long.bag", &long);
    let o = import(&long, &out, &[]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains(&format!("long.bag: the record at byte {} after", chunks[1]))
            && stderr(&o).contains("its header claims 16777215 bytes"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());

    // Not a bag at all.
    let text = write("text.bag", b"#ROSBAG V1.2\nhello");
    let o = import(&text, &out, &[]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("text.bag"), "{}", stderr(&o));
    assert!(!out.exists());
}

/// Byte offsets of the chunk records (op 0x05) of a well-formed bag.
fn chunk_offsets(bytes: &[u8]) -> Vec<usize> {
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let mut at = 13;
    let mut chunks = Vec::new();
    while at < bytes.len() {
        let header_len = u32_at(at);
        let header = &bytes[at + 4..at + 4 + header_len];
        let op = header
            .windows(3)
            .position(|w| w == b"op=")
            .map(|i| header[i + 3])
            .unwrap();
        if op == 0x05 {
            chunks.push(at);
        }
        let data_len = u32_at(at + 4 + header_len);
        at += 8 + header_len + data_len;
    }
    chunks
}

/// Writes the `rosbag` fuzz target's seeds (small, uncompressed: a driver's layout and a
/// RealSense one with an extrinsic):
/// `cargo test --test rosbag write_fuzz_seeds -- --ignored`.
#[test]
#[ignore = "writes files into fuzz/seeds/rosbag"]
fn write_fuzz_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/rosbag");
    std::fs::create_dir_all(&dir).unwrap();
    write_bag(&dir.join("driver-tf"), "ros", "none", 2, &[]);
    write_bag(
        &dir.join("realsense-extrinsic"),
        "realsense",
        "none",
        2,
        &["0.015,0,0,1"],
    );
    write_bag(&dir.join("driver-lz4"), "ros", "lz4", 2, &[]);
}
