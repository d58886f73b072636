//! The command line as a user runs it: the main job, replays, hashes, benchmarks and
//! the catalog. Bad input, refusals and interruptions are in cli_bad_input.rs, damaged
//! recordings in cli_damaged.rs.

mod common;

use common::{ok, run_in, small_recording, stderr, stdout};
use std::path::Path;

fn hash_lines(dir: &Path, rec: &str, threads: Option<&str>) -> String {
    let mut cmd = common::relume();
    cmd.args(["replay", rec, "--hash", "--out", "o"])
        .current_dir(dir);
    if let Some(t) = threads {
        cmd.env("RAYON_NUM_THREADS", t);
    }
    stdout(&ok(cmd.output().unwrap()))
}

#[test]
fn hash_lines_are_identical_across_runs_and_thread_counts() {
    let tmp = tempfile::tempdir().unwrap();
    small_recording(tmp.path(), 6);
    let first = hash_lines(tmp.path(), "small.relume", None);
    let lines: Vec<&str> = first.lines().collect();
    assert_eq!(lines.len(), 6, "{first}");
    for (i, line) in lines.iter().enumerate() {
        assert!(line.starts_with(&format!("{i:06} ")), "{line}");
        for product in [
            "color=", "depth=", "normals=", "points=", "pose=", "record=", "final=",
        ] {
            assert!(line.contains(product), "{line} lacks {product}");
        }
    }
    assert_eq!(hash_lines(tmp.path(), "small.relume", None), first);
    assert_eq!(hash_lines(tmp.path(), "small.relume", Some("1")), first);
    assert_eq!(hash_lines(tmp.path(), "small.relume", Some("3")), first);
}

/// Every pipeline relume ships gives the same `--hash` lines at 1, 2 and 3 threads (on
/// a small synthetic recording; the livingroom1 pipelines' objects then stand where
/// livingroom1's floor would be). The tracked pipelines get a larger one: at 64 x 48 the
/// camera's steps over three frames are too coarse to track, and a lost frame stops
/// them.
#[test]
fn every_shipped_pipeline_hashes_the_same_at_1_2_and_3_threads() {
    let tmp = tempfile::tempdir().unwrap();
    small_recording(tmp.path(), 3);
    ok(run_in(
        tmp.path(),
        &[
            "synth",
            "-o",
            "track.relume",
            "--frames",
            "6",
            "--size",
            "160x120",
            "--seed",
            "3",
        ],
    ));
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines");
    let mut pipelines: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    pipelines.sort();
    assert!(pipelines.len() >= 18, "{pipelines:?}");
    for p in &pipelines {
        let p = p.to_str().unwrap();
        let (recording, frames) = match p.ends_with("-tracked.toml") {
            true => ("track.relume", 6),
            false => ("small.relume", 3),
        };
        let hashes = |threads| common::replay_hashes(tmp.path(), recording, p, threads);
        let one = hashes("1");
        assert_eq!(one.lines().count(), frames, "{p}: {one}");
        assert_eq!(hashes("2"), one, "{p}");
        assert_eq!(hashes("3"), one, "{p}");
    }
}

