//! Fuzzes `relume import k4a`: the input is written as an `.mkv` file, listed (as
//! `--list` does) and imported. Mutations reach the EBML reader, the Matroska element
//! tree, lacing, the calibration JSON, the MJPG and b16g decoders and the registration
//! through both lenses. Nothing may panic; errors are fine. Seeds: `fuzz/seeds/k4a`
//! (written by the ignored test `write_fuzz_seeds` in `tests/k4a.rs`). Run as the
//! `reader` target's doc says.

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::recording::importers::k4a::{import, listing};

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().expect("temporary folder");
    let file = dir.path().join("in.mkv");
    std::fs::write(&file, data).expect("write the input");
    let _ = listing(&file);
    let out = dir.path().join("out.relume");
    if let Err(e) = import(&file, &out, &Default::default(), &mut |_, _| {}) {
        let _ = e.to_string();
    }
});
