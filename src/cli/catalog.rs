//! `relume stages`, `relume objects` and `relume validate`.

use clap::Args;
use relume::graph::{ParamValue, Params, Pipeline};
use relume::stages::world::PipelineObjects;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct StagesArgs {
    /// Print JSON: a list of {kind, summary, inputs, outputs, params}; ports are {role,
    /// default (product name), kinds, optional}, parameters {name, type, default (a value
    /// of that type), min, max, choices, doc}.
    #[arg(long)]
    json: bool,
    /// Also list the external stages of this pipeline file: the program each runs, the
    /// ports its table declares (role and kind) and its settings. With --json the
    /// output is then {kinds: [...], external: [{stage, line, command, inputs,
    /// outputs, settings}]}.
    #[arg(long, value_name = "PIPELINE")]
    pipeline: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct ObjectsArgs {
    /// Print JSON: a list of {name, shape (null for keys every object takes), kind,
    /// min, max, doc}.
    #[arg(long)]
    json: bool,
}

#[derive(Args, Debug)]
pub struct ValidateArgs {
    /// The pipeline file (TOML).
    pipeline: PathBuf,
    /// Also check what depends on a recording: objects anchored to its surfaces (their
    /// `frame` within it, `at_pixel` within its images, a floor or surface found there),
    /// placed as `relume replay` would place them.
    #[arg(long, value_name = "REC")]
    recording: Option<PathBuf>,
    /// With --recording: the pose gap a replay would be given (placing an object needs
    /// its anchor frame's pose); see `relume replay --help`.
    #[arg(long, value_name = "MS", value_parser = super::replay::parse_gap_ms, requires = "recording")]
    max_pose_gap: Option<i64>,
    /// Check the pipeline as `relume replay --set` would change it: STAGE.PARAM=VALUE,
    /// repeatable.
    #[arg(long = "set", value_name = "STAGE.PARAM=VALUE")]
    overrides: Vec<relume::graph::ParamOverride>,
}

pub fn stages(a: StagesArgs) -> anyhow::Result<i32> {
    let registry = relume::stages::registry();
    let mut docs = Vec::new();
    for info in registry.kinds() {
        let ports = (info.ports)(&Params::defaults(info.params));
        let port_list = |ports: &[relume::graph::Port]| {
            ports.iter().map(|p| serde_json::json!({ "role": p.role, "default": p.default_product, "kinds": p.kinds.iter().map(|k| k.name()).collect::<Vec<_>>(), "optional": p.optional, "when_made": p.when_made })).collect::<Vec<_>>()
        };
        let params: Vec<serde_json::Value> = info.params.iter().map(|p| serde_json::json!({ "name": p.name, "type": p.type_name(), "default": json_value(&p.default_value()), "min": p.min, "max": p.max, "choices": p.choices, "doc": p.doc })).collect();
        if !a.json {
            outln!("{}\n    {}", info.kind, info.summary)?;
            // Each port by its role, which configs bind (`inputs = { depth = "..." }`),
            // with its default product where that has another name; "(optional)" marks
            // the inputs that may read the previous frame, "(where made)" those read only
            // where a stage makes them.
            let show = |ports: &[relume::graph::Port]| {
                if ports.is_empty() {
                    return "-".to_string();
                }
                let port = |p: &relume::graph::Port| {
                    let mut shown = if p.role == p.default_product {
                        p.role.clone()
                    } else {
                        format!("{} = {}", p.role, p.default_product)
                    };
                    if p.optional {
                        shown.push_str(" (optional)");
                    }
                    if p.when_made {
                        shown.push_str(" (where made)");
                    }
                    shown
                };
                ports.iter().map(port).collect::<Vec<_>>().join(", ")
            };
            outln!(
                "    reads: {}   writes: {}",
                show(&ports.inputs),
                show(&ports.outputs)
            )?;
            for p in info.params {
                let mut line =
                    format!("    {} = {}  ({}", p.name, p.default_value(), p.type_name());
                if let (Some(lo), Some(hi)) = (p.min, p.max) {
                    line.push_str(&format!(", {lo} to {hi}"));
                }
                if !p.choices.is_empty() {
                    line.push_str(&format!(", one of {}", p.choices.join(" | ")));
                }
                outln!("{line})\n        {}", p.doc)?;
            }
            outln!()?;
        }
        docs.push(serde_json::json!({ "kind": info.kind, "summary": info.summary, "inputs": port_list(&ports.inputs), "outputs": port_list(&ports.outputs), "params": params }));
    }
    let external = match &a.pipeline {
        Some(path) => external_stages(&Pipeline::load(path, &registry)?, !a.json)?,
        None => Vec::new(),
    };
    if a.json {
        let out = match a.pipeline {
            Some(_) => serde_json::json!({ "kinds": docs, "external": external }),
            None => serde_json::Value::Array(docs),
        };
        outln!("{}", serde_json::to_string_pretty(&out)?)?;
    }
    Ok(0)
}

/// The external stages of `pipeline` with their declared ports, printed when `print`,
/// and as JSON.
fn external_stages(pipeline: &Pipeline, print: bool) -> anyhow::Result<Vec<serde_json::Value>> {
    let info = relume::stages::external::INFO;
    let mut out = Vec::new();
    let stages = pipeline.stages.iter().filter(|s| s.kind == info.kind);
    if print {
        outln!(
            "external stages of {} ({}):",
            pipeline.file,
            pipeline
                .stages
                .iter()
                .filter(|s| s.kind == info.kind)
                .count()
        )?;
    }
    for stage in stages {
        let ports = (info.ports)(&stage.params);
        let described =
            |ports: &[relume::graph::Port], bound: &std::collections::BTreeMap<String, String>| {
                ports
                    .iter()
                    .map(|p| {
                        let product = bound
                            .get(&p.role)
                            .cloned()
                            .unwrap_or_else(|| p.role.clone());
                        (p.role.clone(), product, p.kinds[0].name())
                    })
                    .collect::<Vec<_>>()
            };
        let inputs = described(&ports.inputs, &stage.inputs);
        let outputs = described(&ports.outputs, &stage.outputs);
        let command = relume::stages::external::command(&stage.params).join(" ");
        let settings = stage.params.str_list("settings").to_vec();
        if print {
            let show = |ports: &[(String, String, &str)]| {
                if ports.is_empty() {
                    return "-".to_string();
                }
                ports
                    .iter()
                    .map(|(role, product, kind)| {
                        if role == product {
                            format!("{role} ({kind})")
                        } else {
                            format!("{role} = {product} ({kind})")
                        }
                    })
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            outln!(
                "{} (line {})
    runs: {command}",
                stage.name,
                stage.line
            )?;
            outln!("    reads: {}   writes: {}", show(&inputs), show(&outputs))?;
            if !settings.is_empty() {
                outln!("    settings: {}", settings.join(", "))?;
            }
        }
        let json_ports = |ports: &[(String, String, &str)]| {
            ports
                .iter()
                .map(|(role, product, kind)| serde_json::json!({ "role": role, "product": product, "kind": kind }))
                .collect::<Vec<_>>()
        };
        out.push(serde_json::json!({
            "stage": stage.name,
            "line": stage.line,
            "command": command,
            "inputs": json_ports(&inputs),
            "outputs": json_ports(&outputs),
            "settings": settings,
        }));
    }
    Ok(out)
}

const OBJECTS_INTRO: &str = "\
[[object]] tables in a pipeline file add virtual objects to its scene. Every key is
checked when the pipeline loads (`relume validate FILE` says what is wrong, and where).
A point p of the shape lands at

    origin + axes (translation + R (scale p)),   R = Rz Ry Rx (rotation_deg),

where origin and axes are the world's (the recording's poses, metres), or, with
`anchor = \"floor\"` or `at_pixel`, a frame on a real surface found in the recording
when it is opened: y along the surface's normal (up, from a floor), x the image's
rightward direction in frame `frame`, z = x cross y (towards the camera, on a
floor). Built-in shapes are
centred on their origin with y up, so translation = [0, half the height, 0] stands
one on the surface. The run prints where each anchored object went.";

const OBJECTS_EXAMPLE: &str = "\
Example: a ball on the floor where the centre of frame 0 sees it, and a box on the
surface seen at pixel (410, 300) of frame 12:

  [[object]]
  name = \"ball\"
  shape = \"sphere\"
  radius = 0.2
  anchor = \"floor\"
  translation = [0, 0.2, 0]

  [[object]]
  shape = \"box\"
  size = [0.3, 0.2, 0.3]
  at_pixel = [410, 300]
  frame = 12
  translation = [0, 0.1, 0]
  rotation_deg = [0, 30, 0]
  albedo = [0.8, 0.3, 0.2]";

pub fn objects(a: ObjectsArgs) -> anyhow::Result<i32> {
    let keys = relume::stages::world::config::key_docs();
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&keys)?)?;
        return Ok(0);
    }
    outln!("{OBJECTS_INTRO}\n")?;
    let mut shape = None;
    outln!("Keys of every object:")?;
    for key in &keys {
        if key.shape != shape {
            shape = key.shape;
            let name = shape.unwrap_or_default();
            outln!("\nKeys of shape = \"{name}\":")?;
        }
        print_key(key)?;
    }
    outln!(
        "\nKeys of [[light]] tables (spot lights the pipeline knows of; sample.dir, sample.path and sample.val light with them):"
    )?;
    for key in &relume::stages::world::lights::key_docs() {
        print_key(key)?;
    }
    outln!("\n{OBJECTS_EXAMPLE}")?;
    Ok(0)
}

