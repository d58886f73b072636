//! `[[light]]` tables of a pipeline config, checked key by key into
//! [`SpotLight`]s: the light sources the pipeline knows of besides the environment
//! (paper 002 Sec. 3.7: a tracked real spot light, or a virtual one). Errors follow the
//! config style of `[[object]]` tables: file, line and column, and a hint.

use super::config::{Key, Type, Value, check, key};
use glam::Vec3;
use relume_graph::config::{ConfigError, RawValue, SourceFile, TableDecl};
use relume_graph::params::{a, did_you_mean};
use relume_scene::light::spot::MAX_CUTOFF_DEG;
use relume_scene::light::{LightWorld, SpotLight};
use relume_scene::objects::MAX_TRANSLATION;
use std::ops::Range;

/// The most `[[light]]` tables a pipeline may declare.
pub const MAX_LIGHTS: usize = 16;

const POSITION: Type = Type::Numbers(3, -(MAX_TRANSLATION as f64), MAX_TRANSLATION as f64);

/// Keys of a `[[light]]` table.
pub(super) const LIGHT_KEYS: &[Key] = &[
    key(
        "name",
        Type::Str,
        "names the light in messages; default: light N (its place in the file, from 1)",
    ),
    key(
        "kind",
        Type::Str,
        "spot (the only kind so far); default spot",
    ),
    key(
        "world",
        Type::Str,
        "real (a lamp of the recorded room, known to the pipeline: the camera already sees its light, and virtual objects cast shadows in it) or virtual (a lamp of the virtual world: it lights the real surfaces too); required",
    ),
    key(
        "position",
        POSITION,
        "[x, y, z] of the lamp, metres, world coordinates; required",
    ),
    key(
        "aim",
        POSITION,
        "[x, y, z], a point on the cone's axis, metres, world coordinates; required unless direction is given",
    ),
    key(
        "direction",
        Type::Numbers(3, -1e3, 1e3),
        "[x, y, z], the cone's axis (normalized here), in place of aim",
    ),
    key(
        "intensity",
        Type::Numbers(3, 0.0, 1e6),
        "radiant intensity on the axis [r, g, b], linear radiance times square metres (a surface facing it d metres away receives intensity / d^2); required",
    ),
    key(
        "cutoff_deg",
        Type::Float(0.1, MAX_CUTOFF_DEG as f64),
        "half-angle of the cone beyond which it gives nothing, degrees; default 20",
    ),
    key(
        "beam_deg",
        Type::Float(0.0, MAX_CUTOFF_DEG as f64),
        "half-angle of the full-intensity beam, degrees, at most cutoff_deg (the intensity falls linearly in angle between them, as Mitsuba 3's spot); default 3/4 of cutoff_deg",
    ),
];

/// Every key `[[light]]` tables take, for help pages (`relume objects`).
pub fn key_docs() -> Vec<super::config::KeyDoc> {
    LIGHT_KEYS
        .iter()
        .map(|k| super::config::key_doc(None, k))
        .collect()
}

/// Checks the `[[light]]` tables of the config `src`, in file order.
pub fn resolve(decls: &[TableDecl], src: &SourceFile) -> Result<Vec<SpotLight>, ConfigError> {
    if let Some(extra) = decls.get(MAX_LIGHTS) {
        return Err(src.error(
            extra.span.clone(),
            format!("more than {MAX_LIGHTS} [[light]] tables"),
            Some(format!("a pipeline knows of at most {MAX_LIGHTS} lights")),
        ));
    }
    let mut lights: Vec<SpotLight> = Vec::new();
    for (index, decl) in decls.iter().enumerate() {
        let light = resolve_one(decl, index, src)?;
        if let Some(first) = lights.iter().position(|l| l.name == light.name) {
            let span = value_span(decl, "name").unwrap_or(decl.span.clone());
            let line = src.line_col(decls[first].span.start).0;
            return Err(src.error(
                span,
                format!(
                    "a second light named `{}` (the first is on line {line})",
                    light.name
                ),
                Some("give each light a unique `name`".into()),
            ));
        }
        lights.push(light);
    }
    Ok(lights)
}