#[test]
fn livingroom1_imports_inspects_and_replays() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    common::import_livingroom1(d);
    let inspect: serde_json::Value =
        serde_json::from_str(&stdout(&ok(run_in(d, &["inspect", "lr.relume", "--json"])))).unwrap();
    assert_eq!(inspect["frames"], 211);
    assert_eq!(inspect["frames_with_pose"], 211);
    assert_eq!(inspect["damage"], serde_json::Value::Null);

    let geometry = concat!(env!("CARGO_MANIFEST_DIR"), "/pipelines/geometry.toml");
    let o = ok(run_in(
        d,
        &[
            "replay",
            "lr.relume",
            "-p",
            geometry,
            "--frames",
            "0..8",
            "--out",
            "out",
            "--timings",
            "t.csv",
            "--trace",
            "trace.json",
        ],
    ));
    let table = stdout(&o);
    for stage in [
        "source",
        "decode",
        "depth.to_points",
        "normals.cross",
        "write",
        "8 frames in",
    ] {
        assert!(table.contains(stage), "table lacks {stage}:\n{table}");
    }
    for n in 0..8 {
        for product in ["color", "depth", "normals"] {
            assert!(
                d.join(format!("out/{product}/{n:06}.png")).is_file(),
                "{product} of frame {n}"
            );
        }
    }
    assert!(!d.join("out/color/000008.png").exists());
    let depth = image::open(d.join("out/depth/000003.png")).unwrap();
    assert_eq!(
        (depth.width(), depth.height(), depth.color()),
        (640, 480, image::ColorType::L16)
    );
    let csv = std::fs::read_to_string(d.join("t.csv")).unwrap();
    assert_eq!(
        csv.lines().next(),
        Some("stage,kind,frame,start_ms,wait_in_ms,process_ms,wait_out_ms,program_ms")
    );
    assert_eq!(
        csv.lines().count(),
        1 + 5 * 8,
        "source + 4 stages, 8 frames each"
    );
    let trace: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("trace.json")).unwrap()).unwrap();
    let events = trace["traceEvents"].as_array().unwrap();
    assert_eq!(
        events.iter().filter(|e| e["cat"] == "process").count(),
        5 * 8
    );
}

#[test]
fn validate_and_stages_explain_pipelines() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let geometry = concat!(env!("CARGO_MANIFEST_DIR"), "/pipelines/geometry.toml");
    let o = ok(run_in(d, &["validate", geometry]));
    assert!(
        stdout(&o).contains("ok, 4 stages: decode -> depth.to_points -> normals.cross -> write"),
        "{}",
        stdout(&o)
    );
    std::fs::write(d.join("p.toml"), "[[stage]]\nkind = \"decod\"\n").unwrap();
    let o = run_in(d, &["validate", "p.toml"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).starts_with("error: p.toml:2:8: unknown stage kind `decod`"),
        "{}",
        stderr(&o)
    );
    assert!(
        stderr(&o).contains("hint: did you mean `decode`?"),
        "{}",
        stderr(&o)
    );
    let list = stdout(&ok(run_in(d, &["stages"])));
    for kind in [
        "decode",
        "depth.to_points",
        "normals.cross",
        "write",
        "debug.noop",
        "debug.sleep",
        "debug.fail",
        "max_depth_jump = 0.1",
        "occlusion_margin = 0.1  (float",
        // Ports by role, with the default product where it is named otherwise.
        "reads: depth = refined_depth, normals, pose, radiance = compensated, light_table",
    ] {
        assert!(list.contains(kind), "stages lacks {kind}");
    }
    // In JSON every default is a value of its parameter's type.
    let kinds: serde_json::Value =
        serde_json::from_str(&stdout(&ok(run_in(d, &["stages", "--json"])))).unwrap();
    let default = |kind: &str, name: &str| {
        let info = kinds.as_array().unwrap().iter().find(|k| k["kind"] == kind);
        let params = info.unwrap()["params"].as_array().unwrap();
        params.iter().find(|p| p["name"] == name).unwrap()["default"].clone()
    };
    assert_eq!(default("gbuffer.splat", "occlusion_margin"), 0.1);
    assert_eq!(default("filter.axis_aligned", "temporal"), true);
    assert_eq!(default("filter.axis_aligned", "radius"), 15);
    assert_eq!(
        default("write", "products"),
        serde_json::json!(["depth", "normals"])
    );
    assert_eq!(default("write", "dir"), "");
}

