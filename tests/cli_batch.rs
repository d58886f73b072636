//! `relume batch`: a manifest of recordings x pipelines, split into shards by item id,
//! resumable through each item's DONE marker, and summarized with --summary.

mod common;

use common::{ok, relume, stderr, stdout};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Output;

/// The variables `--shard auto` reads: cleared so that a test run inside a Slurm or
/// Kubernetes job is not steered by them.
const SCHEDULER_VARS: &[&str] = &[
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_COUNT",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_MAX",
    "SLURM_ARRAY_TASK_STEP",
    "JOB_COMPLETION_INDEX",
    "RELUME_SHARDS",
];

/// `relume ARGS` in `dir` with `vars` set and no other scheduler variable.
fn batch(dir: &Path, args: &[&str], vars: &[(&str, &str)]) -> Output {
    let mut cmd = relume();
    cmd.args(args).current_dir(dir);
    for v in SCHEDULER_VARS {
        cmd.env_remove(v);
    }
    cmd.envs(vars.iter().copied());
    cmd.output().expect("run relume")
}

/// Three small recordings in `data/` and two pipelines in `pipes/` (acquisition, and
/// geometry with its own `write` stage), and `m.toml` pairing them: six items.
fn setup(dir: &Path) {
    std::fs::create_dir_all(dir.join("data")).unwrap();
    std::fs::create_dir_all(dir.join("pipes")).unwrap();
    for seed in 1..=3 {
        let name = format!("data/r{seed}.relume");
        let seed = seed.to_string();
        ok(batch(
            dir,
            &[
                "synth", "-o", &name, "--frames", "4", "--size", "64x48", "--seed", &seed,
            ],
            &[],
        ));
    }
    for p in ["acquisition.toml", "geometry.toml"] {
        std::fs::copy(common::pipeline(p), dir.join("pipes").join(p)).unwrap();
    }
    std::fs::write(
        dir.join("m.toml"),
        "recordings = [\"data/r1.relume\", \"data/r2.relume\", \"data/r3.relume\"]\n\
         pipelines = [\"pipes/acquisition.toml\", \"pipes/geometry.toml\"]\n\
         \n\
         [settings]\n\
         frames = \"0..3\"\n\
         save = [\"normals\"]\n",
    )
    .unwrap();
}

/// Every file under `dir` (relative path -> bytes), but the timings, which differ from
/// run to run.
fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, into: &mut BTreeMap<String, Vec<u8>>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(root, &path, into);
            } else if path.file_name().unwrap() != "timings.json" {
                let rel = path.strip_prefix(root).unwrap().display().to_string();
                into.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    let mut files = BTreeMap::new();
    walk(dir, dir, &mut files);
    files
}

/// The item folders under `dir`, sorted.
fn items(dir: &Path) -> Vec<String> {
    common::file_names(dir)
        .into_iter()
        .filter(|n| dir.join(n).is_dir())
        .collect()
}

/// The last line of a batch's stderr: `shard I/N: M item(s): ran A, skipped B ...`.
fn tally(o: &Output) -> String {
    stderr(o).lines().last().unwrap_or("").to_string()
}

#[test]
fn shards_together_make_exactly_an_unsharded_run() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    setup(d);
    let all = ok(batch(d, &["batch", "m.toml", "--out", "all"], &[]));
    assert!(tally(&all).ends_with("6 item(s): ran 6, skipped 0 (done earlier), failed 0"));
    let whole = tree(&d.join("all"));
    // Each item: the pipeline's own writes, the saved products, the report, the marker.
    let id = items(&d.join("all"))
        .into_iter()
        .find(|n| n.starts_with("r1__geometry__"))
        .expect("an item r1__geometry__<hash>");
    for file in [
        "normals/000002.png",
        "color/000000.png",
        "report.json",
        "DONE",
    ] {
        assert!(whole.contains_key(&format!("{id}/{file}")), "{id}/{file}");
    }
    assert!(d.join("all").join(&id).join("timings.json").is_file());
    // The three shards as separate processes, at once, into one folder.
    let children: Vec<_> = (0..3)
        .map(|i| {
            let mut cmd = relume();
            let shard = format!("{i}/3");
            cmd.args(["batch", "m.toml", "--out", "sharded", "--shard", &shard])
                .current_dir(d)
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped());
            cmd.spawn().unwrap()
        })
        .collect();
    let mut ran = Vec::new();
    for child in children {
        let o = ok(child.wait_with_output().unwrap());
        let line = tally(&o);
        let n: usize = line
            .split("ran ")
            .nth(1)
            .unwrap()
            .split(',')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        ran.push(n);
    }
    assert_eq!(ran.iter().sum::<usize>(), 6, "{ran:?}");
    assert!(
        ran.iter().all(|&n| n < 6),
        "one shard ran every item: {ran:?}"
    );
    let sharded = tree(&d.join("sharded"));
    assert_eq!(
        sharded.keys().collect::<Vec<_>>(),
        whole.keys().collect::<Vec<_>>()
    );
    for (name, bytes) in &whole {
        assert!(sharded[name] == *bytes, "{name} differs between the runs");
    }
}

