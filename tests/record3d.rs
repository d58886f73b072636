//! Record3D `.r3d` exports written by independent writers (tests/writers/record3d.py:
//! Python's zipfile, Pillow's JPEG, pyliblzfse; in a virtual environment under the target
//! folder) imported with `relume import record3d`: color bytes, stamps, intrinsics, depth
//! and ARKit poses exactly; damaged archives give errors naming the file and frame.

mod common;

use common::{ok, relume, stderr};
use glam::{DQuat, DVec3};
use relume::recording::{Replay, ReplayOptions, codec};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

const W: usize = 96;
const H: usize = 72;

fn python() -> &'static Path {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    common::venv::python(
        &PYTHON,
        "record3d-venv",
        &["pyliblzfse==0.4.1", "pillow", "numpy"],
        "import liblzfse, PIL, numpy",
    )
}

fn write_r3d(path: &Path, frames: usize, extra: &[&str]) {
    let frames = frames.to_string();
    let args = [path.as_os_str(), frames.as_ref()]
        .into_iter()
        .chain(extra.iter().map(|a| a.as_ref()));
    common::venv::run_writer(python(), "record3d.py", &args.collect::<Vec<_>>());
}

fn import(r3d: &Path, out: &Path) -> std::process::Output {
    relume()
        .args(["import", "record3d"])
        .arg(r3d)
        .arg("-o")
        .arg(out)
        .output()
        .unwrap()
}

/// The JPEG bytes of frame `k` as the archive holds them.
fn jpeg(r3d: &Path, k: usize) -> Vec<u8> {
    // Read with Python's zipfile, not relume's reader.
    let o = Command::new("python3")
        .args([
            "-c",
            "import sys, zipfile; sys.stdout.buffer.write(zipfile.ZipFile(sys.argv[1]).read(sys.argv[2]))",
        ])
        .arg(r3d)
        .arg(format!("rgbd/{k}.jpg"))
        .output()
        .unwrap();
    assert!(o.status.success());
    o.stdout
}

#[test]
fn a_record3d_export_imports_exactly_with_its_depth_registered_and_arkit_poses() {
    let dir = tempfile::tempdir().unwrap();
    let r3d = dir.path().join("scan.r3d");
    let out = dir.path().join("scan.relume");
    write_r3d(&r3d, 4, &[]);
    let o = ok(import(&r3d, &out));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("4 color, 4 depth, 4 poses"),
        "{o:?}"
    );
    let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
    let header = replay.recording.header();
    let k = header.color_intrinsics;
    assert_eq!(
        (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
        (96, 72, 80.0, 81.0, 47.5, 35.5)
    );
    assert_eq!(header.depth_intrinsics, k);
    assert_eq!(header.depth_unit_m, 0.001);
    assert_eq!(replay.stats.frames, 4);
    for i in 0..4 {
        let rec = replay.read_frame(i).unwrap();
        assert_eq!(rec.color.stamp_ns, (i as f64 / 30.0 * 1e9).round() as i64);
        assert_eq!(
            rec.color.image.bytes,
            jpeg(&r3d, i),
            "frame {i}: the JPEG as stored"
        );
        // The wall at 1.5 + 0.01 i m, registered from 32x24 to 96x72: its depth on every
        // pixel the depth map covers; none around its missing top-left pixel or outside
        // its outermost pixel centres.
        let depth = codec::decode_depth_units(&rec.depth.unwrap().image).unwrap();
        let want = 1500 + 10 * i as u16;
        let covered = depth.data.iter().filter(|&&d| d != 0).count();
        assert!(
            depth.data.iter().all(|&d| d == 0 || d == want),
            "frame {i}: {:?}",
            depth
                .data
                .iter()
                .filter(|&&d| d != 0 && d != want)
                .take(5)
                .collect::<Vec<_>>()
        );
        assert!(
            covered > W * H * 9 / 10,
            "frame {i}: {covered} pixels with depth"
        );
        assert_eq!(
            depth.data[0], 0,
            "frame {i}: no depth where the depth map had none"
        );
        // ARKit's camera (y up, looking down -z) in the optical frame (y down, +z).
        let half = 0.1 * i as f64 / 2.0;
        let arkit = DQuat::from_xyzw(0.0, half.sin(), 0.0, half.cos());
        let pose = rec.pose.unwrap();
        let forward = pose.rotation() * DVec3::Z;
        assert!(
            (forward - arkit * DVec3::NEG_Z).length() < 1e-9,
            "frame {i}: {forward}"
        );
        let down = pose.rotation() * DVec3::Y;
        assert!(
            (down - arkit * DVec3::NEG_Y).length() < 1e-9,
            "frame {i}: {down}"
        );
        assert!((pose.translation() - DVec3::new(0.2 * i as f64, 1.0, 0.5)).length() < 1e-12);
    }
}