/// One key of the help page: its name, kind and bounds, then its doc wrapped.
fn print_key(key: &relume::stages::world::config::KeyDoc) -> anyhow::Result<()> {
    let bounds = match (key.min, key.max) {
        (Some(lo), Some(hi)) => format!(", {lo} to {hi}"),
        _ => String::new(),
    };
    outln!("  {} ({}{bounds})", key.name, key.kind)?;
    for line in wrap(key.doc, 82) {
        outln!("      {line}")?;
    }
    Ok(())
}

/// `text` in lines of at most `width` characters, broken at spaces.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines: Vec<String> = vec![String::new()];
    for word in text.split_whitespace() {
        let line = lines.last_mut().expect("never empty");
        if !line.is_empty() && line.len() + 1 + word.len() > width {
            lines.push(word.to_string());
        } else {
            if !line.is_empty() {
                line.push(' ');
            }
            line.push_str(word);
        }
    }
    lines
}

/// A parameter value as JSON of its own type (a float default stays a number).
fn json_value(value: &ParamValue) -> serde_json::Value {
    match value {
        ParamValue::Bool(b) => (*b).into(),
        ParamValue::Int(i) => (*i).into(),
        ParamValue::Float(x) => (*x).into(),
        ParamValue::Str(s) => s.as_str().into(),
        ParamValue::StrList(list) => list.clone().into(),
    }
}

