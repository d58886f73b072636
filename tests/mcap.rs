//! `relume import mcap` and `relume export mcap`: files written by an independent ROS 2
//! writer (tests/common/ros2.rs) import with the right images, stamps, intrinsics and
//! poses; livingroom1 goes out to MCAP and back to the same frames; bad files give
//! errors naming the file, topic and message.

mod common;
#[path = "common/ros2.rs"]
mod ros2;

use common::{ok, run_in, stderr, stdout};
use glam::{DQuat, DVec3};
use relume::recording::codec;
use relume::recording::types::Pose;
use relume::recording::{Replay, ReplayOptions};
use ros2::{Bag, Tf};
use std::path::Path;

const T0: i64 = 1_700_000_000_000_000_000;
const DT: i64 = 33_333_333;
const W: u32 = 8;
const H: u32 = 6;

fn color_pixels(k: usize) -> Vec<u8> {
    (0..W * H * 3)
        .map(|i| (i as usize * 7 + k * 31) as u8)
        .collect()
}

fn depth_units(k: usize) -> Vec<u16> {
    (0..W * H).map(|i| 500 + i as u16 * 3 + k as u16).collect()
}

/// The pose of base_link in odom at frame k, and the camera in base_link.
fn base_pose(k: usize) -> (DVec3, DQuat) {
    let a = k as f64 * 0.1;
    (DVec3::new(a, 2.0 * a, 0.5), DQuat::from_rotation_z(a))
}
const CAMERA_IN_BASE: ([f64; 3], [f64; 4]) = ([0.1, 0.0, 1.2], [-0.5, 0.5, -0.5, 0.5]);

fn expected_camera_pose(k: usize) -> Pose {
    let (bt, bq) = base_pose(k);
    let (ct, cq) = CAMERA_IN_BASE;
    let cq = DQuat::from_array(cq);
    Pose::from_parts(bt + bq * DVec3::from(ct), bq * cq)
}

fn tf_at(stamp_ns: i64, k: usize) -> Tf<'static> {
    let (t, q) = base_pose(k);
    Tf {
        stamp_ns,
        parent: "odom",
        child: "base_link",
        t: t.to_array(),
        q: q.to_array(),
    }
}

/// Five frames of raw rgb8 (rows padded to a longer step) and 16UC1 depth, camera
/// infos beside each image topic, a static camera mount and odom -> base_link on /tf
/// from frame 1 on (frame 0 lies before the first transform).
fn write_raw_bag(path: &Path, compression: Option<mcap::Compression>) {
    let info = |_, t, frame: &str| ros2::camera_info(t, frame, W, H, 10.5, 11.0, 3.9, 2.7);
    write_raw_bag_with_info(path, compression, info);
}

/// [`write_raw_bag`] with the color camera info of frame k (stamp t) from `info`.
fn write_raw_bag_with_info(
    path: &Path,
    compression: Option<mcap::Compression>,
    info: impl Fn(usize, i64, &str) -> Vec<u8>,
) {
    fill_raw_bag(Bag::create(path, compression), info);
}

/// Writes [`write_raw_bag`]'s messages into `bag`.
fn fill_raw_bag(mut bag: Bag, info: impl Fn(usize, i64, &str) -> Vec<u8>) {
    let (ct, cq) = CAMERA_IN_BASE;
    let mount = Tf {
        stamp_ns: T0,
        parent: "base_link",
        child: "camera_color_optical_frame",
        t: ct,
        q: cq,
    };
    bag.put(
        "/tf_static",
        "tf2_msgs/msg/TFMessage",
        T0 as u64,
        &ros2::tf_message(&[mount]),
    );
    for k in 0..5 {
        let t = T0 + k as i64 * DT;
        if k >= 1 {
            // Two samples around the frame with the same pose: interpolation gives it.
            for s in [t - 5_000_000, t + 5_000_000] {
                bag.put(
                    "/tf",
                    "tf2_msgs/msg/TFMessage",
                    s as u64,
                    &ros2::tf_message(&[tf_at(s, k)]),
                );
            }
        }
        let step = W * 3 + 4;
        let mut rows = Vec::new();
        for r in color_pixels(k).chunks(W as usize * 3) {
            rows.extend(r);
            rows.extend([0xEE; 4]);
        }
        let frame = "camera_color_optical_frame";
        bag.put(
            "/camera/color/image_raw",
            "sensor_msgs/msg/Image",
            t as u64,
            &ros2::image(t, frame, W, H, "rgb8", step, &rows),
        );
        bag.put(
            "/camera/color/camera_info",
            "sensor_msgs/msg/CameraInfo",
            t as u64,
            &info(k, t, frame),
        );
        let depth: Vec<u8> = depth_units(k)
            .iter()
            .flat_map(|u| u.to_le_bytes())
            .collect();
        let td = t + 2_000_000;
        bag.put(
            "/camera/aligned_depth_to_color/image_raw",
            "sensor_msgs/msg/Image",
            td as u64,
            &ros2::image(td, frame, W, H, "16UC1", W * 2, &depth),
        );
        bag.put(
            "/camera/aligned_depth_to_color/camera_info",
            "sensor_msgs/msg/CameraInfo",
            td as u64,
            &ros2::camera_info(td, frame, W, H, 10.5, 11.0, 3.9, 2.7),
        );
    }
    bag.finish();
}

