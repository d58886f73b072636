//! Importers: a TUM-layout directory written here (depth and pose stamps offset from the
//! color stamps) imports with correct association and interpolated poses; malformed
//! inputs are errors naming the file and line; Redwood reads livingroom1.

mod common;

use glam::{DMat4, DQuat, DVec3};
use relume::recording::importers::redwood::{self, RedwoodOptions};
use relume::recording::importers::{ImportOptions, tum};
use relume::recording::{Replay, ReplayOptions, codec};
use std::path::Path;

const T0: f64 = 1305031102.0;

fn write_color(path: &Path, w: u32, h: u32, value: u8) {
    image::RgbImage::from_pixel(w, h, image::Rgb([value, 2 * value, 3]))
        .save(path)
        .unwrap();
}

fn write_depth(path: &Path, w: u32, h: u32, units: u16) {
    image::ImageBuffer::<image::Luma<u16>, _>::from_pixel(w, h, image::Luma([units]))
        .save(path)
        .unwrap();
}

/// The true pose at time t (seconds after T0): constant linear and angular velocity,
/// so lerp and slerp reproduce it exactly between samples.
fn true_pose(t: f64) -> (DVec3, DQuat) {
    (
        DVec3::new(1.0 * t, 0.2, -0.5 * t),
        DQuat::from_axis_angle(DVec3::new(0.0, 1.0, 0.0), 0.1 + 0.5 * t),
    )
}

/// A TUM groundtruth.txt line: the true pose at `t` seconds after `T0`.
fn groundtruth_line(t: f64) -> String {
    let (p, q) = true_pose(t);
    format!(
        "{:.6} {} {} {} {} {} {} {}\n",
        T0 + t,
        p.x,
        p.y,
        p.z,
        q.x,
        q.y,
        q.z,
        q.w
    )
}

/// Five color frames at 30 Hz; depth 7 ms later except frame 3 (45 ms: unmatched);
/// poses at 100 Hz from -50 ms to +100 ms, so frame 4 (133 ms) has no pose.
fn write_tum(dir: &Path) {
    std::fs::create_dir_all(dir.join("rgb")).unwrap();
    std::fs::create_dir_all(dir.join("depth")).unwrap();
    let mut rgb = String::from("# color images\n# timestamp filename\n");
    let mut depth = String::from("# depth maps\n");
    for i in 0..5u32 {
        let t = i as f64 / 30.0;
        write_color(&dir.join(format!("rgb/{i}.png")), 8, 6, 10 * i as u8);
        write_depth(
            &dir.join(format!("depth/{i}.png")),
            8,
            6,
            1000 * (i as u16 + 1),
        );
        rgb.push_str(&format!("{:.6} rgb/{i}.png\n", T0 + t));
        let offset = if i == 3 { 0.045 } else { 0.007 };
        depth.push_str(&format!("{:.6} depth/{i}.png\n\n", T0 + t + offset));
    }
    std::fs::write(dir.join("rgb.txt"), rgb).unwrap();
    std::fs::write(dir.join("depth.txt"), depth).unwrap();
    let mut gt = String::from("# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n");
    for k in -5..=10 {
        let t = k as f64 * 0.01;
        gt.push_str(&groundtruth_line(t));
    }
    std::fs::write(dir.join("groundtruth.txt"), gt).unwrap();
}

