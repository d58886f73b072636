//! The command line given bad input: missing or wrong files, impossible options,
//! outputs it cannot write, and interruptions (damaged recordings: cli_damaged.rs). Each
//! error names its file, frame or line once, exits with the right status, and leaves no
//! half-written file behind.

mod common;

use common::{ok, run_in, small_recording, stderr, stdout};

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
    // A binary file where a pipeline (text) belongs.
    std::fs::write(d.join("p.toml"), b"RELUME\xff\xfe\x00").unwrap();
    let o = run_in(d, &["validate", "p.toml"]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        stderr(&o),
        "error: p.toml: cannot read the pipeline: is not a text file (not valid UTF-8)\n"
    );
    // A negative size reaches the size parser, not clap's flag matching.
    let o = run_in(d, &["synth", "-o", "r.relume", "--size", "-320x240"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).starts_with(
            "error: invalid value '-320x240' for '--size <SIZE>': expected WIDTHxHEIGHT \
             with positive integers, e.g. 320x240, got \"-320x240\"\n"
        ),
        "{}",
        stderr(&o)
    );
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
    // The run takes --out for itself first (a lock in it): that is where it fails.
    let cause = std::fs::create_dir_all(d.join("a_file/out")).unwrap_err();
    // Nothing ran: no empty timing table before the error.
    assert_eq!(stdout(&o), "", "{err}");
    assert_eq!(
        line,
        format!("error: cannot create a_file/out: {cause}"),
        "{err}"
    );
    assert_eq!(err.matches("Not a directory").count(), 1, "{err}");
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
fn import_warns_of_what_pipelines_will_miss() {
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
    let import = || {
        let args = [
            "import",
            "redwood",
            "rw",
            "-o",
            "r.relume",
            "--intrinsics",
            "6,6,3.5,2.5",
        ];
        ok(run_in(d, &args))
    };
    let o = import();
    assert_eq!(
        stderr(&o),
        "warning: r.relume: only 1 of 2 frames have a camera pose: pipelines that read \
         `pose` stop at the first frame without one\n"
    );
    std::fs::remove_file(rw.join("trajectory.log")).unwrap();
    let o = import();
    assert_eq!(
        stderr(&o),
        "warning: r.relume: no camera poses: pipelines that read `pose` (the default one \
         does) run only with the tracker giving it (pipelines/*-tracked.toml)\n"
    );
    // Depth images of another size than the color images.
    for i in 0..2 {
        image::ImageBuffer::<image::Luma<u16>, _>::from_pixel(4, 3, image::Luma([1500]))
            .save(rw.join(format!("depth/{i:05}.png")))
            .unwrap();
    }
    let o = import();
    assert!(
        stderr(&o).ends_with(
            "warning: r.relume: the color images are 8x6 and the depth images 4x3: stages \
             that combine them, such as cloud.samples (in the acquisition and \
             mixed-reality pipelines), stop at the first frame\n"
        ),
        "{}",
        stderr(&o)
    );
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
            "error: --export-cloud folder: is a folder: give a file name\n",
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
        "warning: --frames ends at 100 but small.relume has 2 frames: replaying 1..2\n"
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
fn synth_and_import_outputs_that_cannot_work_fail_before_starting() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    std::fs::create_dir(d.join("folder")).unwrap();
    for (out, expected) in [
        (
            "folder",
            "error: -o folder: is a folder: give a file name\n",
        ),
        (
            "new/",
            "error: -o new/: ends in `/`, which names a folder: give a file name\n",
        ),
        (
            "no/r.relume",
            "error: -o no/r.relume: the folder no does not exist\n",
        ),
    ] {
        let o = run_in(d, &["synth", "-o", out, "--frames", "1", "--size", "8x6"]);
        assert_eq!(o.status.code(), Some(1), "{out}");
        assert_eq!(stderr(&o), expected);
        let o = run_in(d, &["import", "redwood", "folder", "-o", out]);
        assert_eq!(o.status.code(), Some(1), "{out}");
        assert_eq!(stderr(&o), expected);
    }
    assert_eq!(common::file_names(d), ["folder"], "nothing was written");
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
        let o = common::signal_and_wait(child, signal);
        assert_eq!(o.status.code(), Some(130), "{signal}: {}", stderr(&o));
        assert!(
            stderr(&o).ends_with("interrupted: the unfinished output file was removed\n"),
            "{}",
            stderr(&o)
        );
        assert_eq!(common::file_names(d), Vec::<String>::new(), "{signal}");
    }
}

