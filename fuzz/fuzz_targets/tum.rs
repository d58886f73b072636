//! Fuzzes `relume import tum`: the input holds `rgb.txt`, `depth.txt` and
//! `groundtruth.txt` separated by 0xFF bytes; the folder also holds `c.png` (2x2 color)
//! and `d.png` (2x2 depth), so listings that name them reach association and image
//! checks. Nothing may panic; errors are fine. Seeds: `fuzz/seeds/tum`.

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::recording::importers::{ImportOptions, tum};

#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().expect("temporary folder");
    let root = dir.path().join("tum");
    std::fs::create_dir(&root).expect("folder");
    let parts = common::sections(data, 3);
    for (name, text) in ["rgb.txt", "depth.txt", "groundtruth.txt"]
        .iter()
        .zip(&parts)
    {
        if !text.is_empty() {
            std::fs::write(root.join(name), text).expect("write a listing");
        }
    }
    common::write_tiny_images(&root.join("c.png"), &root.join("d.png"));
    let out = dir.path().join("out.relume");
    if let Err(e) = tum::import(&root, &out, &ImportOptions::default(), &mut |_, _| {}) {
        let _ = e.to_string();
    }
});
