//! Objects placed relative to the recorded scene (`anchor = "floor"`, `at_pixel`,
//! `frame`), checked against the synthetic room's ground truth (floor y = 0, +y up), and
//! the help page of `[[object]]` keys.

mod common;

use common::{ok, run_in, stderr, stdout};
use glam::{DMat3, Vec3};
use relume::graph::{ConfigError, Pipeline, SourceFile};
use relume::pinhole::Pinhole;
use relume::recording::{Replay, ReplayOptions, codec};
use relume::stages::world::PipelineObjects;
use relume::stages::world::Placement;
use std::path::{Path, PathBuf};

const DECODE: &str = "[[stage]]\nkind = \"decode\"\n";

/// A 320x240 synthetic recording of 6 frames in `dir`.
fn recording(dir: &Path) -> PathBuf {
    ok(run_in(
        dir,
        &[
            "synth",
            "-o",
            "room.relume",
            "--frames",
            "6",
            "--size",
            "320x240",
            "--seed",
            "5",
        ],
    ));
    dir.join("room.relume")
}

fn parse(objects: &str) -> Result<Pipeline, ConfigError> {
    let src = SourceFile {
        name: "a.toml".into(),
        text: format!("{DECODE}{objects}"),
    };
    Pipeline::parse(&src, &relume::stages::registry())
}

fn place(replay: &Replay, objects: &str) -> Result<(Pipeline, Vec<Placement>), ConfigError> {
    let mut pipeline = parse(objects).unwrap();
    let placements = pipeline.place_objects(replay)?;
    Ok((pipeline, placements))
}