/// A stage that panics is reported in one clean line, with where it panicked, and
/// without Rust's raw panic output or a backtrace (the runtime caught the panic).
#[test]
fn a_stage_panic_is_one_clean_error_line() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 3);
    let pipeline = "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"debug.fail\"\nparams = { frame = 1, mode = \"panic\" }\n";
    std::fs::write(d.join("p.toml"), pipeline).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_relume"))
        .current_dir(d)
        .args(["replay", "small.relume", "-p", "p.toml", "--out", "out"])
        .env("RUST_BACKTRACE", "1")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(
        lines[0].starts_with(
            "error: replay of small.relume stopped: stage `debug.fail` (debug.fail) panicked at frame 1: debug.fail was asked to panic at frame 1 (at crates/stages/src/debug.rs:"
        ),
        "{err}"
    );
}

/// `validate` reads a light probe file as the run would: a missing or corrupt one is
/// an error naming the stage's line, not "ok".
#[test]
fn validate_reads_the_light_probe_file() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let pipeline = "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"light.envmap\"\nparams = { source = \"file\", path = \"probe.exr\" }\n";
    std::fs::write(d.join("p.toml"), pipeline).unwrap();
    let o = run_in(d, &["validate", "p.toml"]);
    assert_eq!(o.status.code(), Some(1));
    let cause = std::fs::read(d.join("probe.exr")).unwrap_err();
    assert_eq!(
        stderr(&o).trim_end(),
        format!("error: p.toml:3: stage `light.envmap` could not be set up: probe.exr: {cause}")
    );
    // Not a map: refused with what it is not.
    std::fs::write(d.join("probe.exr"), b"not an image").unwrap();
    let o = run_in(d, &["validate", "p.toml"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("probe.exr: not an environment map relume reads"),
        "{}",
        stderr(&o)
    );
}

/// The one SIGTERM a scheduler sends before SIGKILL stops a run that is still setting
/// up: sample.val's radiance transfer precomputation (here a million directions per
/// vertex, minutes of work) gives up at once, and the exit status is 130.
#[test]
fn an_interrupt_during_a_long_set_up_stops_it() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    common::ok(run_in(
        d,
        &[
            "synth", "-o", "r.relume", "--frames", "2", "--size", "64x48",
        ],
    ));
    let child = common::relume()
        .args([
            "replay",
            "r.relume",
            "-p",
            &common::pipeline("mixed-reality-val.toml"),
            "--set",
            "sample.val.transfer_samples=1000000",
            "--out",
            "out",
        ])
        .env("RELUME_CACHE", "off")
        .current_dir(d)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Loading a 2-frame recording takes well under this, even beside other tests; the
    // precomputation takes minutes.
    std::thread::sleep(std::time::Duration::from_secs(5));
    let start = std::time::Instant::now();
    let o = common::signal_and_wait(child, "-TERM");
    assert!(
        start.elapsed().as_secs() < 10,
        "took {:?} to stop",
        start.elapsed()
    );
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("interrupted while computing the objects' radiance transfer"),
        "{}",
        stderr(&o)
    );
}

/// Two runs into one --out: the second is refused at once, naming the first; the
/// lock goes with the process (here a replay stopped by SIGKILL leaves none behind).
#[test]
fn a_second_run_into_one_out_folder_is_refused_naming_the_first() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    common::ok(run_in(
        d,
        &[
            "synth", "-o", "r.relume", "--frames", "2", "--size", "64x48",
        ],
    ));
    let val = common::pipeline("mixed-reality-val.toml");
    // The first holds out/ while it sets up for minutes.
    let first = common::relume()
        .args(["replay", "r.relume", "-p", &val, "--out", "out"])
        .args(["--set", "sample.val.transfer_samples=1000000"])
        .env("RELUME_CACHE", "off")
        .current_dir(d)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_secs(3));
    let second = run_in(d, &["replay", "r.relume", "-p", &val, "--out", "out"]);
    assert_eq!(second.status.code(), Some(1));
    let e = stderr(&second);
    assert!(
        e.starts_with(&format!(
            "error: --out out is in use by another relume run (pid {}: ",
            first.id()
        )) && e.ends_with("): wait for it to finish, or give another --out\n"),
        "{e}"
    );
    let o = common::signal_and_wait(first, "-KILL");
    assert!(!o.status.success());
    // Another folder, or the same once the holder is gone, is free.
    let geometry = common::pipeline("geometry.toml");
    common::ok(run_in(
        d,
        &["replay", "r.relume", "-p", &geometry, "--out", "out"],
    ));
}

