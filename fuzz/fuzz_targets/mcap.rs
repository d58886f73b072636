//! Fuzzes `relume import mcap`: the input is written as an `.mcap` file and imported with
//! the default options (topics chosen by the importer). Each input is tried as it is
//! (strict, and with `--skip-corrupt`, which opens each chunk itself) and
//! with its checksums made to agree (uncompressed chunks' CRCs recomputed, data and
//! summary CRCs zeroed), so that mutated records reach the message decoders. Nothing may
//! panic; errors are fine. Seeds: `fuzz/seeds/mcap` (written by the ignored test
//! `write_fuzz_seeds` in `tests/mcap.rs`). Run as the `reader` target's doc says.

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::recording::mcap::{McapOptions, import};

#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let strict = McapOptions::default();
    let skipping = McapOptions {
        skip_corrupt: true,
        ..McapOptions::default()
    };
    import_bytes(data, &strict);
    import_bytes(data, &skipping);
    let mut fixed = data.to_vec();
    common::fix_mcap_crcs(&mut fixed);
    if fixed != data {
        import_bytes(&fixed, &strict);
    }
});

fn import_bytes(data: &[u8], options: &McapOptions) {
    let dir = tempfile::tempdir().expect("temporary folder");
    let file = dir.path().join("in.mcap");
    std::fs::write(&file, data).expect("write the input");
    let out = dir.path().join("out.relume");
    if let Err(e) = import(&file, &out, options, &mut |_, _| {}) {
        let _ = e.to_string();
    }
}