#[test]
fn tum_import_associates_depth_and_interpolates_poses() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tum");
    write_tum(&dir);
    let out = tmp.path().join("t.relume");
    let summary = tum::import(&dir, &out, &ImportOptions::default(), &mut |_, _| {}).unwrap();
    assert_eq!((summary.color, summary.depth, summary.poses), (5, 5, 16));

    let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
    let s = &replay.stats;
    assert_eq!(
        (s.color_records, s.depth_records, s.pose_records),
        (5, 5, 16)
    );
    assert_eq!(
        (s.frames, s.skipped_no_depth, s.frames_with_pose),
        (4, 1, 3)
    );
    assert_eq!(replay.recording.header().depth_unit_m, 1.0 / 5000.0);
    // The settings as the command line takes them, so an import can be repeated.
    let settings = &replay.recording.header().provenance.settings;
    assert_eq!(settings["intrinsics"], "primesense");
    assert_eq!(settings["store"], "compressed");
    assert_eq!(
        relume::recording::importers::parse_intrinsics(&settings["intrinsics"]).unwrap(),
        ImportOptions::default().intrinsics
    );
    let expected_color_index = [0u32, 1, 2, 4];
    for (n, &i) in expected_color_index.iter().enumerate() {
        let f = replay.read_frame(n).unwrap();
        assert_eq!(
            f.stamp_ns,
            relume::recording::importers::parse_stamp_ns(&format!("{:.6}", T0 + i as f64 / 30.0))
                .unwrap()
        );
        assert_eq!(
            codec::decode_color(&f.color.image).unwrap().data[0],
            [10 * i as u8, 20 * i as u8, 3]
        );
        let depth = codec::decode_depth_units(&f.depth.as_ref().unwrap().image).unwrap();
        assert_eq!(
            depth.data[0],
            1000 * (i as u16 + 1),
            "frame {n} takes the depth 7 ms after it"
        );
        match f.pose {
            Some(pose) => {
                let t = (f.stamp_ns
                    - relume::recording::importers::parse_stamp_ns("1305031102").unwrap())
                    as f64
                    * 1e-9;
                let (p, q) = true_pose(t);
                assert!(
                    (pose.translation() - p).length() < 1e-9,
                    "frame {n}: {:?} vs {p:?}",
                    pose.translation()
                );
                assert!(pose.rotation().angle_between(q) < 1e-7, "frame {n}");
                assert!(i < 4, "frame {n} lies inside the pose stream");
            }
            None => assert_eq!(i, 4, "only the frame after the last pose has none"),
        }
    }
}

fn tum_error(edit: impl Fn(&Path)) -> String {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tum");
    write_tum(&dir);
    edit(&dir);
    let out = tmp.path().join("t.relume");
    let e = tum::import(&dir, &out, &ImportOptions::default(), &mut |_, _| {})
        .expect_err("import fails");
    assert!(!out.exists(), "no recording is left under the final name");
    let leftovers = common::file_names(tmp.path());
    assert_eq!(
        leftovers.len(),
        1,
        "no temporary file is left: {leftovers:?}"
    );
    e.to_string().replace(&format!("{}/", dir.display()), "")
}

fn edit_line(path: &Path, line: usize, text: &str) {
    let mut lines: Vec<String> = std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    lines[line - 1] = text.to_string();
    std::fs::write(path, lines.join("\n")).unwrap();
}

#[test]
fn tum_errors_name_file_and_line() {
    let e = tum_error(|d| edit_line(&d.join("groundtruth.txt"), 4, "1305031102.0 1 2 3 0 0 0"));
    assert_eq!(
        e,
        "groundtruth.txt:4: expected `timestamp tx ty tz qx qy qz qw` (8 fields), found 7 field(s): \"1305031102.0 1 2 3 0 0 0\""
    );
    let e = tum_error(|d| edit_line(&d.join("groundtruth.txt"), 5, "1305031101.5 1 2 3 0 0 0 2"));
    assert_eq!(
        e,
        "groundtruth.txt:5: quaternion qx qy qz qw has length 2.0000, expected 1"
    );
    let e = tum_error(|d| edit_line(&d.join("rgb.txt"), 4, "1305031102.050000 rgb/missing.png"));
    assert!(
        e.starts_with("rgb.txt:4: image ") && e.ends_with("rgb/missing.png does not exist"),
        "{e}"
    );
    let e = tum_error(|d| edit_line(&d.join("rgb.txt"), 4, "1305031102.050000 rgb"));
    assert_eq!(e, "rgb.txt:4: image rgb is a folder, not an image");
    // Two lines at one stamp (the test's stamps start at T0 on line 3 of rgb.txt).
    let e = tum_error(|d| edit_line(&d.join("rgb.txt"), 4, &format!("{T0:.6} rgb/1.png")));
    assert_eq!(
        e,
        "rgb.txt:4: the same timestamp as line 3: each line needs a stamp of its own"
    );
    let e = tum_error(|d| edit_line(&d.join("depth.txt"), 1, "12:00 depth/0.png"));
    assert_eq!(
        e,
        "depth.txt:1: invalid timestamp \"12:00\" (expected seconds like 1305031102.175304)"
    );
    let e = tum_error(|d| write_color(&d.join("rgb/2.png"), 4, 6, 1));
    assert_eq!(
        e,
        "rgb/2.png: image is 4x6, but the sequence's images are 8x6"
    );
    let e = tum_error(|d| {
        image::GrayImage::new(8, 6)
            .save(d.join("depth/1.png"))
            .unwrap()
    });
    assert_eq!(
        e,
        "depth/1.png: a depth image must be a 16-bit single-channel PNG, found 1 channel(s) of 8 bits"
    );
    let e = tum_error(|d| std::fs::write(d.join("rgb/0.png"), b"not an image").unwrap());
    assert!(e.starts_with("rgb/0.png: not an image"), "{e}");
    // A file whose header is whole but whose data is cut short: refused at import, not
    // stored to fail the replay at its frame.
    let cut = |path: std::path::PathBuf| {
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 20]).unwrap();
    };
    let e = tum_error(|d| cut(d.join("rgb/1.png")));
    assert_eq!(e, "rgb/1.png: cannot decode Png: unexpected end of file");
    let e = tum_error(|d| cut(d.join("depth/1.png")));
    assert_eq!(e, "depth/1.png: cannot decode Png: unexpected end of file");
}

