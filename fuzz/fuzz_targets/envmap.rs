//! Fuzzes the environment map loaders: OpenEXR and Radiance `.hdr` (told apart by their
//! magic bytes, as `load_envmap` does). Nothing may panic; every texel of a map that
//! loads must be finite (bad texels are set to 0). Seeds: `fuzz/seeds/envmap`.

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::light::loaders::load_envmap_counted;
use std::io::Write;

fuzz_target!(|data: &[u8]| {
    let mut file = tempfile::NamedTempFile::new().expect("temporary file");
    file.write_all(data).expect("write the input");
    match load_envmap_counted(file.path()) {
        Ok(loaded) => assert!(
            loaded.map.radiance.iter().all(|t| t.is_finite()),
            "a loaded map holds a non-finite texel"
        ),
        Err(e) => {
            let _ = e.to_string();
        }
    }
});