/// Frame `i` of `replay` holds [`write_raw_bag`]'s frame `k`: its color and depth
/// exactly, its camera pose within rounding.
fn assert_frame_is_bag_frame(replay: &Replay, i: usize, k: usize) {
    let rec = replay.read_frame(i).unwrap();
    let rgb = codec::decode_color(&rec.color.image).unwrap();
    let flat: Vec<u8> = rgb.data.iter().flatten().copied().collect();
    assert_eq!(flat, color_pixels(k), "frame {k} color");
    let units = codec::decode_depth_units(&rec.depth.unwrap().image).unwrap();
    assert_eq!(units.data, depth_units(k), "frame {k} depth");
    assert_pose_near(
        &rec.pose.unwrap(),
        &expected_camera_pose(k),
        &format!("frame {k}"),
    );
}

fn assert_pose_near(got: &Pose, want: &Pose, what: &str) {
    let dt = (got.translation() - want.translation()).length();
    let dq = got.rotation().angle_between(want.rotation());
    assert!(dt < 1e-9 && dq < 1e-9, "{what}: {got:?} vs {want:?}");
}

#[test]
fn ros2_raw_images_tf_and_camera_info_import_exactly() {
    for compression in [
        None,
        Some(mcap::Compression::Zstd),
        Some(mcap::Compression::Lz4),
    ] {
        let dir = tempfile::tempdir().unwrap();
        write_raw_bag(&dir.path().join("in.mcap"), compression);
        let out = ok(run_in(
            dir.path(),
            &["import", "mcap", "in.mcap", "-o", "r.relume"],
        ));
        // Frame 0 precedes the first transform: skipped and counted, as tf2 would not
        // extrapolate either.
        assert!(
            stdout(&out).contains("(4 color, 5 depth, 4 poses, 1 frames skipped"),
            "{}",
            stdout(&out)
        );
        let replay = Replay::open(&dir.path().join("r.relume"), ReplayOptions::default()).unwrap();
        let header = replay.recording.header();
        let k = &header.color_intrinsics;
        assert_eq!(
            (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
            (W, H, 10.5, 11.0, 3.9, 2.7)
        );
        assert_eq!(header.depth_unit_m, 0.001);
        assert_eq!(header.provenance.settings["world-frame"], "odom");
        assert_eq!(
            header.provenance.settings["camera-frame"],
            "camera_color_optical_frame"
        );
        assert_eq!(replay.frames.len(), 4, "{compression:?}");
        for (i, f) in replay.frames.iter().enumerate() {
            let k = i + 1;
            assert_eq!(f.stamp_ns, T0 + k as i64 * DT);
            assert_frame_is_bag_frame(&replay, i, k);
        }
    }
}

/// A camera matrix that is not a pinhole's, or absurd values in one, are refused
/// naming the topic; one that changes mid-stream is named in a warning.
#[test]
fn a_camera_info_must_be_a_pinhole_matrix_in_bounds_and_a_change_is_named() {
    let good = [10.5, 0.0, 3.9, 0.0, 11.0, 2.7, 0.0, 0.0, 1.0];
    let with = |i: usize, v: f64| {
        let mut k = good;
        k[i] = v;
        k
    };
    let topic = "/camera/color/camera_info";
    let cases = [
        (
            with(8, 0.0),
            format!(
                "the camera info on {topic}: K = {:?} is not a pinhole camera matrix without \
                 skew ([fx 0 cx; 0 fy cy; 0 0 1]); give --intrinsics fx,fy,cx,cy",
                with(8, 0.0)
            ),
        ),
        (
            with(1, 0.5),
            format!(
                "the camera info on {topic}: K = {:?} is not a pinhole camera matrix without \
                 skew ([fx 0 cx; 0 fy cy; 0 0 1]); give --intrinsics fx,fy,cx,cy",
                with(1, 0.5)
            ),
        ),
        (
            with(2, 1e300),
            format!(
                "the camera info on {topic}: cx = 1e300 px lies further outside the 8x6 image \
                 than its own size (it must lie between -8 and 16 px)"
            ),
        ),
        (
            with(0, 1e-300),
            format!(
                "the camera info on {topic}: fx = 1e-300 px is not a focal length for a 8x6 \
                 image: it must lie between 0.05 and 100 times the image's larger side (0.4 to \
                 800 px)"
            ),
        ),
    ];
    for (k, message) in cases {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("in.mcap");
        write_raw_bag_with_info(&path, None, |_, t, frame| {
            ros2::camera_info_k(t, frame, W, H, k)
        });
        let o = run_in(dir.path(), &["import", "mcap", "in.mcap", "-o", "r.relume"]);
        assert!(!o.status.success());
        assert_eq!(stderr(&o), format!("error: in.mcap: {message}\n"), "{k:?}");
        assert!(!dir.path().join("r.relume").exists());
    }
    // From frame 3 on (message 20 of the file) the camera is zoomed: imported with the
    // first, and said.
    let dir = tempfile::tempdir().unwrap();
    write_raw_bag_with_info(&dir.path().join("in.mcap"), None, |k, t, frame| {
        let f = if k >= 3 { 21.0 } else { 10.5 };
        ros2::camera_info(t, frame, W, H, f, f, 3.9, 2.7)
    });
    let o = ok(run_in(
        dir.path(),
        &["import", "mcap", "in.mcap", "-o", "r.relume"],
    ));
    let out = stdout(&o) + &stderr(&o);
    assert!(
        out.contains(&format!(
            "the camera info on {topic} changes at message 20 (8x6, K = [21.0, 0.0, 3.9, \
             0.0, 21.0, 2.7, 0.0, 0.0, 1.0], after 8x6, K = [10.5, 0.0, 3.9, 0.0, 10.5, 2.7, \
             0.0, 0.0, 1.0]): every frame is imported with the first"
        )),
        "{out}"
    );
}

fn png_rgb(k: usize) -> Vec<u8> {
    let img = image::RgbImage::from_raw(W, H, color_pixels(k)).unwrap();
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

fn png_depth(k: usize) -> Vec<u8> {
    let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(W, H, depth_units(k)).unwrap();
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

/// PNG color on a CompressedImage topic, compressedDepth depth on two topics, camera
/// poses from nav_msgs/Odometry of base_link, mounted by /tf_static.
fn write_compressed_bag(path: &Path) {
    write_compressed_bag_with(path, Some(mcap::Compression::Zstd));
}

fn write_compressed_bag_with(path: &Path, compression: Option<mcap::Compression>) {
    let mut bag = Bag::create(path, compression);
    let (ct, cq) = CAMERA_IN_BASE;
    let mount = Tf {
        stamp_ns: 0,
        parent: "base_link",
        child: "cam",
        t: ct,
        q: cq,
    };
    bag.put(
        "/tf_static",
        "tf2_msgs/msg/TFMessage",
        0,
        &ros2::tf_message(&[mount]),
    );
    for k in 0..4 {
        let t = T0 + k as i64 * DT;
        bag.put(
            "/odom",
            "nav_msgs/msg/Odometry",
            t as u64,
            &ros2::odometry(&tf_at(t, k)),
        );
        bag.put(
            "/cam/color/image/compressed",
            "sensor_msgs/msg/CompressedImage",
            t as u64,
            &ros2::compressed_image(t, "cam", "rgb8; png compressed rgb8", &png_rgb(k)),
        );
        let mut depth = 0i32.to_le_bytes().to_vec();
        depth.extend([0u8; 8]);
        depth.extend(png_depth(k));
        for topic in [
            "/cam/depth/compressedDepth",
            "/cam/depth_raw/compressedDepth",
        ] {
            bag.put(
                topic,
                "sensor_msgs/msg/CompressedImage",
                t as u64,
                &ros2::compressed_image(t, "cam", "16UC1; compressedDepth png", &depth),
            );
        }
    }
    bag.put(
        "/cam/color/camera_info",
        "sensor_msgs/msg/CameraInfo",
        T0 as u64,
        &ros2::camera_info(T0, "cam", W, H, 9.0, 9.0, 4.0, 3.0),
    );
    bag.finish();
}

#[test]
fn compressed_images_and_odometry_import_and_ambiguity_asks_for_a_topic() {
    let dir = tempfile::tempdir().unwrap();
    write_compressed_bag(&dir.path().join("c.mcap"));
    let e = run_in(dir.path(), &["import", "mcap", "c.mcap", "-o", "r.relume"]);
    assert!(!e.status.success());
    assert!(
        stderr(&e).contains(
            "2 topics hold depth images (/cam/depth/compressedDepth, /cam/depth_raw/compressedDepth): choose one with --depth-topic"
        ),
        "{}",
        stderr(&e)
    );
    assert!(!dir.path().join("r.relume").exists());
    let list = ok(run_in(dir.path(), &["import", "mcap", "c.mcap", "--list"]));
    let text = stdout(&list);
    assert!(
        text.contains("/odom") && text.contains("poses in frame \"odom\""),
        "{text}"
    );
    assert!(text.contains("cam <- base_link (static)"), "{text}");
    ok(run_in(
        dir.path(),
        &[
            "import",
            "mcap",
            "c.mcap",
            "-o",
            "r.relume",
            "--depth-topic",
            "/cam/depth/compressedDepth",
        ],
    ));
    let replay = Replay::open(&dir.path().join("r.relume"), ReplayOptions::default()).unwrap();
    assert_eq!(replay.frames.len(), 4);
    assert_eq!(replay.recording.header().color_intrinsics.fx, 9.0);
    for (k, f) in replay.frames.iter().enumerate() {
        let rec = replay.read_frame(k).unwrap();
        // PNG bytes kept as sent.
        assert_eq!(rec.color.image.bytes, png_rgb(k));
        assert_eq!(
            codec::decode_depth_units(&rec.depth.unwrap().image)
                .unwrap()
                .data,
            depth_units(k)
        );
        assert_eq!(f.stamp_ns, T0 + k as i64 * DT);
        // Odometry samples at the frame stamps: base pose, then the static mount.
        assert_pose_near(
            &rec.pose.unwrap(),
            &expected_camera_pose(k),
            &format!("frame {k}"),
        );
    }
}

#[test]
fn damaged_and_unreadable_files_name_what_is_wrong_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_raw_bag(&d.join("in.mcap"), None);
    let bytes = std::fs::read(d.join("in.mcap")).unwrap();
    let fails = |args: &[&str], want: &str| {
        let o = run_in(d, args);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
        assert!(!d.join("r.relume").exists());
    };
    // Not MCAP at all.
    std::fs::write(d.join("junk.mcap"), b"not an mcap file at all").unwrap();
    fails(
        &["import", "mcap", "junk.mcap", "-o", "r.relume"],
        "junk.mcap: not a readable MCAP file",
    );
    // Flags naming what is not there.
    fails(
        &[
            "import",
            "mcap",
            "in.mcap",
            "-o",
            "r.relume",
            "--color-topic",
            "/nope",
        ],
        "--color-topic /nope: no such topic",
    );
    fails(
        &[
            "import",
            "mcap",
            "in.mcap",
            "-o",
            "r.relume",
            "--color-topic",
            "/camera/aligned_depth_to_color/image_raw",
        ],
        "the topic holds depth images",
    );
    fails(
        &[
            "import",
            "mcap",
            "in.mcap",
            "-o",
            "r.relume",
            "--world-frame",
            "map",
        ],
        "the frame \"map\" is not above \"camera_color_optical_frame\"",
    );
    fails(
        &[
            "import",
            "mcap",
            "in.mcap",
            "-o",
            "r.relume",
            "--camera-frame",
            "nope",
        ],
        "--camera-frame nope: the transform tree has no such frame",
    );
    // The input given as the output: refused, the input kept.
    let o = run_in(d, &["import", "mcap", "in.mcap", "-o", "in.mcap"]);
    assert!(
        stderr(&o).contains("-o in.mcap is the input file"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(d.join("in.mcap")).unwrap(), bytes);
    // A file cut short, as by a recorder killed mid-write: what precedes is imported.
    std::fs::write(d.join("cut.mcap"), &bytes[..bytes.len() * 3 / 4]).unwrap();
    let o = ok(run_in(
        d,
        &["import", "mcap", "cut.mcap", "-o", "cut.relume"],
    ));
    assert!(
        stderr(&o).contains("the file ends inside a record after"),
        "{}",
        stderr(&o)
    );
    // One bit flipped inside a chunk (a pixel of frame 2): imported before as other
    // pixels with exit 0; the chunk's CRC no longer matches.
    let row = &color_pixels(2)[..(W * 3) as usize];
    let at = bytes
        .windows(row.len())
        .position(|w| w == row)
        .expect("frame 2's first row is in the file");
    let mut flipped = bytes.clone();
    flipped[at + 5] ^= 0x10;
    std::fs::write(d.join("flip.mcap"), &flipped).unwrap();
    fails(
        &["import", "mcap", "flip.mcap", "-o", "r.relume"],
        "flip.mcap: the file is damaged: ",
    );
    // A message whose byte count runs past its end.
    let mut bag = Bag::create(&d.join("bad.mcap"), None);
    let mut img = ros2::image(T0, "cam", W, H, "rgb8", W * 3, &color_pixels(0));
    let at = img.len() - (W * H * 3) as usize - 4;
    img[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    bag.put(
        "/color",
        "sensor_msgs/msg/Image",
        T0 as u64,
        &ros2::image(T0, "cam", W, H, "rgb8", W * 3, &color_pixels(0)),
    );
    bag.put("/color", "sensor_msgs/msg/Image", T0 as u64 + 1, &img);
    bag.finish();
    fails(
        &["import", "mcap", "bad.mcap", "-o", "r.relume"],
        "message 1 on /color: byte",
    );
    // An image of another size in the middle of a topic.
    let mut bag = Bag::create(&d.join("sizes.mcap"), None);
    let first = ros2::image(T0, "cam", W, H, "rgb8", W * 3, &color_pixels(0));
    let small = ros2::image(T0 + DT, "cam", 4, H, "rgb8", 12, &color_pixels(0)[..72]);
    bag.put("/color", "sensor_msgs/msg/Image", T0 as u64, &first);
    bag.put("/color", "sensor_msgs/msg/Image", (T0 + DT) as u64, &small);
    bag.finish();
    fails(
        &["import", "mcap", "sizes.mcap", "-o", "r.relume"],
        "sizes.mcap: message 1 on /color: the image is 4x6, but the topic's first is 8x6",
    );
    // A ROS 1 message too short for its header: named in the listing, and no colour.
    let mut bag = Bag::create(&d.join("ros1.mcap"), None);
    bag.put_encoded("/img", "sensor_msgs/Image", "ros1", 0, b"\0");
    bag.finish();
    fails(
        &["import", "mcap", "ros1.mcap", "-o", "r.relume"],
        "no color images",
    );
    let list = ok(run_in(d, &["import", "mcap", "ros1.mcap", "--list"]));
    assert!(
        stdout(&list).contains(
            "its first message cannot be read: byte 0: message ends before its header.seq"
        ),
        "{}",
        stdout(&list)
    );
}

/// A ROS 1 `sensor_msgs/Image` (uint32 seq, time, string frame_id, then the fields, packed
/// little-endian), as DepthAI and `mcap convert` of a ROS 1 bag write them into MCAP.
fn ros1_image(
    stamp_ns: i64,
    frame: &str,
    encoding: &str,
    w: u32,
    h: u32,
    step: u32,
    data: &[u8],
) -> Vec<u8> {
    let mut m = 7u32.to_le_bytes().to_vec();
    m.extend(((stamp_ns / 1_000_000_000) as u32).to_le_bytes());
    m.extend(((stamp_ns % 1_000_000_000) as u32).to_le_bytes());
    m.extend((frame.len() as u32).to_le_bytes());
    m.extend(frame.as_bytes());
    m.extend(h.to_le_bytes());
    m.extend(w.to_le_bytes());
    m.extend((encoding.len() as u32).to_le_bytes());
    m.extend(encoding.as_bytes());
    m.push(0);
    m.extend(step.to_le_bytes());
    m.extend((data.len() as u32).to_le_bytes());
    m.extend(data);
    m
}

#[test]
fn ros1_encoded_channels_in_mcap_import_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut bag = Bag::create(&d.join("ros1.mcap"), None);
    for k in 0..3 {
        let t = T0 + k as i64 * DT;
        let color = ros1_image(t, "cam", "rgb8", W, H, W * 3, &color_pixels(k));
        let depth: Vec<u8> = depth_units(k)
            .iter()
            .flat_map(|u| u.to_le_bytes())
            .collect();
        let depth = ros1_image(t, "cam", "16UC1", W, H, W * 2, &depth);
        bag.put_encoded("/color", "sensor_msgs/Image", "ros1", t as u64, &color);
        bag.put_encoded("/depth", "sensor_msgs/Image", "ros1", t as u64, &depth);
    }
    bag.finish();
    ok(run_in(
        d,
        &["import", "mcap", "ros1.mcap", "-o", "r.relume"],
    ));
    let replay = Replay::open(&d.join("r.relume"), ReplayOptions::default()).unwrap();
    assert_eq!(replay.stats.frames, 3);
    for k in 0..3 {
        let rec = replay.read_frame(k).unwrap();
        assert_eq!(rec.color.stamp_ns, T0 + k as i64 * DT);
        let rgb = codec::decode_color(&rec.color.image).unwrap();
        let flat: Vec<u8> = rgb.data.iter().flatten().copied().collect();
        assert_eq!(flat, color_pixels(k), "frame {k} color");
        let units = codec::decode_depth_units(&rec.depth.unwrap().image).unwrap();
        assert_eq!(units.data, depth_units(k), "frame {k} depth");
    }
}

/// A pipeline of the decode stage alone: its hash lines are the frames' color, depth
/// and pose as replay reads them.
const DECODE_ONLY: &str = "[pipeline]\nname = \"decode\"\n\n[[stage]]\nkind = \"decode\"\n";

fn decoded_hashes(dir: &Path, recording: &str) -> Vec<String> {
    let out = ok(run_in(
        dir,
        &[
            "replay",
            recording,
            "-p",
            "decode.toml",
            "--hash",
            "--out",
            "o",
        ],
    ));
    stdout(&out)
        .lines()
        .map(|l| {
            l.split(' ')
                .filter(|w| !w.starts_with("record="))
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect()
}

#[test]
fn livingroom1_exported_to_mcap_imports_back_to_the_same_frames() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    common::import_livingroom1(d);
    std::fs::write(d.join("decode.toml"), DECODE_ONLY).unwrap();
    let out = ok(run_in(d, &["export", "mcap", "lr.relume", "-o", "lr.mcap"]));
    assert!(
        stdout(&out).contains("(211 color, 211 depth, 211 poses"),
        "{}",
        stdout(&out)
    );
    // What a viewer finds: Foxglove's well-known schemas in JSON.
    let bytes = std::fs::read(d.join("lr.mcap")).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a summary section");
    let mut topics: Vec<(String, String, String)> = summary
        .channels
        .values()
        .map(|c| {
            let s = c.schema.as_ref().unwrap();
            (c.topic.clone(), s.name.clone(), c.message_encoding.clone())
        })
        .collect();
    topics.sort();
    let json = |t: &str, s: &str| (t.to_string(), s.to_string(), "json".to_string());
    assert_eq!(
        topics,
        [
            json("/camera/color/calibration", "foxglove.CameraCalibration"),
            json("/camera/color/image", "foxglove.CompressedImage"),
            json("/camera/depth/calibration", "foxglove.CameraCalibration"),
            json("/camera/depth/image", "foxglove.RawImage"),
            json("/tf", "foxglove.FrameTransform"),
        ]
    );
    ok(run_in(
        d,
        &["import", "mcap", "lr.mcap", "-o", "back.relume"],
    ));
    let (a, b) = (
        decoded_hashes(d, "lr.relume"),
        decoded_hashes(d, "back.relume"),
    );
    assert_eq!(a.len(), 211);
    assert!(
        a[5].contains(" color=") && a[5].contains(" depth=") && a[5].contains(" pose="),
        "{}",
        a[5]
    );
    assert_eq!(a, b);
}

#[test]
fn saved_products_export_as_images_and_point_clouds_at_their_frames() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let rec = common::small_recording(d, 4);
    let rec = rec.to_str().unwrap();
    let acquisition = common::pipeline("acquisition.toml");
    ok(run_in(
        d,
        &[
            "replay",
            rec,
            "-p",
            &acquisition,
            "--save",
            "color,cloud",
            "--out",
            "saved",
        ],
    ));
    let out = ok(run_in(
        d,
        &["export", "mcap", rec, "-o", "s.mcap", "--products", "saved"],
    ));
    assert!(
        stdout(&out).contains("products: 4 cloud, 4 color"),
        "{}",
        stdout(&out)
    );
    let stamps: Vec<u64> = Replay::open(Path::new(rec), ReplayOptions::default())
        .unwrap()
        .frames
        .iter()
        .map(|f| f.stamp_ns as u64)
        .collect();
    let bytes = std::fs::read(d.join("s.mcap")).unwrap();
    let (mut clouds, mut colors) = (0, 0);
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let json: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        let data = || {
            use base64::Engine;
            base64::engine::general_purpose::STANDARD
                .decode(json["data"].as_str().unwrap())
                .unwrap()
        };
        let frame = || {
            stamps
                .iter()
                .position(|&s| s == m.log_time)
                .expect("a frame stamp")
        };
        match m.channel.topic.as_str() {
            "/relume/cloud" => {
                assert_eq!(
                    m.channel.schema.as_ref().unwrap().name,
                    "foxglove.PointCloud"
                );
                assert_eq!(json["point_stride"], 39);
                let ply = std::fs::read(d.join(format!("saved/cloud/{:06}.ply", frame()))).unwrap();
                let body = &ply[ply.windows(11).position(|w| w == b"end_header\n").unwrap() + 11..];
                assert_eq!(data(), body);
                clouds += 1;
            }
            "/relume/color" => {
                let png = std::fs::read(d.join(format!("saved/color/{:06}.png", frame()))).unwrap();
                assert_eq!(data(), png);
                colors += 1;
            }
            _ => {}
        }
    }
    assert_eq!((clouds, colors), (4, 4));
    // The recording's own color topic is imported, not the saved products.
    ok(run_in(
        d,
        &["import", "mcap", "s.mcap", "-o", "back.relume"],
    ));
    let back = Replay::open(&d.join("back.relume"), ReplayOptions::default()).unwrap();
    assert_eq!(
        back.recording.header().provenance.settings["color-topic"],
        "/camera/color/image"
    );
}

#[test]
fn poses_are_not_invented_from_unlinked_or_mistimed_transforms() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let image = |k: usize| {
        let t = T0 + k as i64 * DT;
        ros2::image(t, "cam", W, H, "rgb8", W * 3, &color_pixels(k))
    };
    // An Odometry of base_link, and nothing links base_link to the camera.
    let mut bag = Bag::create(&d.join("odom.mcap"), None);
    for k in 0..3 {
        let t = T0 + k as i64 * DT;
        bag.put(
            "/odom",
            "nav_msgs/msg/Odometry",
            t as u64,
            &ros2::odometry(&tf_at(t, k)),
        );
        bag.put("/color", "sensor_msgs/msg/Image", t as u64, &image(k));
    }
    bag.finish();
    let o = ok(run_in(
        d,
        &["import", "mcap", "odom.mcap", "-o", "a.relume"],
    ));
    assert!(
        stdout(&o).contains("(3 color, 0 depth, 0 poses"),
        "{}",
        stdout(&o)
    );
    assert!(
        stderr(&o).contains("no camera poses are taken from /odom by default"),
        "{}",
        stderr(&o)
    );
    let e = run_in(
        d,
        &[
            "import",
            "mcap",
            "odom.mcap",
            "-o",
            "b.relume",
            "--pose-topic",
            "/odom",
        ],
    );
    assert!(!e.status.success());
    assert!(
        stderr(&e).contains(
            "the poses on /odom are of frame \"base_link\", which no transform links to the camera frame \"cam\""
        ),
        "{}",
        stderr(&e)
    );
    assert!(!d.join("b.relume").exists());
    // The camera's transforms stamped by another clock than its images.
    let mut bag = Bag::create(&d.join("sim.mcap"), None);
    for k in 0..3 {
        let t = T0 + k as i64 * DT;
        let sim = 1_000_000_000 + k as i64 * DT;
        let mut tf = tf_at(sim, k);
        tf.child = "cam";
        bag.put(
            "/tf",
            "tf2_msgs/msg/TFMessage",
            t as u64,
            &ros2::tf_message(&[tf]),
        );
        bag.put("/color", "sensor_msgs/msg/Image", t as u64, &image(k));
    }
    bag.finish();
    let e = run_in(d, &["import", "mcap", "sim.mcap", "-o", "c.relume"]);
    assert!(!e.status.success());
    assert!(
        stderr(&e).contains(
            "none of the 3 color images (stamped 1700000000.000 s to 1700000000.067 s) lies \
             within the camera's transforms (1.000 s to 1.067 s)"
        ),
        "{}",
        stderr(&e)
    );
    assert!(!d.join("c.relume").exists());
}

#[test]
fn a_pose_stamped_topic_gives_the_camera_poses_when_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut bag = Bag::create(&d.join("p.mcap"), Some(mcap::Compression::Lz4));
    for k in 0..3 {
        let t = T0 + k as i64 * DT;
        let img = ros2::image(t, "cam", W, H, "rgb8", W * 3, &color_pixels(k));
        bag.put("/color", "sensor_msgs/msg/Image", t as u64, &img);
        let mut pose = tf_at(t, k);
        pose.parent = "map";
        bag.put(
            "/slam/pose",
            "geometry_msgs/msg/PoseStamped",
            t as u64,
            &ros2::pose_stamped(&pose),
        );
    }
    bag.finish();
    // Not taken by default: a PoseStamped may be anything.
    let o = ok(run_in(d, &["import", "mcap", "p.mcap", "-o", "a.relume"]));
    assert!(
        stdout(&o).contains("(3 color, 0 depth, 0 poses"),
        "{}",
        stdout(&o)
    );
    ok(run_in(
        d,
        &[
            "import",
            "mcap",
            "p.mcap",
            "-o",
            "b.relume",
            "--pose-topic",
            "/slam/pose",
        ],
    ));
    let replay = Replay::open(&d.join("b.relume"), ReplayOptions::default()).unwrap();
    assert_eq!(
        replay.recording.header().provenance.settings["world-frame"],
        "map"
    );
    for k in 0..3 {
        let (t, q) = base_pose(k);
        let want = Pose::from_parts(t, q);
        let got = replay.read_frame(k).unwrap().pose.unwrap();
        // The camera's own pose, as sent: bit for bit at the message's stamp.
        assert_eq!(got, want, "frame {k}");
    }
}

