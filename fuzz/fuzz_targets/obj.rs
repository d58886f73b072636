//! Fuzzes the OBJ mesh reader used by `[[object]]` tables. Nothing may panic. Seeds:
//! `fuzz/seeds/obj`.

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::objects::mesh::parse_obj;

fuzz_target!(|data: &[u8]| {
    if let Err(e) = parse_obj(data, std::path::Path::new("<fuzz>.obj")) {
        let _ = e.to_string();
    }
});
