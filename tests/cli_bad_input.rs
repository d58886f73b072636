//! The command line given bad input: damaged or missing files, impossible options,
//! outputs it cannot write, and interruptions. Each error names its file, frame or line
//! once, exits with the right status, and leaves no half-written file behind.

mod common;

use common::{ok, run_in, small_recording, stderr, stdout};
use relume::recording::format::{FRAME_HEADER_LEN, IndexEntry};
use relume::recording::{Recording, StreamKind};
use std::path::Path;

#[test]
fn a_failing_stage_exits_non_zero_naming_stage_and_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 8);
    let pipeline = "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\n[[stage]]\nname = \"fail\"\nkind = \"debug.fail\"\nparams = { frame = 5 }\n[[stage]]\nkind = \"write\"\nparams = { products = [\"depth\"] }\n";
    std::fs::write(d.join("p.toml"), pipeline).unwrap();
    let o = run_in(
        d,
        &[
            "replay",
            "small.relume",
            "--pipeline",
            "p.toml",
            "--out",
            "out",
        ],
    );
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(err.contains("error: replay of small.relume stopped: stage `fail` (debug.fail) failed at frame 5: debug.fail was asked to fail at frame 5"), "{err}");
    let written = common::file_names(&d.join("out/depth"));
    assert_eq!(
        written,
        [
            "000000.png",
            "000001.png",
            "000002.png",
            "000003.png",
            "000004.png"
        ],
        "complete outputs before the failure stay, nothing partial"
    );
}

/// The `nth` record of `kind` in the recording at `path`: its number and index entry.
fn nth_record(path: &Path, kind: StreamKind, nth: usize) -> (usize, IndexEntry) {
    let rec = Recording::open(path).unwrap();
    rec.index()
        .iter()
        .enumerate()
        .filter(|(_, e)| e.kind == kind)
        .nth(nth)
        .map(|(i, e)| (i, *e))
        .unwrap()
}

/// Flips one byte in the middle of the payload of the `nth` record of `kind`.
fn corrupt_record(path: &Path, kind: StreamKind, nth: usize) -> (usize, u64) {
    let (record, entry) = nth_record(path, kind, nth);
    let mut bytes = std::fs::read(path).unwrap();
    bytes[(entry.offset + FRAME_HEADER_LEN + entry.len as u64 / 2) as usize] ^= 0x40;
    std::fs::write(path, bytes).unwrap();
    (record, entry.offset)
}

/// `relume replay small.relume --hash --skip-corrupt` in `d`, which must succeed: the
/// frames it replayed (from the hash lines) and its stderr.
fn replay_skipping_corrupt(d: &Path) -> (Vec<String>, String) {
    let o = ok(run_in(
        d,
        &[
            "replay",
            "small.relume",
            "--hash",
            "--out",
            "o",
            "--skip-corrupt",
        ],
    ));
    let frames = stdout(&o).lines().map(|l| l[..6].to_string()).collect();
    (frames, stderr(&o))
}

#[test]
fn a_corrupt_record_stops_replay_unless_skipped() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = small_recording(d, 6);
    let (record, offset) = corrupt_record(&path, StreamKind::Color, 2);
    let o = run_in(d, &["replay", "small.relume", "--hash", "--out", "o"]);
    assert_eq!(o.status.code(), Some(1));
    let expected = format!(
        "cannot read frame 2: small.relume: record {record} (color) at byte {offset} is corrupt: checksum mismatch"
    );
    assert!(stderr(&o).contains(&expected), "{}", stderr(&o));
    assert_eq!(stdout(&o).lines().count(), 2, "frames 0 and 1 complete");

    let (frames, errors) = replay_skipping_corrupt(d);
    assert_eq!(frames, ["000000", "000001", "000003", "000004", "000005"]);
    assert!(errors.contains("1 corrupt frame(s) skipped"), "{errors}");

    let o = run_in(d, &["inspect", "small.relume", "--verify"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stdout(&o).contains("1 corrupt"), "{}", stdout(&o));
    let o = run_in(d, &["inspect", "small.relume", "--verify", "--json"]);
    assert_eq!(o.status.code(), Some(1));
    let doc: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let streams = doc["streams"].as_array().unwrap();
    let records: u64 = streams.iter().map(|s| s["records"].as_u64().unwrap()).sum();
    assert_eq!(doc["records_verified"], records);
    assert_eq!(doc["corrupt_records"].as_array().unwrap().len(), 1);
}

