//! `relume import scannet`: `.sens` files written here (a writer of ScanNet's layout,
//! below) import as the same frames as the Redwood import of livingroom1; frames with
//! an invalid pose are skipped and counted; damaged files are refused naming the file
//! and frame, writing nothing; stamps come from the file or from k / fps.

mod common;

use relume::recording::importers::scannet::{self, ScannetOptions};
use relume::recording::{Replay, ReplayOptions, codec};
use std::path::Path;

const IDENTITY: [f32; 16] = [
    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
];

/// A row-major 4x4 intrinsic matrix as ScanNet writes it.
fn intrinsic(fx: f32, fy: f32, cx: f32, cy: f32) -> [f32; 16] {
    [
        fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
    ]
}

struct SensFrame {
    pose: [f32; 16],
    color_us: u64,
    depth_us: u64,
    color: Vec<u8>,
    depth: Vec<u8>,
}

/// A `.sens` file's content, written by [`Sens::bytes`] in ScanNet's layout.
struct Sens {
    color_type: i32,
    depth_type: i32,
    color_size: (u32, u32),
    depth_size: (u32, u32),
    color_k: [f32; 16],
    depth_k: [f32; 16],
    depth_shift: f32,
    frames: Vec<SensFrame>,
}

impl Sens {
    fn new(color_size: (u32, u32), depth_size: (u32, u32), k: [f32; 16]) -> Sens {
        Sens {
            color_type: 2,
            depth_type: 1,
            color_size,
            depth_size,
            color_k: k,
            depth_k: k,
            depth_shift: 1000.0,
            frames: Vec::new(),
        }
    }

    fn bytes(&self) -> Vec<u8> {
        let mut b = Vec::new();
        let matrix = |b: &mut Vec<u8>, m: &[f32; 16]| {
            m.iter().for_each(|v| b.extend(v.to_le_bytes()));
        };
        b.extend(4u32.to_le_bytes());
        let name = b"StructureSensor";
        b.extend((name.len() as u64).to_le_bytes());
        b.extend(name);
        for m in [&self.color_k, &IDENTITY, &self.depth_k, &IDENTITY] {
            matrix(&mut b, m);
        }
        b.extend(self.color_type.to_le_bytes());
        b.extend(self.depth_type.to_le_bytes());
        for v in [
            self.color_size.0,
            self.color_size.1,
            self.depth_size.0,
            self.depth_size.1,
        ] {
            b.extend(v.to_le_bytes());
        }
        b.extend(self.depth_shift.to_le_bytes());
        b.extend((self.frames.len() as u64).to_le_bytes());
        for f in &self.frames {
            matrix(&mut b, &f.pose);
            for v in [
                f.color_us,
                f.depth_us,
                f.color.len() as u64,
                f.depth.len() as u64,
            ] {
                b.extend(v.to_le_bytes());
            }
            b.extend(&f.color);
            b.extend(&f.depth);
        }
        // IMU data may follow the frames: the importer ignores it.
        b.extend(0u64.to_le_bytes());
        b
    }
}

/// Byte offset of the frame count in a header written by [`Sens::bytes`].
const FRAMES_OFFSET: usize = 4 + 8 + 15 + 4 * 64 + 2 * 4 + 4 * 4 + 4;
/// Byte offset of frame 0.
const FRAME0: usize = FRAMES_OFFSET + 8;

fn zlib_depth(units: &[u16]) -> Vec<u8> {
    let bytes: Vec<u8> = units.iter().flat_map(|u| u.to_le_bytes()).collect();
    miniz_oxide::deflate::compress_to_vec_zlib(&bytes, 1)
}

fn jpeg(w: u32, h: u32, value: u8) -> Vec<u8> {
    let img = image::RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([value, (x * 20) as u8, (y * 30) as u8])
    });
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Jpeg).unwrap();
    out.into_inner()
}