#[test]
fn bench_reports_stage_medians_as_json() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 4);
    let o = ok(run_in(
        d,
        &["bench", "small.relume", "--repeat", "2", "--json"],
    ));
    let doc: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    for stage in [
        "source",
        "decode",
        "depth.to_points",
        "sample.path",
        "filter.axis_aligned",
        "composite.differential",
        "write",
    ] {
        for key in ["median_ms", "p95_ms", "max_ms"] {
            assert!(
                doc["stages"][stage][key].as_f64().is_some_and(|v| v >= 0.0),
                "{stage}.{key} in {doc}"
            );
        }
    }
    // sample.path splits its time into paper 000 Table 2's rows; no other stage does.
    let parts = doc["stages"]["sample.path"]["parts"].as_object().unwrap();
    let names: Vec<&str> = parts.keys().map(|k| k.as_str()).collect();
    assert_eq!(names, ["differential", "material", "object", "setup"]);
    for (name, stats) in parts {
        let median = stats["median_ms"].as_f64().unwrap();
        assert!(
            median >= 0.0 && median <= stats["max_ms"].as_f64().unwrap(),
            "{name}"
        );
    }
    assert!(parts["material"]["median_ms"].as_f64().unwrap() > 0.0);
    assert!(doc["stages"]["decode"].get("parts").is_none());
    assert!(doc["fps"].as_f64().unwrap() > 0.0);
    assert_eq!(doc["repeat"], 2);
    assert!(
        !d.join("out").exists(),
        "bench writes into a scratch directory"
    );
}

/// `relume bench` of small.relume through p.toml, one run, as JSON.
const BENCH_ONCE_JSON: [&str; 7] = [
    "bench",
    "small.relume",
    "-p",
    "p.toml",
    "--repeat",
    "1",
    "--json",
];

/// `--isolated` runs one frame at a time: two stages of 20 ms each then take at least
/// 40 ms a frame together (pipelined they would overlap).
#[test]
fn bench_isolated_runs_one_frame_at_a_time() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 6);
    let pipeline = "[[stage]]\nname = \"a\"\nkind = \"debug.sleep\"\nparams = { ms = 20.0 }\n\
                    [[stage]]\nname = \"b\"\nkind = \"debug.sleep\"\nparams = { ms = 20.0 }\n";
    std::fs::write(d.join("p.toml"), pipeline).unwrap();
    let args = BENCH_ONCE_JSON;
    let o = ok(run_in(d, &[&args[..], &["--isolated"]].concat()));
    let doc: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(doc["isolated"], true);
    for stage in ["a", "b"] {
        assert!(
            doc["stages"][stage]["median_ms"].as_f64().unwrap() >= 20.0,
            "{doc}"
        );
    }
    let fps = doc["fps"].as_f64().unwrap();
    assert!(fps > 0.0 && fps < 25.0, "{fps} frames/s");
    let o = ok(run_in(d, &args));
    let doc: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(doc["isolated"], false);
    // The table says what pipelined stage times hold.
    let o = ok(run_in(d, &args[..args.len() - 1]));
    assert!(
        stdout(&o).contains("--isolated times each stage alone"),
        "{}",
        stdout(&o)
    );
}

/// `--isolated` measures each stage's allocation high-water mark: decode's holds at
/// least the 64 x 48 color (3 bytes a pixel) and depth (4) images it makes, and a
/// sleeping stage's only what other threads allocate meanwhile (the progress display:
/// a few hundred bytes); a pipelined bench, where stages allocate at once, gives none.
/// Both say the process's peak resident memory.
#[test]
fn bench_isolated_reports_each_stages_allocation_peak() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 3);
    let pipeline = "[[stage]]\nkind = \"decode\"\n\
                    [[stage]]\nkind = \"debug.sleep\"\nparams = { ms = 1.0 }\n";
    std::fs::write(d.join("p.toml"), pipeline).unwrap();
    let bench = |isolated: bool| {
        let mut args = BENCH_ONCE_JSON.to_vec();
        if isolated {
            args.push("--isolated");
        }
        let doc: serde_json::Value = serde_json::from_str(&stdout(&ok(run_in(d, &args)))).unwrap();
        doc
    };
    let doc = bench(true);
    let decode = doc["stages"]["decode"]["alloc_peak_mb"].as_f64().unwrap();
    assert!(
        decode >= (64 * 48 * 7) as f64 / 1e6 && decode < 1.0,
        "decode: {decode} MB"
    );
    let sleep = doc["stages"]["debug.sleep"]["alloc_peak_mb"]
        .as_f64()
        .unwrap();
    assert!(sleep < 0.005, "{doc}");
    let resident = doc["peak_resident_mb"].as_f64().unwrap();
    assert!(resident > 1.0 && resident < 4000.0, "{resident} MB");
    let doc = bench(false);
    assert_eq!(
        doc["stages"]["decode"]["alloc_peak_mb"],
        serde_json::Value::Null
    );
    assert!(doc["peak_resident_mb"].as_f64().unwrap() > 1.0);
}