#[test]
fn a_rerun_redoes_only_unfinished_items() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    setup(d);
    ok(batch(d, &["batch", "m.toml"], &[]));
    let out = d.join("m-out");
    let first = tree(&out);
    let ids = items(&out);
    assert_eq!(ids.len(), 6);
    let stamp = |id: &str| {
        std::fs::metadata(out.join(id).join("report.json"))
            .unwrap()
            .modified()
            .unwrap()
    };
    let before: Vec<_> = ids.iter().map(|id| stamp(id)).collect();
    // A killed item: its folder half-written, without a marker; and an item whose marker
    // was removed.
    let killed = &ids[1];
    std::fs::remove_dir_all(out.join(killed)).unwrap();
    std::fs::create_dir_all(out.join(killed).join("normals")).unwrap();
    std::fs::write(out.join(killed).join("normals/000000.png"), b"half").unwrap();
    let unmarked = &ids[4];
    std::fs::remove_file(out.join(unmarked).join("DONE")).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    let o = ok(batch(d, &["batch", "m.toml"], &[]));
    assert!(
        tally(&o).ends_with("6 item(s): ran 2, skipped 4 (done earlier), failed 0"),
        "{}",
        stderr(&o)
    );
    for (id, was) in ids.iter().zip(&before) {
        let redone = id == killed || id == unmarked;
        assert_eq!(stamp(id) != *was, redone, "{id}");
    }
    // Redone from scratch: the same files as the first run, none of the half-written.
    assert_eq!(tree(&out), first);
    // A third run does nothing.
    let o = ok(batch(d, &["batch", "m.toml"], &[]));
    assert!(tally(&o).ends_with("ran 0, skipped 6 (done earlier), failed 0"));
    // Changed settings make the markers invalid: everything runs again.
    let text = std::fs::read_to_string(d.join("m.toml")).unwrap();
    std::fs::write(d.join("m.toml"), text.replace("0..3", "0..2")).unwrap();
    let o = ok(batch(d, &["batch", "m.toml"], &[]));
    assert!(tally(&o).ends_with("ran 6, skipped 0 (done earlier), failed 0"));
    assert!(stderr(&o).contains("its recording, settings or pipeline changed since it was done"));
}

