//! `[[object]]` tables of a pipeline config, checked key by key into [`ObjectSpec`]s and
//! built into the pipeline's [`VirtualScene`]. Errors follow the config style: file, line
//! and column of the offending value, and a hint (the keys a shape takes, the shapes
//! there are, the closest spelling).

use glam::{Vec2, Vec3};
use relume_graph::config::{ConfigError, Located, RawValue, SourceFile, TableDecl};
use relume_graph::params::{a, did_you_mean};
use relume_recording::MAX_IMAGE_SIDE;
use relume_scene::objects::anchor::{Anchor, AnchorFrame};
use relume_scene::objects::motion::MAX_KEYFRAMES;
use relume_scene::objects::{
    Keyframe, MAX_TRANSLATION, Material, Motion, ObjectError, ObjectSpec, Shape, VirtualScene,
};
use std::ops::Range;

/// The type and bounds of an object key.
#[derive(Clone, Copy)]
pub(super) enum Type {
    Float(f64, f64),
    Int(i64, i64),
    /// An array of N numbers, each in the bounds.
    Numbers(usize, f64, f64),
    /// An array of 1 to N numbers, each in the bounds.
    List(usize, f64, f64),
    /// An array of 1 to N arrays of 3 numbers, each in the bounds.
    Triples(usize, f64, f64),
    Str,
}

pub(super) struct Key {
    pub(super) name: &'static str,
    pub(super) ty: Type,
    pub(super) doc: &'static str,
}

pub(super) const fn key(name: &'static str, ty: Type, doc: &'static str) -> Key {
    Key { name, ty, doc }
}

const LENGTH: Type = Type::Float(1e-4, 1e3);

/// Keys every object takes.
const COMMON: &[Key] = &[
    key(
        "name",
        Type::Str,
        "names the object in messages; default: the shape",
    ),
    key("shape", Type::Str, "sphere, box, torus, quad or mesh"),
    key(
        "translation",
        Type::Numbers(3, -(MAX_TRANSLATION as f64), MAX_TRANSLATION as f64),
        "position of the object's origin [x, y, z], metres, in the world or in the anchor's frame; default [0, 0, 0]",
    ),
    key(
        "rotation_deg",
        Type::Numbers(3, -3600.0, 3600.0),
        "rotation about x, then y, then z (R = Rz Ry Rx) of the world or the anchor's frame, degrees; default [0, 0, 0]",
    ),
    key("scale", Type::Float(1e-4, 1e4), "uniform scale; default 1"),
    key(
        "albedo",
        Type::Numbers(3, 0.0, 1.0),
        "diffuse albedo k_V [r, g, b]; default [0.7, 0.7, 0.7]",
    ),
    key(
        "exponent",
        Type::Float(0.0, 1e5),
        "Phong exponent, 0 = diffuse; default 0",
    ),
    key(
        "anchor",
        Type::Str,
        "what translation and rotation_deg are measured from: world (the recording's coordinates; the default), floor (the floor found in frames `frame` to `frame` + 4) or surface (the surface seen at at_pixel; implied by at_pixel)",
    ),
    key(
        "at_pixel",
        Type::Numbers(2, 0.0, MAX_IMAGE_SIDE as f64),
        "[u, v], a pixel of frame `frame`'s color image: the object stands on the surface seen there, or with anchor = \"floor\" where its view ray meets the floor (default: the image centre)",
    ),
    key(
        "frame",
        Type::Int(0, 1_000_000_000),
        "the frame at_pixel is a pixel of, and the first of the 5 frames the floor is found in; default 0",
    ),
    key(
        "keyframes",
        Type::List(MAX_KEYFRAMES, 0.0, 1e9),
        "frames (of the recording) at which the object stands at the poses keyframe_translation and keyframe_rotation_deg give, ascending: it moves along them (linear positions, slerp rotations) and holds the first pose before the first, the last after the last",
    ),
    key(
        "keyframe_translation",
        Type::Triples(
            MAX_KEYFRAMES,
            -(MAX_TRANSLATION as f64),
            MAX_TRANSLATION as f64,
        ),
        "[[x, y, z], ...]: the translation at each of `keyframes`, metres, in place of translation",
    ),
    key(
        "keyframe_rotation_deg",
        Type::Triples(MAX_KEYFRAMES, -3600.0, 3600.0),
        "[[x, y, z], ...]: the rotation at each of `keyframes`, degrees, in place of rotation_deg",
    ),
    key(
        "velocity",
        Type::Numbers(3, -100.0, 100.0),
        "[x, y, z], metres per frame: the object moves from translation (where it is at frame 0) at this constant velocity",
    ),
];