/// A NUL byte in a write stage's `dir` is refused by validate, not first at replay.
#[test]
fn a_nul_byte_in_a_write_folder_is_refused_by_validate() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    std::fs::write(
        d.join("w.toml"),
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"write\"\nparams = { dir = \"a\\u0000b\", products = [\"color\"] }\n",
    )
    .unwrap();
    let o = run_in(d, &["validate", "w.toml"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).starts_with(
            "error: w.toml:5:18: dir = \"a\\0b\" holds a NUL byte, which no folder name can\n"
        ),
        "{}",
        stderr(&o)
    );
}

/// A thread the system will not start (here: each stack reserves 1 GB, under a 3 GB
/// address-space ceiling) ends the run with an error naming the stage, or the worker
/// threads when those are refused first, not a panic.
#[test]
fn a_stage_thread_the_system_refuses_is_an_error_naming_the_stage() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    ok(run_in(
        d,
        &[
            "synth", "-o", "r.relume", "--frames", "2", "--size", "64x48",
        ],
    ));
    let o = std::process::Command::new("sh")
        .args([
            "-c",
            "ulimit -v 3000000 && exec \"$0\" replay r.relume -p \"$1\" --out out",
            env!("CARGO_BIN_EXE_relume"),
            &common::pipeline("geometry.toml"),
        ])
        .env("RUST_MIN_STACK", "1000000000")
        .current_dir(d)
        .output()
        .unwrap();
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(ends_with_a_thread_error(&e), "{e}");
}

/// Whether `stderr` ends with the thread error for some stage of the geometry pipeline or
/// the recording's reader, or for rayon's worker threads (started before them): which
/// the system refuses first depends on what it has mapped already.
fn ends_with_a_thread_error(stderr: &str) -> bool {
    let Some(line) = stderr.lines().last() else {
        return false;
    };
    if line.starts_with(
        "error: cannot start the worker threads (a higher thread or memory limit, or \
         RAYON_NUM_THREADS=1, lets them start): ",
    ) {
        return true;
    }
    ["decode", "depth.to_points", "normals.cross", "write"]
        .iter()
        .map(|stage| format!("stage `{stage}`"))
        .chain(["the recording's reader".to_string()])
        .any(|what| {
            line.starts_with(&format!(
                "error: replay of r.relume stopped: cannot start the thread of {what} \
                 (each stage runs on a thread of its own: a pipeline this large needs a higher \
                 thread or memory limit, or fewer stages): "
            ))
        })
}

/// validate checks the pipeline a replay with the same `--set` would run, and
/// `--max-pose-gap` means something only with the recording it associates.
#[test]
fn validate_takes_the_overrides_a_replay_would() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let geometry = common::pipeline("geometry.toml");
    ok(run_in(d, &["validate", &geometry]));
    let o = run_in(d, &["validate", &geometry, "--set", "normals.cross.step=0"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("parameter `step` = 0 is out of range (1 to 16)"),
        "the override is checked: {}",
        stderr(&o)
    );
    let o = run_in(d, &["validate", &geometry, "--max-pose-gap", "100"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--recording <REC>"), "{}", stderr(&o));
}

/// An EXR light probe whose data window runs backwards (x from 788529152 to 7): the exr
/// crate sized one block's buffer from it at 9.4 GB and relume aborted under a memory
/// limit (found by the `envmap` fuzz target). Now refused from its header.
#[test]
fn an_exr_whose_data_window_runs_backwards_is_refused_without_allocating_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let path = d.join("probe.exr");
    exr::prelude::write_rgb_file(&path, 8, 4, |x, y| (x as f32, y as f32, 1.0)).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    let key = b"dataWindow\0box2i\0";
    let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
    bytes[at..at + 4].copy_from_slice(&0x2f00_0000i32.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    std::fs::write(
        d.join("env.toml"),
        "[[stage]]\nkind = \"light.envmap\"\nparams = { source = \"file\", path = \"probe.exr\" }\n",
    )
    .unwrap();
    let o = std::process::Command::new("sh")
        .args([
            "-c",
            "ulimit -v 2000000 && exec \"$0\" validate env.toml",
            env!("CARGO_BIN_EXE_relume"),
        ])
        .current_dir(d)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("probe.exr"), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "probe.exr: cannot read the OpenEXR environment map: a layer's data window is \
             788529146x4 pixels: over 16384 a side"
        ),
        "{}",
        stderr(&o)
    );
}