/// Writes the seed corpus of the `mcap` fuzz target (`fuzz/seeds/mcap`): the raw and the
/// compressed-image bags of these tests, with uncompressed chunks (so the target can
/// recompute their CRCs after a mutation) and one zstd bag. Run with
/// `cargo test --test mcap write_fuzz_seeds -- --ignored`.
#[test]
#[ignore = "writes files into fuzz/seeds/mcap"]
fn write_fuzz_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/mcap");
    std::fs::create_dir_all(&dir).unwrap();
    write_raw_bag(&dir.join("raw-images-tf"), None);
    write_compressed_bag_with(&dir.join("compressed-images-odometry"), None);
    write_compressed_bag(&dir.join("zstd-chunks"));
}

/// A depth topic in an encoding relume does not read (8UC1) is named with the reason,
/// not only "no depth images".
#[test]
fn an_unreadable_depth_topic_is_named_with_its_encoding() {
    let dir = tempfile::tempdir().unwrap();
    let mut bag = Bag::create(&dir.path().join("in.mcap"), None);
    for k in 0..2 {
        let t = T0 + k as i64 * DT;
        let frame = "cam";
        bag.put(
            "/cam/color/image_raw",
            "sensor_msgs/msg/Image",
            t as u64,
            &ros2::image(t, frame, W, H, "rgb8", W * 3, &color_pixels(k)),
        );
        bag.put(
            "/cam/depth/image_raw",
            "sensor_msgs/msg/Image",
            t as u64,
            &ros2::image(t, frame, W, H, "8UC1", W, &vec![7u8; (W * H) as usize]),
        );
    }
    bag.finish();
    let o = ok(run_in(
        dir.path(),
        &["import", "mcap", "in.mcap", "-o", "r.relume"],
    ));
    let e = stderr(&o);
    assert!(
        e.contains(
            "no depth topic was read; image topics that were not: /cam/depth/image_raw: raw \
             encoding `8UC1` is not read (color: rgb8, bgr8, rgba8, bgra8, mono8; depth: "
        ),
        "{e}"
    );
}