fn angle_deg(a: Vec3, b: Vec3) -> f32 {
    a.normalize()
        .dot(b.normalize())
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// Frame 0's truth: its camera (color = depth), camera-to-world rotation and centre, and
/// per pixel the noise-free world point and world normal.
struct Truth {
    camera: Pinhole,
    rotation: glam::Mat3,
    position: Vec3,
    points: Vec<Vec3>,
    normals: Vec<Vec3>,
}

fn truth(replay: &Replay) -> Truth {
    let frame = replay.read_frame(0).unwrap();
    let pose = frame.pose.unwrap();
    let rotation = DMat3::from_quat(pose.rotation()).as_mat3();
    let position = pose.translation().as_vec3();
    let k = replay.recording.header().depth_intrinsics;
    let camera = Pinhole::new(&k, k.width, k.height);
    let t = frame.truth.unwrap();
    let depth = codec::decode_floats(&t.depth).unwrap();
    let normals = codec::decode_floats(&t.normals).unwrap();
    let (w, h) = (k.width, k.height);
    let mut truth = Truth {
        camera,
        rotation,
        position,
        points: Vec::new(),
        normals: Vec::new(),
    };
    for v in 0..h {
        for u in 0..w {
            let i = (v * w + u) as usize;
            let p = camera.back_project(u as f32, v as f32, depth[i]);
            truth.points.push(rotation * p + position);
            truth
                .normals
                .push(rotation * Vec3::from_slice(&normals[3 * i..3 * i + 3]));
        }
    }
    truth
}

impl Truth {
    /// The first pixel (row by row, on a grid of 8) whose 21 x 21 neighbourhood is one
    /// flat surface with normal `normal`, within `max_depth` metres.
    fn flat_pixel(&self, normal: Vec3, max_depth: f32) -> Option<(u32, u32)> {
        let (w, h) = (self.camera.width, self.camera.height);
        for v in (10..h - 10).step_by(8) {
            for u in (10..w - 10).step_by(8) {
                let centre = self.points[(v * w + u) as usize];
                if (centre - self.position).length() > max_depth {
                    continue;
                }
                let flat = (v - 10..=v + 10).all(|y| {
                    (u - 10..=u + 10).all(|x| {
                        let i = (y * w + x) as usize;
                        angle_deg(self.normals[i], normal) < 0.1
                            && (self.points[i] - centre).dot(normal).abs() < 1e-3
                    })
                });
                if flat {
                    return Some((u, v));
                }
            }
        }
        None
    }
}

#[test]
fn objects_anchored_to_the_floor_stand_on_the_true_floor() {
    let dir = tempfile::tempdir().unwrap();
    let replay = Replay::open(&recording(dir.path()), ReplayOptions::default()).unwrap();
    let truth = truth(&replay);
    let (u, v) = truth
        .flat_pixel(Vec3::Y, 3.0)
        .expect("frame 0 sees the floor");
    let (pipeline, placed) = place(
        &replay,
        &format!(
            "[[object]]\nname = \"ball\"\nshape = \"sphere\"\nradius = 0.1\nanchor = \"floor\"\ntranslation = [0, 0.1, 0]\n\
             [[object]]\nname = \"box\"\nshape = \"box\"\nsize = [0.2, 0.3, 0.2]\nanchor = \"floor\"\nat_pixel = [{u}, {v}]\ntranslation = [0, 0.15, 0]\n\
             [[object]]\nname = \"fixed\"\nshape = \"box\"\ntranslation = [0, 2, 0]\n"
        ),
    )
    .unwrap();
    assert_eq!(placed.len(), 2, "the world object is not placed");
    for p in &placed {
        assert!(p.origin.y.abs() < 0.01, "{p}");
        assert!(angle_deg(p.up, Vec3::Y) < 1.0, "{p}");
    }
    // The ball goes where the image centre's ray meets the floor; the box below its pixel.
    let centre = truth.camera.ray(
        (truth.camera.width - 1) as f32 / 2.0,
        (truth.camera.height - 1) as f32 / 2.0,
    );
    let direction = truth.rotation * centre;
    let on_floor = truth.position - direction * (truth.position.y / direction.y);
    assert!(
        (placed[0].origin - on_floor).length() < 0.03,
        "{} vs {on_floor}",
        placed[0]
    );
    let seen = truth.points[(v * truth.camera.width + u) as usize];
    assert!(
        (placed[1].origin - seen).length() < 0.02,
        "{} vs {seen}",
        placed[1]
    );
    // Standing on it: the lowest vertex of every anchored object at y = 0.
    let scene = &pipeline.objects();
    assert_eq!(scene.materials.len(), 3);
    for material in 0..2 {
        let lowest = scene
            .triangles
            .iter()
            .filter(|t| t.material == material)
            .flat_map(|t| t.vertices)
            .map(|p| p.y)
            .fold(f32::INFINITY, f32::min);
        assert!(
            lowest.abs() < 0.012,
            "object {material}: lowest vertex at y = {lowest}"
        );
    }
    assert!(pipeline.unplaced_objects().is_empty());
    assert!(
        placed[0]
            .to_string()
            .starts_with("object `ball`: anchored on the floor (a plane through "),
        "{}",
        placed[0]
    );
}

#[test]
fn objects_at_a_pixel_stand_on_the_surface_seen_there() {
    let dir = tempfile::tempdir().unwrap();
    let replay = Replay::open(&recording(dir.path()), ReplayOptions::default()).unwrap();
    let truth = truth(&replay);
    // A level surface and an upright one (a wall or a block's side), both seen in frame 0.
    let level = truth
        .flat_pixel(Vec3::Y, 3.5)
        .expect("frame 0 sees the floor");
    let upright = [Vec3::X, Vec3::NEG_X, Vec3::Z, Vec3::NEG_Z]
        .into_iter()
        .find_map(|n| Some((n, truth.flat_pixel(n, 3.5)?)))
        .expect("frame 0 sees an upright surface");
    for (normal, (u, v)) in [(Vec3::Y, level), upright] {
        let (_, placed) = place(
            &replay,
            &format!("[[object]]\nshape = \"box\"\nat_pixel = [{u}, {v}]\nframe = 0\n"),
        )
        .unwrap();
        let seen = truth.points[(v * truth.camera.width + u) as usize];
        let p = &placed[0];
        assert!(
            (p.origin - seen).length() < 0.03,
            "{p} vs {seen} at ({u}, {v})"
        );
        assert!(
            angle_deg(p.up, normal) < 3.0,
            "{p} vs {normal} at ({u}, {v})"
        );
        assert!(p.how.starts_with(&format!(
            "on the surface seen at pixel ({u}, {v}) of frame 0"
        )));
    }
}

#[test]
fn anchors_the_recording_cannot_give_are_errors_at_their_keys() {
    let dir = tempfile::tempdir().unwrap();
    let path = recording(dir.path());
    let replay = Replay::open(&path, ReplayOptions::default()).unwrap();
    let error = |objects: &str| place(&replay, objects).unwrap_err();
    let e =
        error("[[object]]\nname = \"ball\"\nshape = \"sphere\"\nanchor = \"floor\"\nframe = 50\n");
    assert_eq!((e.line, e.column), (7, 9));
    assert_eq!(
        e.message,
        format!(
            "object `ball`: frame 50 is past the end of `{}`, which has 6 frames",
            path.display()
        )
    );
    let e = error("[[object]]\nshape = \"box\"\nat_pixel = [320, 10]\n");
    assert_eq!((e.line, e.column), (5, 12));
    assert_eq!(
        e.message,
        format!(
            "object `box`: pixel (320, 10) lies outside `{}`'s 320x240 color images",
            path.display()
        )
    );
    assert_eq!(
        e.hint.as_deref(),
        Some("at_pixel = [u, v] runs from the top-left pixel [0, 0] to [319, 239]")
    );
    // A pixel on a wall asks for the floor: the floor's plane runs on behind the wall.
    let truth = truth(&replay);
    let (u, v) = [Vec3::X, Vec3::NEG_X, Vec3::Z, Vec3::NEG_Z]
        .into_iter()
        .find_map(|n| truth.flat_pixel(n, 6.0))
        .expect("frame 0 sees a wall");
    let e = error(&format!(
        "[[object]]\nshape = \"box\"\nanchor = \"floor\"\nat_pixel = [{u}, {v}]\n"
    ));
    assert!(
        e.message.starts_with(&format!(
            "object `box`: pixel ({u}, {v}) of frame 0 does not see the floor: it sees a surface "
        )),
        "{e}"
    );
}

#[test]
fn anchor_keys_that_say_nothing_are_config_errors() {
    let object = |body: &str| parse(&format!("[[object]]\nshape = \"box\"\n{body}")).unwrap_err();
    let e = object("anchor = \"flor\"\n");
    assert_eq!(e.message, "unknown anchor `flor`");
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `floor`? anchors: world, floor, surface")
    );
    let e = object("frame = 3\n");
    assert_eq!(
        e.message,
        "`frame` of object `box` applies only to an object anchored to the scene"
    );
    let e = object("anchor = \"world\"\nat_pixel = [1, 2]\n");
    assert_eq!((e.line, e.column), (6, 12));
    assert_eq!(
        e.message,
        "`at_pixel` of object `box` applies only to an object anchored to the scene"
    );
    assert!(
        e.hint.as_deref().unwrap().starts_with(
            "`anchor = \"world\"` places it in world coordinates: make it \"floor\" or \"surface\""
        ),
        "{e}"
    );
    let e = object("anchor = \"surface\"\n");
    assert_eq!(
        e.message,
        "object `box` is anchored to a surface but has no `at_pixel`"
    );
    let e = object("at_pixel = [1, 2, 3]\n");
    assert_eq!(
        e.message,
        "`at_pixel` of object `box` must be an array of 2 numbers, found 3"
    );
}

