//! The pipeline files relume ships: the built-in default is the mixed-reality chain, and
//! the presets derived from it stay in step with it.

use relume::graph::{Pipeline, Registry, SourceFile};

#[test]
fn the_default_pipeline_is_the_mixed_reality_chain() {
    let p = Pipeline::builtin_default(&Registry::builtin()).unwrap();
    let kinds: Vec<&str> = p.stages.iter().map(|s| s.kind).collect();
    assert_eq!(
        kinds,
        [
            "decode",
            "gbuffer.splat",
            "color.compensate",
            "depth.fuse",
            "depth.to_points",
            "normals.plane_fit",
            "cloud.samples",
            "light.impostor",
            "light.importance",
            "sample.path",
            "filter.axis_aligned",
            "composite.differential",
            "write",
            "write"
        ]
    );
    assert!(
        !p.objects.is_empty(),
        "the default scene has virtual objects"
    );
    let file = |name: &str| {
        std::fs::read_to_string(format!("{}/pipelines/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
    };
    let on_disk = file("default.toml");
    assert_eq!(
        on_disk,
        relume::graph::pipeline::DEFAULT_PIPELINE_TOML,
        "the built-in copy is the file"
    );
    assert_eq!(
        on_disk.replacen("name = \"default\"", "name = \"mixed-reality\"", 1),
        file("mixed-reality.toml"),
        "default.toml is mixed-reality.toml under another name"
    );
}

/// The fast preset is the mixed-reality chain with fewer samples and a fixed B_e, and
/// nothing else: a change to one file that is not made to the other fails here.
#[test]
fn the_fast_pipeline_is_mixed_reality_with_fewer_samples_and_a_fixed_b_e() {
    let file = |name: &str| {
        std::fs::read_to_string(format!("{}/pipelines/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
    };
    let body = |text: &str| text[text.find("[pipeline]").unwrap()..].to_string();
    let fast = file("mixed-reality-fast.toml");
    assert_eq!(
        body(&file("mixed-reality.toml"))
            .replacen(
                "name = \"mixed-reality\"",
                "name = \"mixed-reality-fast\"",
                1
            )
            .replacen(
                "kind = \"sample.path\"\n",
                "kind = \"sample.path\"\nparams = { primary = 2, direct = 2, indirect = 2 }\n",
                1
            )
            .replacen(
                "kind = \"filter.axis_aligned\"\n",
                "kind = \"filter.axis_aligned\"\nparams = { environment_bandwidth = 4.0 }\n",
                1
            ),
        body(&fast)
    );
    let p = Pipeline::parse(
        &SourceFile {
            name: "pipelines/mixed-reality-fast.toml".into(),
            text: fast.clone(),
        },
        &Registry::builtin(),
    )
    .unwrap();
    let path = p.stages.iter().find(|s| s.kind == "sample.path").unwrap();
    for (key, value) in [("primary", 2), ("direct", 2), ("indirect", 2)] {
        assert_eq!(path.params.int(key), value, "{key}");
    }
    let filter = p.stages.iter().find(|s| s.kind == "filter.axis_aligned");
    assert_eq!(filter.unwrap().params.float("environment_bandwidth"), 4.0);
}