/// An object as declared, with where its anchor keys were written (for errors found
/// when it is placed against a recording).
#[derive(Clone, Debug)]
pub struct DeclaredObject {
    pub spec: ObjectSpec,
    /// `None` for objects in world coordinates.
    pub sites: Option<AnchorSites>,
}

/// Where an anchored object's keys stand in its config: each is an error at that
/// place, to be [`ConfigError::retold`] with what went wrong.
#[derive(Clone, Debug)]
pub struct AnchorSites {
    /// `anchor` (or `at_pixel` when it implies the anchor).
    pub anchor: ConfigError,
    pub at_pixel: Option<ConfigError>,
    pub frame: Option<ConfigError>,
}

/// The `[[object]]` tables of a config: every object as declared, and the scene of
/// those in world coordinates (anchored ones join it when placed).
#[derive(Clone, Debug, Default)]
pub struct Objects {
    pub declared: Vec<DeclaredObject>,
    pub world_scene: VirtualScene,
}

/// Keys of each shape, in the order of [`Shape::NAMES`].
const SHAPE_KEYS: [&[Key]; 5] = [
    &[
        key("radius", LENGTH, "metres; default 0.25"),
        key(
            "segments",
            Type::Int(4, 1024),
            "segments around the y axis (half as many rings); default 48",
        ),
    ],
    &[key(
        "size",
        Type::Numbers(3, 1e-4, 1e3),
        "edge lengths [x, y, z], metres; default [0.3, 0.3, 0.3]",
    )],
    &[
        key("major_radius", LENGTH, "ring radius, metres; default 0.25"),
        key("minor_radius", LENGTH, "tube radius, metres; default 0.08"),
        key(
            "segments",
            Type::Int(3, 1024),
            "segments around the ring; default 64",
        ),
        key(
            "minor_segments",
            Type::Int(3, 1024),
            "segments around the tube; default 32",
        ),
    ],
    &[key(
        "size",
        Type::Numbers(2, 1e-4, 1e4),
        "extents [x, z] of the rectangle in the xz plane, metres; default [1, 1]",
    )],
    &[key(
        "path",
        Type::Str,
        "OBJ file, relative to the pipeline file's directory",
    )],
];

/// One key of `[[object]]` tables, for help pages (`relume objects`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct KeyDoc {
    pub name: &'static str,
    /// The shape that takes it, or `None` for keys every object takes.
    pub shape: Option<&'static str>,
    /// "string", "number", "integer", or "array of N numbers".
    pub kind: String,
    /// Inclusive bounds of numbers (of each number of an array).
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// What it means, and its default.
    pub doc: &'static str,
}

/// The help page's entry of `k` (taken by `shape`, or by every table: `None`).
pub(super) fn key_doc(shape: Option<&'static str>, k: &Key) -> KeyDoc {
    let (kind, min, max) = match k.ty {
        Type::Float(lo, hi) => ("number".to_string(), Some(lo), Some(hi)),
        Type::Int(lo, hi) => ("integer".to_string(), Some(lo as f64), Some(hi as f64)),
        Type::Numbers(n, lo, hi) => (format!("array of {n} numbers"), Some(lo), Some(hi)),
        Type::List(n, lo, hi) => (format!("array of 1 to {n} numbers"), Some(lo), Some(hi)),
        Type::Triples(n, lo, hi) => (
            format!("array of 1 to {n} arrays of 3 numbers"),
            Some(lo),
            Some(hi),
        ),
        Type::Str => ("string".to_string(), None, None),
    };
    KeyDoc {
        name: k.name,
        shape,
        kind,
        min,
        max,
        doc: k.doc,
    }
}

/// Every key `[[object]]` tables take: those of every object, then each shape's.
pub fn key_docs() -> Vec<KeyDoc> {
    let common = COMMON.iter().map(|k| key_doc(None, k));
    let shapes = Shape::NAMES
        .iter()
        .zip(SHAPE_KEYS)
        .flat_map(|(&shape, keys)| keys.iter().map(move |k| key_doc(Some(shape), k)));
    common.chain(shapes).collect()
}