/// A channel record of a few bytes whose topic says it is 3 GB long (found by the `mcap`
/// fuzz target): refused by its length, not by a 3 GB allocation. Under a 2 GB address
/// space ceiling the allocation aborted the process.
#[test]
fn a_string_longer_than_its_record_is_refused_without_allocating_it() {
    let dir = tempfile::tempdir().unwrap();
    let mut file = b"\x89MCAP0\r\n".to_vec();
    let mut record = |opcode: u8, body: &[u8]| {
        file.push(opcode);
        file.extend_from_slice(&(body.len() as u64).to_le_bytes());
        file.extend_from_slice(body);
    };
    record(0x01, &[0; 8]);
    let mut channel = vec![1, 0, 0, 0];
    channel.extend_from_slice(&3_086_843_275u32.to_le_bytes());
    channel.extend_from_slice(b"/cam");
    record(0x04, &channel);
    std::fs::write(dir.path().join("big.mcap"), &file).unwrap();
    let o = std::process::Command::new("sh")
        .args([
            "-c",
            "ulimit -v 2000000 && exec \"$0\" import mcap big.mcap -o r.relume",
            env!("CARGO_BIN_EXE_relume"),
        ])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "big.mcap: record 0x04 after 0 messages is damaged: its topic says it is \
             3086843275 bytes long, but only 4 bytes of the record follow"
        ),
        "{}",
        stderr(&o)
    );
    assert!(!dir.path().join("r.relume").exists());
}