#[test]
fn an_anchored_object_not_placed_stops_the_build_instead_of_vanishing() {
    let pipeline =
        parse("[[object]]\nname = \"ball\"\nshape = \"sphere\"\nanchor = \"floor\"\n").unwrap();
    assert_eq!(pipeline.unplaced_objects(), ["ball"]);
    assert!(
        pipeline.objects().is_empty(),
        "not in the world scene until placed"
    );
    let header =
        relume::recording::Header::new("h", relume::recording::Intrinsics::PRIMESENSE, 0.001);
    let dir = tempfile::tempdir().unwrap();
    let Err((stage, e)) = pipeline.build(&relume::stages::registry(), &header, dir.path(), 0)
    else {
        panic!("built with an unplaced object");
    };
    assert_eq!(stage, "decode");
    assert!(
        e.to_string()
            .contains("object `ball` is anchored to the scene and has not been placed"),
        "{e}"
    );
    // Beside a pipeline with the same (empty) world scene and the same stages, it shares
    // none of them, so the guard still stands.
    let plain = parse("").unwrap();
    let branches = [("a".to_string(), &plain), ("b".to_string(), &pipeline)];
    let graph = relume::graph::tree::StageGraph::shared(&branches);
    let dirs = [dir.path().join("a"), dir.path().join("b")];
    assert!(
        graph
            .build(&relume::stages::registry(), &header, &dirs, 0)
            .is_err()
    );
}

