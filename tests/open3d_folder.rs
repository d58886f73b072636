//! A folder as Open3D's RealSense recorder leaves it (color/, depth/ and
//! camera_intrinsic.json, no trajectory) imports with the camera Open3D wrote: the
//! intrinsics file is written here by Open3D itself (`o3d.io.write_pinhole_camera_intrinsic`,
//! PyPI's open3d 0.19), and the frames are livingroom1's first few.

mod common;

use common::open3d::python;
use common::{ok, run_in, stderr, stdout};
use std::path::Path;
use std::process::Command;

/// Writes `dir/camera_intrinsic.json` with Open3D for a `width` x `height` camera.
fn write_with_open3d(dir: &Path, (width, height): (u32, u32), k: [f64; 4]) {
    let [fx, fy, cx, cy] = k;
    let script = format!(
        "import open3d as o3d\n\
         k = o3d.camera.PinholeCameraIntrinsic({width}, {height}, {fx}, {fy}, {cx}, {cy})\n\
         assert o3d.io.write_pinhole_camera_intrinsic('{}', k)\n",
        dir.join("camera_intrinsic.json").display()
    );
    let o = Command::new(python())
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn an_open3d_folder_imports_with_its_own_intrinsics_and_no_poses() {
    let tmp = tempfile::tempdir().unwrap();
    let data = common::data_dir().join("livingroom1");
    let dir = tmp.path().join("o3d");
    for (sub, ext) in [("color", "jpg"), ("depth", "png")] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        for i in 0..3 {
            let file = format!("{i:05}.{ext}");
            std::os::unix::fs::symlink(data.join(sub).join(&file), dir.join(sub).join(&file))
                .unwrap();
        }
    }
    let k = [612.25, 611.75, 321.5, 238.25];
    write_with_open3d(&dir, (640, 480), k);
    let o = ok(run_in(
        tmp.path(),
        &["import", "redwood", "o3d", "-o", "r.relume"],
    ));
    // The camera is the file's: no note on a preset.
    assert!(!stderr(&o).contains("preset"), "{}", stderr(&o));
    let inspect: serde_json::Value = serde_json::from_str(&stdout(&ok(run_in(
        tmp.path(),
        &["inspect", "r.relume", "--json"],
    ))))
    .unwrap();
    for stream in ["color_intrinsics", "depth_intrinsics"] {
        let got = &inspect[stream];
        let got = ["fx", "fy", "cx", "cy"].map(|key| got[key].as_f64().unwrap());
        assert_eq!(got, k, "{stream}");
    }
    assert_eq!(inspect["depth_unit_m"], 0.001);
    assert_eq!(inspect["frames_with_pose"], 0);
    let settings = &inspect["provenance"]["settings"];
    assert!(
        settings["intrinsics_file"]
            .as_str()
            .unwrap()
            .ends_with("o3d/camera_intrinsic.json"),
        "{settings}"
    );
    // --intrinsics wins over the file.
    ok(run_in(
        tmp.path(),
        &[
            "import",
            "redwood",
            "o3d",
            "-o",
            "p.relume",
            "--intrinsics",
            "primesense",
        ],
    ));
    let inspect: serde_json::Value = serde_json::from_str(&stdout(&ok(run_in(
        tmp.path(),
        &["inspect", "p.relume", "--json"],
    ))))
    .unwrap();
    assert_eq!(inspect["color_intrinsics"]["fx"], 525.0);

    // A file for another image size is refused, naming both.
    write_with_open3d(&dir, (1280, 720), [900.0, 900.0, 640.0, 360.0]);
    let o = run_in(tmp.path(), &["import", "redwood", "o3d", "-o", "q.relume"]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("o3d/camera_intrinsic.json: is for 1280x720 images, but ")
            && err.contains("o3d/color/00000.jpg is 640x480 (give --intrinsics fx,fy,cx,cy"),
        "{err}"
    );
    assert!(!tmp.path().join("q.relume").exists());
}