/// Extra arguments and the variables of a `--shard auto` run.
type Run<'a> = (&'a [&'a str], Vec<(&'a str, &'a str)>);

/// The items a batch ran, from its progress lines `[k/m] <id>: ...`, sorted.
fn ran_items(o: &Output) -> Vec<String> {
    let mut ids: Vec<String> = stderr(o)
        .lines()
        .filter(|l| l.starts_with('[') && l.contains(" through "))
        .filter_map(|l| l.split_once("] ")?.1.split(':').next().map(str::to_string))
        .collect();
    ids.sort();
    ids.dedup();
    ids
}

#[test]
fn shard_auto_takes_the_shard_from_slurm_or_kubernetes() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    setup(d);
    for i in 0..3 {
        let fixed = format!("{i}/3");
        let out = format!("fixed{i}");
        let expected = ran_items(&ok(batch(
            d,
            &["batch", "m.toml", "--shard", &fixed, "--out", &out],
            &[],
        )));
        let index = i.to_string();
        let slurm_id = (i + 1).to_string();
        let runs: [Run; 4] = [
            (
                &[],
                vec![
                    ("SLURM_ARRAY_TASK_ID", &index),
                    ("SLURM_ARRAY_TASK_COUNT", "3"),
                ],
            ),
            // An array numbered 1-3 that gives only its minimum and maximum.
            (
                &[],
                vec![
                    ("SLURM_ARRAY_TASK_ID", &slurm_id),
                    ("SLURM_ARRAY_TASK_MIN", "1"),
                    ("SLURM_ARRAY_TASK_MAX", "3"),
                ],
            ),
            (&["--shards", "3"], vec![("JOB_COMPLETION_INDEX", &index)]),
            (
                &[],
                vec![("JOB_COMPLETION_INDEX", &index), ("RELUME_SHARDS", "3")],
            ),
        ];
        for (k, (extra, vars)) in runs.iter().enumerate() {
            let out = format!("auto{i}-{k}");
            let mut args = vec!["batch", "m.toml", "--shard", "auto", "--out", &out];
            args.extend_from_slice(extra);
            let o = ok(batch(d, &args, vars));
            assert!(
                stderr(&o).starts_with(&format!("shard {i}/3 (--shard auto: ")),
                "{vars:?}: {}",
                stderr(&o)
            );
            assert_eq!(ran_items(&o), expected, "{vars:?}");
        }
    }
    let o = batch(
        d,
        &["batch", "m.toml", "--shard", "auto"],
        &[("JOB_COMPLETION_INDEX", "1")],
    );
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        stderr(&o),
        "error: --shard auto: JOB_COMPLETION_INDEX is set but not the number of shards \
         (Kubernetes sets no count variable for an Indexed Job; N is its completions): pass \
         --shards N or set RELUME_SHARDS=N\n"
    );
    let o = batch(d, &["batch", "m.toml", "--shard", "auto"], &[]);
    assert_eq!(
        stderr(&o),
        "error: --shard auto: neither SLURM_ARRAY_TASK_ID (a Slurm job array) nor \
         JOB_COMPLETION_INDEX (a Kubernetes Indexed Job) is set; give --shard I/N instead\n"
    );
}

#[test]
fn bad_shard_specs_and_manifests_say_what_and_where() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    setup(d);
    for (spec, message) in [
        (
            "3/2",
            "index 3 is not below the shard count 2 (shards are numbered 0 to 1)",
        ),
        (
            "a/b",
            "expected I/N (the 0-based index I of N shards, e.g. 0/4) or auto",
        ),
        ("0/0", "the shard count must be at least 1"),
    ] {
        let o = batch(d, &["batch", "m.toml", "--shard", spec], &[]);
        assert_eq!(o.status.code(), Some(1));
        assert_eq!(
            stderr(&o),
            format!("error: invalid --shard {spec:?}: {message}\n")
        );
    }
    assert!(
        !d.join("m-out").exists(),
        "nothing runs after a wrong --shard"
    );
    let manifest = |text: &str| {
        std::fs::write(d.join("bad.toml"), text).unwrap();
        let o = batch(d, &["batch", "bad.toml"], &[]);
        assert_eq!(o.status.code(), Some(1));
        stderr(&o)
    };
    let e = manifest(
        "recordings = [\"data/r1.relume\"]\npipelines = [\"pipes/geometry.toml\"]\nouts = \"x\"\n",
    );
    assert!(
        e.starts_with("error: bad.toml:3:1: unknown key in the manifest `outs`"),
        "{e}"
    );
    assert!(e.contains("did you mean `out`?"), "{e}");
    let e = manifest(
        "recordings = [\n  \"data/r1.relume\",\n  \"data/r9.relume\",\n]\npipelines = [\"pipes/geometry.toml\"]\n",
    );
    assert!(
        e.starts_with("error: bad.toml:3:3: recording `data/r9.relume` does not exist"),
        "{e}"
    );
    let e = manifest(
        "recordings = [\"data/r1.relume\"]\npipelines = [\"pipes/geometry.toml\"]\n[settings]\nframes = \"3..1\"\n",
    );
    assert!(
        e.starts_with("error: bad.toml:4:10: frame range \"3..1\" is empty"),
        "{e}"
    );
    let e = manifest(
        "out = \"/\"\nrecordings = [\"data/r1.relume\"]\npipelines = [\"pipes/geometry.toml\"]\n",
    );
    assert!(
        e.starts_with(
            "error: bad.toml:1:7: `out` = \"/\" is the root of a file system: give a folder \
             of its own for the batch's items"
        ),
        "{e}"
    );
    // A shard count far beyond the items: said, not silently empty.
    let o = batch(d, &["batch", "m.toml", "--shard", "5/1000000000000"], &[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "warning: 1000000000000 shards for 6 items: at least 999999999994 shards have \
             nothing to run, this one among them"
        ),
        "{}",
        stderr(&o)
    );
    let e = manifest("recordings = [\"data/r1.relume\"]\n");
    assert!(
        e.starts_with("error: bad.toml:1:1: the manifest has no `pipelines`"),
        "{e}"
    );
}

