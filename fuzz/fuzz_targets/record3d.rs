//! Fuzzes `relume import record3d`: the input is written as an `.r3d` file and imported.
//! Mutations reach the ZIP directory parser, the metadata JSON, the LZFSE decoder and the
//! registration. Nothing may panic; errors are fine. Seeds: `fuzz/seeds/record3d`
//! (written by the ignored test `write_fuzz_seeds` in `tests/record3d.rs`: small exports
//! stored without deflate, so that mutations reach the entries). Run as the `reader`
//! target's doc says.

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::recording::importers::record3d::import;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().expect("temporary folder");
    let file = dir.path().join("in.r3d");
    std::fs::write(&file, data).expect("write the input");
    let out = dir.path().join("out.relume");
    if let Err(e) = import(&file, &out, &Default::default(), &mut |_, _| {}) {
        let _ = e.to_string();
    }
});
