//! Fuzzes pipeline configs: the input is parsed as a pipeline TOML and checked against
//! the built-in registry, as `relume validate` does (nothing is run). Nothing may panic,
//! and an error must render. Seeds: `fuzz/seeds/pipeline` (the shipped pipelines).

#![no_main]

use libfuzzer_sys::fuzz_target;
use relume::graph::{Pipeline, config::SourceFile};
use std::sync::LazyLock;

static REGISTRY: LazyLock<relume::graph::Registry> = LazyLock::new(relume::stages::registry);

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let src = SourceFile {
        name: "<fuzz>".into(),
        text: text.into(),
    };
    if let Err(e) = Pipeline::parse(&src, &REGISTRY) {
        let _ = e.to_string();
    }
});