/// An image whose bytes are damaged but whose checksum was made to fit: `--verify`
/// counts it, and `--skip-corrupt` skips its frame rather than stopping in `decode`.
#[test]
fn an_image_that_does_not_decode_is_skipped_like_a_corrupt_record() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = small_recording(d, 4);
    let (record, entry) = nth_record(&path, StreamKind::Depth, 1);
    let mut bytes = std::fs::read(&path).unwrap();
    let start = (entry.offset + FRAME_HEADER_LEN) as usize;
    let end = start + entry.len as usize;
    // The PNG signature sits near the start of the image bytes in the payload.
    let png = start
        + bytes[start..end]
            .windows(4)
            .position(|w| w == b"\x89PNG")
            .unwrap();
    bytes[png + 1] ^= 0xFF;
    let crc = crc32fast::hash(&bytes[entry.offset as usize + 8..end]);
    bytes[entry.offset as usize + 4..entry.offset as usize + 8].copy_from_slice(&crc.to_le_bytes());
    std::fs::write(&path, bytes).unwrap();

    let o = run_in(d, &["replay", "small.relume", "--hash", "--out", "o"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("stage `decode` (decode) failed at frame 1"),
        "{}",
        stderr(&o)
    );
    let (frames, errors) = replay_skipping_corrupt(d);
    assert_eq!(frames, ["000000", "000002", "000003"]);
    let expected = format!(
        "skipped corrupt frame 1: small.relume: record {record} (depth) at byte {} cannot be \
         decoded: cannot decode its image: ",
        entry.offset
    );
    assert!(errors.contains(&expected), "{errors}");
}

#[test]
fn a_truncated_recording_replays_its_complete_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = small_recording(d, 6);
    let rec = Recording::open(&path).unwrap();
    // Cut inside frame 4's color record: frames 0-3 stay complete.
    let cut = rec
        .index()
        .iter()
        .filter(|e| e.kind == StreamKind::Color)
        .nth(4)
        .unwrap()
        .offset
        + 30;
    drop(rec);
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..cut as usize]).unwrap();
    let o = ok(run_in(
        d,
        &["replay", "small.relume", "--hash", "--out", "o"],
    ));
    assert_eq!(stdout(&o).lines().count(), 4);
    let err = stderr(&o);
    assert!(
        err.contains(&format!("warning: small.relume: truncated at byte {cut}")),
        "{err}"
    );
    let inspect = stdout(&ok(run_in(d, &["inspect", "small.relume"])));
    assert!(inspect.contains("DAMAGED"), "{inspect}");
}

#[test]
fn bad_files_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    std::fs::write(d.join("bad.relume"), b"GIF89a not a recording at all").unwrap();
    let o = run_in(d, &["inspect", "bad.relume"]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        stderr(&o),
        "error: bad.relume: not a relume recording (the file does not start with the relume magic bytes)\n"
    );
    let o = run_in(d, &["replay", "missing.relume"]);
    assert_eq!(o.status.code(), Some(1));
    // The cause once, not repeated by the error's source chain.
    let cause = std::fs::File::open(d.join("missing.relume")).unwrap_err();
    assert_eq!(stderr(&o), format!("error: missing.relume: {cause}\n"));
}

#[test]
fn an_unwritable_output_folder_is_named_with_its_cause_once() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 1);
    std::fs::write(d.join("a_file"), b"").unwrap();
    let pipeline = "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"write\"\nparams = { products = [\"depth\"] }\n";
    std::fs::write(d.join("p.toml"), pipeline).unwrap();
    let o = run_in(
        d,
        &[
            "replay",
            "small.relume",
            "-p",
            "p.toml",
            "--out",
            "a_file/out",
        ],
    );
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    let line = err
        .lines()
        .find(|l| l.starts_with("error: "))
        .unwrap_or_default();
    let cause = std::fs::create_dir_all(d.join("a_file/out/depth")).unwrap_err();
    assert_eq!(
        line,
        format!(
            "error: replay of small.relume stopped: p.toml:3: stage `write` could not be set up: a_file/out/depth: {cause}"
        ),
        "{err}"
    );
}

