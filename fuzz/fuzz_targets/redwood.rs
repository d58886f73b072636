//! Fuzzes `relume import redwood` and `--intrinsics`: the input holds a trajectory
//! `.log`, a list of image file names (one per line, at most 12, reduced to
//! `[0-9A-Za-z._-]`) and an `--intrinsics` text, separated by 0xFF bytes. Each name
//! becomes a 2x2 image in both `color/` and `depth/` (the depth side drops every third
//! name, so pairing by number meets gaps), which exercises numeric ordering, pairing,
//! the numbering-gap warning and the trajectory reader. Nothing may panic. Seeds:
//! `fuzz/seeds/redwood`.

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::recording::importers::{parse_intrinsics, redwood};

#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let parts = common::sections(data, 3);
    let _ = parse_intrinsics(&String::from_utf8_lossy(parts[2]));
    let dir = tempfile::tempdir().expect("temporary folder");
    let root = dir.path().join("redwood");
    for sub in ["color", "depth"] {
        std::fs::create_dir_all(root.join(sub)).expect("folder");
    }
    let (color, depth) = (dir.path().join("c.png"), dir.path().join("d.png"));
    common::write_tiny_images(&color, &depth);
    let names = String::from_utf8_lossy(parts[1]);
    for (i, name) in names.lines().take(12).enumerate() {
        let name: String = name
            .chars()
            .filter(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
            .take(40)
            .collect();
        if name.is_empty() || name.starts_with('.') {
            continue;
        }
        let _ = std::fs::copy(&color, root.join("color").join(&name));
        if i % 3 != 2 {
            let _ = std::fs::copy(&depth, root.join("depth").join(&name));
        }
    }
    if !parts[0].is_empty() {
        std::fs::write(root.join("trajectory.log"), parts[0]).expect("write the log");
    }
    let out = dir.path().join("out.relume");
    let options = redwood::RedwoodOptions::default();
    if let Err(e) = redwood::import(&root, &out, &options, &mut |_, _| {}) {
        let _ = e.to_string();
    }
});