fn value_span(decl: &TableDecl, key: &str) -> Option<Range<usize>> {
    decl.entries
        .iter()
        .find(|(k, _)| k.value == key)
        .map(|(_, v)| v.span.clone())
}

fn resolve_one(decl: &TableDecl, index: usize, src: &SourceFile) -> Result<SpotLight, ConfigError> {
    let name = match decl.entries.iter().find(|(k, _)| k.value == "name") {
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
        None => format!("light {}", index + 1),
    };
    let owner = format!("light `{name}`");
    let mut values: Vec<(&'static str, Value, Range<usize>)> = Vec::new();
    for (k, v) in &decl.entries {
        let Some(spec) = LIGHT_KEYS.iter().find(|s| s.name == k.value) else {
            let names = LIGHT_KEYS.iter().map(|s| s.name);
            let keys = format!(
                "keys of a light: {}",
                names.clone().collect::<Vec<_>>().join(", ")
            );
            let hint = match did_you_mean(&k.value, names) {
                Some(s) => format!("did you mean `{s}`? {keys}"),
                None => keys,
            };
            return Err(src.error(
                k.span.clone(),
                format!("unknown key `{}` for {owner}", k.value),
                Some(hint),
            ));
        };
        values.push((spec.name, check(src, spec, v, &owner)?, v.span.clone()));
    }
    let find = |key: &str| values.iter().find(|(n, _, _)| *n == key);
    let vec3 = |key: &str| match find(key) {
        Some((_, Value::Numbers(x), span)) => Some((
            Vec3::new(x[0] as f32, x[1] as f32, x[2] as f32),
            span.clone(),
        )),
        _ => None,
    };
    let number = |key: &str| match find(key) {
        Some((_, Value::Number(x), span)) => Some((*x as f32, span.clone())),
        _ => None,
    };
    let missing = |key: &str, example: &str| {
        src.error(
            decl.span.clone(),
            format!("{owner} has no `{key}`"),
            Some(format!("e.g. {key} = {example}")),
        )
    };
    if let Some((_, Value::Str(kind), span)) = find("kind")
        && kind != "spot"
    {
        return Err(src.error(
            span.clone(),
            format!("unknown light kind `{kind}`"),
            Some("kinds: spot".into()),
        ));
    }
    let world = match find("world") {
        None => return Err(missing("world", "\"real\" or world = \"virtual\"")),
        Some((_, Value::Str(w), span)) => LightWorld::from_name(w).ok_or_else(|| {
            src.error(
                span.clone(),
                format!("`world` of {owner} must be real or virtual, found `{w}`"),
                Some(LIGHT_KEYS[2].doc.to_string()),
            )
        })?,
        Some(_) => unreachable!("`world` is checked as a string"),
    };
    let (position, _) = vec3("position").ok_or_else(|| missing("position", "[0.0, 2.4, 0.0]"))?;
    let direction = match (vec3("aim"), vec3("direction")) {
        (Some(_), Some((_, span))) => {
            return Err(src.error(
                span,
                format!("{owner} has both `aim` and `direction`"),
                Some("give one: the point it aims at, or its axis".into()),
            ));
        }
        (None, None) => return Err(missing("aim", "[0.0, 0.0, 0.0]")),
        (Some((aim, span)), None) => {
            let d = aim - position;
            if d.length() < 1e-3 {
                return Err(src.error(
                    span,
                    format!("`aim` of {owner} is its `position`"),
                    Some("aim at a point at least a millimetre away".into()),
                ));
            }
            d.normalize()
        }
        (None, Some((d, span))) => {
            if d.length() < 1e-6 {
                return Err(src.error(
                    span,
                    format!("`direction` of {owner} is zero"),
                    Some("give the cone's axis, e.g. [0, -1, 0] to shine down".into()),
                ));
            }
            d.normalize()
        }
    };
    let (intensity, _) =
        vec3("intensity").ok_or_else(|| missing("intensity", "[20.0, 18.0, 15.0]"))?;
    let cutoff = number("cutoff_deg").map_or(20.0, |(c, _)| c);
    let beam = match number("beam_deg") {
        Some((b, span)) if b > cutoff => {
            return Err(src.error(
                span,
                format!("`beam_deg` ({b}) of {owner} is wider than its cutoff ({cutoff})"),
                Some("the full-intensity beam lies within the cone".into()),
            ));
        }
        Some((b, _)) => b,
        None => 0.75 * cutoff,
    };
    Ok(SpotLight {
        name,
        world,
        position,
        direction,
        intensity,
        beam: beam.to_radians(),
        cutoff: cutoff.to_radians(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lights(text: &str) -> Result<Vec<SpotLight>, String> {
        let src = SourceFile {
            name: "p.toml".into(),
            text: format!("{text}[[stage]]\nkind = \"depth.decode\"\n"),
        };
        let decl = relume_graph::config::parse(&src).map_err(|e| e.to_string())?;
        resolve(&decl.world.lights, &src).map_err(|e| e.to_string())
    }

    #[test]
    fn a_spot_light_is_read_with_its_defaults() {
        let l = lights(
            "[[light]]\nworld = \"virtual\"\nposition = [0, 2, 0]\naim = [0, 0, 0]\nintensity = [4, 2, 1]\n",
        )
        .unwrap();
        assert_eq!(l.len(), 1);
        assert_eq!(l[0].name, "light 1");
        assert_eq!(l[0].world, LightWorld::Virtual);
        assert_eq!(l[0].direction, Vec3::NEG_Y);
        assert_eq!(l[0].intensity, Vec3::new(4.0, 2.0, 1.0));
        assert_eq!(l[0].cutoff, 20f32.to_radians());
        assert_eq!(l[0].beam, 15f32.to_radians());
    }

    #[test]
    fn bad_lights_are_errors_at_their_keys() {
        let base = "[[light]]\nname = \"lamp\"\nposition = [0, 2, 0]\nintensity = [1, 1, 1]\n";
        let err = lights(&format!("{base}aim = [0, 0, 0]\n")).unwrap_err();
        assert!(err.contains("light `lamp` has no `world`"), "{err}");
        let err = lights(&format!("{base}world = \"imagined\"\naim = [0, 0, 0]\n")).unwrap_err();
        assert!(err.contains("p.toml:5:"), "{err}");
        assert!(
            err.contains("`world` of light `lamp` must be real or virtual, found `imagined`"),
            "{err}"
        );
        let err = lights(&format!("{base}world = \"real\"\n")).unwrap_err();
        assert!(err.contains("light `lamp` has no `aim`"), "{err}");
        let err = lights(&format!("{base}world = \"real\"\naim = [0, 2, 0]\n")).unwrap_err();
        assert!(
            err.contains("`aim` of light `lamp` is its `position`"),
            "{err}"
        );
        let err = lights(&format!(
            "{base}world = \"real\"\naim = [0, 0, 0]\ncutoff_deg = 95\n"
        ))
        .unwrap_err();
        assert!(
            err.contains("`cutoff_deg` of light `lamp` = 95 is out of range (0.1 to 89)"),
            "{err}"
        );
        let err = lights(&format!(
            "{base}world = \"real\"\naim = [0, 0, 0]\ncutoff_deg = 10\nbeam_deg = 12\n"
        ))
        .unwrap_err();
        assert!(
            err.contains("`beam_deg` (12) of light `lamp` is wider than its cutoff (10)"),
            "{err}"
        );
        let err = lights(&format!(
            "{base}world = \"real\"\naim = [0, 0, 0]\ncolour = 1\n"
        ))
        .unwrap_err();
        assert!(
            err.contains("unknown key `colour` for light `lamp`"),
            "{err}"
        );
        let twice = format!("{base}world = \"real\"\naim = [0, 0, 0]\n");
        let err = lights(&format!("{twice}{twice}")).unwrap_err();
        assert!(
            err.contains("a second light named `lamp` (the first is on line 1)"),
            "{err}"
        );
    }
}