/// `n` small frames (8x6 JPEG color, zlib depth of 1000 + k mm), translated by k
/// along x, stamps 0.
fn small_sens(n: usize) -> Sens {
    let mut sens = Sens::new((8, 6), (8, 6), intrinsic(10.0, 10.0, 3.5, 2.5));
    for k in 0..n {
        let mut pose = IDENTITY;
        pose[3] = k as f32;
        sens.frames.push(SensFrame {
            pose,
            color_us: 0,
            depth_us: 0,
            color: jpeg(8, 6, 40 * k as u8),
            depth: zlib_depth(&[1000 + k as u16; 48]),
        });
    }
    sens
}

/// livingroom1 as a `.sens`: the same JPEG bytes, the depth PNGs' units as zlib u16,
/// the trajectory's matrices rounded to f32, fx = fy = 525, cx = 319.5, cy = 239.5.
fn livingroom1_sens() -> Sens {
    let data = common::data_dir().join("livingroom1");
    let text = std::fs::read_to_string(data.join("trajectory.log")).unwrap();
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let mut sens = Sens::new(
        (640, 480),
        (640, 480),
        intrinsic(525.0, 525.0, 319.5, 239.5),
    );
    for (k, record) in lines.chunks(5).enumerate() {
        let values: Vec<f32> = record[1..]
            .iter()
            .flat_map(|l| l.split_whitespace().map(|v| v.parse::<f32>().unwrap()))
            .collect();
        let color = std::fs::read(data.join(format!("color/{k:05}.jpg"))).unwrap();
        let depth = image::open(data.join(format!("depth/{k:05}.png")))
            .unwrap()
            .into_luma16();
        sens.frames.push(SensFrame {
            pose: values.try_into().unwrap(),
            color_us: 0,
            depth_us: 0,
            color,
            depth: zlib_depth(depth.as_raw()),
        });
    }
    assert_eq!(sens.frames.len(), 211);
    sens
}

/// The `--hash` lines of `rec` through a decode-only pipeline, as (index and stamp,
/// color digest, depth digest).
fn color_depth_hashes(dir: &Path, rec: &str) -> Vec<(String, String, String)> {
    std::fs::write(
        dir.join("decode.toml"),
        "[pipeline]\nname = \"decode\"\n\n[[stage]]\nkind = \"decode\"\n",
    )
    .unwrap();
    let text = common::replay_hashes(dir, rec, "decode.toml", "2");
    let field = |line: &str, name: &str| {
        line.split_whitespace()
            .find(|f| f.starts_with(name))
            .unwrap_or_else(|| panic!("{line} lacks {name}"))
            .to_string()
    };
    text.lines()
        .map(|l| {
            let stamp = l.split_whitespace().take(2).collect::<Vec<_>>().join(" ");
            (stamp, field(l, "color="), field(l, "depth="))
        })
        .collect()
}

#[test]
fn livingroom1_as_sens_imports_as_the_redwood_import_does() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    std::fs::write(d.join("lr.sens"), livingroom1_sens().bytes()).unwrap();
    common::import_livingroom1(d);
    let o = common::ok(common::run_in(
        d,
        &["import", "scannet", "lr.sens", "-o", "s.relume"],
    ));
    let said = common::stdout(&o);
    assert!(said.contains("(211 color, 211 depth, 211 poses,"), "{said}");
    assert!(!said.contains("skipped"), "{said}");

    let redwood = color_depth_hashes(d, "lr.relume");
    let sens = color_depth_hashes(d, "s.relume");
    assert_eq!(redwood.len(), 211);
    assert_eq!(sens, redwood, "index, stamp, color and depth digests");

    let r = Replay::open(&d.join("lr.relume"), ReplayOptions::default()).unwrap();
    let s = Replay::open(&d.join("s.relume"), ReplayOptions::default()).unwrap();
    let (rh, sh) = (r.recording.header(), s.recording.header());
    assert_eq!(sh.color_intrinsics, rh.color_intrinsics);
    assert_eq!(sh.depth_intrinsics, rh.depth_intrinsics);
    assert_eq!(sh.depth_unit_m, rh.depth_unit_m);
    assert_eq!(sh.provenance.settings["stamps"], "k / fps (30)");
    assert_eq!(sh.provenance.settings["intrinsics"], "file");
    // The .sens holds the matrices rounded to f32: each entry within 2^-24 of its
    // size (6e-8 relative; the trajectory's entries are under 4 in size), and the
    // quaternion taken from the rounded rotation moves the matrix by the same order.
    // 1e-6 * max(1, |x|) allows 16 times that, and still fails a transposed or
    // mispaired matrix (entries off by 1e-2 and more).
    for k in 0..211 {
        let a = r
            .read_frame(k)
            .unwrap()
            .pose
            .unwrap()
            .matrix()
            .to_cols_array();
        let b = s
            .read_frame(k)
            .unwrap()
            .pose
            .unwrap()
            .matrix()
            .to_cols_array();
        for (x, y) in a.iter().zip(&b) {
            assert!(
                (x - y).abs() <= 1e-6 * x.abs().max(1.0),
                "frame {k}: {a:?} vs {b:?}"
            );
        }
    }
}