fn write_redwood(dir: &Path, frames: usize, trajectory: &str) {
    std::fs::create_dir_all(dir.join("color")).unwrap();
    std::fs::create_dir_all(dir.join("depth")).unwrap();
    for i in 0..frames {
        write_color(&dir.join(format!("color/{i:05}.jpg")), 8, 6, 50);
        write_depth(&dir.join(format!("depth/{i:05}.png")), 8, 6, 1500);
    }
    std::fs::write(dir.join("trajectory.log"), trajectory).unwrap();
}

/// The error of importing a two-frame Redwood directory with `trajectory`, after
/// `edit`, with the directory prefix removed from paths.
fn redwood_error(trajectory: &str, edit: impl Fn(&Path)) -> String {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rw");
    write_redwood(&dir, 2, trajectory);
    edit(&dir);
    let out = tmp.path().join("r.relume");
    let e = redwood::import(&dir, &out, &RedwoodOptions::default(), &mut |_, _| {}).unwrap_err();
    e.to_string().replace(&format!("{}/", dir.display()), "")
}

const IDENTITY_RECORD: &str = "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";

#[test]
fn redwood_errors_name_file_and_line() {
    let cases = [
        (
            format!("0 0 1\n{IDENTITY_RECORD}1 1 2\n1 0 0 0.5\n0 1 0\n0 0 1 0\n0 0 0 1\n"),
            "trajectory.log:8: matrix row 2 must hold four finite numbers, found \"0 1 0\"",
        ),
        (
            format!("0 0 1\n{IDENTITY_RECORD}1 1 2\n1 0 0 0\n"),
            "trajectory.log:6: incomplete record: 7 lines are not a multiple of 5 (a line of three integers, then four matrix rows)",
        ),
        (
            format!("0 0 x\n{IDENTITY_RECORD}"),
            "trajectory.log:1: expected three integers starting a pose record, found \"0 0 x\"",
        ),
        (
            format!("0 0 1\n{IDENTITY_RECORD}0 0 1\n{IDENTITY_RECORD}"),
            "trajectory.log:6: record 1 is for frame 0: records must list frames 0, 1, 2, ... in order, one each",
        ),
        (
            "0 0 1\n2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n".to_string(),
            "trajectory.log:2: the matrix is not a rigid transform (rotation and translation, last row 0 0 0 1)",
        ),
    ];
    for (trajectory, expected) in cases {
        assert_eq!(redwood_error(&trajectory, |_| {}), expected);
    }
    // Names without numbers pair by position: the counts must agree.
    let e = redwood_error(IDENTITY_RECORD, |dir| {
        std::fs::rename(dir.join("color/00000.jpg"), dir.join("color/first.jpg")).unwrap();
        std::fs::remove_file(dir.join("depth/00001.png")).unwrap();
    });
    assert!(
        e.ends_with("/rw: color holds 2 images but depth holds 1: color and depth must pair up"),
        "{e}"
    );
    // A depth folder without PNGs (found by the redwood fuzz target: numbered color
    // beside an empty depth folder indexed an empty list, a panic).
    let e = redwood_error(IDENTITY_RECORD, |dir| {
        for i in 0..2 {
            std::fs::remove_file(dir.join(format!("depth/{i:05}.png"))).unwrap();
        }
    });
    assert_eq!(e, "depth: holds no PNG images");
    // Two files of one number in a folder: which is frame 1 is not known.
    let e = redwood_error(IDENTITY_RECORD, |dir| {
        std::fs::copy(dir.join("depth/00001.png"), dir.join("depth/1.png")).unwrap();
    });
    assert_eq!(
        e,
        "depth: depth/00001.png and depth/1.png carry the same frame number 1: keep one"
    );
    let e = redwood_error(IDENTITY_RECORD, |dir| std::fs::remove_dir_all(dir).unwrap());
    assert!(e.ends_with("/rw: no such directory"), "{e}");
    // Rates whose stamps k / fps would collapse to one nanosecond or overflow.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rw");
    write_redwood(&dir, 2, IDENTITY_RECORD);
    for fps in [1e10, 1e-12, 0.0, f64::NAN] {
        let options = RedwoodOptions {
            fps,
            ..RedwoodOptions::default()
        };
        let e = redwood::import(&dir, &tmp.path().join("r.relume"), &options, &mut |_, _| {})
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{}: --fps must be a number from 0.001 to 1e6 (stamps are k / fps in nanoseconds), got {fps}",
                dir.display()
            )
        );
    }
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("tum");
    let e = tum::import(
        &missing,
        &tmp.path().join("t.relume"),
        &ImportOptions::default(),
        &mut |_, _| {},
    )
    .unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("{}: no such directory", missing.display())
    );
}

