//! Pipeline configs: unknown kinds, parameters, roles, wrong types, out-of-range values
//! and products nobody produces are load-time errors with file, line, column and hint.

use relume::graph::{ConfigError, Params, Pipeline, Registry, SourceFile};
use relume::recording::{Header, Intrinsics};

fn load(text: &str) -> Result<Pipeline, ConfigError> {
    Pipeline::parse(
        &SourceFile {
            name: "pipelines/p.toml".into(),
            text: text.into(),
        },
        &Registry::builtin(),
    )
}

fn error(text: &str) -> ConfigError {
    load(text).expect_err("the config is rejected")
}

#[test]
fn the_default_pipeline_chains_the_four_stages() {
    let p = Pipeline::builtin_default(&Registry::builtin()).unwrap();
    let kinds: Vec<&str> = p.stages.iter().map(|s| s.kind).collect();
    assert_eq!(
        kinds,
        ["decode", "depth.to_points", "normals.cross", "write"]
    );
    let on_disk = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/pipelines/default.toml"
    ))
    .unwrap();
    assert_eq!(
        on_disk,
        relume::graph::pipeline::DEFAULT_PIPELINE_TOML,
        "the built-in copy is the file"
    );
}

#[test]
fn unknown_kind_suggests_the_closest() {
    let e = error("[[stage]]\nkind = \"decode\"\n\n[[stage]]\nkind = \"normals.crss\"\n");
    assert_eq!(
        (e.file.as_str(), e.line, e.column),
        ("pipelines/p.toml", 5, 8)
    );
    assert_eq!(e.message, "unknown stage kind `normals.crss`");
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `normals.cross`? `relume stages` lists every kind")
    );
    assert!(
        e.to_string()
            .contains("5 | kind = \"normals.crss\"\n  |        ^^^^^^^^^^^^^^"),
        "{e}"
    );
}

#[test]
fn unknown_parameter_names_the_key_and_lists_the_parameters() {
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\n[[stage]]\nkind = \"normals.cross\"\nparams = { stpe = 2 }\n",
    );
    assert_eq!((e.line, e.column), (7, 12));
    assert_eq!(
        e.message,
        "unknown parameter `stpe` for stage `normals.cross` (normals.cross)"
    );
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `step`? parameters of normals.cross: step, difference, max_depth_jump")
    );
}

#[test]
fn wrong_types_ranges_and_choices_are_located() {
    let head = "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\n[[stage]]\nkind = \"normals.cross\"\n";
    let e = error(&format!("{head}params = {{ step = \"two\" }}\n"));
    assert_eq!(
        (e.line, e.message.as_str()),
        (7, "parameter `step` must be an integer, found a string")
    );
    let e = error(&format!("{head}params = {{ step = 40 }}\n"));
    assert_eq!(e.message, "parameter `step` = 40 is out of range (1 to 16)");
    let e = error(&format!("{head}params = {{ difference = \"centrl\" }}\n"));
    assert_eq!(
        e.message,
        "parameter `difference` does not accept \"centrl\""
    );
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean \"central\"? choices: forward, central")
    );
    // A float parameter accepts an integer.
    load(&format!("{head}params = {{ max_depth_jump = 1 }}\n")).unwrap();
}

#[test]
fn inputs_must_be_produced_upstream() {
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"normals.cross\"\n[[stage]]\nkind = \"depth.to_points\"\n",
    );
    assert_eq!(
        e.line, 4,
        "points at the stage's kind when the input is not mapped"
    );
    assert_eq!(
        e.message,
        "stage `normals.cross` reads `points` as its `points` input, but no upstream stage produces it"
    );
    assert_eq!(
        e.hint.as_deref(),
        Some(
            "`points` is produced later, by stage `depth.to_points`: move that stage up, or read `points@prev` for its previous-frame value"
        )
    );

    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\ninputs = { depth = \"dpeth\" }\n",
    );
    assert_eq!((e.line, e.column), (5, 20));
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `depth`? products available here: color, depth, pose, record")
    );
}

#[test]
fn kinds_of_products_must_match() {
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"normals.cross\"\ninputs = { points = \"depth\" }\n",
    );
    assert_eq!(
        e.message,
        "stage `normals.cross` reads `depth` as its `points` input, but `depth` is a depth map; it needs a point map"
    );
}

#[test]
fn roles_names_and_products_are_checked() {
    let e = error("[[stage]]\nkind = \"decode\"\noutputs = { colour = \"c\" }\n");
    assert_eq!(e.message, "stage `decode` has no output `colour`");
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `color`? outputs of this stage: color, depth, pose")
    );
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"decode\"\ninputs = { record = \"record\" }\n",
    );
    assert_eq!(
        e.message,
        "a second stage named `decode` (the first is on line 1)"
    );
    let e = error("[[stage]]\nkind = \"decode\"\n[[stage]]\nname = \"again\"\nkind = \"decode\"\n");
    assert_eq!(
        e.message,
        "stage `again` writes product `color`, which stage `decode` already produces"
    );
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\ninputs = { depth = \"record@prev\" }\n",
    );
    assert!(
        e.message.starts_with(
            "stage `depth.to_points` reads `record` as its `depth` input, but `record` is a record"
        ),
        "{e}"
    );
}

#[test]
fn structure_errors() {
    assert_eq!(error("").message, "the pipeline has no stages");
    let e = error("[pipeline]\nchannel_capacity = 0\n[[stage]]\nkind = \"decode\"\n");
    assert_eq!(
        (e.line, e.message.as_str()),
        (2, "channel_capacity must be between 1 and 1024, got 0")
    );
    let e = error("[[stage]]\nname = \"x\"\n");
    assert_eq!(e.message, "this stage has no `kind`");
    let e = error("[pipline]\n");
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `pipeline`? allowed: pipeline, stage")
    );
}

#[test]
fn every_builtin_kind_builds_from_its_defaults() {
    let registry = Registry::builtin();
    let header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
    let dir = tempfile::tempdir().unwrap();
    for info in registry.kinds() {
        let params = Params::defaults(info.params);
        let ports = (info.ports)(&params);
        let names = |ports: &[relume::graph::Port]| {
            ports
                .iter()
                .map(|p| (p.role.clone(), p.default_product.clone()))
                .collect()
        };
        let (inputs, outputs) = (names(&ports.inputs), names(&ports.outputs));
        let ctx = relume::graph::BuildContext {
            stage_name: info.kind,
            params: &params,
            inputs: &inputs,
            outputs: &outputs,
            header: &header,
            out_dir: dir.path(),
            seed: 1,
            objects: &Default::default(),
        };
        assert!(
            (info.build)(&ctx).is_ok(),
            "{} builds from its defaults",
            info.kind
        );
        assert!(
            !info.summary.is_empty() && info.params.iter().all(|p| !p.doc.is_empty()),
            "{} is documented",
            info.kind
        );
    }
}
