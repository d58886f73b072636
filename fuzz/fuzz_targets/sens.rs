//! Fuzzes `relume import scannet`: the input is written as a `.sens` file and imported
//! with the default options. `.sens` has no checksums, so raw mutation reaches every
//! field. Nothing may panic; errors are fine. Seeds: `fuzz/seeds/sens` (written by the
//! ignored test `write_fuzz_seeds` in `tests/importers_scannet.rs`).

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::recording::importers::scannet::{ScannetOptions, import};

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().expect("temporary folder");
    let file = dir.path().join("in.sens");
    std::fs::write(&file, data).expect("write the input");
    let out = dir.path().join("out.relume");
    if let Err(e) = import(&file, &out, &ScannetOptions::default(), &mut |_, _| {}) {
        let _ = e.to_string();
    }
});