#[test]
fn damaged_record3d_exports_name_the_file_and_frame_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let r3d = dir.path().join("good.r3d");
    write_r3d(&r3d, 3, &[]);
    let bytes = std::fs::read(&r3d).unwrap();
    let out = dir.path().join("out.relume");
    let fails = |name: &str, bytes: &[u8], want: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let o = import(&p, &out);
        assert!(!o.status.success(), "{name} imported");
        assert!(stderr(&o).contains(want), "{name}: {}", stderr(&o));
        assert!(!out.exists(), "{name}: a file was left");
    };
    // Cut: the ZIP's directory is at its end.
    fails(
        "cut.r3d",
        &bytes[..bytes.len() / 2],
        "cut.r3d: not a Record3D export (a ZIP archive)",
    );
    fails("text.r3d", b"hello", "text.r3d: not a Record3D export");
    // One frame's depth damaged inside the archive: rewrite it with a short stream.
    let p = dir.path().join("short.r3d");
    rewrite_entry(&r3d, &p, "rgbd/1.depth", b"bvx2\x00\x00");
    let o = import(&p, &out);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("short.r3d: frame 1: rgbd/1.depth"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
    // Without poses: imported, with a warning and none in the recording.
    let p = dir.path().join("noposes.r3d");
    write_r3d(&p, 2, &["noposes"]);
    let o = ok(import(&p, &out));
    assert!(
        stderr(&o).contains("the metadata has no poses"),
        "{}",
        stderr(&o)
    );
    let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
    assert_eq!(replay.stats.frames, 2);
    assert!(replay.read_frame(0).unwrap().pose.is_none());
}

/// Copies the archive `from` to `to` with entry `name` replaced by `data`.
fn rewrite_entry(from: &Path, to: &Path, name: &str, data: &[u8]) {
    let script = "import sys, zipfile\n\
        src, dst, name = sys.argv[1:4]\n\
        data = sys.stdin.buffer.read()\n\
        with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, 'w') as b:\n\
        \x20   for i in a.infolist():\n\
        \x20       b.writestr(i, data if i.filename == name else a.read(i.filename))\n";
    let mut child = Command::new("python3")
        .args(["-c", script])
        .arg(from)
        .arg(to)
        .arg(name)
        .stdin(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::Write;
    child.stdin.take().unwrap().write_all(data).unwrap();
    assert!(child.wait().unwrap().success());
}

/// Writes the `record3d` fuzz target's seeds (12x9 color, 4x3 depth, entries stored
/// without deflate): `cargo test --test record3d write_fuzz_seeds -- --ignored`.
#[test]
#[ignore = "writes files into fuzz/seeds/record3d"]
fn write_fuzz_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/record3d");
    std::fs::create_dir_all(&dir).unwrap();
    write_r3d(&dir.join("two-frames"), 2, &["stored", "--small"]);
    write_r3d(&dir.join("no-poses"), 1, &["noposes", "--small"]);
}