#[test]
fn redwood_reads_livingroom1_with_every_pose() {
    let data = common::data_dir().join("livingroom1");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("lr.relume");
    let summary = redwood::import(&data, &out, &RedwoodOptions::default(), &mut |_, _| {}).unwrap();
    assert_eq!(
        (summary.color, summary.depth, summary.poses),
        (211, 211, 211)
    );
    let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
    assert_eq!(
        (replay.stats.frames, replay.stats.frames_with_pose),
        (211, 211)
    );
    assert!((replay.duration_s() - 210.0 / 30.0).abs() < 1e-6);

    // Frame 100's pose is the trajectory's 101st matrix.
    let text = std::fs::read_to_string(data.join("trajectory.log")).unwrap();
    let rows: Vec<f64> = text
        .lines()
        .skip(100 * 5 + 1)
        .take(4)
        .flat_map(|l| {
            l.split_whitespace()
                .map(|v| v.parse::<f64>().unwrap())
                .collect::<Vec<_>>()
        })
        .collect();
    let expected = DMat4::from_cols_slice(&rows).transpose();
    let f = replay.read_frame(100).unwrap();
    let got = f.pose.unwrap().matrix();
    assert!(
        got.abs_diff_eq(expected, 1e-6),
        "{got:?} vs {expected:?} (the file has 8 decimals)"
    );
    assert_eq!(
        replay.read_frame(0).unwrap().pose.unwrap().matrix(),
        DMat4::IDENTITY
    );

    let color = codec::decode_color(&f.color.image).unwrap();
    let depth = codec::decode_depth(
        &f.depth.unwrap().image,
        replay.recording.header().depth_unit_m,
    )
    .unwrap();
    assert_eq!(
        (color.width, color.height, depth.width, depth.height),
        (640, 480, 640, 480)
    );
    let valid: Vec<f32> = depth.data.iter().copied().filter(|&z| z > 0.0).collect();
    let mean = valid.iter().sum::<f32>() / valid.len() as f32;
    assert!(
        valid.len() > 640 * 480 / 2 && (0.5..6.0).contains(&mean),
        "{} valid, mean {mean} m",
        valid.len()
    );
}

#[test]
fn raw_storage_decodes_to_the_same_pixels_as_compressed() {
    use relume::recording::ImageEncoding;
    use relume::recording::importers::StoreMode;
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rw");
    let trajectory: String = (0..3)
        .map(|i| format!("{i} {i} {}\n{IDENTITY_RECORD}", i + 1))
        .collect();
    write_redwood(&dir, 3, &trajectory);
    let mut frames = Vec::new();
    for store in [StoreMode::Compressed, StoreMode::Raw] {
        let out = tmp.path().join(format!("{store:?}.relume"));
        let mut options = RedwoodOptions::default();
        options.common.store = store;
        redwood::import(&dir, &out, &options, &mut |_, _| {}).unwrap();
        let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
        let f = replay.read_frame(2).unwrap();
        let depth = f.depth.unwrap().image;
        let expected = if store == StoreMode::Raw {
            (ImageEncoding::RawU8, ImageEncoding::RawU16)
        } else {
            (ImageEncoding::Jpeg, ImageEncoding::Png)
        };
        assert_eq!((f.color.image.encoding, depth.encoding), expected);
        frames.push((
            codec::decode_color(&f.color.image).unwrap(),
            codec::decode_depth(&depth, 0.001).unwrap(),
        ));
    }
    assert_eq!(frames[0], frames[1]);
}

