//! RealSense recordings written by librealsense itself: pyrealsense2 2.55's recorder (the
//! last release that writes ROS 1 bags) records a software device (tests/writers/
//! realsense.py, in a virtual environment under the target folder), and `relume import bag`
//! reads it back: pixels, stamps, intrinsics and depth unit exactly, and a depth camera of
//! its own registered into the color view, checked against the wall's exact depth.

mod common;

use common::{ok, relume};
use relume::recording::{Replay, ReplayOptions, codec};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const W: usize = 64;
const H: usize = 48;

fn python() -> &'static Path {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    common::venv::python(
        &PYTHON,
        "pyrealsense2-venv",
        &["pyrealsense2==2.55.1.6486", "numpy"],
        "import pyrealsense2",
    )
}

fn record(dir: &Path, name: &str, frames: usize, separate: bool) -> PathBuf {
    let bag = dir.join(format!("{name}.bag"));
    let frames = frames.to_string();
    let mut args = vec![bag.as_os_str(), frames.as_ref()];
    if separate {
        args.push("separate".as_ref());
    }
    common::venv::run_writer(python(), "realsense.py", &args);
    bag
}

fn import(bag: &Path) -> Replay {
    let out = bag.with_extension("relume");
    ok(relume()
        .args(["import", "bag"])
        .arg(bag)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap());
    Replay::open(&out, ReplayOptions::default()).unwrap()
}

#[test]
fn librealsense_recordings_import_exactly_and_register_a_separate_depth_camera() {
    let dir = tempfile::tempdir().unwrap();
    let replay = import(&record(dir.path(), "same", 4, false));
    let header = replay.recording.header();
    assert_eq!(header.depth_unit_m, 0.0001);
    let k = header.color_intrinsics;
    assert_eq!(
        (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
        (64, 48, 55.0, 55.5, 32.0, 24.0)
    );
    assert_eq!(header.depth_intrinsics, k);
    assert!(!header.provenance.settings.contains_key("registered"));
    assert_eq!(replay.stats.frames, 4);
    let first = replay.read_frame(0).unwrap().color.stamp_ns;
    for i in 0..4 {
        let rec = replay.read_frame(i).unwrap();
        // 33.3 ms apart, as recorded (the recorder's clock origin is its own).
        let step = rec.color.stamp_ns - first - i as i64 * 33_300_000;
        assert!(
            step.abs() <= 1_000,
            "frame {i}: stamp {}",
            rec.color.stamp_ns
        );
        let rgb = codec::decode_color(&rec.color.image).unwrap();
        for (p, px) in rgb.data.iter().enumerate() {
            assert_eq!(
                *px,
                [i as u8, (p % W) as u8, (p / W) as u8],
                "frame {i} pixel {p}"
            );
        }
        let depth = codec::decode_depth_units(&rec.depth.unwrap().image).unwrap();
        assert!(
            depth.data.iter().all(|&d| d == 20000 + i as u16),
            "frame {i}"
        );
    }

    // The depth camera 1.5 cm to the right with its own intrinsics: registered, the wall
    // keeps its 2 m on every color pixel the depth camera sees, and no other gets depth.
    let replay = import(&record(dir.path(), "separate", 2, true));
    let header = replay.recording.header();
    assert_eq!(header.depth_intrinsics, header.color_intrinsics);
    assert!(
        header.provenance.settings["registered"]
            .starts_with("depth 64x48 to color, depth camera at (0.0150, 0.0000, 0.0000) m"),
        "{:?}",
        header.provenance.settings
    );
    let (cfx, cfy, ccx, ccy) = (55.0, 55.5, 32.0, 24.0);
    let (dfx, dfy, dcx, dcy) = (48.0, 48.0, 31.0, 23.0);
    let depth =
        codec::decode_depth_units(&replay.read_frame(1).unwrap().depth.unwrap().image).unwrap();
    let mut seen = 0;
    for (p, &got) in depth.data.iter().enumerate() {
        let (x, y) = ((p % W) as f64, (p / W) as f64);
        // The color pixel's wall point in the depth camera (p_depth = p_color - t).
        let (px, py) = ((x - ccx) / cfx * 2.0 - 0.015, (y - ccy) / cfy * 2.0);
        let (u, v) = (px / 2.0 * dfx + dcx, py / 2.0 * dfy + dcy);
        let inside = (0.0..=(W - 1) as f64).contains(&u) && (0.0..=(H - 1) as f64).contains(&v);
        assert_eq!(
            got,
            if inside { 20001 } else { 0 },
            "color pixel {x},{y} (depth {u:.2},{v:.2})"
        );
        seen += inside as usize;
    }
    assert!(seen > W * H * 3 / 4, "{seen} pixels seen");

    // The registered recording replays through the geometry pipeline, end to end.
    let out = dir.path().join("geometry");
    let o = ok(relume()
        .arg("replay")
        .arg(dir.path().join("separate.relume"))
        .args(["-p", &common::pipeline("geometry.toml")])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap());
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("2 frames in")
            || String::from_utf8_lossy(&o.stderr).contains("2 frames in"),
        "{o:?}"
    );
    for product in ["color", "depth", "normals"] {
        assert!(out.join(product).join("000001.png").is_file(), "{product}");
    }
}
