//! `relume compare` and `relume diff` from the command line: the pipelines' shared
//! acquisition runs once, each is scored as `relume eval` scores it alone, the report's
//! three files are written and the page renders in a browser; a branch's products are
//! the lone pipeline's, bit for bit, at 1 and 2 threads; diff's exit status and
//! numbers.

mod common;

use common::{ok, pipeline, run_in, small_recording, stderr, stdout};
use serde_json::Value;
use std::io::Write;
use std::path::Path;
use std::process::Command;

/// The renderers that exist: the default (sample.path), the fast one, and sample.dir.
const VARIANTS: [&str; 3] = [
    "default.toml",
    "mixed-reality-fast.toml",
    "mixed-reality-dir.toml",
];

fn eval_json(dir: &Path, pipeline_file: &str) -> Value {
    let o = ok(run_in(
        dir,
        &[
            "eval",
            "small.relume",
            "-p",
            pipeline_file,
            "--frames",
            "0..16",
            "--json",
        ],
    ));
    serde_json::from_str(&stdout(&o)).unwrap()
}

#[test]
fn compare_runs_acquisition_once_and_scores_each_pipeline_as_eval_does() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 16);
    let files: Vec<String> = VARIANTS.iter().map(|f| pipeline(f)).collect();
    let mut args = vec![
        "compare",
        "small.relume",
        "--frames",
        "0..16",
        "--out",
        "cmp",
    ];
    for f in &files {
        args.extend(["-p", f.as_str()]);
    }
    let o = ok(run_in(d, &args));
    let table = stdout(&o);
    // One row for each shared stage, one per branch for the rest.
    let rows = |name: &str| {
        table
            .lines()
            .filter(|l| l.split_whitespace().next() == Some(name))
            .count()
    };
    for shared in [
        "decode",
        "depth.fuse",
        "normals.plane_fit",
        "light.importance",
    ] {
        assert_eq!(rows(shared), 1, "{shared} runs once:\n{table}");
    }
    for label in ["default", "mixed-reality-fast"] {
        assert_eq!(rows(&format!("{label}/sample.path")), 1, "{table}");
    }
    assert_eq!(rows("mixed-reality-dir/sample.dir"), 1, "{table}");

    let out = d.join("cmp");
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let variants = report["variants"].as_array().unwrap();
    assert_eq!(variants.len(), 3);
    for (variant, file) in variants.iter().zip(&files) {
        let alone = eval_json(d, file);
        let label = variant["label"].as_str().unwrap();
        let stages = alone["stages"].as_object().unwrap();
        for (stage, scores) in stages {
            assert_eq!(
                &variant["scores"][stage], scores,
                "{label}: {stage}'s scores equal eval's of the pipeline alone"
            );
        }
        let psnr = &alone["stages"]["composite.differential"]["psnr_db"];
        assert!(psnr.as_f64().is_some_and(|p| p > 20.0), "{label}: {psnr}");
    }
    let shared: Vec<&str> = report["stages"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["variants"].as_array().unwrap().len() == 3)
        .map(|s| s["name"].as_str().unwrap())
        .collect();
    assert!(shared.contains(&"cloud.samples"), "{shared:?}");

    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("## composite.differential (composite.differential)"));
    assert!(md.contains("## Stage times (median ms per frame)"));
    assert!(md.contains("**"), "the best of a column is marked");
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    for id in ["scatter", "quality-curve", "time-curve", "frame-14"] {
        assert!(
            page.contains(&format!("id=\"{id}\"")),
            "{id} is on the page"
        );
    }
    // Per variant and frame its composite and its differences from the reference and
    // from the truth (the recording is `relume synth`'s); one reference, one truth.
    let frame = out.join("frames/000014");
    assert!(frame.join("reference.png").is_file());
    assert!(frame.join("truth.png").is_file());
    for v in variants {
        let label = v["label"].as_str().unwrap();
        for kind in ["composite", "difference", "truth_difference"] {
            assert!(frame.join(format!("{label}.{kind}.png")).is_file());
        }
        let own = &report["images"][0]["variants"]
            .as_array()
            .unwrap()
            .iter()
            .find(|i| i["label"] == label)
            .unwrap()["truth"];
        assert_eq!(own, "frames/000014/truth.png", "{label}: one truth for all");
        let truth = &v["scores"]["composite.differential"]["psnr_db_truth"];
        assert!(truth.as_f64().is_some_and(|p| p > 10.0), "{label}: {truth}");
    }
    assert!(page.contains("<th>psnr_db against the truth</th>"));
    check_page_in_browser(&out.join("index.html"));
}

