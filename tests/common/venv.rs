//! Python virtual environments for tests that run Python peers (Mitsuba, Open3D,
//! relume's own Python package): made once under the target folder, in a fresh folder
//! first and moved into place, so that an interrupted install never leaves a half-made
//! environment that looks complete.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Instant;

/// The folder of the virtual environment `name` under the target folder, where
/// `python3 -c check` succeeds; made with `pip install packages` when it does not yet.
/// An error says which command failed and how.
pub fn make(name: &str, packages: &[&str], check: &str) -> Result<PathBuf, String> {
    let venv = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let works = |venv: &Path| {
        Command::new(venv.join("bin/python3"))
            .args(["-c", check])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if works(&venv) {
        return Ok(venv);
    }
    let fresh = venv.with_extension(format!("making-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&fresh);
    let run = |cmd: &mut Command| -> Result<(), String> {
        let o = cmd.output().map_err(|e| format!("{cmd:?}: {e}"))?;
        if !o.status.success() {
            return Err(format!("{cmd:?}: {}", String::from_utf8_lossy(&o.stderr)));
        }
        Ok(())
    };
    let started = Instant::now();
    run(Command::new("python3").args(["-m", "venv"]).arg(&fresh))?;
    run(Command::new(fresh.join("bin/python3"))
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
        ])
        .args(packages))?;
    let _ = std::fs::remove_dir_all(&venv);
    std::fs::rename(&fresh, &venv).map_err(|e| e.to_string())?;
    eprintln!(
        "made {} in {:.1} s",
        venv.display(),
        started.elapsed().as_secs_f64()
    );
    // A venv's scripts name its folder: the moved one runs its python by path.
    if works(&venv) {
        Ok(venv)
    } else {
        Err(format!(
            "{} does not pass `{check}` after installing {}",
            venv.display(),
            packages.join(" ")
        ))
    }
}

/// The `python3` of the virtual environment `name` ([`make`] with `packages` and `check`),
/// made once per test binary through `cell` (tests run in parallel threads); a panic
/// saying what could not be installed otherwise.
pub fn python(
    cell: &'static OnceLock<Result<PathBuf, String>>,
    name: &str,
    packages: &[&str],
    check: &str,
) -> &'static Path {
    let made = cell.get_or_init(|| make(name, packages, check).map(|v| v.join("bin/python3")));
    match made {
        Ok(python) => python,
        Err(e) => panic!(
            "cannot make the {name} environment ({}): {e}",
            packages.join(" ")
        ),
    }
}

/// Runs `tests/writers/<script>` with `python` and `args`; a panic with its error output
/// when it fails.
pub fn run_writer<S: AsRef<std::ffi::OsStr>>(python: &Path, script: &str, args: &[S]) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/writers")
        .join(script);
    let o = std::process::Command::new(python)
        .arg(path)
        .args(args)
        .output()
        .expect("run python");
    assert!(
        o.status.success(),
        "{script} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}
