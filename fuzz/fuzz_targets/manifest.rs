//! Fuzzes batch manifests: the input is parsed as `manifest.toml` in a folder that holds
//! `a.relume` and `p.toml` (so that file checks can pass), as `relume batch` does before
//! it runs anything. Nothing may panic. Seeds: `fuzz/seeds/manifest`.

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::batch::manifest::Manifest;
use relume::graph::config::SourceFile;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let dir = tempfile::tempdir().expect("temporary folder");
    std::fs::write(dir.path().join("a.relume"), b"").expect("write");
    std::fs::write(dir.path().join("p.toml"), b"").expect("write");
    let path = dir.path().join("manifest.toml");
    let src = SourceFile {
        name: path.display().to_string(),
        text: text.into(),
    };
    if let Err(e) = Manifest::parse(&src, &path) {
        let _ = e.to_string();
    }
});
