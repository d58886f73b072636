//! Fuzzes the `.relume` reader: arbitrary bytes are written to a file, opened with
//! `Recording::open`, every indexed record is read, and the file is replayed frame by
//! frame with and without `skip_corrupt`. Nothing may panic (errors are fine). Each
//! input is tried twice: as it is, and with every record's CRC recomputed, so that
//! mutated payloads reach the decoders (structure-aware: most raw mutations stop at
//! the first checksum).
//!
//! Run from the repository root (cargo-fuzz and a nightly toolchain needed:
//! `cargo install cargo-fuzz`, `rustup toolchain install nightly`):
//!
//! ```text
//! cd fuzz && mkdir -p corpus/reader && TMPDIR=/dev/shm cargo +nightly fuzz run reader corpus/reader seeds/reader -- -max_total_time=300
//! ```
//!
//! New inputs go to `fuzz/corpus/reader` (ignored by git); `fuzz/seeds/reader` holds a
//! few small committed recordings to start from (written by the ignored test
//! `write_fuzz_seeds` in `tests/format.rs`). `TMPDIR=/dev/shm` keeps the per-input temp
//! files in memory. To only check that it builds on stable: `cd fuzz && cargo check`.

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::recording::{Recording, Replay, ReplayOptions};
use std::io::Write;

#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    read_everything(data);
    let mut fixed = data.to_vec();
    common::fix_relume_crcs(&mut fixed);
    if fixed != data {
        read_everything(&fixed);
    }
});

fn read_everything(data: &[u8]) {
    let mut file = tempfile::NamedTempFile::new().expect("temporary file");
    file.write_all(data).expect("write the input");
    let path = file.path();
    if let Ok(rec) = Recording::open(path) {
        let _ = rec.damage().map(|d| d.to_string());
        for i in 0..=rec.index().len() {
            if let Err(e) = rec.read_record(i) {
                let _ = e.to_string();
            }
        }
    }
    for skip_corrupt in [false, true] {
        let options = ReplayOptions {
            skip_corrupt,
            ..ReplayOptions::default()
        };
        if let Ok(replay) = Replay::open(path, options) {
            let _ = replay.duration_s();
            for n in 0..=replay.len() {
                if let Err(e) = replay.read_frame(n) {
                    let _ = e.to_string();
                }
            }
        }
    }
}