/// Decodes, sleeps 40 ms and writes the color image of each frame: a run slow enough to
/// interrupt in the middle, whose progress shows in the files it writes.
const SLOW_COLOR_WRITER: &str = "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"debug.sleep\"\nparams = { ms = 40.0 }\n[[stage]]\nkind = \"write\"\nparams = { products = [\"color\"] }\n";

#[test]
fn ctrl_c_stops_after_the_frames_in_flight_and_keeps_complete_outputs() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 40);
    std::fs::write(d.join("p.toml"), SLOW_COLOR_WRITER).unwrap();
    let child = common::relume()
        .args([
            "replay",
            "small.relume",
            "--pipeline",
            "p.toml",
            "--out",
            "out",
        ])
        .current_dir(d)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until a few frames are written, then interrupt.
    let first = d.join("out/color/000003.png");
    let start = std::time::Instant::now();
    while !first.exists() && start.elapsed().as_secs() < 30 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let o = common::signal_and_wait(child, "-INT");
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(stderr(&o).contains("interrupted:"), "{}", stderr(&o));
    let written = common::file_names(&d.join("out/color"));
    assert!((4..40).contains(&written.len()), "{written:?}");
    for (i, name) in written.iter().enumerate() {
        assert_eq!(
            name,
            &format!("{i:06}.png"),
            "only complete, consecutive frames"
        );
        image::open(d.join("out/color").join(name)).expect("every output is a complete PNG");
    }
    assert!(
        stdout(&o).contains("frames in"),
        "the timing table is still printed"
    );
}

/// Which write of `path` stands there: its inode and modification time (outputs are
/// renamed over their target, so each write brings a new inode), `None` before the first.
fn version(path: &Path) -> Option<(u64, std::time::SystemTime)> {
    use std::os::unix::fs::MetadataExt;
    let meta = path.metadata().ok()?;
    Some((meta.ino(), meta.modified().ok()?))
}

#[test]
fn an_interrupted_bench_exits_130_with_the_complete_runs_only() {
    for during_warm_up in [true, false] {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        small_recording(d, 20);
        std::fs::write(d.join("p.toml"), SLOW_COLOR_WRITER).unwrap();
        // bench writes into a scratch folder under the temporary directory: watching its
        // frames tells the runs apart (each run writes them all again).
        std::fs::create_dir(d.join("tmp")).unwrap();
        let child = common::relume()
            .args([
                "bench",
                "small.relume",
                "-p",
                "p.toml",
                "--repeat",
                "3",
                "--json",
            ])
            .env("TMPDIR", d.join("tmp"))
            .current_dir(d)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let frames = d.join(format!("tmp/relume-bench-{}/color", child.id()));
        let (first, last) = (frames.join("000000.png"), frames.join("000019.png"));
        let start = std::time::Instant::now();
        let wait_for = |done: &dyn Fn() -> bool, what: &str| {
            while !done() {
                assert!(
                    start.elapsed().as_secs() < 60,
                    "no sign of {what} after a minute"
                );
                std::thread::sleep(std::time::Duration::from_millis(5));
            }
        };
        if during_warm_up {
            wait_for(&|| version(&first).is_some(), "the warm-up run");
        } else {
            // The warm-up run's last frame, then the first measured run's, then the
            // second measured run under way.
            wait_for(&|| version(&last).is_some(), "the warm-up run's end");
            let warm_up = version(&last);
            wait_for(
                &|| version(&last) != warm_up,
                "the first measured run's end",
            );
            let measured = version(&first);
            wait_for(&|| version(&first) != measured, "the second measured run");
        }
        let o = common::signal_and_wait(child, "-INT");
        assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
        if during_warm_up {
            assert_eq!(stdout(&o), "");
            assert!(
                stderr(&o).ends_with("error: interrupted before a measured run was complete\n"),
                "{}",
                stderr(&o)
            );
            continue;
        }
        let doc: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        assert_eq!(doc["interrupted"], true);
        assert_eq!(doc["frames"], 20, "only complete runs are reported");
        // The second measured run was under way when the interrupt came; if it finished
        // first, the third was.
        let runs = doc["repeat"].as_u64().unwrap();
        assert!((1..=2).contains(&runs), "{runs}");
        assert!(
            stderr(&o).ends_with(&format!(
                "interrupted: the timings cover the {runs} of 3 measured runs complete\n"
            )),
            "{}",
            stderr(&o)
        );
    }
}