#[test]
fn the_built_in_recording_needs_a_folder_for_it() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("recordings"), b"").unwrap();
    let o = run_in(tmp.path(), &["replay", "--frames", "0..1"]);
    assert_eq!(o.status.code(), Some(1));
    let cause = std::fs::create_dir_all(tmp.path().join("recordings")).unwrap_err();
    assert_eq!(
        stderr(&o),
        format!("error: cannot create the folder recordings: {cause}\n")
    );
}

#[test]
fn a_closed_or_full_standard_output_ends_the_command_without_a_panic() {
    // A reader that went away (`relume stages | head -1`): quietly, status 0.
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let o = common::relume()
        .arg("stages")
        .stdout(writer)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stderr(&o), "");
    // The same for hash lines: the run stops, and nothing is reported as an error.
    let tmp = tempfile::tempdir().unwrap();
    small_recording(tmp.path(), 3);
    std::fs::write(tmp.path().join("p.toml"), "[[stage]]\nkind = \"decode\"\n").unwrap();
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let o = common::relume()
        .args(["replay", "small.relume", "--hash", "-p", "p.toml"])
        .current_dir(tmp.path())
        .stdout(writer)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stderr(&o).contains("error"), "{}", stderr(&o));
    // A full disk: an error that says so, status 1.
    #[cfg(target_os = "linux")]
    {
        let full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let o = common::relume()
            .arg("stages")
            .stdout(full)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(1));
        assert_eq!(
            stderr(&o),
            "error: cannot write to standard output: No space left on device (os error 28)\n"
        );
    }
}

#[test]
fn verify_decodes_images_and_fails_on_damage() {
    use relume::recording::{
        ColorRecord, DepthRecord, EncodedImage, Header, ImageEncoding, Intrinsics, Record,
        RecordingWriter,
    };
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let intrinsics = Intrinsics {
        width: 4,
        height: 3,
        fx: 4.0,
        fy: 4.0,
        cx: 1.5,
        cy: 1.0,
    };
    let mut w =
        RecordingWriter::create(&d.join("x.relume"), &Header::new("x", intrinsics, 0.001)).unwrap();
    // A PNG signature and nothing else: the record's checksum is right, its image is not.
    let color = EncodedImage {
        encoding: ImageEncoding::Png,
        width: 4,
        height: 3,
        channels: 3,
        bytes: b"\x89PNG\r\n\x1a\n".to_vec(),
    };
    let depth = EncodedImage {
        encoding: ImageEncoding::RawU16,
        width: 4,
        height: 3,
        channels: 1,
        bytes: vec![0x10; 24],
    };
    for r in [
        Record::Color(ColorRecord {
            stamp_ns: 0,
            image: color,
        }),
        Record::Depth(DepthRecord {
            stamp_ns: 0,
            image: depth,
        }),
    ] {
        w.write(&r).unwrap();
    }
    w.finish().unwrap();
    let o = run_in(d, &["inspect", "x.relume", "--verify"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("  verified  2 records, 1 corrupt\n"), "{out}");
    assert!(
        out.contains("\n    x.relume: record 0 (color): cannot decode its image: "),
        "{out}"
    );
    // A damaged file (its index cut off) fails the check too; without --verify,
    // inspect describes what it can and succeeds.
    let bytes = std::fs::read(d.join("x.relume")).unwrap();
    std::fs::write(d.join("cut.relume"), &bytes[..bytes.len() - 30]).unwrap();
    let o = run_in(d, &["inspect", "cut.relume", "--verify"]);
    assert_eq!(o.status.code(), Some(1), "{}", stdout(&o));
    assert!(
        stdout(&o).contains("  DAMAGED   cut.relume: "),
        "{}",
        stdout(&o)
    );
    ok(run_in(d, &["inspect", "cut.relume"]));
}

#[test]
fn import_warns_of_frames_without_a_pose() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let rw = d.join("rw");
    std::fs::create_dir_all(rw.join("color")).unwrap();
    std::fs::create_dir_all(rw.join("depth")).unwrap();
    for i in 0..2 {
        image::RgbImage::from_pixel(8, 6, image::Rgb([90, 80, 70]))
            .save(rw.join(format!("color/{i:05}.png")))
            .unwrap();
        image::ImageBuffer::<image::Luma<u16>, _>::from_pixel(8, 6, image::Luma([1500]))
            .save(rw.join(format!("depth/{i:05}.png")))
            .unwrap();
    }
    // One pose for two frames.
    std::fs::write(
        rw.join("trajectory.log"),
        "0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n",
    )
    .unwrap();
    let o = ok(run_in(d, &["import", "redwood", "rw", "-o", "r.relume"]));
    assert_eq!(
        stderr(&o),
        "warning: r.relume: only 1 of 2 frames have a camera pose: pipelines that read \
         `pose` stop at the first frame without one\n"
    );
    std::fs::remove_file(rw.join("trajectory.log")).unwrap();
    let o = ok(run_in(d, &["import", "redwood", "rw", "-o", "r.relume"]));
    assert_eq!(
        stderr(&o),
        "warning: r.relume: no camera poses: pipelines that read `pose` (the default one \
         does) will not run\n"
    );
}

