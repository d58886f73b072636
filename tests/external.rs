//! External stages (`kind = "external"`, docs/external-stages.md): a numpy program run
//! through relume's Python package, its outputs arriving bit for bit and the same on
//! every run and thread count; and each fault a program can commit, with its error.
//!
//! The Python side runs in a virtual environment made once under the target folder by
//! `pip install ./python` (numpy, msgpack), with `PYTHONPATH` on the working tree's
//! package so that edits to it count.

mod common;

use common::{ok, relume, stderr, stdout};
use relume::graph::Product;
use relume::raster::Image;
use relume::stages::kind;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

const W: u32 = 32;
const H: u32 = 24;

/// The bin folder of a virtual environment with relume's Python package installed.
fn python_bin() -> &'static Path {
    static BIN: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let made = BIN.get_or_init(|| {
        let package = Path::new(env!("CARGO_MANIFEST_DIR")).join("python");
        common::venv::make(
            "python-venv",
            &[package.to_str().expect("a UTF-8 checkout path")],
            "import numpy, msgpack, relume_stage",
        )
        .map(|venv| venv.join("bin"))
    });
    match made {
        Ok(bin) => bin,
        Err(why) => panic!(
            "the external-stage tests need Python 3 with venv and pip, and PyPI (or a wheel \
             cache) for numpy and msgpack: {why}"
        ),
    }
}

/// `relume ARGS` in `dir` with the environment's python3 first on PATH.
fn relume_py(dir: &Path, args: &[&str]) -> Output {
    relume_py_cmd(dir, args).output().expect("run relume")
}

fn relume_py_cmd(dir: &Path, args: &[&str]) -> Command {
    let path = format!(
        "{}:{}",
        python_bin().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut cmd = relume();
    cmd.args(args).current_dir(dir).env("PATH", path).env(
        "PYTHONPATH",
        Path::new(env!("CARGO_MANIFEST_DIR")).join("python"),
    );
    cmd
}

/// A folder with a small synthetic recording `r.relume` (5 frames of 32x24).
fn folder() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    ok(relume()
        .args(["synth", "-o", "r.relume", "--frames", "5", "--size"])
        .arg(format!("{W}x{H}"))
        .current_dir(dir.path())
        .output()
        .unwrap());
    dir
}

/// Writes `prog.py` and `p.toml`: decode, then the program as stage `prog` reading
/// the depth as `image` and writing `scaled` (depth), with `params` added.
fn setup(dir: &Path, program: &str, params: &str) {
    std::fs::write(dir.join("prog.py"), program).unwrap();
    std::fs::write(
        dir.join("p.toml"),
        format!(
            "[pipeline]\nname = \"ext\"\n\n[[stage]]\nkind = \"decode\"\n\n[[stage]]\n\
             kind = \"external\"\nname = \"prog\"\ninputs = {{ image = \"depth\" }}\n\
             params = {{ interpreter = \"python3\", program = \"prog.py\", \
             input_kinds = [\"image=depth\"], output_kinds = [\"scaled=depth\"], \
             timeout_s = 20{params} }}\n"
        ),
    )
    .unwrap();
}