#[test]
fn a_frame_with_an_infinite_pose_is_skipped_and_counted() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let mut sens = small_sens(5);
    sens.frames[2].pose[0] = f32::NEG_INFINITY;
    std::fs::write(d.join("x.sens"), sens.bytes()).unwrap();
    let summary = scannet::import(
        &d.join("x.sens"),
        &d.join("lib.relume"),
        &ScannetOptions::default(),
        &mut |_, _| {},
    )
    .unwrap();
    assert_eq!(
        (
            summary.color,
            summary.depth,
            summary.poses,
            summary.skipped_frames
        ),
        (4, 4, 4, 1)
    );
    let o = common::ok(common::run_in(
        d,
        &["import", "scannet", "x.sens", "-o", "x.relume"],
    ));
    let said = common::stdout(&o);
    assert!(
        said.contains("(4 color, 4 depth, 4 poses, 1 frames skipped,"),
        "{said}"
    );
    assert!(
        common::stderr(&o).contains("1 frame(s) have no valid camera pose (frames 2;"),
        "{}",
        common::stderr(&o)
    );
    // Frame 2 is absent, color and depth: the others keep their stamps and poses.
    let replay = Replay::open(&d.join("x.relume"), ReplayOptions::default()).unwrap();
    assert_eq!(
        (
            replay.stats.frames,
            replay.stats.depth_records,
            replay.stats.frames_with_pose
        ),
        (4, 4, 4)
    );
    for (n, k) in [0usize, 1, 3, 4].into_iter().enumerate() {
        let f = replay.read_frame(n).unwrap();
        assert_eq!(f.stamp_ns, (k as f64 / 30.0 * 1e9).round() as i64);
        assert_eq!(f.pose.unwrap().translation, [k as f64, 0.0, 0.0]);
        let depth = codec::decode_depth_units(&f.depth.unwrap().image).unwrap();
        assert_eq!(depth.data[0], 1000 + k as u16);
    }
}

/// Imports `bytes` as `bad.sens`; returns the error's text, after checking that no
/// file was left in the folder but the input.
fn import_error(bytes: &[u8]) -> (String, String) {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("bad.sens");
    std::fs::write(&path, bytes).unwrap();
    let e = scannet::import(
        &path,
        &tmp.path().join("out.relume"),
        &ScannetOptions::default(),
        &mut |_, _| {},
    )
    .unwrap_err();
    assert_eq!(common::file_names(tmp.path()), ["bad.sens"]);
    let o = common::run_in(
        tmp.path(),
        &[
            "import",
            "scannet",
            path.to_str().unwrap(),
            "-o",
            "o.relume",
        ],
    );
    assert!(!o.status.success());
    assert!(
        common::stderr(&o).contains(&e.to_string()),
        "{}",
        common::stderr(&o)
    );
    assert_eq!(common::file_names(tmp.path()), ["bad.sens"]);
    (e.to_string(), format!("{}: ", path.display()))
}

