//! The layers of ARCHITECTURE.md, checked: every workspace crate depends only on the
//! relume crates below it, in `[dependencies]` and `[dev-dependencies]` alike. Cargo
//! already refuses a crate that reaches up into one that depends on it; this test also
//! refuses the arrows the compiler would allow but the architecture does not (the graph
//! runtime using the scene, a scene crate using the runtime).

use std::collections::BTreeSet;
use std::path::Path;

/// Each crate and the relume crates it may use.
const LAYERS: &[(&str, &[&str])] = &[
    ("relume-base", &[]),
    ("relume-recording", &["relume-base"]),
    ("relume-scene", &["relume-base", "relume-recording"]),
    ("relume-graph", &["relume-base", "relume-recording"]),
    (
        "relume-stages",
        &[
            "relume-base",
            "relume-recording",
            "relume-scene",
            "relume-graph",
        ],
    ),
    (
        "relume-eval",
        &[
            "relume-base",
            "relume-recording",
            "relume-scene",
            "relume-graph",
            "relume-stages",
        ],
    ),
];

fn manifest(path: &Path) -> toml::Table {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.parse()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The relume crates a manifest names in its dependency tables.
fn relume_dependencies(m: &toml::Table) -> BTreeSet<String> {
    let mut tables: Vec<&toml::Table> = Vec::new();
    for key in ["dependencies", "dev-dependencies", "build-dependencies"] {
        if let Some(t) = m.get(key).and_then(|v| v.as_table()) {
            tables.push(t);
        }
    }
    if let Some(targets) = m.get("target").and_then(|v| v.as_table()) {
        for target in targets.values().filter_map(|v| v.as_table()) {
            for key in ["dependencies", "dev-dependencies", "build-dependencies"] {
                if let Some(t) = target.get(key).and_then(|v| v.as_table()) {
                    tables.push(t);
                }
            }
        }
    }
    tables
        .iter()
        .flat_map(|t| t.keys())
        .filter(|k| k.starts_with("relume"))
        .cloned()
        .collect()
}

#[test]
fn every_crate_uses_only_the_layers_below_it() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut found = BTreeSet::new();
    for entry in std::fs::read_dir(root.join("crates")).unwrap() {
        let path = entry.unwrap().path().join("Cargo.toml");
        let m = manifest(&path);
        let name = m["package"]["name"].as_str().unwrap().to_string();
        let allowed: BTreeSet<String> = LAYERS
            .iter()
            .find(|(n, _)| *n == name)
            .unwrap_or_else(|| panic!("{name} is not in ARCHITECTURE.md's table (LAYERS)"))
            .1
            .iter()
            .map(|s| s.to_string())
            .collect();
        let used = relume_dependencies(&m);
        let beyond: Vec<_> = used.difference(&allowed).collect();
        assert!(
            beyond.is_empty(),
            "{name} depends on {beyond:?}, which ARCHITECTURE.md puts above it or beside it"
        );
        found.insert(name);
    }
    let listed: BTreeSet<String> = LAYERS.iter().map(|(n, _)| n.to_string()).collect();
    assert_eq!(found, listed, "the workspace's crates and the table agree");
}

#[test]
fn the_runtime_knows_no_scene_or_stage() {
    let m = manifest(&Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/graph/Cargo.toml"));
    let used = relume_dependencies(&m);
    for forbidden in ["relume-scene", "relume-stages", "relume-eval"] {
        assert!(
            !used.contains(forbidden),
            "relume-graph depends on {forbidden}"
        );
    }
}