/// A pipeline with a virtual lamp has a truth of its own (the lamp inserted with the
/// objects): compare scores it as eval does alone, not against the truth of the
/// pipeline with the same objects and no lamp, and saves that truth beside the first.
#[test]
fn compare_scores_a_virtual_lamp_against_its_own_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 16);
    let (plain, lamp) = (
        pipeline("mixed-reality-dir.toml"),
        pipeline("mixed-reality-dir-lamp.toml"),
    );
    ok(run_in(
        d,
        &[
            "compare",
            "small.relume",
            "--frames",
            "0..16",
            "--out",
            "cmp",
            "-p",
            &plain,
            "-p",
            &lamp,
        ],
    ));
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("cmp/report.json")).unwrap()).unwrap();
    let scores = |label: &str| {
        report["variants"]
            .as_array()
            .unwrap()
            .iter()
            .find(|v| v["label"] == label)
            .unwrap()["scores"]["composite.differential"]
            .clone()
    };
    let alone = eval_json(d, &lamp);
    assert_eq!(
        scores("mixed-reality-dir-lamp"),
        alone["stages"]["composite.differential"]
    );
    let with = scores("mixed-reality-dir-lamp")["psnr_db_truth"]
        .as_f64()
        .unwrap();
    let without = scores("mixed-reality-dir")["psnr_db_truth"]
        .as_f64()
        .unwrap();
    assert_ne!(with, without);
    let images = &report["images"][0];
    assert_eq!(images["truth"], "frames/000014/truth.png");
    let truth_of = |label: &str| {
        images["variants"]
            .as_array()
            .unwrap()
            .iter()
            .find(|v| v["label"] == label)
            .unwrap()["truth"]
            .clone()
    };
    assert_eq!(truth_of("mixed-reality-dir"), "frames/000014/truth.png");
    let own = "frames/000014/mixed-reality-dir-lamp.truth.png";
    assert_eq!(truth_of("mixed-reality-dir-lamp"), own);
    assert!(d.join("cmp").join(own).is_file());
    let page = std::fs::read_to_string(d.join("cmp/index.html")).unwrap();
    assert!(page.contains(own), "the page shows its truth");
}

/// Loads the page in headless Chromium from the file system: every image decodes, no
/// script error, and the elements the report promises are there.
fn check_page_in_browser(page: &Path) {
    let chromium = ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .into_iter()
        .find(|p| Path::new(p).exists());
    let Some(chromium) = chromium else {
        let message = "the report page is tested in headless Chromium, which is not installed: \
                       `apt-get install chromium` (.ci/run does)";
        if std::env::var_os("RELUME_REQUIRE_BROWSER").is_some() {
            panic!("{message}; RELUME_REQUIRE_BROWSER is set, so the check may not be skipped");
        }
        // Written past the test harness's capture, so that `cargo test` shows it.
        let _ = writeln!(
            std::io::stderr(),
            "\nskipped: the report page's browser check ({message})"
        );
        return;
    };
    let profile = tempfile::tempdir().unwrap();
    let o = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--enable-logging=stderr",
            "--v=0",
            "--virtual-time-budget=5000",
            "--dump-dom",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(format!("file://{}", page.display()))
        .output()
        .expect("run chromium");
    let dom = stdout(&o);
    let log = stderr(&o);
    assert!(o.status.success(), "chromium failed:\n{log}");
    let console: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("CONSOLE") || l.contains("Failed to load resource"))
        .collect();
    assert!(console.is_empty(), "console messages: {console:?}");
    assert!(
        dom.contains("data-images=\"ok\""),
        "every image decodes: {}",
        dom.lines().find(|l| l.contains("<body")).unwrap_or("")
    );
    assert!(dom.contains("data-errors=\"\""), "no script error");
    assert_eq!(dom.matches("<svg").count(), 3, "three charts");
    assert!(
        dom.matches("<img").count() >= 7,
        "reference and 2 images per variant"
    );
    assert!(dom.contains("id=\"summary\""));
}

#[test]
fn a_branch_hashes_as_the_lone_pipeline_at_1_and_2_threads() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_recording(d, 4);
    let (default, dir) = (pipeline("default.toml"), pipeline("mixed-reality-dir.toml"));
    for threads in ["1", "2"] {
        let alone = common::replay_hashes(d, "small.relume", &default, threads);
        let o = common::relume()
            .args(["compare", "small.relume", "-p", &default, "-p", &dir])
            .args(["--no-scores", "--hash", "--out", "cmp"])
            .current_dir(d)
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        let lines = stdout(&ok(o));
        let branch: Vec<&str> = lines
            .lines()
            .filter_map(|l| l.strip_prefix("default "))
            .collect();
        assert_eq!(branch.len(), 4, "{lines}");
        assert_eq!(
            branch,
            alone.lines().collect::<Vec<_>>(),
            "{threads} threads"
        );
        assert_eq!(
            lines
                .lines()
                .filter(|l| l.starts_with("mixed-reality-dir "))
                .count(),
            4
        );
    }
}

fn write_png(path: &Path, pixels: &[[u8; 3]]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let raw: Vec<u8> = pixels.iter().flatten().copied().collect();
    image::save_buffer(path, &raw, pixels.len() as u32, 1, image::ColorType::Rgb8).unwrap();
}