/// An attachment record whose body ends before its data length and CRC (found by the
/// `mcap` fuzz target): the `mcap` crate slices between them and panicked; now refused.
#[test]
fn an_attachment_without_room_for_its_crc_is_refused_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let string = |s: &str| [&(s.len() as u32).to_le_bytes()[..], s.as_bytes()].concat();
    let body = [
        &[0u8; 16][..],
        &string("a.png"),
        &string("image/png"),
        &[0u8; 8],
    ]
    .concat();
    let mut file = b"\x89MCAP0\r\n".to_vec();
    file.push(0x09);
    file.extend_from_slice(&(body.len() as u64).to_le_bytes());
    file.extend_from_slice(&body);
    std::fs::write(dir.path().join("a.mcap"), &file).unwrap();
    let o = run_in(dir.path(), &["import", "mcap", "a.mcap", "-o", "r.relume"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "a.mcap: record 0x09 after 0 messages is damaged: its data length and CRC take 12 \
             bytes, but only 8 bytes of the record follow its name and media type"
        ),
        "{}",
        stderr(&o)
    );
    assert!(!dir.path().join("r.relume").exists());
}

/// A chunk inside a chunk whose compression string says it is 2.5 GB long (found by the
/// `mcap` fuzz target): the reader hands the inner chunk over as a record, and parsing
/// it reserved the string's length; now refused by its length.
#[test]
fn a_nested_chunk_with_an_overlong_compression_is_refused_without_allocating_it() {
    let dir = tempfile::tempdir().unwrap();
    let record = |opcode: u8, body: &[u8]| {
        [&[opcode][..], &(body.len() as u64).to_le_bytes(), body].concat()
    };
    let chunk = |compression_len: u32, records: &[u8]| {
        let mut body = vec![0u8; 8 + 8];
        body.extend_from_slice(&(records.len() as u64).to_le_bytes());
        body.extend_from_slice(&0u32.to_le_bytes()); // no CRC
        body.extend_from_slice(&compression_len.to_le_bytes());
        body.extend_from_slice(&(records.len() as u64).to_le_bytes());
        body.extend_from_slice(records);
        record(0x06, &body)
    };
    let inner = chunk(2_587_895_296, b"zstd");
    let mut file = b"\x89MCAP0\r\n".to_vec();
    file.extend(record(0x01, &[0; 8]));
    file.extend(chunk(0, &inner));
    std::fs::write(dir.path().join("nested.mcap"), &file).unwrap();
    let o = std::process::Command::new("sh")
        .args([
            "-c",
            "ulimit -v 2000000 && exec \"$0\" import mcap nested.mcap -o r.relume",
            env!("CARGO_BIN_EXE_relume"),
        ])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "nested.mcap: record 0x06 after 0 messages is damaged: its compression says it is \
             2587895296 bytes long, but only 12 bytes of the record follow"
        ),
        "{}",
        stderr(&o)
    );
}