#[test]
/// `relume` with no arguments is `relume replay` with no arguments (src/cli/mod.rs);
/// this runs the same job on its first frames only, as the whole 30 frames of mixed
/// reality at 640x480 take minutes in a test build.
fn the_main_job_generates_its_recording_and_writes_finished_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let o = ok(run_in(d, &["replay", "--frames", "0..2"]));
    let table = stdout(&o);
    assert!(
        table.starts_with(
            "default on recordings/default.relume (<built-in pipelines/default.toml>):"
        ),
        "{table}"
    );
    assert!(table.contains("2 frames in"), "{table}");
    for stage in [
        "sample.path",
        "filter.axis_aligned",
        "composite.differential",
    ] {
        assert!(table.contains(stage), "{table}");
    }
    assert!(
        stderr(&o).contains(
            "generating the built-in synthetic recording into recordings/default.relume \
             (first use; 30 frames at 640x480)"
        ),
        "{}",
        stderr(&o)
    );
    for (product, ext) in [
        ("final", "png"),
        ("final_hdr", "exr"),
        ("differential", "png"),
    ] {
        let path = d.join(format!("out/{product}/000001.{ext}"));
        assert!(path.is_file(), "{}", path.display());
    }
    let finished = image::open(d.join("out/final/000001.png")).unwrap();
    assert_eq!((finished.width(), finished.height()), (640, 480));
    let inspect: serde_json::Value = serde_json::from_str(&stdout(&ok(run_in(
        d,
        &["inspect", "recordings/default.relume", "--json"],
    ))))
    .unwrap();
    assert_eq!(
        (
            inspect["frames"].as_u64(),
            inspect["frames_with_pose"].as_u64(),
            inspect["frames_with_truth"].as_u64()
        ),
        (Some(30), Some(30), Some(30))
    );
    // The second run reuses the recording instead of rendering it again.
    let o = ok(run_in(d, &["replay", "--frames", "0..1"]));
    assert!(!stderr(&o).contains("generating"), "{}", stderr(&o));
    // A damaged one is rendered again, and the message says what was wrong with it.
    let path = d.join("recordings/default.relume");
    let bytes = std::fs::read(&path).unwrap();
    let cut = bytes.len() - 1000;
    std::fs::write(&path, &bytes[..cut]).unwrap();
    let o = ok(run_in(d, &["replay", "--frames", "0..1"]));
    let damaged =
        format!("(the old one is damaged: recordings/default.relume: truncated at byte {cut}:");
    assert!(stderr(&o).contains(&damaged), "{}", stderr(&o));
    assert_eq!(
        std::fs::read(&path).unwrap(),
        bytes,
        "the same recording again"
    );
}

/// `relume -h` and `relume --help` open with the same description.
#[test]
fn short_and_long_help_open_alike() {
    let tmp = tempfile::tempdir().unwrap();
    let first = |flag: &str| {
        let o = run_in(tmp.path(), &[flag]);
        assert!(o.status.success(), "{flag}");
        stdout(&o)
            .lines()
            .next()
            .unwrap_or_default()
            .trim_end_matches('.')
            .to_string()
    };
    let short = first("-h");
    assert!(
        short.starts_with("relume replays recorded RGB-D sensor logs"),
        "{short}"
    );
    assert_eq!(short, first("--help"));
}