/// A checked value.
pub(super) enum Value {
    Number(f64),
    Numbers(Vec<f64>),
    Triples(Vec<[f64; 3]>),
    Str(String),
}

/// Checks the `[[object]]` tables of the config `src` and builds the scene of those in
/// world coordinates (empty when there are none); anchored objects are checked the
/// same way, built in the world frame and set aside. Mesh paths resolve against the
/// directory of `src.name`.
pub fn resolve(decls: &[TableDecl], src: &SourceFile) -> Result<Objects, ConfigError> {
    let base = src.base_dir();
    let mut names: Vec<(String, usize)> = Vec::new();
    let mut triangles = Vec::new();
    let mut materials = Vec::new();
    let mut declared = Vec::new();
    for decl in decls {
        let get = |name: &str| decl.entries.iter().find(|(k, _)| k.value == name);
        let line = src.line_col(decl.span.start).0;
        // The shape first: it says which keys are allowed.
        let Some((_, shape_value)) = get("shape") else {
            return Err(src.error(
                decl.span.clone(),
                "this object has no `shape`",
                Some(format!(
                    "e.g. shape = \"sphere\"; shapes: {}",
                    Shape::NAMES.join(", ")
                )),
            ));
        };
        let shape_name = match &shape_value.value {
            RawValue::Str(s) => s.as_str(),
            other => {
                return Err(src.error(
                    shape_value.span.clone(),
                    format!("`shape` must be a string, found {}", a(other.type_name())),
                    Some(format!("shapes: {}", Shape::NAMES.join(", "))),
                ));
            }
        };
        let Some(shape_index) = Shape::NAMES.iter().position(|&s| s == shape_name) else {
            let list = Shape::NAMES.join(", ");
            let hint = match did_you_mean(shape_name, Shape::NAMES.iter().copied()) {
                Some(s) => format!("did you mean `{s}`? shapes: {list}"),
                None => format!("shapes: {list}"),
            };
            return Err(src.error(
                shape_value.span.clone(),
                format!("unknown shape `{shape_name}`"),
                Some(hint),
            ));
        };
        let name = match get("name") {
            Some((_, v)) => match &v.value {
                RawValue::Str(s) => s.clone(),
                other => {
                    return Err(src.error(
                        v.span.clone(),
                        format!("`name` must be a string, found {}", a(other.type_name())),
                        None,
                    ));
                }
            },
            None => shape_name.to_string(),
        };
        if let Some((_, first)) = names.iter().find(|(n, _)| *n == name) {
            let span = get("name").map_or(shape_value.span.clone(), |(_, v)| v.span.clone());
            return Err(src.error(
                span,
                format!("a second object named `{name}` (the first is on line {first})"),
                Some("give each object a unique `name`".into()),
            ));
        }
        names.push((name.clone(), line));
        let shape_keys = SHAPE_KEYS[shape_index];
        let mut values: Vec<(&'static str, Value, Range<usize>)> = Vec::new();
        for (k, v) in &decl.entries {
            let Some(spec) = COMMON
                .iter()
                .chain(shape_keys.iter())
                .find(|s| s.name == k.value)
            else {
                let own: Vec<&str> = shape_keys.iter().map(|s| s.name).collect();
                let all = COMMON.iter().chain(shape_keys.iter()).map(|s| s.name);
                let keys = format!(
                    "keys of {}: {}; of every object: {}",
                    a(shape_name),
                    own.join(", "),
                    COMMON.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
                );
                let hint = match did_you_mean(&k.value, all) {
                    Some(s) => format!("did you mean `{s}`? {keys}"),
                    None => keys,
                };
                return Err(src.error(
                    k.span.clone(),
                    format!(
                        "unknown key `{}` for object `{name}` ({shape_name})",
                        k.value
                    ),
                    Some(hint),
                ));
            };
            values.push((
                spec.name,
                check(src, spec, v, &format!("object `{name}`"))?,
                v.span.clone(),
            ));
        }
        let find = |key: &str| values.iter().find(|(n, _, _)| *n == key);
        let number = |key: &str, default: f64| match find(key) {
            Some((_, Value::Number(x), _)) => *x,
            _ => default,
        };
        let numbers = |key: &str, default: &[f64]| match find(key) {
            Some((_, Value::Numbers(x), _)) => x.clone(),
            _ => default.to_vec(),
        };
        let vec3 = |x: Vec<f64>| Vec3::new(x[0] as f32, x[1] as f32, x[2] as f32);
        let mut path_span = None;
        let shape = match shape_name {
            "sphere" => Shape::Sphere {
                radius: number("radius", 0.25) as f32,
                segments: number("segments", 48.0) as u32,
            },
            "box" => Shape::Box {
                size: vec3(numbers("size", &[0.3; 3])),
            },
            "torus" => {
                let (major, minor) = (number("major_radius", 0.25), number("minor_radius", 0.08));
                if minor >= major {
                    let span = find("minor_radius")
                        .or(find("major_radius"))
                        .map_or(decl.span.clone(), |(_, _, s)| s.clone());
                    return Err(src.error(
                        span,
                        format!(
                            "`minor_radius` ({minor}) of object `{name}` must be smaller than `major_radius` ({major})"
                        ),
                        Some("a tube wider than its ring would pass through itself".into()),
                    ));
                }
                Shape::Torus {
                    major_radius: major as f32,
                    minor_radius: minor as f32,
                    segments: number("segments", 64.0) as u32,
                    minor_segments: number("minor_segments", 32.0) as u32,
                }
            }
            "quad" => {
                let s = numbers("size", &[1.0, 1.0]);
                Shape::Quad {
                    size: Vec2::new(s[0] as f32, s[1] as f32),
                }
            }
            _ => {
                let Some((_, Value::Str(p), span)) = find("path") else {
                    return Err(src.error(
                        decl.span.clone(),
                        format!("object `{name}` is a mesh but has no `path`"),
                        Some(
                            "e.g. path = \"meshes/bunny.obj\": an OBJ file, relative to the pipeline file's directory"
                                .into(),
                        ),
                    ));
                };
                path_span = Some(span.clone());
                Shape::Mesh { path: base.join(p) }
            }
        };
        let (anchor, sites) = anchor(src, decl, &name, &values)?;
        let motion = motion(src, &name, &values)?;
        let spec = ObjectSpec {
            anchor,
            anchor_frame: None,
            motion,
            name: name.clone(),
            shape,
            translation: vec3(numbers("translation", &[0.0; 3])),
            rotation_deg: vec3(numbers("rotation_deg", &[0.0; 3])),
            scale: number("scale", 1.0) as f32,
            material: Material {
                albedo: vec3(numbers("albedo", &[0.7; 3])),
                exponent: number("exponent", 0.0) as f32,
            },
        };
        let built = spec.triangles_in(&AnchorFrame::WORLD, materials.len() as u32);
        let built = built.map_err(|e| {
            let span = match e {
                ObjectError::InvalidSpec { .. } => decl.span.clone(),
                _ => path_span.clone().unwrap_or(decl.span.clone()),
            };
            let message = match e {
                ObjectError::InvalidSpec { .. } => e.to_string(),
                _ => format!("object `{name}`: {e}"),
            };
            let hint = matches!(e, ObjectError::MeshUnreadable { .. }).then(|| {
                format!(
                    "relative paths resolve against the pipeline file's directory ({})",
                    if base.as_os_str().is_empty() {
                        "the current directory".to_string()
                    } else {
                        format!("`{}`", base.display())
                    }
                )
            });
            src.error(span, message, hint)
        })?;
        if sites.is_none() {
            triangles.extend(built);
            materials.push(spec.material);
        }
        declared.push(DeclaredObject { spec, sites });
    }
    Ok(Objects {
        declared,
        world_scene: VirtualScene::new(triangles, materials),
    })
}

/// The motion an object's `keyframes`, `keyframe_translation`, `keyframe_rotation_deg` and
/// `velocity` keys ask for (`None`: it stays put); errors for keys that contradict each
/// other or keyframes out of order, at the key.
fn motion(
    src: &SourceFile,
    name: &str,
    values: &[(&'static str, Value, Range<usize>)],
) -> Result<Option<Motion>, ConfigError> {
    let find = |key: &str| values.iter().find(|(n, _, _)| *n == key);
    let vec3 = |x: &[f64]| Vec3::new(x[0] as f32, x[1] as f32, x[2] as f32);
    let fixed = |key: &str, default: Vec3| match find(key) {
        Some((_, Value::Numbers(x), _)) => vec3(x),
        _ => default,
    };
    let triples = |key: &str| match find(key) {
        Some((_, Value::Triples(x), span)) => Some((x, span.clone())),
        _ => None,
    };
    let frames = match find("keyframes") {
        Some((_, Value::Numbers(x), span)) => Some((x, span.clone())),
        _ => None,
    };
    let (translations, rotations) = (
        triples("keyframe_translation"),
        triples("keyframe_rotation_deg"),
    );
    if let Some((_, _, span)) = find("velocity") {
        if let Some((key, _, _)) = ["keyframes", "keyframe_translation", "keyframe_rotation_deg"]
            .into_iter()
            .find_map(find)
        {
            return Err(src.error(
                span.clone(),
                format!("object `{name}` has both `velocity` and `{key}`"),
                Some("an object moves at a constant velocity or along keyframes, not both".into()),
            ));
        }
        if fixed("velocity", Vec3::ZERO) == Vec3::ZERO {
            return Err(src.error(
                span.clone(),
                format!("`velocity` of object `{name}` is zero"),
                Some("leave `velocity` out for an object that stays put".into()),
            ));
        }
        return Ok(Some(Motion::Velocity {
            start: fixed("translation", Vec3::ZERO),
            per_frame: fixed("velocity", Vec3::ZERO),
            rotation_deg: fixed("rotation_deg", Vec3::ZERO),
        }));
    }
    let Some((frames, frames_span)) = frames else {
        if let Some((key, _, span)) = ["keyframe_translation", "keyframe_rotation_deg"]
            .into_iter()
            .find_map(find)
        {
            return Err(src.error(
                span.clone(),
                format!("`{key}` of object `{name}` needs `keyframes`"),
                Some("keyframes = [f0, f1, ...] names the frame of each pose".into()),
            ));
        }
        return Ok(None);
    };
    if frames.len() < 2 {
        return Err(src.error(
            frames_span,
            format!("object `{name}` has a single keyframe"),
            Some(
                "a path needs two keyframes or more; one pose is `translation` and `rotation_deg`"
                    .into(),
            ),
        ));
    }
    if translations.is_none() && rotations.is_none() {
        return Err(src.error(
            frames_span,
            format!("object `{name}` has `keyframes` but no poses for them"),
            Some("give keyframe_translation = [[x, y, z], ...], keyframe_rotation_deg, or both: one per keyframe".into()),
        ));
    }
    for (keyed, still) in [
        ("keyframe_translation", "translation"),
        ("keyframe_rotation_deg", "rotation_deg"),
    ] {
        if let (Some(_), Some((_, _, span))) = (triples(keyed), find(still)) {
            return Err(src.error(
                span.clone(),
                format!("object `{name}` has both `{still}` and `{keyed}`"),
                Some(format!(
                    "`{keyed}` gives the {still} at every keyframe; leave `{still}` out"
                )),
            ));
        }
    }
    for (key, poses) in [
        ("keyframe_translation", &translations),
        ("keyframe_rotation_deg", &rotations),
    ] {
        if let Some((poses, span)) = poses
            && poses.len() != frames.len()
        {
            return Err(src.error(
                span.clone(),
                format!(
                    "`{key}` of object `{name}` has {} pose{} for {} keyframes",
                    poses.len(),
                    if poses.len() == 1 { "" } else { "s" },
                    frames.len()
                ),
                Some("give one [x, y, z] per frame of `keyframes`".into()),
            ));
        }
    }
    let keys: Vec<Keyframe> = frames
        .iter()
        .enumerate()
        .map(|(i, &frame)| Keyframe {
            frame,
            translation: translations
                .as_ref()
                .map_or(fixed("translation", Vec3::ZERO), |(t, _)| vec3(&t[i])),
            rotation_deg: rotations
                .as_ref()
                .map_or(fixed("rotation_deg", Vec3::ZERO), |(r, _)| vec3(&r[i])),
        })
        .collect();
    let motion = Motion::Keyframes(keys);
    motion
        .check()
        .map_err(|e| match (e.contains(" turn by "), &rotations) {
            // A turn too wide for one step: at the rotations.
            (true, Some((_, span))) => {
                src.error(span.clone(), format!("object `{name}`: {e}"), None)
            }
            _ => src.error(
                frames_span,
                format!("object `{name}`: {e}"),
                Some("list each keyframe's frame once, in ascending order".into()),
            ),
        })?;
    Ok(Some(motion))
}

/// The anchor an object's `anchor`, `at_pixel` and `frame` keys ask for, and where they
/// stand (`None` for world coordinates); errors for combinations that say nothing.
fn anchor(
    src: &SourceFile,
    decl: &TableDecl,
    name: &str,
    values: &[(&'static str, Value, Range<usize>)],
) -> Result<(Anchor, Option<AnchorSites>), ConfigError> {
    let find = |key: &str| values.iter().find(|(n, _, _)| *n == key);
    let site = |key: &str| find(key).map(|(_, _, span)| src.error(span.clone(), "", None));
    let at_pixel = match find("at_pixel") {
        Some((_, Value::Numbers(x), _)) => Some(Vec2::new(x[0] as f32, x[1] as f32)),
        _ => None,
    };
    let frame = match find("frame") {
        Some((_, Value::Number(x), _)) => Some(*x as usize),
        _ => None,
    };
    let named = match find("anchor") {
        Some((_, Value::Str(s), span)) => Some((s.as_str(), span.clone())),
        _ => None,
    };
    let anchor = match (named.as_ref().map(|(s, _)| *s), at_pixel) {
        (None, None) | (Some("world"), _) => {
            let stray = ["at_pixel", "frame"].into_iter().find_map(find);
            if let Some((key, _, span)) = stray {
                return Err(src.error(
                    span.clone(),
                    format!("`{key}` of object `{name}` applies only to an object anchored to the scene"),
                    Some(if named.is_some() {
                        "`anchor = \"world\"` places it in world coordinates: make it \"floor\" or \"surface\", or leave `anchor` out with `at_pixel` to stand it on the surface seen there".into()
                    } else {
                        "add `anchor = \"floor\"`, or `at_pixel = [u, v]` to stand it on the surface seen there".into()
                    }),
                ));
            }
            return Ok((Anchor::World, None));
        }
        (Some("floor"), at_pixel) => Anchor::Floor {
            at_pixel,
            frame: frame.unwrap_or(0),
        },
        (Some("surface") | None, Some(at_pixel)) => Anchor::Surface {
            at_pixel,
            frame: frame.unwrap_or(0),
        },
        (Some("surface"), None) => {
            let span = named.map_or(decl.span.clone(), |(_, span)| span);
            return Err(src.error(
                span,
                format!("object `{name}` is anchored to a surface but has no `at_pixel`"),
                Some("at_pixel = [u, v] names the pixel of frame `frame` (default 0) where that surface is seen".into()),
            ));
        }
        (Some(other), _) => {
            let list = Anchor::NAMES.join(", ");
            let hint = match did_you_mean(other, Anchor::NAMES.iter().copied()) {
                Some(s) => format!("did you mean `{s}`? anchors: {list}"),
                None => format!("anchors: {list}"),
            };
            let span = named.map_or(decl.span.clone(), |(_, span)| span);
            return Err(src.error(span, format!("unknown anchor `{other}`"), Some(hint)));
        }
    };
    let anchor_site = site("anchor").or_else(|| site("at_pixel"));
    let sites = AnchorSites {
        anchor: anchor_site.expect("an anchored object has `anchor` or `at_pixel`"),
        at_pixel: site("at_pixel"),
        frame: site("frame"),
    };
    Ok((anchor, Some(sites)))
}

/// Checks one value against its key's type and bounds.
/// Checks `value` against `spec`; errors name the key "of {owner}" (`object `torus``,
/// `light `lamp``).
pub(super) fn check(
    src: &SourceFile,
    spec: &Key,
    value: &Located<RawValue>,
    owner: &str,
) -> Result<Value, ConfigError> {
    let wrong_type = |expected: String, found: &RawValue, span: &Range<usize>| {
        src.error(
            span.clone(),
            format!(
                "`{}` of {owner} must be {}, found {}",
                spec.name,
                a(&expected),
                a(found.type_name())
            ),
            Some(spec.doc.to_string()),
        )
    };
    let in_range = |x: f64, lo: f64, hi: f64, span: &Range<usize>| {
        if x >= lo && x <= hi {
            return Ok(x);
        }
        Err(src.error(
            span.clone(),
            format!(
                "`{}` of {owner} = {x} is out of range ({lo} to {hi})",
                spec.name
            ),
            Some(spec.doc.to_string()),
        ))
    };
    let number = |v: &RawValue| match *v {
        RawValue::Float(f) => Some(f),
        RawValue::Int(i) => Some(i as f64),
        _ => None,
    };
    // An array of the wrong length: "`key` of object `o` must <what>, found <count>".
    let wrong_count = |what: String, count: usize| {
        src.error(
            value.span.clone(),
            format!("`{}` of {owner} must {what}, found {count}", spec.name),
            Some(spec.doc.to_string()),
        )
    };
    match (spec.ty, &value.value) {
        (Type::Str, RawValue::Str(s)) => Ok(Value::Str(s.clone())),
        (Type::Str, other) => Err(wrong_type("string".into(), other, &value.span)),
        (Type::Int(lo, hi), RawValue::Int(i)) => {
            in_range(*i as f64, lo as f64, hi as f64, &value.span).map(Value::Number)
        }
        (Type::Int(..), other) => Err(wrong_type("integer".into(), other, &value.span)),
        (Type::Float(lo, hi), v) => match number(v) {
            Some(x) => in_range(x, lo, hi, &value.span).map(Value::Number),
            None => Err(wrong_type("float".into(), v, &value.span)),
        },
        (Type::Numbers(n, ..), RawValue::Array(items)) if items.len() != n => Err(wrong_count(
            format!("be an array of {n} numbers"),
            items.len(),
        )),
        (Type::List(n, ..), RawValue::Array(items)) if items.is_empty() || items.len() > n => {
            Err(wrong_count(format!("hold 1 to {n} numbers"), items.len()))
        }
        (Type::Numbers(_, lo, hi) | Type::List(_, lo, hi), RawValue::Array(items)) => items
            .iter()
            .map(|item| match number(&item.value) {
                Some(x) => in_range(x, lo, hi, &item.span),
                None => Err(src.error(
                    item.span.clone(),
                    format!(
                        "`{}` of {owner} must hold numbers, found {}",
                        spec.name,
                        a(item.value.type_name())
                    ),
                    Some(spec.doc.to_string()),
                )),
            })
            .collect::<Result<Vec<f64>, _>>()
            .map(Value::Numbers),
        (Type::Numbers(n, ..), other) => Err(wrong_type(
            format!("array of {n} numbers"),
            other,
            &value.span,
        )),
        (Type::List(n, ..), other) => Err(wrong_type(
            format!("array of 1 to {n} numbers"),
            other,
            &value.span,
        )),
        (Type::Triples(n, ..), RawValue::Array(items)) if items.is_empty() || items.len() > n => {
            Err(wrong_count(
                format!("hold 1 to {n} arrays of 3 numbers"),
                items.len(),
            ))
        }
        (Type::Triples(_, lo, hi), RawValue::Array(items)) => {
            let triple = |item: &Located<RawValue>| {
                let not_triple = || {
                    src.error(
                        item.span.clone(),
                        format!(
                            "each item of `{}` of {owner} must be [x, y, z], found {}",
                            spec.name,
                            a(item.value.type_name())
                        ),
                        Some(spec.doc.to_string()),
                    )
                };
                let RawValue::Array(xyz) = &item.value else {
                    return Err(not_triple());
                };
                if xyz.len() != 3 {
                    return Err(not_triple());
                }
                let mut out = [0.0; 3];
                for (o, c) in out.iter_mut().zip(xyz) {
                    *o = match number(&c.value) {
                        Some(x) => in_range(x, lo, hi, &c.span)?,
                        None => return Err(not_triple()),
                    };
                }
                Ok(out)
            };
            items
                .iter()
                .map(triple)
                .collect::<Result<Vec<_>, _>>()
                .map(Value::Triples)
        }
        (Type::Triples(n, ..), other) => Err(wrong_type(
            format!("array of 1 to {n} arrays of 3 numbers"),
            other,
            &value.span,
        )),
    }
}