pub fn validate(a: ValidateArgs) -> anyhow::Result<i32> {
    let mut pipeline = Pipeline::load_with(&a.pipeline, &relume::stages::registry(), &a.overrides)?;
    if let Some(rec) = &a.recording {
        let options = relume::recording::ReplayOptions {
            max_pose_gap_ns: a.max_pose_gap,
            ..Default::default()
        };
        let replay = relume::recording::Replay::open(rec, options)?;
        super::prepare::place_objects(&mut pipeline, &replay, 0, "")?;
    }
    // A light probe file is read when its stage is set up: read it now, so that a
    // missing or corrupt one does not pass here and stop the run.
    let probes = pipeline
        .stages
        .iter()
        .filter(|s| s.kind == "light.envmap" && s.params.str("source") == "file");
    for s in probes {
        if let Err(e) = relume::light::load_envmap(s.params.str("path")) {
            anyhow::bail!(
                "{}:{}: stage `{}` could not be set up: {e}",
                pipeline.file,
                s.line,
                s.name
            );
        }
    }
    let chain: Vec<String> = pipeline
        .stages
        .iter()
        .map(|s| {
            if s.name == s.kind {
                s.name.clone()
            } else {
                format!("{} ({})", s.name, s.kind)
            }
        })
        .collect();
    outln!(
        "{}: ok, {} stages: {}",
        a.pipeline.display(),
        pipeline.stages.len(),
        chain.join(" -> ")
    )?;
    for (stage, command) in relume::stages::external::programs(&pipeline.stages) {
        outln!("  starts a program: stage `{stage}` runs `{command}`")?;
    }
    for fb in &pipeline.feedback {
        outln!(
            "  feedback: `{}` from stage `{}` reaches stage `{}` one frame later",
            fb.product,
            pipeline.stages[fb.producer].name,
            pipeline.stages[fb.consumer].name
        )?;
    }
    for object in pipeline
        .declared_objects()
        .iter()
        .filter(|o| o.sites.is_some() && a.recording.is_none())
    {
        outln!(
            "  object `{}`: anchored to the recording's {}, placed when a run opens it \
             (`--recording REC` places it now)",
            object.spec.name,
            match object.spec.anchor {
                relume::objects::anchor::Anchor::Floor { .. } => "floor",
                _ => "surface at a pixel",
            }
        )?;
    }
    let objects = &pipeline.objects();
    if !objects.is_empty() {
        let b = objects.bounds();
        outln!(
            "  objects: {} triangles in {} materials, bounds [{:.3}, {:.3}, {:.3}] .. [{:.3}, {:.3}, {:.3}] m",
            objects.triangles.len(),
            objects.materials.len(),
            b.min.x,
            b.min.y,
            b.min.z,
            b.max.x,
            b.max.y,
            b.max.z
        )?;
    }
    Ok(0)
}