#[test]
fn summary_lists_done_failed_and_missing_items() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    setup(d);
    // A recording that is not one: its items fail, the others still run.
    std::fs::write(d.join("data/broken.relume"), b"not a recording").unwrap();
    let text = std::fs::read_to_string(d.join("m.toml")).unwrap();
    std::fs::write(
        d.join("m.toml"),
        text.replace(
            "[\"data/r1.relume\"",
            "[\"data/broken.relume\", \"data/r1.relume\"",
        ),
    )
    .unwrap();
    let o = batch(d, &["batch", "m.toml"], &[]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(tally(&o).ends_with("8 item(s): ran 6, skipped 0 (done earlier), failed 2"));
    let out = d.join("m-out");
    let ids = items(&out);
    let find = |prefix: &str| ids.iter().find(|n| n.starts_with(prefix)).unwrap().clone();
    // One item never ran, one was killed before its marker.
    let never = find("r2__acquisition__");
    std::fs::remove_dir_all(out.join(&never)).unwrap();
    let killed = find("r3__geometry__");
    std::fs::remove_file(out.join(&killed).join("DONE")).unwrap();
    let o = batch(d, &["batch", "--summary", "m-out"], &[]);
    assert_eq!(o.status.code(), Some(1), "not every item is done");
    let table = stdout(&o);
    let row = |id: &str| {
        table
            .lines()
            .find(|l| l.starts_with(id))
            .unwrap_or_else(|| panic!("no row for {id} in\n{table}"))
            .to_string()
    };
    let broken = find("broken__geometry__");
    assert!(row(&broken).contains(" failed "), "{table}");
    assert!(
        row(&never).contains(" missing ") && row(&never).ends_with("not run"),
        "{table}"
    );
    assert!(row(&killed).contains(" missing "), "{table}");
    let done = find("r1__geometry__");
    assert!(
        row(&done).split_whitespace().collect::<Vec<_>>()[1..3] == ["done", "3"],
        "{table}"
    );
    assert!(
        table.ends_with("8 item(s): 4 done, 2 failed, 2 missing\n"),
        "{table}"
    );
    let o = batch(d, &["batch", "m.toml", "--summary", "--json"], &[]);
    let doc: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(
        doc["counts"],
        serde_json::json!({"done": 4, "failed": 2, "missing": 2})
    );
    let item = |id: &str| {
        doc["items"]
            .as_array()
            .unwrap()
            .iter()
            .find(|i| i["id"] == id)
            .unwrap()
            .clone()
    };
    assert_eq!(item(&never)["status"], "missing");
    assert_eq!(item(&never)["recording"], "data/r2.relume");
    assert_eq!(item(&broken)["status"], "failed");
    assert!(
        item(&broken)["note"]
            .as_str()
            .unwrap()
            .contains("broken.relume")
    );
    assert_eq!(item(&done)["frames"], 3);
    assert!(item(&done)["fps"].as_f64().unwrap() > 0.0);
    // The rerun fills in what is missing and retries the failed.
    let o = batch(d, &["batch", "m.toml"], &[]);
    assert!(tally(&o).ends_with("ran 2, skipped 4 (done earlier), failed 2"));
}