/// `--save-format`'s help says what a depth PNG holds: it is not for viewing.
#[test]
fn save_format_help_says_depth_pngs_are_millimetres() {
    let tmp = tempfile::tempdir().unwrap();
    let o = run_in(tmp.path(), &["replay", "--help"]);
    let help = stdout(&o).split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        help.contains("depth PNGs hold 16-bit millimetres"),
        "{help}"
    );
}

#[test]
fn long_runs_without_a_terminal_say_how_far_they_are() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    // A line per frame here (every 5 s by default).
    let run = |args: &[&str]| {
        let o = common::relume()
            .args(args)
            .current_dir(d)
            .env("RELUME_PROGRESS_SECONDS", "0")
            .output()
            .unwrap();
        common::stderr(&common::ok(o))
    };
    let said = run(&[
        "synth", "-o", "s.relume", "--frames", "3", "--size", "64x48",
    ]);
    assert!(said.contains("rendering: 3/3 frames, "), "{said}");
    let pipeline = common::pipeline("geometry.toml");
    let said = run(&["replay", "s.relume", "-p", &pipeline, "--out", "o"]);
    for n in 1..=3 {
        assert!(
            said.contains(&format!("replaying: {n}/3 frames, ")),
            "{said}"
        );
    }
    assert!(said.contains("frames/s"), "{said}");
}

#[test]
fn a_killed_runs_half_written_files_go_and_an_earlier_runs_frames_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 3);
    let pipeline = common::pipeline("geometry.toml");
    let replay = |extra: &[&str]| {
        let mut args = vec![
            "replay",
            "small.relume",
            "-p",
            pipeline.as_str(),
            "--out",
            "o",
        ];
        args.extend(extra);
        stderr(&ok(run_in(d, &args)))
    };
    replay(&[]);
    let folder = d.join("o/normals");
    let frames = || common::file_names(&folder);
    assert_eq!(frames(), ["000000.png", "000001.png", "000002.png"]);
    // What a killed run leaves: a hidden temporary of a process that no longer runs.
    let stale = folder.join(".000001.png.999999999.partial");
    std::fs::write(&stale, vec![0u8; 1000]).unwrap();
    // Untouched for two hours (a live writer on another machine keeps it fresh).
    let two_hours_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(7200);
    std::fs::File::options()
        .write(true)
        .open(&stale)
        .unwrap()
        .set_modified(two_hours_ago)
        .unwrap();
    let said = replay(&["--frames", "0..2"]);
    assert!(!stale.exists(), "the half-written file is removed");
    assert!(
        said.contains("removed 1 half-written file(s) (0.0 MB) that an interrupted run left in o"),
        "{said}"
    );
    assert!(
        said.contains(
            "warning: o/normals holds 1 frame(s) of an earlier run that this run (frames 0..2) \
             does not replace, 2 to 2: they stay beside its own (--clean-out removes them first)"
        ),
        "{said}"
    );
    let said = replay(&["--frames", "0..2", "--clean-out"]);
    assert!(
        said.contains("--clean-out: removed 3 frame file(s) from o/normals"),
        "{said}"
    );
    assert_eq!(frames(), ["000000.png", "000001.png"]);
}

#[test]
fn a_synthetic_recording_too_short_for_color_compensation_says_so() {
    // Issue 36 item 14: the filter's gain fell on 10-frame recordings because their
    // camera's exposure sweeps faster than color.compensate follows.
    let tmp = tempfile::tempdir().unwrap();
    let synth = |frames: &str| {
        let args = [
            "synth", "-o", "s.relume", "--frames", frames, "--size", "32x24",
        ];
        common::stderr(&common::ok(run_in(tmp.path(), &args)))
    };
    let said = synth("10");
    assert!(
        said.contains("warning: the camera's exposure sweeps 0.5x to 2x and back over any recording: over 10 frames it changes faster than color.compensate follows"),
        "{said}"
    );
    assert!(said.contains("give --frames 15 or more"), "{said}");
    assert_eq!(synth("15"), "");
    assert_eq!(synth("1"), "", "one frame has no sweep");
}
