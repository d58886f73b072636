//! `scripts/bvh_peer.py`: relume's objects' BVH beside Embree 4 (PyPI's `embreex`) on
//! the same triangles and rays. Here only what does not depend on the machine's speed:
//! both peers find the same nearest hits (the script exits with status 2 when fewer
//! than 99.9 % of a scene's rays agree), on the default pipeline's objects and on the
//! 100k-triangle mesh, for camera and bounce rays; and the report has its rows.
//!
//! The Python side runs in a virtual environment made once under the target folder by
//! `pip install embreex==4.4.0.post1 numpy` (about 20 s and 60 MB here). The script
//! runs the `bvh_rate` example, which `cargo test` builds beside this test.

mod common;

use common::{stdout, succeeded};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

fn python() -> &'static Path {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    common::venv::python(
        &PYTHON,
        "embree-venv",
        &["embreex==4.4.0.post1", "numpy"],
        "import numpy, embreex.rtcore_scene",
    )
}

/// The `bvh_rate` example of this build (target/PROFILE/examples/, beside deps/).
fn example() -> PathBuf {
    let exe = std::env::current_exe().expect("the test's path");
    let profile_dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("the test binary lies in PROFILE/deps");
    let example = profile_dir.join("examples/bvh_rate");
    assert!(
        example.exists(),
        "{} is missing: `cargo test` builds the examples with the tests \
         (or run `cargo build --example bvh_rate`)",
        example.display()
    );
    example
}

#[test]
fn relume_and_embree_find_the_same_nearest_hits() {
    let work = tempfile::tempdir().unwrap();
    let out = Command::new(python())
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/bvh_peer.py"))
        .arg("--relume-example")
        .arg(example())
        .args(["--rays", "20000", "--repeat", "1", "--json", "--work"])
        .arg(work.path())
        .output()
        .expect("run python");
    let out = succeeded("bvh_peer.py", out);
    let report: Value = serde_json::from_str(&stdout(&out)).expect("the report is JSON");
    let rows = report["rows"].as_array().expect("rows");
    let names: Vec<(String, String)> = rows
        .iter()
        .map(|r| {
            (
                r["scene"].as_str().unwrap().to_string(),
                r["rays"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    assert_eq!(
        names,
        [
            ("default", "camera"),
            ("default", "bounce"),
            ("mesh100k", "camera"),
            ("mesh100k", "bounce")
        ]
        .map(|(s, r)| (s.to_string(), r.to_string()))
    );
    for row in rows {
        let agree = row["agree"].as_f64().unwrap();
        assert!(agree >= 0.999, "{row}");
        // Both kinds of rays meet the objects, and miss them, in numbers.
        let hits = row["hit_share"].as_f64().unwrap();
        assert!((0.1..0.9).contains(&hits), "{row}");
    }
    // The default's objects are the torus and the ball of pipelines/default.toml.
    assert!(rows[0]["triangles"].as_u64().unwrap() > 1000, "{}", rows[0]);
    assert_eq!(rows[2]["triangles"].as_u64(), Some(2 * 224 * 224));
}