#[test]
fn damaged_sens_files_are_refused_naming_file_and_frame() {
    let good = small_sens(3);
    let bytes = good.bytes();
    let frame_len = |f: &SensFrame| 96 + f.color.len() + f.depth.len();
    let frame1 = FRAME0 + frame_len(&good.frames[0]);
    let frame2 = frame1 + frame_len(&good.frames[1]);

    let (e, p) = import_error(&bytes[..100]);
    assert_eq!(
        e,
        format!("{p}truncated header: the file ends at byte 100, in the color extrinsics")
    );
    // Cut inside frame 1's depth image.
    let (e, p) = import_error(&bytes[..frame2 - 5]);
    assert_eq!(
        e,
        format!(
            "{p}frame 1: depth image of {} bytes is larger than the {} bytes left in the file",
            good.frames[1].depth.len(),
            good.frames[1].depth.len() - 5
        )
    );
    let (e, p) = import_error(&bytes[..frame1 + 70]);
    assert_eq!(
        e,
        format!(
            "{p}frame 1: truncated: the file ends at byte {}, in the color timestamp",
            frame1 + 70
        )
    );
    // A color size of 2^62 bytes: refused before anything is allocated.
    let mut huge = bytes.clone();
    huge[frame1 + 80..frame1 + 88].copy_from_slice(&(1u64 << 62).to_le_bytes());
    let (e, p) = import_error(&huge);
    assert_eq!(
        e,
        format!(
            "{p}frame 1: color size of {} bytes is not what a 8x6 color image takes (at most {} bytes)",
            1u64 << 62,
            2 * 8 * 6 * 3 + (1 << 20)
        )
    );
    // Plausible for the image, but more than the file holds.
    let mut big = bytes.clone();
    big[frame1 + 80..frame1 + 88].copy_from_slice(&100_000u64.to_le_bytes());
    let (e, p) = import_error(&big);
    let left = bytes.len() - (frame1 + 96);
    assert_eq!(
        e,
        format!(
            "{p}frame 1: color image of 100000 bytes is larger than the {left} bytes left in the file"
        )
    );
    // A finite but absurd depth shift: every depth would be 1e30 metres.
    let mut shift = small_sens(3);
    shift.depth_shift = 1e-30;
    let (e, p) = import_error(&shift.bytes());
    assert_eq!(
        e,
        format!(
            "{p}depth shift 1.0000000031710769e-30 units per metre is not a depth sensor's: it \
             must lie between 0.1 and 1000000 (a stored unit of 1e-6 m to 10 m)"
        )
    );
    // Depth that inflates to more than its image: said in words, not "HasMoreOutput".
    let mut long = small_sens(3);
    long.frames[1].depth = zlib_depth(&[1000; 96]);
    let (e, p) = import_error(&long.bytes());
    assert_eq!(
        e,
        format!(
            "{p}frame 1: depth: cannot inflate the zlib data: it inflates to more than the 96 \
             bytes the image's size allows"
        )
    );
    let mut unknown = small_sens(3);
    unknown.color_type = 7;
    let (e, p) = import_error(&unknown.bytes());
    assert_eq!(
        e,
        format!("{p}unknown color compression type 7: raw (0), PNG (1) and JPEG (2) can be read")
    );
    let mut occi = small_sens(3);
    occi.depth_type = 2;
    let (e, p) = import_error(&occi.bytes());
    assert_eq!(
        e,
        format!(
            "{p}depth compression type 2 (occi_ushort) cannot be read: raw_ushort (0) and zlib_ushort (1) can"
        )
    );
    let mut version = bytes.clone();
    version[..4].copy_from_slice(&3u32.to_le_bytes());
    let (e, p) = import_error(&version);
    assert_eq!(
        e,
        format!("{p}not a ScanNet .sens file of version 4: its version field is 3")
    );
    let mut many = bytes.clone();
    many[FRAMES_OFFSET..FRAME0].copy_from_slice(&(1u64 << 40).to_le_bytes());
    let (e, p) = import_error(&many);
    let after = bytes.len() - FRAME0;
    assert_eq!(
        e,
        format!(
            "{p}the header says {} frames, but the {after} bytes after it hold at most {} \
             (each frame takes at least 96 bytes)",
            1u64 << 40,
            after / 96
        )
    );
    // A damaged JPEG (its second half zeroed) is refused naming its frame.
    let mut jpeg = small_sens(3);
    let color = &mut jpeg.frames[2].color;
    let half = color.len() / 2;
    color[half..].fill(0);
    let (e, p) = import_error(&jpeg.bytes());
    assert!(
        e.starts_with(&format!("{p}frame 2: color: ")) && e.contains("Jpeg"),
        "{e}"
    );
    let mut depth = small_sens(3);
    depth.frames[1].depth = zlib_depth(&[7; 47]);
    let (e, p) = import_error(&depth.bytes());
    assert_eq!(
        e,
        format!("{p}frame 1: depth: the zlib depth inflates to 94 bytes, but 8x6 u16 take 96")
    );
}