#[test]
fn a_run_with_every_frame_skipped_as_corrupt_fails() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = small_recording(d, 2);
    for nth in 0..2 {
        corrupt_record(&path, StreamKind::Color, nth);
    }
    let expected = "error: small.relume: all 2 frames in the range are corrupt and were \
                    skipped: nothing was replayed\n";
    for args in [
        &["replay", "small.relume", "--skip-corrupt", "-p", "p.toml"][..],
        &[
            "bench",
            "small.relume",
            "--skip-corrupt",
            "-p",
            "p.toml",
            "--repeat",
            "1",
        ],
        &["eval", "small.relume", "--skip-corrupt", "-p", "p.toml"],
    ] {
        std::fs::write(
            d.join("p.toml"),
            "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\n[[stage]]\nkind = \"normals.cross\"\n",
        )
        .unwrap();
        let o = run_in(d, args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        let err = stderr(&o);
        assert!(err.ends_with(expected), "{args:?}: {err}");
    }
}

#[test]
fn output_options_that_cannot_work_fail_before_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 2);
    std::fs::create_dir(d.join("folder")).unwrap();
    let cases: [(&[&str], &str); 9] = [
        (
            &["--timings", "/dev/null"],
            "error: --timings /dev/null: not a regular file (outputs are written beside \
             their target and renamed over it, which would replace it)\n",
        ),
        (
            &["--trace", "no/t.json"],
            "error: --trace no/t.json: the folder no does not exist\n",
        ),
        (
            &["--export-cloud", "folder"],
            "error: --export-cloud folder: not a regular file (outputs are written beside \
             their target and renamed over it, which would replace it)\n",
        ),
        (
            &["--save", "color,color"],
            "error: --save names \"color\" twice\n",
        ),
        (
            &["-p", "p.toml", "--export-cloud", "c.ply"],
            "error: --export-cloud: pipeline `p.toml` produces no environment-sample cloud (add a \
             cloud.samples stage)\n",
        ),
        (
            &["--timings", "t.txt"],
            "error: --timings t.txt: the file name must end in .csv or .json\n",
        ),
        (
            &["--trace", "t.csv"],
            "error: --trace t.csv: the file name must end in .json\n",
        ),
        (
            &["--timings", "t.json", "--trace", "t.json"],
            "error: --timings and --trace name the same file t.json\n",
        ),
        (
            &["-p", "p.toml", "--save", "nonsense"],
            "error: --save: pipeline `p.toml` makes no product `nonsense`; it makes: color, \
             depth, pose\n",
        ),
    ];
    std::fs::write(d.join("p.toml"), "[[stage]]\nkind = \"decode\"\n").unwrap();
    for (options, expected) in cases {
        let mut args = vec!["replay", "small.relume"];
        args.extend_from_slice(options);
        let o = run_in(d, &args);
        assert_eq!(o.status.code(), Some(1), "{options:?}");
        assert_eq!(stderr(&o), expected, "{options:?}");
        assert_eq!(stdout(&o), "", "{options:?}: nothing ran");
    }
    // A write stage's `dir` stays under --out, and it writes something: both are
    // checked when the pipeline loads, before anything runs.
    for dir in ["../escape", "/tmp/escape"] {
        let pipeline = format!(
            "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"write\"\nparams = {{ dir = {dir:?}, products = [\"color\"] }}\n"
        );
        std::fs::write(d.join("w.toml"), pipeline).unwrap();
        let o = run_in(d, &["replay", "small.relume", "-p", "w.toml"]);
        assert_eq!(o.status.code(), Some(1));
        let first_line = stderr(&o).lines().next().unwrap_or_default().to_string();
        assert_eq!(
            first_line,
            format!(
                "error: w.toml:5:18: dir = {dir:?} must be a folder under the output directory \
                 (--out): no absolute path, no `..`"
            )
        );
        assert_eq!(stdout(&o), "", "nothing ran");
    }
    for list in ["products = []", "formats = []"] {
        let pipeline = format!(
            "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"write\"\nparams = {{ {list} }}\n"
        );
        std::fs::write(d.join("w.toml"), pipeline).unwrap();
        let o = run_in(d, &["validate", "w.toml"]);
        assert_eq!(o.status.code(), Some(1), "{list}");
        let name = list.split(' ').next().unwrap();
        assert!(
            stderr(&o).starts_with(&format!(
                "error: w.toml:5:{}: parameter `{name}` is empty: name at least one\n",
                10 + list.len()
            )),
            "{}",
            stderr(&o)
        );
    }
}

