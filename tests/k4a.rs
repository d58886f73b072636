//! Azure Kinect recordings written by an independent writer (tests/writers/k4a.py: ffmpeg's
//! Matroska muxer through PyAV, k4arecorder's layout, a real device's calibration) imported
//! with `relume import k4a`: color bytes, stamps and intrinsics exactly; depth registered
//! through both lenses and the extrinsic to within a millimetre of the color view's true
//! depth on every pixel the depth camera sees, none elsewhere; damaged files give errors
//! naming the file and frame.

mod common;

use common::{ok, relume, stderr};
use relume::recording::{Replay, ReplayOptions, codec};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const W: usize = 1280;
const H: usize = 720;

fn python() -> &'static Path {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    common::venv::python(
        &PYTHON,
        "k4a-venv",
        &["av==18.1.0", "pillow", "numpy"],
        "import av, PIL, numpy",
    )
}

fn write_mkv(path: &Path, frames: usize, extra: &[&str]) {
    let frames = frames.to_string();
    let args = [path.as_os_str(), frames.as_ref()]
        .into_iter()
        .chain(extra.iter().map(|a| a.as_ref()));
    common::venv::run_writer(python(), "k4a.py", &args.collect::<Vec<_>>());
}

fn import(mkv: &Path, out: &Path) -> std::process::Output {
    relume()
        .args(["import", "k4a"])
        .arg(mkv)
        .arg("-o")
        .arg(out)
        .output()
        .unwrap()
}

/// The color camera's 720P intrinsics as the SDK derives them from the calibration's
/// normalized parameters (binned 1280x960, 120 rows cropped off the top, pixel centres).
/// The literals are the calibration file's, digit for digit.
#[allow(clippy::excessive_precision)]
fn color_intrinsics() -> [f64; 4] {
    let (cx, cy, fx, fy) = (
        0.50639921426773071,
        0.50126415491104126,
        0.47318029403686523,
        0.6306186318397522,
    );
    [
        fx * 1280.0,
        fy * 960.0,
        cx * 1280.0 - 0.0 - 0.5,
        cy * 960.0 - 120.0 - 0.5,
    ]
}

#[test]
fn an_ffmpeg_written_recording_imports_exactly_and_registers_to_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let mkv = dir.path().join("kinect.mkv");
    write_mkv(&mkv, 3, &[]);
    let out = dir.path().join("kinect.relume");
    let o = ok(import(&mkv, &out));
    let warnings = stderr(&o);
    assert!(warnings.contains("no poses"), "{warnings}");
    assert!(warnings.contains("color lens bends rays"), "{warnings}");

    let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
    let header = replay.recording.header();
    let k = header.color_intrinsics;
    assert_eq!((k.width, k.height), (W as u32, H as u32));
    assert_eq!([k.fx, k.fy, k.cx, k.cy], color_intrinsics());
    assert_eq!(header.depth_intrinsics, k);
    assert_eq!(header.depth_unit_m, 0.001);
    assert_eq!(replay.stats.frames, 3);

    let truth: Vec<f32> = std::fs::read(mkv.with_extension("mkv.truth"))
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(truth.len(), W * H);
    let seen = truth.iter().filter(|&&t| t > 0.0).count();
    assert!(
        seen > W * H / 2,
        "the depth camera sees {seen} color pixels"
    );
    for i in 0..3 {
        let frame = replay.read_frame(i).unwrap();
        let depth_record = frame.depth.unwrap();
        // The device's stamps: the start offset plus each block's time.
        let stamp = 211_000_000 + i as i64 * 33_000_000;
        assert_eq!(
            (frame.color.stamp_ns, depth_record.stamp_ns),
            (stamp, stamp)
        );
        let jpeg = std::fs::read(mkv.with_extension(format!("mkv.color{i}.jpg"))).unwrap();
        assert_eq!(frame.color.image.bytes, jpeg, "frame {i}'s JPEG bytes");
        let depth = codec::decode_depth_units(&depth_record.image).unwrap();
        // The registered units against the true depth in units (rounded): within one
        // unit everywhere, half a unit on average (input and output are both rounded).
        let (mut worst, mut missing, mut invented) = (0u16, 0, 0);
        let (mut sum, mut count) = (0f64, 0);
        for (&d, &t) in depth.data.iter().zip(&truth) {
            // Negative truth: within the edge depth pixels' footprint, outside their centres.
            match (d, t) {
                (0, t) if t > 0.0 => missing += 1,
                (0, _) => {}
                (_, 0.0) => invented += 1,
                (_, t) => {
                    worst = worst.max(d.abs_diff(t.abs().round() as u16));
                    sum += (d as f64 - t.abs() as f64).abs();
                    count += 1;
                }
            }
        }
        assert_eq!(
            (missing, invented),
            (0, 0),
            "frame {i}: holes, invented depth"
        );
        let mean = sum / count as f64;
        assert!(
            worst <= 1 && mean < 0.5,
            "frame {i}: {worst} units off, {mean} mm on average"
        );
    }

    // It replays through the geometry pipeline, end to end.
    let products = dir.path().join("geometry");
    let o = ok(relume()
        .arg("replay")
        .arg(&out)
        .args(["-p", &common::pipeline("geometry.toml")])
        .arg("--out")
        .arg(&products)
        .output()
        .unwrap());
    let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), stderr(&o));
    assert!(text.contains("3 frames in"), "{text}");
    for product in ["color", "depth", "normals"] {
        assert!(
            products.join(product).join("000002.png").is_file(),
            "{product}"
        );
    }
}