#[test]
fn runs_say_where_anchored_objects_went_and_validate_says_they_will_be() {
    let dir = tempfile::tempdir().unwrap();
    recording(dir.path());
    std::fs::write(
        dir.path().join("p.toml"),
        format!(
            "{DECODE}[[object]]\nname = \"ball\"\nshape = \"sphere\"\nradius = 0.1\nanchor = \"floor\"\ntranslation = [0, 0.1, 0]\n"
        ),
    )
    .unwrap();
    let o = ok(run_in(dir.path(), &["validate", "p.toml"]));
    assert!(
        stdout(&o).contains(
            "  object `ball`: anchored to the recording's floor, placed when a run opens it \
             (`--recording REC` places it now)\n"
        ),
        "{}",
        stdout(&o)
    );
    let o = ok(run_in(
        dir.path(),
        &[
            "replay",
            "room.relume",
            "-p",
            "p.toml",
            "--frames",
            "0..1",
            "--out",
            "o",
        ],
    ));
    let line = stderr(&o)
        .lines()
        .find(|l| l.starts_with("object `ball`: anchored on the floor (a plane through "))
        .map(str::to_string);
    assert!(line.is_some(), "{}", stderr(&o));
    // Where the object itself went: a ball of radius 0.1 lifted by 0.1 spans 0.2 in y
    // from the floor.
    let line = line.unwrap();
    let spans = &line[line
        .find("; the object spans [")
        .expect("the object's bounds")..];
    assert!(spans.ends_with(" m"), "{line}");
    // The same error a library user gets, with the caret under the key.
    std::fs::write(
        dir.path().join("bad.toml"),
        format!("{DECODE}[[object]]\nname = \"ball\"\nshape = \"sphere\"\nat_pixel = [5, 5]\nframe = 9\n"),
    )
    .unwrap();
    let o = run_in(
        dir.path(),
        &["replay", "room.relume", "-p", "bad.toml", "--out", "o2"],
    );
    assert_eq!(o.status.code(), Some(1));
    let past_the_end = "bad.toml:7:9: object `ball`: frame 9 is past the end of `room.relume`, which has 6 frames\n  |\n7 | frame = 9\n  |         ^";
    assert!(stderr(&o).contains(past_the_end), "{}", stderr(&o));
    // validate alone cannot know the recording; given it, validate says the same before
    // any run, and a pixel outside its images too.
    ok(run_in(dir.path(), &["validate", "bad.toml"]));
    let o = run_in(
        dir.path(),
        &["validate", "bad.toml", "--recording", "room.relume"],
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains(past_the_end), "{}", stderr(&o));
    std::fs::write(
        dir.path().join("bad.toml"),
        format!("{DECODE}[[object]]\nname = \"ball\"\nshape = \"sphere\"\nat_pixel = [500, 5]\n"),
    )
    .unwrap();
    let o = run_in(
        dir.path(),
        &["validate", "bad.toml", "--recording", "room.relume"],
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains(
            "bad.toml:6:12: object `ball`: pixel (500, 5) lies outside `room.relume`'s 320x240 color images"
        ),
        "{}",
        stderr(&o)
    );
    let o = ok(run_in(
        dir.path(),
        &["validate", "p.toml", "--recording", "room.relume"],
    ));
    assert!(
        stderr(&o).contains("object `ball`: anchored on the floor (a plane through "),
        "{}",
        stderr(&o)
    );
}

#[test]
fn the_objects_help_page_lists_every_key() {
    let dir = tempfile::tempdir().unwrap();
    let text = stdout(&ok(run_in(dir.path(), &["objects"])));
    let keys = relume::stages::world::config::key_docs();
    for key in &keys {
        assert!(
            text.contains(&format!("\n  {} ({}", key.name, key.kind)),
            "`{}` missing from:\n{text}",
            key.name
        );
    }
    for shape in relume::objects::Shape::NAMES {
        assert!(text.contains(&format!("Keys of shape = \"{shape}\":")));
    }
    let names: Vec<&str> = keys.iter().map(|k| k.name).collect();
    for key in [
        "anchor",
        "at_pixel",
        "frame",
        "translation",
        "albedo",
        "radius",
        "path",
    ] {
        assert!(names.contains(&key), "{key}");
    }
    // The [[light]] tables' keys follow, under their own heading.
    let lights = text
        .split("Keys of [[light]] tables")
        .nth(1)
        .expect("a [[light]] section");
    for key in relume::stages::world::lights::key_docs() {
        assert!(
            lights.contains(&format!("\n  {} ({}", key.name, key.kind)),
            "light key `{}` missing",
            key.name
        );
    }
    let json: serde_json::Value =
        serde_json::from_str(&stdout(&ok(run_in(dir.path(), &["objects", "--json"])))).unwrap();
    assert_eq!(json.as_array().unwrap().len(), keys.len());
    assert_eq!(json[0]["name"], "name");
    assert!(json[0]["shape"].is_null());
}