/// The body (start and length) of the top-level chunk holding the message logged at
/// `log_time` on `topic`, found by walking the file's records.
fn chunk_holding(bytes: &[u8], topic: &str, log_time: u64) -> (usize, usize) {
    let mut at = 8;
    let mut channels = std::collections::BTreeMap::new();
    while at + 9 <= bytes.len() {
        let opcode = bytes[at];
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        let body = &bytes[at + 9..at + 9 + len];
        if let Ok(mcap::records::Record::Chunk { header, data }) = mcap::parse_record(opcode, body)
        {
            for record in mcap::read::ChunkReader::new(header, &data).unwrap() {
                match record.unwrap() {
                    mcap::records::Record::Channel(c) => {
                        channels.insert(c.id, c.topic);
                    }
                    mcap::records::Record::Message { header, .. }
                        if header.log_time == log_time
                            && channels.get(&header.channel_id).map(String::as_str)
                                == Some(topic) =>
                    {
                        return (at + 9, len);
                    }
                    _ => {}
                }
            }
        }
        at += 9 + len;
    }
    panic!("no chunk holds {topic} at {log_time}");
}

/// `--skip-corrupt`: a chunk whose CRC or compression fails is passed over, named in a
/// warning with its byte offset, and the other chunks' frames import exactly; without
/// the flag the same file stops the import. Issue 59's first item.
#[test]
fn skip_corrupt_passes_over_a_damaged_chunk_and_imports_the_rest_exactly() {
    for compression in [
        None,
        Some(mcap::Compression::Zstd),
        Some(mcap::Compression::Lz4),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let info = |_, t, frame: &str| ros2::camera_info(t, frame, W, H, 10.5, 11.0, 3.9, 2.7);
        fill_raw_bag(
            Bag::create_chunked(&d.join("in.mcap"), compression, Some(1)),
            info,
        );
        // An undamaged file reads the same either way (the chunks opened by relume or
        // by the crate).
        std::fs::write(d.join("decode.toml"), DECODE_ONLY).unwrap();
        ok(run_in(d, &["import", "mcap", "in.mcap", "-o", "a.relume"]));
        ok(run_in(
            d,
            &[
                "import",
                "mcap",
                "in.mcap",
                "-o",
                "b.relume",
                "--skip-corrupt",
            ],
        ));
        let strict_hashes = decoded_hashes(d, "a.relume");
        assert_eq!(strict_hashes.len(), 4, "{strict_hashes:?}");
        assert_eq!(strict_hashes, decoded_hashes(d, "b.relume"));
        let mut bytes = std::fs::read(d.join("in.mcap")).unwrap();
        let frame2 = (T0 + 2 * DT) as u64;
        let (body, len) = chunk_holding(&bytes, "/camera/color/image_raw", frame2);
        // A byte in the middle of the chunk's (compressed) records.
        bytes[body + len - len / 4] ^= 0x5A;
        std::fs::write(d.join("in.mcap"), &bytes).unwrap();
        let strict = run_in(d, &["import", "mcap", "in.mcap", "-o", "r.relume"]);
        assert_eq!(strict.status.code(), Some(1), "{compression:?}");
        assert!(
            stderr(&strict).contains("in.mcap: the file is damaged: ")
                && stderr(&strict).contains("--skip-corrupt passes over a damaged chunk"),
            "{compression:?}: {}",
            stderr(&strict)
        );
        assert!(!d.join("r.relume").exists());
        let o = ok(run_in(
            d,
            &[
                "import",
                "mcap",
                "in.mcap",
                "-o",
                "r.relume",
                "--skip-corrupt",
            ],
        ));
        let want = format!(
            "skipped 1 damaged chunk (--skip-corrupt): chunk {} at byte {} after ",
            count_chunks_before(&bytes, body - 9) + 1,
            body - 9
        );
        assert!(
            stderr(&o).contains(&want),
            "{compression:?}: want {want:?} in {}",
            stderr(&o)
        );
        let replay = Replay::open(&d.join("r.relume"), ReplayOptions::default()).unwrap();
        let stamps: Vec<i64> = replay.frames.iter().map(|f| f.stamp_ns).collect();
        assert_eq!(
            stamps,
            [1, 3, 4].map(|k| T0 + k * DT),
            "{compression:?}: frame 2's color was in the damaged chunk"
        );
        for (i, k) in [1usize, 3, 4].into_iter().enumerate() {
            assert_frame_is_bag_frame(&replay, i, k);
        }
    }
}

/// How many top-level chunk records start before byte `end`.
fn count_chunks_before(bytes: &[u8], end: usize) -> usize {
    let mut at = 8;
    let mut n = 0;
    while at < end {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        n += usize::from(bytes[at] == 0x06);
        at += 9 + len;
    }
    n
}