#[test]
fn bgra_color_is_stored_as_its_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let mkv = dir.path().join("bgra.mkv");
    write_mkv(&mkv, 2, &["--bgra"]);
    let out = dir.path().join("bgra.relume");
    ok(import(&mkv, &out));
    let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
    for i in 0..2 {
        let frame = replay.read_frame(i).unwrap();
        let rgb = codec::decode_color(&frame.color.image).unwrap();
        // The writer's pixels (saved by numpy as .npy: a 128-byte header here, then RGB).
        let npy = std::fs::read(mkv.with_extension(format!("mkv.color{i}.npy"))).unwrap();
        let pixels = &npy[npy.len() - W * H * 3..];
        let ours: Vec<u8> = rgb.data.iter().flatten().copied().collect();
        assert!(ours == pixels, "frame {i}'s pixels");
    }
}

#[test]
fn damaged_recordings_are_named_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mkv = dir.path().join("kinect.mkv");
    write_mkv(&mkv, 3, &["--short-depth", "1"]);
    let out = dir.path().join("out.relume");
    // A depth frame of the wrong length.
    let o = import(&mkv, &out);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("kinect.mkv") && err.contains("depth frame 1") && err.contains("not 320x288"),
        "{err}"
    );
    assert!(!out.exists());

    // No calibration: nothing to register with.
    let bare = dir.path().join("bare.mkv");
    write_mkv(&bare, 1, &["--no-calibration"]);
    let err = stderr(&import(&bare, &out));
    assert!(
        err.contains("bare.mkv") && err.contains("no calibration.json"),
        "{err}"
    );
    assert!(!out.exists());

    // Cut in the middle: the frames before the cut are kept, and the cut is told.
    let good = dir.path().join("good.mkv");
    write_mkv(&good, 3, &[]);
    let bytes = std::fs::read(&good).unwrap();
    let cut = dir.path().join("cut.mkv");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let o = ok(import(&cut, &out));
    assert!(
        stderr(&o).contains("the file ends inside"),
        "{}",
        stderr(&o)
    );
    let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
    assert!(
        (1..3).contains(&replay.stats.frames),
        "{}",
        replay.stats.frames
    );
    std::fs::remove_file(&out).unwrap();

    // Cut inside the header: an error, no file.
    std::fs::write(&cut, &bytes[..300]).unwrap();
    let err = stderr(&import(&cut, &out));
    assert!(
        err.contains("cut.mkv") && err.contains("ends inside"),
        "{err}"
    );
    assert!(!out.exists());

    // A block whose size runs past its cluster: damage at a named byte.
    let at = find(&bytes, &[0xA3]).expect("a SimpleBlock");
    let mut damaged = bytes.clone();
    damaged[at + 1..at + 9].copy_from_slice(&[0x01, 0, 0, 0, 0x0F, 0, 0, 0]);
    let bad = dir.path().join("bad.mkv");
    std::fs::write(&bad, &damaged).unwrap();
    let err = stderr(&import(&bad, &out));
    assert!(
        err.contains("bad.mkv") && err.contains("damaged at byte"),
        "{err}"
    );
    assert!(!out.exists());

    // Not Matroska at all.
    std::fs::write(&bad, b"RIFF....AVI ").unwrap();
    let err = stderr(&import(&bad, &out));
    assert!(err.contains("not a Matroska file"), "{err}");
}

/// The first SimpleBlock: its ID (0xA3) followed by an 8-byte size (ffmpeg writes
/// cluster children with 0x01-prefixed sizes only for large blocks; find the first A3
/// whose next byte starts a size of 1 to 8 bytes and whose track byte is 0x81 or 0x82).
fn find(bytes: &[u8], id: &[u8]) -> Option<usize> {
    let cluster = bytes
        .windows(4)
        .position(|w| w == [0x1F, 0x43, 0xB6, 0x75])?;
    (cluster..bytes.len() - 12).find(|&i| {
        bytes[i..].starts_with(id) && {
            let len = bytes[i + 1].leading_zeros() as usize + 1;
            len <= 8 && matches!(bytes[i + 1 + len], 0x81 | 0x82)
        }
    })
}

#[test]
fn the_listing_names_tracks_attachments_and_what_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let mkv = dir.path().join("kinect.mkv");
    write_mkv(&mkv, 1, &[]);
    let o = ok(relume()
        .args(["import", "k4a", "--list"])
        .arg(&mkv)
        .output()
        .unwrap());
    let text = String::from_utf8_lossy(&o.stdout);
    for line in [
        " 1 COLOR         1 blocks  1280x720 MJPG color",
        " 2 DEPTH         1 blocks  320x288 b16g depth (16-bit mm)",
        "calibration.json (application/octet-stream, ",
        "K4A_DEPTH_MODE = NFOV_2X2BINNED",
        "imports: color track 1 (1280x720 720P, MJPG color), depth track 2 (320x288 \
         NFOV_2X2BINNED) registered to it (baseline 32.3 mm)",
    ] {
        assert!(text.contains(line), "{line:?} not in\n{text}");
    }
}

/// Writes the fuzz seeds for `fuzz/fuzz_targets/k4a.rs`: a one-frame recording, and its
/// first 16 KiB (header, tracks, calibration, tags and a cut cluster), so that most
/// mutations land on the element structure rather than in the depth payload:
/// `cargo test --test k4a write_fuzz_seeds -- --ignored`.
#[test]
#[ignore = "writes files into fuzz/seeds/k4a"]
fn write_fuzz_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/k4a");
    std::fs::create_dir_all(&dir).unwrap();
    let one = dir.join("one-frame");
    write_mkv(&one, 1, &[]);
    let bytes = std::fs::read(&one).unwrap();
    std::fs::write(dir.join("header"), &bytes[..bytes.len().min(16 << 10)]).unwrap();
    for k in ["truth", "color0.jpg", "color0.npy"] {
        let _ = std::fs::remove_file(dir.join(format!("one-frame.{k}")));
    }
}
