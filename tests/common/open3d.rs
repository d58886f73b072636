//! Python with Open3D, for tests that check relume against Open3D or read files Open3D
//! writes: a virtual environment made once under the target folder by
//! `pip install open3d==0.19.0 numpy` (about 2.5 minutes and 1.8 GB here).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The python3 of a virtual environment with Open3D installed.
pub fn python() -> &'static Path {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let made = PYTHON.get_or_init(|| {
        super::venv::make(
            "open3d-venv",
            &["open3d==0.19.0", "numpy"],
            "import numpy, open3d; assert open3d.__version__ == '0.19.0'",
        )
        .map(|venv| venv.join("bin/python3"))
    });
    match made {
        Ok(python) => python,
        Err(why) => panic!(
            "the Open3D comparison needs Python 3 with venv and pip, and Open3D from PyPI \
             (`pip install open3d==0.19.0 numpy`; Open3D's wheel needs libusb-1.0: \
             apt-get install libusb-1.0-0): {why}"
        ),
    }
}