#[test]
fn zero_stamps_are_k_over_fps_and_the_files_stamps_are_used() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("s.sens");
    let stamps = |sens: &Sens, options: &ScannetOptions| {
        std::fs::write(&path, sens.bytes()).unwrap();
        let out = tmp.path().join("s.relume");
        let summary = scannet::import(&path, &out, options, &mut |_, _| {}).unwrap();
        let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
        let list: Vec<(i64, i64)> = (0..replay.frames.len())
            .map(|n| {
                let f = replay.read_frame(n).unwrap();
                (f.stamp_ns, f.depth.unwrap().stamp_ns)
            })
            .collect();
        let setting = replay.recording.header().provenance.settings["stamps"].clone();
        (list, setting, summary.warnings)
    };
    let options = ScannetOptions {
        fps: 10.0,
        ..ScannetOptions::default()
    };
    let mut sens = small_sens(3);
    let (list, setting, warnings) = stamps(&sens, &options);
    assert_eq!(
        list,
        [
            (0, 0),
            (100_000_000, 100_000_000),
            (200_000_000, 200_000_000)
        ]
    );
    assert_eq!(setting, "k / fps (10)");
    assert!(warnings.is_empty(), "{warnings:?}");

    // Microseconds; depth 4 ms after color in the file, written at the color stamp: the
    // file pairs them by frame, and replay must not re-pair them by stamp.
    for (k, f) in sens.frames.iter_mut().enumerate() {
        f.color_us = 5_000_000 + 40_000 * k as u64;
        f.depth_us = f.color_us + 4_000;
    }
    let (list, setting, warnings) = stamps(&sens, &options);
    assert_eq!(
        list,
        [
            (5_000_000_000, 5_000_000_000),
            (5_040_000_000, 5_040_000_000),
            (5_080_000_000, 5_080_000_000)
        ]
    );
    assert_eq!(setting, "file");
    assert!(warnings.is_empty(), "{warnings:?}");

    // A stamp that goes back: k / fps, with a warning naming the frame.
    sens.frames[2].color_us = 1;
    let (list, setting, warnings) = stamps(&sens, &options);
    assert_eq!(list[2], (200_000_000, 200_000_000));
    assert_eq!(setting, "k / fps (10)");
    assert!(
        warnings.len() == 1 && warnings[0].contains("frame 2 has a stamp no later than"),
        "{warnings:?}"
    );
}

/// Writes the seed corpus of the `sens` fuzz target (`fuzz/seeds/sens`): two and three
/// small frames. Run with
/// `cargo test --test importers_scannet write_fuzz_seeds -- --ignored`.
#[test]
#[ignore = "writes files into fuzz/seeds/sens"]
fn write_fuzz_seeds() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/sens");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("two-frames"), small_sens(2).bytes()).unwrap();
    std::fs::write(dir.join("three-frames"), small_sens(3).bytes()).unwrap();
}