#[test]
fn a_batch_killed_mid_run_resumes_without_redoing_finished_items() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    setup(d);
    let out = d.join("m-out");
    let done = || -> Vec<String> {
        if !out.is_dir() {
            return Vec::new();
        }
        items(&out)
            .into_iter()
            .filter(|id| out.join(id).join("DONE").is_file())
            .collect()
    };
    // SIGKILL (no chance to clean up) as soon as the first item is done.
    let mut cmd = relume();
    cmd.args(["batch", "m.toml"])
        .current_dir(d)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    for v in SCHEDULER_VARS {
        cmd.env_remove(v);
    }
    let mut child = cmd.spawn().unwrap();
    let start = std::time::Instant::now();
    while done().is_empty() {
        assert!(
            start.elapsed().as_secs() < 120,
            "no item finished in 2 minutes"
        );
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let finished = done();
    assert!(
        !finished.is_empty() && finished.len() < 6,
        "the kill should land mid-batch: {finished:?}"
    );
    let stamp = |id: &str| {
        std::fs::metadata(out.join(id).join("DONE"))
            .unwrap()
            .modified()
            .unwrap()
    };
    let before: Vec<_> = finished.iter().map(|id| stamp(id)).collect();
    let o = ok(batch(d, &["batch", "m.toml"], &[]));
    let (k, rest) = (finished.len(), 6 - finished.len());
    assert!(
        tally(&o).ends_with(&format!(
            "6 item(s): ran {rest}, skipped {k} (done earlier), failed 0"
        )),
        "{}",
        stderr(&o)
    );
    for (id, was) in finished.iter().zip(&before) {
        assert_eq!(stamp(id), *was, "{id} was redone");
    }
    // The resumed batch holds exactly what an uninterrupted one does.
    let fresh = tempfile::tempdir().unwrap();
    setup(fresh.path());
    ok(batch(fresh.path(), &["batch", "m.toml"], &[]));
    assert_eq!(tree(&out), tree(&fresh.path().join("m-out")));
}

/// Two runs of one shard (a resubmitted job array): the second leaves the item the first
/// is running to it, naming the first, and clears nothing of it; the item's lock file
/// is gone when its holder ends, so a later run takes the item.
#[test]
fn a_second_run_of_an_item_leaves_it_to_the_first() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    ok(batch(
        d,
        &[
            "synth", "-o", "r.relume", "--frames", "2", "--size", "64x48",
        ],
        &[],
    ));
    std::fs::copy(
        common::pipeline("mixed-reality-val.toml"),
        d.join("val.toml"),
    )
    .unwrap();
    // The item sets up for minutes (sample.val's transfer precomputation).
    std::fs::write(
        d.join("m.toml"),
        "recordings = [\"r.relume\"]\npipelines = [\"val.toml\"]\n\n[settings]\n\
         frames = \"0..1\"\nset = [\"sample.val.transfer_samples=1000000\"]\n",
    )
    .unwrap();
    let mut first = relume();
    for v in SCHEDULER_VARS {
        first.env_remove(v);
    }
    let first = first
        .args(["batch", "m.toml", "--out", "runs"])
        .env("RELUME_CACHE", "off")
        .current_dir(d)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let id = relume::batch::manifest::item_id("r.relume", "val.toml");
    let lock = d.join("runs").join(format!(".{id}.lock"));
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while !std::fs::read_to_string(&lock).is_ok_and(|s| s.starts_with("pid")) {
        assert!(
            std::time::Instant::now() < deadline,
            "the first run never took the item"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let second = batch(d, &["batch", "m.toml", "--out", "runs"], &[]);
    let e = stderr(&second);
    assert_eq!(second.status.code(), Some(75), "not done yet: {e}");
    assert!(
        e.contains(&format!(
            "[1/1] {id}: being run by another relume process (pid {}: ",
            first.id()
        )) && e.contains("): left to it\n"),
        "{e}"
    );
    assert!(
        e.ends_with(
            "shard 0/1: 1 item(s): ran 0, skipped 0 (done earlier), failed 0, 1 left to \
             another run that holds them (see their DONE or FAILED there)\n"
        ),
        "{e}"
    );
    assert!(!d.join("runs").join(&id).join("FAILED").exists(), "{e}");
    let killed = common::signal_and_wait(first, "-KILL");
    assert_eq!(killed.status.code(), None);
    // SIGKILL leaves the lock file, but not the lock: the next run takes the item (a
    // quick pipeline under the same name, so that it ends here).
    assert!(lock.exists());
    std::fs::copy(common::pipeline("geometry.toml"), d.join("val.toml")).unwrap();
    std::fs::write(
        d.join("m.toml"),
        "recordings = [\"r.relume\"]\npipelines = [\"val.toml\"]\n[settings]\nframes = \"0..1\"\n",
    )
    .unwrap();
    let third = ok(batch(d, &["batch", "m.toml", "--out", "runs"], &[]));
    assert!(
        stderr(&third).contains("ran 1, skipped 0"),
        "{}",
        stderr(&third)
    );
    assert!(!lock.exists(), "the lock file goes with its item");
    assert!(d.join("runs").join(&id).join("DONE").exists());
}