#[test]
fn a_gap_in_redwood_numbering_is_a_warning_naming_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rw");
    let trajectory: String = (0..3)
        .map(|k| format!("{k} {k} {}\n{IDENTITY_RECORD}", k + 1))
        .collect();
    write_redwood(&dir, 3, &trajectory);
    let out = tmp.path().join("r.relume");
    let summary = redwood::import(&dir, &out, &RedwoodOptions::default(), &mut |_, _| {}).unwrap();
    assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    for (from, to) in [
        ("color/00002.jpg", "color/00005.jpg"),
        ("depth/00002.png", "depth/00005.png"),
    ] {
        std::fs::rename(dir.join(from), dir.join(to)).unwrap();
    }
    let summary = redwood::import(&dir, &out, &RedwoodOptions::default(), &mut |_, _| {}).unwrap();
    assert_eq!(
        summary.warnings.len(),
        2,
        "color and depth: {:?}",
        summary.warnings
    );
    let color = summary.warnings[0].replace(&format!("{}/", dir.display()), "");
    assert!(
        color.starts_with(
            "color: the file numbers jump from 1 to 5 (3 number(s) missing in all): frames are \
             stamped by position"
        ),
        "{color}"
    );
}

/// Frame numbers without leading zeros (`0.jpg` ... `11.jpg`) order by value, not as
/// strings (0, 1, 10, 11, 2, ...), and each frame gets the pose of its number.
#[test]
fn redwood_orders_frames_by_number_and_pairs_color_and_depth_by_number() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rw");
    std::fs::create_dir_all(dir.join("color")).unwrap();
    std::fs::create_dir_all(dir.join("depth")).unwrap();
    // Color 0..=11, depth 1..=12: frames 1..=11 pair; color 0 and depth 12 are alone.
    // Each image's value is its number, so the order can be read back.
    for i in 0..12u16 {
        write_color(&dir.join(format!("color/{i}.jpg")), 8, 6, 10 * i as u8);
        write_depth(
            &dir.join(format!("depth/{}.png", i + 1)),
            8,
            6,
            1000 + i + 1,
        );
    }
    let trajectory: String = (0..11)
        .map(|k| format!("{k} {k} {}\n1 0 0 {k}\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", k + 1))
        .collect();
    std::fs::write(dir.join("trajectory.log"), trajectory).unwrap();
    let out = tmp.path().join("r.relume");
    let summary = redwood::import(&dir, &out, &RedwoodOptions::default(), &mut |_, _| {}).unwrap();
    assert_eq!((summary.color, summary.depth, summary.poses), (11, 11, 11));
    let warnings: Vec<String> = summary
        .warnings
        .iter()
        .map(|w| w.replace(&format!("{}/", dir.display()), ""))
        .collect();
    assert_eq!(
        warnings,
        [
            "color and depth pair by the numbers in their names: left out 1 file(s) with no \
             partner in depth (the first: color/0.jpg); 1 file(s) with no partner in color \
             (the first: depth/12.png)"
        ]
    );
    let replay = Replay::open(&out, ReplayOptions::default()).unwrap();
    let unit = replay.recording.header().depth_unit_m;
    let frames: Vec<(f32, u8, f64)> = (0..11)
        .map(|k| {
            let f = replay.read_frame(k).unwrap();
            let depth = codec::decode_depth(&f.depth.unwrap().image, unit).unwrap();
            let color = codec::decode_color(&f.color.image).unwrap();
            (
                depth.data[0],
                color.data[0][0],
                f.pose.unwrap().matrix().w_axis.x,
            )
        })
        .collect();
    for (k, &(depth, color, x)) in frames.iter().enumerate() {
        // Frame k is number k + 1 in both folders, with the k-th pose of the file.
        assert!(
            (depth - (1001 + k) as f32 / 1000.0).abs() < 1e-6,
            "frame {k}: {depth}"
        );
        assert!(
            (color as i32 - 10 * (k as i32 + 1)).abs() <= 2,
            "frame {k}: {color}"
        );
        assert_eq!(x, k as f64, "frame {k}");
    }
}

