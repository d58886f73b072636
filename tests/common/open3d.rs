//! Python with Open3D, for tests that check relume against Open3D or read files Open3D
//! writes: a virtual environment made once under the target folder by
//! `pip install open3d==0.19.0 numpy` (about 2.5 minutes and 1.8 GB here).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Instant;

/// The python3 of a virtual environment with Open3D installed.
pub fn python() -> &'static Path {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let made = PYTHON.get_or_init(|| {
        let venv = Path::new(env!("CARGO_TARGET_TMPDIR")).join("open3d-venv");
        let python = |venv: &Path| venv.join("bin/python3");
        let works = |python: &Path| {
            Command::new(python)
                .args([
                    "-c",
                    "import numpy, open3d; assert open3d.__version__ == '0.19.0'",
                ])
                .output()
                .is_ok_and(|o| o.status.success())
        };
        if works(&python(&venv)) {
            return Ok(python(&venv));
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
        run(Command::new(python(&fresh)).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "open3d==0.19.0",
            "numpy",
        ]))?;
        let _ = std::fs::remove_dir_all(&venv);
        std::fs::rename(&fresh, &venv).map_err(|e| e.to_string())?;
        eprintln!(
            "made {} in {:.1} s",
            venv.display(),
            started.elapsed().as_secs_f64()
        );
        // A venv's scripts name its folder: the moved one runs its python by path.
        if works(&python(&venv)) {
            Ok(python(&venv))
        } else {
            Err(format!(
                "{} does not import open3d 0.19.0 after installing it (Open3D's wheel \
                 needs libusb-1.0: apt-get install libusb-1.0-0)",
                venv.display()
            ))
        }
    });
    match made {
        Ok(python) => python,
        Err(why) => panic!(
            "the Open3D comparison needs Python 3 with venv and pip, and Open3D from PyPI \
             (`pip install open3d==0.19.0 numpy`): {why}"
        ),
    }
}
