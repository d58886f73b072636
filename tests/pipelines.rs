//! The pipeline files relume ships: the built-in default is the mixed-reality chain, and
//! the presets derived from it stay in step with it.

use relume::graph::{Pipeline, SourceFile};
use relume::stages::world::PipelineObjects;

#[test]
fn the_default_pipeline_is_the_mixed_reality_chain() {
    let p = Pipeline::builtin_default(&relume::stages::registry()).unwrap();
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
            "temporal.accumulate",
            "filter.axis_aligned",
            "composite.differential",
            "write",
            "write"
        ]
    );
    assert!(
        !p.objects().is_empty(),
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

/// The fast preset is the reference chain with fewer samples and a fixed B_e, and
/// nothing else: a change to one file that is not made to the other fails here.
#[test]
fn the_fast_pipeline_is_mixed_reality_with_fewer_samples_and_a_fixed_b_e() {
    let file = |name: &str| {
        std::fs::read_to_string(format!("{}/pipelines/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
    };
    let body = |text: &str| text[text.find("[pipeline]").unwrap()..].to_string();
    let fast = file("mixed-reality-fast.toml");
    assert_eq!(
        body(&file("mixed-reality-reference.toml"))
            .replacen(
                "name = \"mixed-reality-reference\"",
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
        &relume::stages::registry(),
    )
    .unwrap();
    let path = p.stages.iter().find(|s| s.kind == "sample.path").unwrap();
    for (key, value) in [("primary", 2), ("direct", 2), ("indirect", 2)] {
        assert_eq!(path.params.int(key), value, "{key}");
    }
    let filter = p.stages.iter().find(|s| s.kind == "filter.axis_aligned");
    assert_eq!(filter.unwrap().params.float("environment_bandwidth"), 4.0);
}

/// Paper 000's low / medium / high presets are the reference chain with sample.path's
/// parameters changed (its query, samples, cache, visibility and bounce, the objects
/// tested through their voxel volume) and no filter (Table 2 has none).
#[test]
fn the_nei_presets_are_mixed_reality_with_another_radiance_query() {
    let file = |name: &str| {
        std::fs::read_to_string(format!("{}/pipelines/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
    };
    let body = |text: &str| text[text.find("[pipeline]").unwrap()..].to_string();
    let presets = [
        (
            "low",
            "query = \"em\", material_query = \"dit\", iterations = 6, visibility = false, object_visibility = \"voxels\", object_voxels = 32, object_aware = true, candidates = 16, cache_size = 8",
        ),
        (
            "medium",
            "query = \"dit\", iterations = 6, self_bounce = false, object_visibility = \"voxels\", object_voxels = 32, object_aware = true, candidates = 16, cache_size = 8",
        ),
        (
            "high",
            "query = \"dit\", iterations = 8, primary = 4, direct = 16, indirect = 16, object_direct = 32, object_indirect = 32, self_bounce = true, object_visibility = \"voxels\", object_voxels = 128, object_aware = true, candidates = 64, cache_size = 32",
        ),
    ];
    let unfiltered = |chain: String| {
        chain
            .replacen(" -> filter.axis_aligned", "", 1)
            .replacen(
                "# --- Sampling, filtering, compositing. ---",
                "# --- Sampling and compositing: no filter (paper 000 has none). ---",
                1,
            )
            .replacen("[[stage]]\nkind = \"filter.axis_aligned\"\n\n", "", 1)
            .replacen(
                "kind = \"composite.differential\"\n",
                "kind = \"composite.differential\"\ninputs = { e_r_dir = \"e_r_dir\", e_r_ind = \"e_r_ind\", e_rv_dir = \"e_rv_dir\", e_rv_ind = \"e_rv_ind\" }\n",
                1,
            )
    };
    for (level, params) in presets {
        let name = format!("mixed-reality-nei-{level}");
        let text = file(&format!("{name}.toml"));
        assert_eq!(
            unfiltered(body(&file("mixed-reality-reference.toml")))
                .replacen(
                    "name = \"mixed-reality-reference\"",
                    &format!("name = \"{name}\""),
                    1
                )
                .replacen(
                    "kind = \"sample.path\"\n",
                    &format!("kind = \"sample.path\"\nparams = {{ {params} }}\n"),
                    1
                ),
            body(&text),
            "{name}"
        );
        let p = Pipeline::parse(
            &SourceFile {
                name: format!("pipelines/{name}.toml"),
                text,
            },
            &relume::stages::registry(),
        )
        .unwrap();
        let path = p.stages.iter().find(|s| s.kind == "sample.path").unwrap();
        assert_eq!(path.inputs["environment"], "environment", "{name}");
        assert_eq!(path.params.bool("visibility"), level != "low", "{name}");
        assert_eq!(path.params.bool("self_bounce"), level != "medium", "{name}");
        assert_eq!(path.params.str("object_visibility"), "voxels", "{name}");
        let material = if level == "low" { "dit" } else { "same" };
        assert_eq!(path.params.str("material_query"), material, "{name}");
        assert!(
            p.stages.iter().all(|s| s.kind != "filter.axis_aligned"),
            "{name}"
        );
    }
}

/// The vct pipeline is the reference chain with light.voxels added and only
/// sample.path's query (and the medium preset's object-aware sampling) changed.
#[test]
fn the_vct_pipeline_is_mixed_reality_with_voxel_cone_tracing() {
    let file = |name: &str| {
        std::fs::read_to_string(format!("{}/pipelines/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
    };
    let body = |text: &str| text[text.find("[pipeline]").unwrap()..].to_string();
    let text = file("mixed-reality-vct.toml");
    assert_eq!(
        body(&file("mixed-reality-reference.toml"))
            .replacen(
                "name = \"mixed-reality-reference\"",
                "name = \"mixed-reality-vct\"",
                1
            )
            .replacen("-> light.impostor ->", "-> light.impostor, light.voxels ->", 1)
            .replacen(
                "kind = \"light.impostor\"\n",
                "kind = \"light.impostor\"\n\n[[stage]]\nkind = \"light.voxels\"\n",
                1
            )
            .replacen(
                "kind = \"sample.path\"\n",
                "kind = \"sample.path\"\nparams = { query = \"vct\", object_aware = true, candidates = 16, cache_size = 8 }\n",
                1
            ),
        body(&text)
    );
    let p = Pipeline::parse(
        &SourceFile {
            name: "pipelines/mixed-reality-vct.toml".into(),
            text: text.clone(),
        },
        &relume::stages::registry(),
    )
    .unwrap();
    let path = p.stages.iter().find(|s| s.kind == "sample.path").unwrap();
    assert_eq!(path.inputs["voxels"], "voxels");
    assert!(!path.inputs.contains_key("environment"));
    // Without light.voxels the pipeline is refused when it loads.
    let without = text.replacen("[[stage]]\nkind = \"light.voxels\"\n\n", "", 1);
    let err = Pipeline::parse(
        &SourceFile {
            name: "p.toml".into(),
            text: without,
        },
        &relume::stages::registry(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("voxels") && err.contains("sample.path"),
        "{err}"
    );
}

/// Asserts that `pipelines/{name}.toml` is `pipelines/{twin}.toml` from its `[pipeline]`
/// table on, renamed and with each of `swaps` (old, new) replaced once, and that it
/// loads; returns it.
fn assert_twin(twin: &str, name: &str, swaps: &[(&str, &str)]) -> Pipeline {
    let file = |name: &str| {
        std::fs::read_to_string(format!(
            "{}/pipelines/{name}.toml",
            env!("CARGO_MANIFEST_DIR")
        ))
        .unwrap()
    };
    let body = |text: &str| text[text.find("[pipeline]").unwrap()..].to_string();
    let text = file(name);
    let mut expected = body(&file(twin)).replacen(
        &format!("name = \"{twin}\""),
        &format!("name = \"{name}\""),
        1,
    );
    for (old, new) in swaps {
        assert!(expected.contains(old), "{twin} has no {old:?}");
        expected = expected.replacen(old, new, 1);
    }
    assert_eq!(expected, body(&text), "{name}");
    Pipeline::parse(
        &SourceFile {
            name: format!("pipelines/{name}.toml"),
            text,
        },
        &relume::stages::registry(),
    )
    .unwrap()
}

/// The mixed-reality pipelines (the default and its livingroom1 twin) are their
/// reference chains with temporal reuse swapped in: few fresh samples, more near the
/// objects, the accumulator between the sampler and the filter, B_e fixed and the
/// filter's own temporal extension off.
#[test]
fn the_mixed_reality_pipelines_are_the_reference_chains_with_temporal_reuse() {
    let reference_block = "# --- Sampling, filtering, compositing. ---\n[[stage]]\nkind = \"sample.path\"\n\n[[stage]]\nkind = \"filter.axis_aligned\"\n";
    let temporal_block = std::fs::read_to_string(format!(
        "{}/pipelines/mixed-reality.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let start = temporal_block
        .find("# --- Sampling with temporal reuse")
        .unwrap();
    let end = temporal_block
        .find("[[stage]]\nkind = \"composite")
        .unwrap();
    let temporal_block = &temporal_block[start..end - 1];
    for (twin, name) in [
        ("mixed-reality-reference", "mixed-reality"),
        (
            "mixed-reality-reference-livingroom1",
            "mixed-reality-livingroom1",
        ),
    ] {
        let swaps = [
            (
                "-> sample.path -> filter.axis_aligned ->",
                "-> sample.path -> temporal.accumulate -> filter.axis_aligned ->",
            ),
            (reference_block, temporal_block),
        ];
        let p = assert_twin(twin, name, &swaps);
        let path = p.stages.iter().find(|s| s.kind == "sample.path").unwrap();
        for (key, value) in [
            ("primary", 1),
            ("direct", 1),
            ("indirect", 1),
            ("near_primary", 2),
        ] {
            assert_eq!(path.params.int(key), value, "{name}: {key}");
        }
        let accumulate = p
            .stages
            .iter()
            .find(|s| s.kind == "temporal.accumulate")
            .unwrap();
        assert_eq!(
            path.outputs["e_r_dir"], accumulate.inputs["e_r_dir"],
            "{name}"
        );
        let filter = p
            .stages
            .iter()
            .find(|s| s.kind == "filter.axis_aligned")
            .unwrap();
        assert_eq!(
            accumulate.outputs["e_rv_dir"], filter.inputs["e_rv_dir"],
            "{name}"
        );
        assert_eq!(filter.params.float("environment_bandwidth"), 4.0, "{name}");
        assert!(!filter.params.bool("temporal"), "{name}");
    }
}

/// The Differential Instant Radiosity pipelines are their reference twins with the
/// renderer swapped and nothing else changed.
#[test]
fn the_dir_pipelines_are_their_twins_with_sample_dir_swapped_in() {
    for (twin, name) in [
        ("mixed-reality-reference", "mixed-reality-dir"),
        (
            "mixed-reality-reference-livingroom1",
            "mixed-reality-dir-livingroom1",
        ),
    ] {
        let swaps = [
            ("-> sample.path ->", "-> sample.dir ->"),
            ("kind = \"sample.path\"\n", "kind = \"sample.dir\"\n"),
        ];
        let p = assert_twin(twin, name, &swaps);
        assert!(p.stages.iter().any(|s| s.kind == "sample.dir"), "{name}");
    }
}

/// The virtual lamp pipeline is the Differential Instant Radiosity one with a virtual
/// spot light added and nothing else changed.
#[test]
fn the_lamp_pipeline_is_the_dir_pipeline_with_a_virtual_spot_light() {
    let lamp = "exponent = 40\n\n# A warm desk lamp";
    let p = assert_twin(
        "mixed-reality-dir",
        "mixed-reality-dir-lamp",
        &[(
            "exponent = 40\n\n# --- Acquisition",
            &format!(
                "{}{}",
                lamp,
                " 1.3 m up in front of the torus on its right, aimed at it: 1.56 m\n# away, it brings intensity cos / d^2 = 1.4 (green 1.0) to the floor at the torus's centre.\n[[light]]\nname = \"desk lamp\"\nworld = \"virtual\"\nposition = [0.7, 1.3, -0.5]\naim = [0.0, 0.0, 0.0]\ncutoff_deg = 35\nbeam_deg = 20\nintensity = [4.0, 3.0, 1.8]\n\n# --- Acquisition"
            ),
        )],
    );
    let lights = &relume::stages::world::object_world(&p.world).lights;
    assert_eq!(lights.len(), 1);
    assert_eq!(lights[0].world, relume::light::LightWorld::Virtual);
}

/// The double-shadow pipeline is the Differential Instant Radiosity one with paper 002
/// Fig. 5's virtual box for its objects and the synthetic room's real lamp as a
/// `[[light]]`; its [4] twin changes sample.dir's flags and nothing else.
#[test]
fn the_room_lamp_pipelines_are_the_dir_pipeline_with_the_real_lamp_and_a_box() {
    let dir = std::fs::read_to_string(format!(
        "{}/pipelines/mixed-reality-dir.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let lamp = std::fs::read_to_string(format!(
        "{}/pipelines/mixed-reality-dir-room-lamp.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    // The objects' block of each: from its first comment above [[object]] to the
    // acquisition.
    let objects = |text: &str| {
        let start = text
            .find("\n\n# A torus")
            .or(text.find("\n\n# Paper 002 Fig. 5"));
        text[start.unwrap() + 2..text.find("# --- Acquisition").unwrap()].to_string()
    };
    let p = assert_twin(
        "mixed-reality-dir",
        "mixed-reality-dir-room-lamp",
        &[(&objects(&dir), &objects(&lamp))],
    );
    let world = relume::stages::world::object_world(&p.world);
    assert_eq!(world.scene.triangles.len(), 12, "one box");
    // The [[light]] is the room's lamp as `relume synth --lamp-on-at` switches it on.
    let room = relume::recording::synth::lamp::room_lamp();
    let [light] = &world.lights[..] else {
        panic!("one light: {:?}", world.lights)
    };
    assert_eq!(light.world, relume::light::LightWorld::Real);
    assert_eq!(light.position, room.position);
    assert!((light.direction - room.direction).length() < 1e-6);
    assert_eq!(light.intensity, room.intensity);
    assert!((light.beam - room.beam).abs() < 1e-6 && (light.cutoff - room.cutoff).abs() < 1e-6);

    let knecht = assert_twin(
        "mixed-reality-dir-room-lamp",
        "mixed-reality-dir-room-lamp-knecht2010",
        &[(
            "kind = \"sample.dir\"\n",
            "kind = \"sample.dir\"\nparams = { flags = \"knecht2010\" }\n",
        )],
    );
    assert!(knecht.stages.iter().any(|s| s.kind == "sample.dir"));
}

/// The atlas pipeline is the VAL one with light.val's lights found on the room's
/// surfaces (paper 004 Secs. 4.1-4.3) and nothing else changed.
#[test]
fn the_val_atlas_pipeline_is_the_val_pipeline_with_the_atlas_source() {
    let p = assert_twin(
        "mixed-reality-val",
        "mixed-reality-val-atlas",
        &[(
            "kind = \"light.val\"\nevery = 8\nlag = 1\n",
            "kind = \"light.val\"\nevery = 8\nlag = 1\nparams = { source = \"atlas\" }\n",
        )],
    );
    let val = p.stages.iter().find(|s| s.kind == "light.val").unwrap();
    assert_eq!(val.inputs["cloud"], "cloud");
}

/// The Distance Impostor Tracing pipeline is the default chain with the query swapped
/// and nothing else changed (its temporal reuse and filter settings included).
#[test]
fn the_dit_pipeline_is_the_default_chain_with_the_impostor_traced() {
    let sampling = "params = { primary = 1, direct = 1, indirect = 1,";
    let swaps = [(
        sampling,
        "params = { query = \"dit\", primary = 1, direct = 1, indirect = 1,",
    )];
    let p = assert_twin("mixed-reality", "mixed-reality-dit", &swaps);
    let path = p.stages.iter().find(|s| s.kind == "sample.path").unwrap();
    assert_eq!(path.params.str("query"), "dit");
    assert!(path.params.bool("visibility"));
}

/// The light-probe pipeline is the default chain with the recording's probe in place of
/// the cloud's impostor, nothing else changed: scored against the truth beside the
/// default, the difference is what capture misses.
#[test]
fn the_probe_pipeline_is_the_default_chain_lit_by_the_recordings_probe() {
    let swaps = [
        (
            "-> light.impostor -> light.importance ->",
            "-> light.envmap -> light.importance ->",
        ),
        (
            "# --- Light: from the reconstructed cloud, centred on the objects. ---",
            "# --- Light: the recording's light probe, seen from the objects' spot. ---",
        ),
        ("kind = \"light.impostor\"\n", "kind = \"light.envmap\"\n"),
    ];
    let p = assert_twin("mixed-reality", "mixed-reality-probe", &swaps);
    let probe = p.stages.iter().find(|s| s.kind == "light.envmap").unwrap();
    assert_eq!(probe.params.str("source"), "attachment");
    assert!(p.stages.iter().all(|s| s.kind != "light.impostor"));
}

/// The Voxel Cone Tracing pipeline with temporal reuse is the default chain with the
/// voxel volume built and the query swapped, nothing else changed.
#[test]
fn the_vct_reuse_pipeline_is_the_default_chain_with_cones_through_the_voxels() {
    let swaps = [
        (
            "-> light.impostor -> light.importance ->",
            "-> light.impostor, light.voxels -> light.importance ->",
        ),
        (
            "kind = \"light.importance\"\n",
            "kind = \"light.voxels\"\n\n[[stage]]\nkind = \"light.importance\"\n",
        ),
        (
            "params = { primary = 1, direct = 1, indirect = 1,",
            "params = { query = \"vct\", primary = 1, direct = 1, indirect = 1,",
        ),
    ];
    let p = assert_twin("mixed-reality", "mixed-reality-vct-reuse", &swaps);
    let path = p.stages.iter().find(|s| s.kind == "sample.path").unwrap();
    assert_eq!(path.params.str("query"), "vct");
    assert!(path.params.bool("visibility"));
    assert!(p.stages.iter().any(|s| s.kind == "light.voxels"));
}

/// The area-light pipelines (paper 004) are their reference twins with the light model,
/// sample.val and an unfiltered composite swapped in for sampling and filtering.
#[test]
fn the_val_pipelines_are_their_twins_with_area_lights_swapped_in() {
    let sampling = "[[stage]]\nkind = \"sample.path\"\n\n[[stage]]\nkind = \"filter.axis_aligned\"\n\n[[stage]]\nkind = \"composite.differential\"\n";
    let area_lights = "[[stage]]\nkind = \"light.split\"\nevery = 8\n\n[[stage]]\nkind = \"light.val\"\nevery = 8\nlag = 1\n\n[[stage]]\nkind = \"sample.val\"\nparams = { shadow_updates = 4 }\n\n[[stage]]\nkind = \"composite.differential\"\ninputs = { e_r_dir = \"e_r_dir\", e_r_ind = \"e_r_ind\", e_rv_dir = \"e_rv_dir\", e_rv_ind = \"e_rv_ind\" }\n";
    for (twin, name) in [
        ("mixed-reality-reference", "mixed-reality-val"),
        (
            "mixed-reality-reference-livingroom1",
            "mixed-reality-val-livingroom1",
        ),
    ] {
        let swaps = [
            (
                "-> sample.path -> filter.axis_aligned ->",
                "-> light.split -> light.val -> sample.val ->",
            ),
            (
                "# --- Sampling, filtering, compositing. ---",
                "# --- Area lights and SH (paper 004 Sec. 4), shading, compositing. ---",
            ),
            (sampling, area_lights),
        ];
        let p = assert_twin(twin, name, &swaps);
        assert!(p.stages.iter().any(|s| s.kind == "sample.val"), "{name}");
        assert!(!p.stages.iter().any(|s| s.kind == "sample.path"), "{name}");
    }
}

/// The impostor queries read light.impostor's map: a pipeline where no stage makes
/// it is refused when it loads, naming the missing product and the stage.
#[test]
fn an_impostor_query_without_an_environment_map_is_refused_at_load_time() {
    let text = std::fs::read_to_string(format!(
        "{}/pipelines/mixed-reality-reference.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
    .replacen(
        "kind = \"light.impostor\"\n",
        "kind = \"light.impostor\"\noutputs = { environment = \"room\" }\n",
        1,
    )
    .replacen(
        "kind = \"light.importance\"\n",
        "kind = \"light.importance\"\ninputs = { environment = \"room\" }\n",
        1,
    )
    .replacen(
        "kind = \"filter.axis_aligned\"\n",
        "kind = \"filter.axis_aligned\"\ninputs = { environment = \"room\" }\n",
        1,
    );
    let source = |text: String| SourceFile {
        name: "p.toml".into(),
        text,
    };
    // ssrt does not read it: the pipeline loads.
    Pipeline::parse(&source(text.clone()), &relume::stages::registry()).unwrap();
    let dit = text.replacen(
        "kind = \"sample.path\"\n",
        "kind = \"sample.path\"\nparams = { query = \"dit\" }\n",
        1,
    );
    let Err(err) = Pipeline::parse(&source(dit), &relume::stages::registry()) else {
        panic!("a dit query with no `environment` product loaded");
    };
    let err = err.to_string();
    assert!(
        err.contains("`environment`") && err.contains("sample.path"),
        "{err}"
    );
}

/// `--set STAGE.PARAM=VALUE` changes a parameter as if the file said so, and a bad
/// override is reported on its own line, with the file's checks.
#[test]
fn set_overrides_change_parameters_and_report_their_own_line() {
    use relume::graph::ParamOverride;
    let src = SourceFile {
        name: "pipelines/mixed-reality-vct.toml".into(),
        text: std::fs::read_to_string(format!(
            "{}/pipelines/mixed-reality-vct.toml",
            env!("CARGO_MANIFEST_DIR")
        ))
        .unwrap(),
    };
    let set =
        |list: &[&str]| -> Vec<ParamOverride> { list.iter().map(|s| s.parse().unwrap()).collect() };
    let p = Pipeline::parse_with(
        &src,
        &relume::stages::registry(),
        &set(&[
            "sample.path.query=em",
            "sample.path.direct=8",
            "write.hdr.formats=[\"exr\"]",
        ]),
    )
    .unwrap();
    let path = p.stages.iter().find(|s| s.kind == "sample.path").unwrap();
    assert_eq!(path.params.str("query"), "em");
    assert_eq!(path.params.int("direct"), 8);
    // The file's own value stays where it is not overridden.
    assert_eq!(path.params.int("cache_size"), 8);
    assert_eq!(path.inputs["environment"], "environment");
    let err = |list: &[&str]| {
        Pipeline::parse_with(&src, &relume::stages::registry(), &set(list))
            .unwrap_err()
            .to_string()
    };
    let typo = err(&["sample.path.quer=vct"]);
    assert!(
        typo.contains("unknown parameter `quer`")
            && typo.contains("# --set sample.path.quer = \"vct\"")
            && typo.contains("did you mean `query`?"),
        "{typo}"
    );
    let range = err(&["sample.path.direct=500"]);
    assert!(range.contains("out of range (0 to 64)"), "{range}");
    let stage = err(&["sample.paths.direct=5"]);
    assert!(
        stage.contains("no stage named `sample.paths`") && stage.contains("light.voxels"),
        "{stage}"
    );
}

/// The tracked pipelines are their twins with `pose.track` in place of the recording's
/// poses: decode's pose renamed `recorded_pose`, the tracker after it, nothing else
/// changed; every stage that read `pose` now reads the tracker's.
#[test]
fn the_tracked_pipelines_are_their_twins_with_the_tracker_giving_poses() {
    let tracker = "kind = \"decode\"\noutputs = { pose = \"recorded_pose\" }\n\n\
# The camera's pose from color and depth, aligned to the depth fused so far (depth.fuse's\n\
# below, a frame back; see pipelines/tracking.toml and `relume stages pose.track`);\n\
# started from the recording's first pose where it has one, else from the identity.\n\
[[stage]]\nkind = \"pose.track\"\nparams = { model = \"depth.fuse\" }\n";
    for (twin, name, description) in [
        (
            "acquisition",
            "acquisition-tracked",
            (
                "decode -> gbuffer.splat",
                "decode -> pose.track -> gbuffer.splat",
            ),
        ),
        (
            "mixed-reality",
            "mixed-reality-tracked",
            (
                "acquisition -> light.impostor",
                "acquisition (poses from pose.track) -> light.impostor",
            ),
        ),
        (
            "mixed-reality-livingroom1",
            "mixed-reality-livingroom1-tracked",
            (
                "acquisition -> light.impostor",
                "acquisition (poses from pose.track) -> light.impostor",
            ),
        ),
    ] {
        let swaps = [description, ("kind = \"decode\"\n", tracker)];
        let p = assert_twin(twin, name, &swaps);
        assert_eq!(p.stages[1].kind, "pose.track", "{name}");
        // Its model is depth.fuse's map, a frame back.
        assert_eq!(p.stages[1].inputs["fused"], "fused_depth@prev", "{name}");
        assert!(
            p.feedback
                .iter()
                .any(|f| p.stages[f.producer].kind == "depth.fuse" && f.consumer == 1),
            "{name}: {:?}",
            p.feedback
        );
        let registry = relume::stages::registry();
        assert_eq!(
            relume::stages::track::reads_recorded_pose(&p.stages, &registry),
            None,
            "{name}"
        );
        // Its twin reads the recording's: the first stage after decode that needs one.
        let twin = Pipeline::load(
            std::path::Path::new(&format!(
                "{}/pipelines/{twin}.toml",
                env!("CARGO_MANIFEST_DIR")
            )),
            &registry,
        )
        .unwrap();
        let reader = relume::stages::track::reads_recorded_pose(&twin.stages, &registry)
            .expect("the twin reads the recording's poses");
        assert_eq!(
            (
                reader.stage.as_str(),
                reader.role.as_str(),
                reader.product.as_str()
            ),
            ("gbuffer.splat", "pose", "pose"),
            "{name}"
        );
    }
}