#[test]
fn an_import_where_nothing_associates_is_an_error_naming_the_offsets() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tum");
    write_tum(&dir);
    // Every depth stamp 2 s after its color image: nothing within 20 ms.
    let mut depth = String::new();
    for i in 0..5u32 {
        depth.push_str(&format!(
            "{:.6} depth/{i}.png\n",
            T0 + i as f64 / 30.0 + 2.0
        ));
    }
    std::fs::write(dir.join("depth.txt"), depth).unwrap();
    let o = common::run_in(
        tmp.path(),
        &["import", "tum", dir.to_str().unwrap(), "-o", "t.relume"],
    );
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        common::stderr(&o),
        "error: no frames: none of the 5 color images has one of the 5 depth images within 20 \
         ms; from each color image the nearest depth image is +1.867 s to +2.000 s away \
         (median +1.933 s, positive: depth later); if the streams' clocks differ by a \
         constant, fix the stamps in the dataset's lists; nothing was written\n"
    );
    assert!(
        !tmp.path().join("t.relume").exists(),
        "no 0-frame recording left"
    );
}

#[test]
fn given_intrinsics_are_for_the_images_own_size_and_a_rescaled_preset_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tum");
    write_tum(&dir);
    let import = |intrinsics: &str| {
        let o = common::run_in(
            tmp.path(),
            &[
                "import",
                "tum",
                dir.to_str().unwrap(),
                "-o",
                "t.relume",
                "--intrinsics",
                intrinsics,
            ],
        );
        let o = common::ok(o);
        let replay = Replay::open(&tmp.path().join("t.relume"), ReplayOptions::default()).unwrap();
        (common::stderr(&o), replay.recording.header().clone())
    };
    // The test's images are 8x6.
    let (said, header) = import("5,6,4,3");
    let k = header.color_intrinsics;
    assert_eq!(
        (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
        (8, 6, 5.0, 6.0, 4.0, 3.0)
    );
    assert!(!said.contains("note:"), "{said}");
    let (said, header) = import("tum-fr1");
    let k = header.color_intrinsics;
    assert_eq!((k.width, k.fx), (8, 517.3 * 8.0 / 640.0));
    assert!(
        said.contains(
            "note: the intrinsics preset `tum-fr1` is for 640x480 images; the color images \
             are 8x6, so it is rescaled to fx,fy,cx,cy = "
        ),
        "{said}"
    );
    assert_eq!(
        said.matches("note:").count(),
        1,
        "one note for one size: {said}"
    );
}

#[test]
fn poses_are_not_interpolated_across_a_long_gap_and_the_frames_are_counted() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tum");
    write_tum(&dir);
    // 100 Hz from -50 ms to 0, then a 400 ms hole, then 400 to 500 ms: frames 1, 2
    // and 4 (33, 67, 133 ms; frame 3 has no depth) fall in the hole.
    let mut gt = String::new();
    for k in (-5..=0).chain(40..=50) {
        gt.push_str(&groundtruth_line(k as f64 * 0.01));
    }
    std::fs::write(dir.join("groundtruth.txt"), gt).unwrap();
    let d = tmp.path();
    common::ok(common::run_in(
        d,
        &["import", "tum", dir.to_str().unwrap(), "-o", "t.relume"],
    ));
    let inspect = |extra: &[&str]| {
        let mut args = vec!["inspect", "t.relume", "--json"];
        args.extend(extra);
        let o = common::ok(common::run_in(d, &args));
        serde_json::from_str::<serde_json::Value>(&common::stdout(&o)).unwrap()
    };
    let doc = inspect(&[]);
    assert_eq!(doc["frames"], 4);
    assert_eq!(doc["frames_with_pose"], 1);
    assert_eq!(doc["association"]["frames_in_pose_gaps"], 3);
    assert_eq!(doc["association"]["max_pose_gap_ns"], 50_000_000);
    let text = common::stdout(&common::ok(common::run_in(d, &["inspect", "t.relume"])));
    assert!(
        text.contains("pose gaps 3 frames lie in gaps of the pose stream longer than 50 ms"),
        "{text}"
    );
    // A limit above the hole bridges it, as before.
    let doc = inspect(&["--max-pose-gap", "500"]);
    assert_eq!(doc["frames_with_pose"], 4);
    assert_eq!(doc["association"]["frames_in_pose_gaps"], 0);
    // A replay says so before it starts.
    let pipeline = common::pipeline("geometry.toml");
    let o = common::run_in(
        d,
        &[
            "replay", "t.relume", "-p", &pipeline, "--frames", "0", "--out", "o",
        ],
    );
    assert!(
        common::stderr(&o).contains(
            "warning: t.relume: 3 of 4 frames lie in gaps of the pose stream longer than 50 ms \
             and have no pose"
        ),
        "{}",
        common::stderr(&o)
    );
}