#[test]
fn diff_names_the_first_differing_frame_and_exits_by_tolerance() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let frame = [[10u8, 20, 30], [40, 50, 60]];
    for run in ["a", "b"] {
        write_png(&d.join(run).join("final/000000.png"), &frame);
        std::fs::write(d.join(run).join("final/notes.json"), b"{}").unwrap();
    }
    let mut changed = frame;
    changed[1][2] = 63;
    write_png(&d.join("a/final/000001.png"), &frame);
    write_png(&d.join("b/final/000001.png"), &changed);

    // An EXR holding NaN (an image's invalid pixels) in both runs, in a `write` stage's
    // own folder: equal.
    for run in ["a", "b"] {
        let exr = d.join(run).join("x/final_hdr/000000.exr");
        std::fs::create_dir_all(exr.parent().unwrap()).unwrap();
        exr::prelude::write_rgb_file(&exr, 2, 1, |x, _| (x as f32, f32::NAN, 0.5)).unwrap();
    }

    let same = run_in(d, &["diff", "a", "a"]);
    assert_eq!(same.status.code(), Some(0), "{}", stdout(&same));
    assert!(stdout(&same).ends_with("the runs match\n"));

    let differ = run_in(d, &["diff", "a", "b", "--json"]);
    assert_eq!(differ.status.code(), Some(1));
    let doc: Value = serde_json::from_str(&stdout(&differ)).unwrap();
    let p = &doc["products"][0];
    assert_eq!(p["product"], "final");
    let hdr = &doc["products"][1];
    assert_eq!(hdr["product"], "x/final_hdr");
    assert_eq!((&hdr["frames"], &hdr["differing"]), (&1.into(), &0.into()));
    assert_eq!(p["frames"], 3);
    assert_eq!(p["differing"], 1);
    assert_eq!(p["first_differing"], "000001.png");
    assert_eq!(p["max_abs"], 3.0);
    // One value of the file's 6 (RGB) off by 3, peak 255: 46.4 dB.
    let want = 10.0 * (255.0f64 * 255.0 / (9.0 / 6.0)).log10();
    assert!((p["worst_psnr_db"].as_f64().unwrap() - want).abs() < 1e-9);

    let tolerated = run_in(d, &["diff", "a", "b", "--tolerance", "3"]);
    assert_eq!(tolerated.status.code(), Some(0), "{}", stdout(&tolerated));
    let by_psnr = run_in(d, &["diff", "a", "b", "--min-psnr", "45"]);
    assert_eq!(by_psnr.status.code(), Some(0), "{}", stdout(&by_psnr));
    let strict = run_in(d, &["diff", "a", "b", "--min-psnr", "50"]);
    assert_eq!(strict.status.code(), Some(1));

    std::fs::remove_file(d.join("b/final/000000.png")).unwrap();
    let missing = run_in(d, &["diff", "a", "b", "--tolerance", "3"]);
    assert_eq!(missing.status.code(), Some(1));
    assert!(stdout(&missing).contains("only in RUN_A: 000000.png"));

    let unreadable = run_in(d, &["diff", "a", "nowhere"]);
    assert_eq!(unreadable.status.code(), Some(2));
    assert_eq!(stderr(&unreadable), "error: nowhere: not a folder\n");
    // A symbolic link back up the tree is followed once, not round and round.
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("..", d.join("a/final/up")).unwrap();
        let looped = run_in(d, &["diff", "a", "a"]);
        assert_eq!(looped.status.code(), Some(0), "{}", stderr(&looped));
        std::fs::remove_file(d.join("a/final/up")).unwrap();
    }

    // A frame that does not decode is unreadable (2), not a difference (1); its name
    // is in the message.
    std::fs::write(d.join("b/final/000001.png"), b"\x89PNG\r\n\x1a\n broken").unwrap();
    let broken = run_in(d, &["diff", "a", "b"]);
    assert_eq!(broken.status.code(), Some(2), "{}", stdout(&broken));
    assert!(
        stderr(&broken).starts_with("error: b/final/000001.png: "),
        "{}",
        stderr(&broken)
    );

    // A PNG whose header claims 20000 x 20000 pixels is refused before it is decoded.
    write_png(&d.join("b/final/000001.png"), &frame);
    let mut png = std::fs::read(d.join("b/final/000001.png")).unwrap();
    // IHDR's width and height are bytes 16..24, its CRC 29..33 (over bytes 12..29).
    png[16..20].copy_from_slice(&20000u32.to_be_bytes());
    png[20..24].copy_from_slice(&20000u32.to_be_bytes());
    let crc = crc32fast::hash(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    std::fs::write(d.join("b/final/000001.png"), &png).unwrap();
    let huge = run_in(d, &["diff", "a", "b"]);
    assert_eq!(huge.status.code(), Some(2));
    assert_eq!(
        stderr(&huge),
        "error: b/final/000001.png: the image is 20000x20000: relume diff compares images \
         of up to 16384 pixels a side and 64 megapixels\n"
    );
}