/// A replay of `p.toml` that must fail: its stderr.
fn fails(dir: &Path) -> String {
    let o = relume_py(dir, &["replay", "r.relume", "-p", "p.toml", "--out", "o"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    stderr(&o)
}

fn assert_has(text: &str, want: &str) {
    assert!(text.contains(want), "want {want:?} in:\n{text}");
}

/// The numpy stage of the tests: scaled = 0.5 depth plus noise drawn from the frame's
/// seed, and a mask (labels) of the far pixels; each output's bytes also written to
/// `dump/` as the program sent them.
const DUMP: &str = r#"
import os, sys
import numpy as np
import relume_stage

def process(frame, settings):
    depth = frame.inputs["image"]
    rng = np.random.default_rng(frame.seed)
    noise = rng.standard_normal(depth.shape).astype(np.float32)
    scaled = depth * np.float32(settings["gain"]) + np.float32(1e-3) * noise
    mask = ((depth[:, :, 0] > 2.0) * 255).astype(np.uint8)
    os.makedirs("dump", exist_ok=True)
    for name, a in (("scaled", scaled), ("mask", mask)):
        with open(f"dump/{frame.index}-{name}", "wb") as f:
            f.write(np.ascontiguousarray(a).tobytes())
    print(f"frame {frame.index} done ({frame.transport})")
    return {"scaled": scaled, "mask": mask}

sys.exit(relume_stage.run(process, settings={"gain": 1.0}))
"#;

/// Scales the depth by `gain` and leaves a file `ran` behind.
const SCALE_AND_MARK: &str = r#"
import sys
import relume_stage

def process(frame, settings):
    open("ran", "w").close()
    return {"scaled": frame.inputs["image"] * settings["gain"]}

sys.exit(relume_stage.run(process, settings={"gain": 1.0}))
"#;

#[test]
fn a_numpy_stage_gives_its_bytes_exactly_and_the_same_on_every_run_and_thread_count() {
    let dir = folder();
    let d = dir.path();
    setup(
        d,
        DUMP,
        ", output_kinds = [\"scaled=depth\", \"mask=labels\"], settings = [\"gain=0.5\"]",
    );
    // Two outputs in place of the default one (TOML refuses a key twice); a stage name
    // of its own, to look for its shared memory.
    let toml = std::fs::read_to_string(d.join("p.toml"))
        .unwrap()
        .replace("output_kinds = [\"scaled=depth\"], ", "")
        .replace("name = \"prog\"", "name = \"exact\"");
    std::fs::write(d.join("p.toml"), toml).unwrap();
    let run = |threads: &str| {
        let o = relume_py_cmd(
            d,
            &["replay", "r.relume", "-p", "p.toml", "--hash", "--out", "o"],
        )
        .env("RAYON_NUM_THREADS", threads)
        .output()
        .unwrap();
        (stdout(&ok(o.clone())), stderr(&o))
    };
    let (first, err) = run("1");
    assert_has(
        &err,
        "pipeline `ext` starts programs: stage `exact` runs `python3 ",
    );
    assert_has(&err, "[exact] frame 4 done (shm)");
    // The program's reported time apart from the rest, under the timing table.
    assert_has(&err, "\nexact: the program's own time median ");
    assert_has(&err, " ms, transport median ");
    let lines: Vec<&str> = first.lines().collect();
    assert_eq!(lines.len(), 5, "{first}");
    for (index, line) in lines.iter().enumerate() {
        let digest = |name: &str| -> String {
            line.split(' ')
                .find_map(|w| w.strip_prefix(&format!("{name}=")))
                .unwrap_or_else(|| panic!("no {name} in {line}"))
                .to_string()
        };
        let bytes = |name: &str| std::fs::read(d.join(format!("dump/{index}-{name}"))).unwrap();
        let scaled: Vec<f32> = bytes("scaled")
            .chunks(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        let sent = Product::new(kind::DEPTH, Image::from_vec(W, H, scaled).unwrap());
        assert_eq!(
            digest("scaled"),
            format!("{:016x}", sent.digest()),
            "frame {index}"
        );
        let mask = Product::new(kind::LABELS, Image::from_vec(W, H, bytes("mask")).unwrap());
        assert_eq!(
            digest("mask"),
            format!("{:016x}", mask.digest()),
            "frame {index}"
        );
    }
    assert_eq!(run("1").0, first, "a second run");
    assert_eq!(run("2").0, first, "two threads");
    // The images went through shared memory (the package maps it); over the pipe they
    // are the same bytes.
    let shared = std::fs::read_to_string(d.join("p.toml")).unwrap();
    std::fs::write(
        d.join("p.toml"),
        shared.replace("timeout_s = 20", "timeout_s = 20, transport = \"pipe\""),
    )
    .unwrap();
    let (piped, err) = run("1");
    assert_has(&err, "[exact] frame 4 done (pipe)");
    assert_eq!(piped, first, "over the pipe");
    // No shared memory file is left behind.
    let left: Vec<String> = std::fs::read_dir("/dev/shm")
        .map(|entries| {
            entries
                .filter_map(|e| e.ok()?.file_name().into_string().ok())
                .filter(|n| n.starts_with("relume-") && n.contains("-exact-"))
                .collect()
        })
        .unwrap_or_default();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn validate_checks_the_declared_ports_and_names_the_program() {
    let dir = folder();
    let d = dir.path();
    setup(d, DUMP, "");
    let o = ok(relume_py(d, &["validate", "p.toml"]));
    assert_has(&stdout(&o), "starts a program: stage `prog` runs `python3 ");
    // `relume stages` lists the declared ports of a pipeline's external stages.
    let o = ok(relume_py(d, &["stages", "--pipeline", "p.toml"]));
    assert_has(
        &stdout(&o),
        "prog (line 7)\n    runs: python3 ./prog.py\n    reads: image = depth (depth map)   \
         writes: scaled (depth map)\n",
    );
    let o = ok(relume_py(d, &["stages", "--pipeline", "p.toml", "--json"]));
    let json: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(json["external"][0]["outputs"][0]["kind"], "depth map");
    assert_eq!(json["external"][0]["inputs"][0]["product"], "depth");
    assert!(json["kinds"].as_array().unwrap().len() > 20);
    // A kind no external stage exchanges, at its line and column.
    let toml = std::fs::read_to_string(d.join("p.toml")).unwrap();
    std::fs::write(
        d.join("p.toml"),
        toml.replace("scaled=depth", "scaled=light"),
    )
    .unwrap();
    let o = relume_py(d, &["validate", "p.toml"]);
    assert_eq!(o.status.code(), Some(1));
    assert_has(
        &stderr(&o),
        "\"light\" is not a kind an external stage exchanges: color, depth, points, normals, \
         radiance, scalar, labels",
    );
    assert_has(&stderr(&o), "p.toml:11:105:");
    // An input bound to a product of another kind: the same check as a built-in stage's.
    std::fs::write(
        d.join("p.toml"),
        toml.replace("image=depth", "image=radiance"),
    )
    .unwrap();
    let o = relume_py(d, &["validate", "p.toml"]);
    assert_eq!(o.status.code(), Some(1));
    assert_has(&stderr(&o), "depth");
}

#[test]
fn a_missing_program_is_named_with_the_fix() {
    let dir = folder();
    setup(dir.path(), DUMP, "");
    let toml = std::fs::read_to_string(dir.path().join("p.toml")).unwrap();
    std::fs::write(
        dir.path().join("p.toml"),
        toml.replace(
            "interpreter = \"python3\", program = \"prog.py\"",
            "program = \"nope\"",
        ),
    )
    .unwrap();
    let err = fails(dir.path());
    assert_has(&err, "stage `prog`");
    assert_has(
        &err,
        "nope`: No such file or directory (os error 2) (no such program",
    );
}

#[test]
fn a_program_that_is_not_executable_is_named_with_the_fix() {
    let dir = folder();
    setup(dir.path(), DUMP, "");
    let toml = std::fs::read_to_string(dir.path().join("p.toml")).unwrap();
    std::fs::write(
        dir.path().join("p.toml"),
        toml.replace("interpreter = \"python3\", ", ""),
    )
    .unwrap();
    let err = fails(dir.path());
    assert_has(
        &err,
        "./prog.py`: Permission denied (os error 13) (not executable: `chmod +x` it, or name its `interpreter`)",
    );
}

#[test]
fn a_program_exiting_at_start_gives_its_status_and_last_words() {
    let dir = folder();
    setup(
        dir.path(),
        "import sys\nprint('cannot load the model weights', file=sys.stderr)\nsys.exit(3)\n",
        "",
    );
    let err = fails(dir.path());
    assert_has(&err, "stage `prog`");
    assert_has(
        &err,
        "the program exited with status 3; its last lines of standard error:\n  cannot load \
         the model weights",
    );
}

#[test]
fn a_program_exiting_mid_run_gives_the_frame_status_and_last_words() {
    let dir = folder();
    setup(
        dir.path(),
        r#"
import os, sys
import relume_stage

def process(frame, settings):
    if frame.index == 2:
        print("out of memory on frame 2", file=sys.stderr, flush=True)
        os._exit(4)
    return {"scaled": frame.inputs["image"]}

sys.exit(relume_stage.run(process))
"#,
        "",
    );
    let err = fails(dir.path());
    assert_has(&err, "stage `prog` (external) failed at frame 2");
    assert_has(
        &err,
        "the program exited with status 4; its last lines of standard error:\n  out of memory \
         on frame 2",
    );
}

#[test]
fn a_hanging_program_is_stopped_after_its_timeout() {
    let dir = folder();
    setup(
        dir.path(),
        r#"
import sys, time
import relume_stage

def process(frame, settings):
    if frame.index == 1:
        time.sleep(600)
    return {"scaled": frame.inputs["image"]}

sys.exit(relume_stage.run(process))
"#,
        ", timeout_s = 1",
    );
    let toml = std::fs::read_to_string(dir.path().join("p.toml")).unwrap();
    std::fs::write(
        dir.path().join("p.toml"),
        toml.replace("timeout_s = 20, ", ""),
    )
    .unwrap();
    let start = Instant::now();
    let err = fails(dir.path());
    assert!(
        start.elapsed() < Duration::from_secs(30),
        "{:?}",
        start.elapsed()
    );
    assert_has(&err, "stage `prog` (external) failed at frame 1");
    assert_has(
        &err,
        "no reply within 1 s (timeout_s): the program was stopped",
    );
}

/// A program started by a shell wrapper without `exec` (as conda run and many launch
/// scripts do) that hangs: the timeout stops the wrapper and what it started, and the
/// run ends.
#[test]
fn a_hanging_program_behind_a_wrapper_is_stopped_with_its_wrapper() {
    let dir = folder();
    let d = dir.path();
    setup(
        d,
        r#"
import os, sys, time
import relume_stage

def process(frame, settings):
    with open("inner", "w") as f:
        f.write(str(os.getpid()))
    time.sleep(600)

sys.exit(relume_stage.run(process))
"#,
        ", timeout_s = 1",
    );
    std::fs::write(
        d.join("wrapper.sh"),
        "#!/bin/sh
python3 ./prog.py
echo done
",
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(d.join("wrapper.sh"), std::fs::Permissions::from_mode(0o755)).unwrap();
    let toml = std::fs::read_to_string(d.join("p.toml"))
        .unwrap()
        .replace("timeout_s = 20, ", "")
        .replace(
            "interpreter = \"python3\", program = \"prog.py\"",
            "program = \"wrapper.sh\"",
        );
    std::fs::write(d.join("p.toml"), toml).unwrap();
    let start = Instant::now();
    let err = fails(d);
    assert!(
        start.elapsed() < Duration::from_secs(30),
        "{:?}",
        start.elapsed()
    );
    assert_has(
        &err,
        "no reply within 1 s (timeout_s): the program was stopped",
    );
    let pid = std::fs::read_to_string(d.join("inner")).unwrap();
    assert!(
        ends_soon(pid.trim()),
        "the wrapped program (pid {pid}) outlived the run"
    );
}

/// Whether process `pid` is gone (or a zombie waiting to be reaped) within 5 s: a
/// SIGKILL is delivered asynchronously.
fn ends_soon(pid: &str) -> bool {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(5) {
        match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
            Err(_) => return true,
            // The state follows the command name in parentheses.
            Ok(stat)
                if stat
                    .rsplit(')')
                    .next()
                    .is_some_and(|r| r.trim_start().starts_with('Z')) =>
            {
                return true;
            }
            Ok(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
    false
}

/// A program speaking the protocol by hand (msgpack alone): `reply(request)` gives the
/// bytes it writes for each frame request.
fn raw(reply: &str) -> String {
    format!(
        r#"
import struct, sys
import msgpack

inp, out = sys.stdin.buffer, sys.stdout.buffer

def read():
    head = inp.read(8)
    if len(head) < 8:
        sys.exit(0)
    meta = msgpack.unpackb(inp.read(struct.unpack("<I", head[4:])[0]))
    for image in meta["inputs"] if meta["type"] == "frame" else []:
        inp.read(image["width"] * image["height"] * image["channels"] * (4 if image["dtype"] == "f32" else 1))
    return meta

def send(meta, blob=b""):
    body = msgpack.packb(meta)
    out.write(b"RLX1" + struct.pack("<I", len(body)) + body + blob)
    out.flush()

def image(width, height, channels, dtype):
    meta = dict(role="scaled", kind="depth", width=width, height=height, channels=channels, dtype=dtype)
    return meta, bytes(width * height * channels * (4 if dtype == "f32" else 1))

hello = read()
{reply}
"#
    )
}

const READY: &str = "send(dict(type=\"ready\", protocol=1))\n";

#[test]
fn bytes_that_are_not_a_message_are_named() {
    let dir = folder();
    let program = raw(&format!(
        "{READY}read()\nout.write(b'hello world, a stray print\\n'); out.flush()\nread()\n"
    ));
    setup(dir.path(), &program, "");
    let err = fails(dir.path());
    assert_has(&err, "failed at frame 0");
    assert_has(
        &err,
        "its reply is a message starts with \"hello wo\", not \"RLX1\" (does the program \
         print to its standard output?",
    );
}

#[test]
fn an_oversized_reply_is_refused_before_it_is_read() {
    let dir = folder();
    let program = raw(&format!(
        "{READY}read()\nout.write(b'RLX1' + struct.pack('<I', 0xFFFFFFFF)); out.flush()\nread()\n"
    ));
    setup(dir.path(), &program, "");
    let err = fails(dir.path());
    assert_has(&err, "a meta of 4294967295 bytes, over the 1048576 allowed");
    let program = raw(&format!(
        "{READY}read()\nm, _ = image(20000, 20000, 1, 'f32')\n\
         send(dict(type='frame', index=0, outputs=[m]))\nread()\n"
    ));
    setup(dir.path(), &program, "");
    let err = fails(dir.path());
    assert_has(
        &err,
        "`scaled` is 20000x20000: over 16384 a side or 67108864 pixels",
    );
}

#[test]
fn an_output_outside_the_shared_memory_is_named() {
    let dir = folder();
    let program = raw(&format!(
        "{READY}read()\nm, _ = image(32, 24, 1, 'f32')\nm['offset'] = 10**9\n\
         send(dict(type='frame', index=0, outputs=[m]))\nread()\n"
    ));
    setup(dir.path(), &program, "");
    assert_has(
        &fails(dir.path()),
        "`scaled` lies at bytes 1000000000..+3072 of a shared memory of 0 bytes",
    );
}

#[test]
fn a_missing_output_is_named() {
    let dir = folder();
    let program = raw(&format!(
        "{READY}read()\nsend(dict(type='frame', index=0, outputs=[]))\nread()\n"
    ));
    setup(dir.path(), &program, "");
    assert_has(&fails(dir.path()), "the reply lacks the output `scaled`");
}

#[test]
fn an_output_of_the_wrong_size_is_named() {
    let dir = folder();
    let program = raw(&format!(
        "{READY}read()\nm, b = image(4, 4, 1, 'f32')\n\
         send(dict(type='frame', index=0, outputs=[m]), b)\nread()\n"
    ));
    setup(dir.path(), &program, "");
    assert_has(
        &fails(dir.path()),
        "`scaled` is 4x4; the frame's images are 32x24",
    );
}

#[test]
fn an_output_of_the_wrong_channels_or_type_is_named() {
    let dir = folder();
    let program = raw(&format!(
        "{READY}read()\nm, b = image(32, 24, 3, 'f32')\n\
         send(dict(type='frame', index=0, outputs=[m]), b)\nread()\n"
    ));
    setup(dir.path(), &program, "");
    assert_has(
        &fails(dir.path()),
        "`scaled` is depth with 3 f32 channels; it is declared depth (1 f32 channels)",
    );
    let program = raw(&format!(
        "{READY}read()\nm, b = image(32, 24, 1, 'u8')\n\
         send(dict(type='frame', index=0, outputs=[m]), b)\nread()\n"
    ));
    setup(dir.path(), &program, "");
    assert_has(
        &fails(dir.path()),
        "`scaled` is depth with 1 u8 channels; it is declared depth (1 f32 channels)",
    );
}

#[test]
fn another_protocol_version_is_refused_at_start() {
    let dir = folder();
    let program = raw("send(dict(type='ready', protocol=2))\nread()\n");
    setup(dir.path(), &program, "");
    assert_has(
        &fails(dir.path()),
        "the program speaks protocol 2; this relume speaks 1: update one of the two",
    );
}

#[test]
fn an_error_in_the_program_stops_the_run_with_its_message() {
    let dir = folder();
    setup(
        dir.path(),
        r#"
import sys
import relume_stage

def process(frame, settings):
    if frame.index == 3:
        raise relume_stage.StageError("the denoiser diverged")
    return {"scaled": frame.inputs["image"] * settings["gain"]}

sys.exit(relume_stage.run(process, settings={"gain": 1.0}))
"#,
        "",
    );
    let err = fails(dir.path());
    assert_has(&err, "stage `prog` (external) failed at frame 3");
    assert_has(&err, "the program failed: the denoiser diverged");
    // An unknown setting: refused by the package at start, with what it takes.
    let toml = std::fs::read_to_string(dir.path().join("p.toml")).unwrap();
    std::fs::write(
        dir.path().join("p.toml"),
        toml.replace("timeout_s = 20", "timeout_s = 20, settings = [\"gian=2\"]"),
    )
    .unwrap();
    assert_has(
        &fails(dir.path()),
        "the program refused to start: unknown setting 'gian' (this stage takes: gain)",
    );
}

#[test]
fn an_interrupt_stops_a_busy_program() {
    let dir = folder();
    setup(
        dir.path(),
        r#"
import os, sys, time
import relume_stage

def process(frame, settings):
    with open("busy", "w") as f:
        f.write(str(os.getpid()))
    time.sleep(600)

sys.exit(relume_stage.run(process))
"#,
        "",
    );
    let child = relume_py_cmd(
        dir.path(),
        &["replay", "r.relume", "-p", "p.toml", "--out", "o"],
    )
    .stdout(std::process::Stdio::piped())
    .stderr(std::process::Stdio::piped())
    .spawn()
    .unwrap();
    let busy = dir.path().join("busy");
    let start = Instant::now();
    while !busy.exists() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "the program never started"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let pid = std::fs::read_to_string(&busy).unwrap();
    // SIGTERM to relume alone, as a scheduler sends it: the program is stopped too.
    let o = common::signal_and_wait(child, "-TERM");
    assert_ne!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        start.elapsed() < Duration::from_secs(30),
        "{:?}",
        start.elapsed()
    );
    let alive = Command::new("kill")
        .args(["-0", pid.trim()])
        .status()
        .unwrap()
        .success();
    assert!(
        !alive,
        "the program (pid {pid}) outlived the run: {}",
        stderr(&o)
    );
}

#[test]
fn a_batch_starts_programs_only_when_its_manifest_says_so() {
    let dir = folder();
    let d = dir.path();
    setup(d, SCALE_AND_MARK, "");
    std::fs::write(
        d.join("m.toml"),
        "recordings = [\"r.relume\"]\npipelines = [\"p.toml\"]\n[settings]\nframes = \"0..2\"\n",
    )
    .unwrap();
    let o = relume_py(d, &["batch", "m.toml"]);
    assert_ne!(o.status.code(), Some(0));
    let all = format!("{}{}", stdout(&o), stderr(&o));
    assert_has(&all, "stage `prog` would start `python3 ");
    assert_has(&all, "run_programs = true");
    assert!(!d.join("ran").exists(), "the program ran");
    std::fs::write(
        d.join("m.toml"),
        "recordings = [\"r.relume\"]\npipelines = [\"p.toml\"]\n[settings]\nframes = \"0..2\"\n\
         run_programs = true\n",
    )
    .unwrap();
    ok(relume_py(d, &["batch", "m.toml"]));
    assert!(d.join("ran").exists());
}

/// The shipped example pipeline runs on the built-in recording's kind of input.
#[test]
fn the_shipped_example_runs() {
    let dir = folder();
    let pipeline = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/examples/scale.toml");
    let o = ok(relume_py(
        dir.path(),
        &[
            "replay",
            "r.relume",
            "-p",
            pipeline.to_str().unwrap(),
            "--hash",
            "--out",
            "o",
        ],
    ));
    assert_eq!(stdout(&o).lines().count(), 5);
    assert_has(&stdout(&o), " scaled=");
}

/// `filter.oidn` (python/examples/oidn.py, Intel Open Image Denoise through pyoidn,
/// installed into the test environment on first use) in place of the axis-aligned
/// filter: the mixed-reality chain runs through it, the program's own time is reported,
/// and it denoises: on every layer, the filtered estimate differs less from pixel to
/// pixel than the accumulated one it was given.
#[test]
fn the_oidn_stage_runs_in_the_mixed_reality_chain_and_smooths_the_layers() {
    let bin = python_bin();
    let has = |bin: &Path| {
        Command::new(bin.join("python3"))
            .args(["-c", "import pyoidn"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if !has(bin) {
        let o = Command::new(bin.join("python3"))
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
                "pyoidn",
            ])
            .output()
            .unwrap();
        assert!(
            o.status.success() && has(bin),
            "pip install pyoidn (PyPI) failed: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let dir = folder();
    let d = dir.path();
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/examples");
    // The shipped pipeline, saving the layers before and after the filter as EXR.
    let toml = std::fs::read_to_string(examples.join("mixed-reality-oidn.toml"))
        .unwrap()
        .replace(
            "program = \"oidn.py\"",
            &format!("program = {:?}", examples.join("oidn.py")),
        )
        + "\n[[stage]]\nname = \"layers\"\nkind = \"write\"\n\
           params = { products = [\"e_r_dir\", \"filtered_e_r_dir\"], formats = [\"exr\"] }\n";
    std::fs::write(d.join("oidn.toml"), toml).unwrap();
    let o = ok(relume_py(
        d,
        &[
            "replay",
            "r.relume",
            "-p",
            "oidn.toml",
            "--frames",
            "0..2",
            "--out",
            "o",
        ],
    ));
    assert_has(&stdout(&o), "filter.oidn: the program's own time median ");
    // Mean absolute difference between horizontal neighbours over the image.
    let roughness = |file: &str| -> f64 {
        let image = exr::prelude::read_first_rgba_layer_from_file(
            d.join("o").join(file),
            |size, _| (size.width(), vec![[0f32; 3]; size.width() * size.height()]),
            |(w, px), at, (r, g, b, _a): (f32, f32, f32, f32)| px[at.y() * *w + at.x()] = [r, g, b],
        )
        .unwrap();
        let (w, px) = &image.layer_data.channel_data.pixels;
        let mut sum = 0.0;
        let mut n = 0;
        for (i, p) in px.iter().enumerate() {
            let finite = |p: &[f32; 3]| p.iter().all(|c| c.is_finite());
            if (i + 1) % w != 0 && finite(p) && finite(&px[i + 1]) {
                let q = px[i + 1];
                sum += (0..3).map(|c| (p[c] - q[c]).abs() as f64).sum::<f64>();
                n += 1;
            }
        }
        sum / n as f64
    };
    let before = roughness("e_r_dir/000001.exr");
    let after = roughness("filtered_e_r_dir/000001.exr");
    assert!(
        after < 0.7 * before,
        "OIDN: {after} against {before} before"
    );
}

/// Poses travel too, in the meta: the camera pose arrives bit for bit, and a pose the
/// program makes comes back as a product of the pose kind; a rotation that is not a
/// unit quaternion is refused naming the output.
#[test]
fn poses_travel_both_ways_and_a_bad_rotation_is_refused() {
    let dir = folder();
    let d = dir.path();
    setup(
        d,
        r#"
import json, sys
import relume_stage

def process(frame, settings):
    camera = frame.inputs["camera"]
    t = [float(v) for v in camera["translation"]]
    r = [float(v) for v in camera["rotation"]]
    lifted = [t[0], t[1] + 1.0, t[2]]
    if settings["bad"]:
        r = [v * 0.5 for v in r]
    with open(f"pose-{frame.index}.json", "w") as f:
        json.dump({"camera": [t, [float(v) for v in camera["rotation"]]], "lifted": [lifted, r]}, f)
    return {"scaled": frame.inputs["image"], "lifted": {"translation": lifted, "rotation": r}}

sys.exit(relume_stage.run(process, settings={"bad": False}))
"#,
        "",
    );
    let toml = std::fs::read_to_string(d.join("p.toml")).unwrap().replace(
        "input_kinds = [\"image=depth\"], output_kinds = [\"scaled=depth\"]",
        "input_kinds = [\"image=depth\", \"camera=pose\"], \
         output_kinds = [\"scaled=depth\", \"lifted=pose\"]",
    );
    let toml = toml.replace(
        "inputs = { image = \"depth\" }",
        "inputs = { image = \"depth\", camera = \"pose\" }",
    );
    std::fs::write(d.join("p.toml"), &toml).unwrap();
    let o = ok(relume_py(
        d,
        &["replay", "r.relume", "-p", "p.toml", "--hash", "--out", "o"],
    ));
    let pose_digest = |p: &serde_json::Value| {
        let f = |v: &serde_json::Value| -> Vec<f64> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        let (t, r) = (f(&p[0]), f(&p[1]));
        let pose = relume::recording::Pose {
            translation: [t[0], t[1], t[2]],
            rotation: [r[0], r[1], r[2], r[3]],
        };
        format!(
            "{:016x}",
            Product::new(relume::recording::POSE, pose).digest()
        )
    };
    for (index, line) in stdout(&o).lines().enumerate() {
        let dumped: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(d.join(format!("pose-{index}.json"))).unwrap(),
        )
        .unwrap();
        assert_has(line, &format!(" pose={}", pose_digest(&dumped["camera"])));
        assert_has(line, &format!(" lifted={}", pose_digest(&dumped["lifted"])));
    }
    // `relume stages` shows the pose ports with their kind.
    let o = ok(relume_py(d, &["stages", "--pipeline", "p.toml"]));
    assert_has(&stdout(&o), "camera = pose (pose)");
    assert_has(&stdout(&o), "lifted (pose)");
    std::fs::write(
        d.join("p.toml"),
        toml.replace(
            "timeout_s = 20",
            "timeout_s = 20, settings = [\"bad=true\"]",
        ),
    )
    .unwrap();
    assert_has(&fails(d), "`lifted`'s rotation");
    assert_has(&fails(d), "not 1: not a unit quaternion");
}