#[test]
fn a_frame_range_past_the_end_is_cut_with_a_note() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 2);
    std::fs::write(d.join("p.toml"), "[[stage]]\nkind = \"decode\"\n").unwrap();
    let run = |frames: &str| {
        let o = run_in(
            d,
            &["replay", "small.relume", "-p", "p.toml", "--frames", frames],
        );
        assert_eq!(o.status.code(), Some(0), "{frames}");
        assert!(
            stdout(&o).contains("1 frames in"),
            "{frames}: {}",
            stdout(&o)
        );
        stderr(&o)
    };
    assert_eq!(
        run("1..100"),
        "note: --frames ends at 100 but small.relume has 2 frames: replaying 1..2\n"
    );
    assert_eq!(run("1.."), "", "an open end is the last frame");
}

#[test]
fn an_absurd_thread_count_is_an_error_not_a_crash() {
    let tmp = tempfile::tempdir().unwrap();
    let o = common::relume()
        .args(["stages"])
        .current_dir(tmp.path())
        .env("RAYON_NUM_THREADS", "20000")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        stderr(&o),
        "error: RAYON_NUM_THREADS=20000 asks for more than 1024 worker threads; leave it \
         unset for one per core\n"
    );
}

#[test]
fn an_interrupted_synth_leaves_no_partial_file() {
    for signal in ["-INT", "-TERM"] {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        let child = common::relume()
            .args([
                "synth",
                "-o",
                "big.relume",
                "--frames",
                "400",
                "--size",
                "320x240",
            ])
            .current_dir(d)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // Wait until the temporary file has data, then interrupt.
        let start = std::time::Instant::now();
        let partial = d.join(format!(".big.relume.{}.partial", child.id()));
        while partial.metadata().map_or(true, |m| m.len() < 1_000_000)
            && start.elapsed().as_secs() < 30
        {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        assert!(partial.exists(), "the recording is being written");
        let status = std::process::Command::new("kill")
            .args([signal, &child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        let o = child.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(130), "{signal}: {}", stderr(&o));
        assert!(
            stderr(&o).ends_with("interrupted: the unfinished recording was removed\n"),
            "{}",
            stderr(&o)
        );
        assert_eq!(common::file_names(d), Vec::<String>::new(), "{signal}");
    }
}
