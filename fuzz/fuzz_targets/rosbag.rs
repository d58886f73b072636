//! Fuzzes `relume import bag`: the input is written as a `.bag` file and imported with the
//! default options, strict and with `--skip-corrupt`. Bags have no checksums, so every
//! mutation reaches the record parser, the decompressors and the message decoders.
//! Nothing may panic; errors are fine. Seeds: `fuzz/seeds/rosbag` (written by the ignored
//! test `write_fuzz_seeds` in `tests/rosbag.rs`, uncompressed so that mutations reach
//! the messages). Run as the `reader` target's doc says.

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::recording::mcap::{McapOptions, import};

fuzz_target!(|data: &[u8]| {
    for skip_corrupt in [false, true] {
        let options = McapOptions {
            skip_corrupt,
            ..McapOptions::default()
        };
        let dir = tempfile::tempdir().expect("temporary folder");
        let file = dir.path().join("in.bag");
        std::fs::write(&file, data).expect("write the input");
        let out = dir.path().join("out.relume");
        if let Err(e) = import(&file, &out, &options, &mut |_, _| {}) {
            let _ = e.to_string();
        }
    }
});
