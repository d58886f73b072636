//! A pipeline config checked against the registry: kinds exist, parameters have the
//! declared types and bounds, every input is produced upstream (or, with `@prev`,
//! anywhere, as a feedback edge delivering the previous frame's value), and kinds match.

use super::config::{self, ConfigError, Located, PipelineDecl, RawValue, SourceFile, StageDecl};
use super::frame::ProductKind;
use super::params::{ParamDefault, ParamSpec, ParamValue, Params, a, did_you_mean};
use super::registry::Registry;
use super::stage::{Stage, StageError};
use crate::recording::Header;
use std::collections::BTreeMap;
use std::path::Path;

/// The product the source puts into every frame: the frame's encoded records.
pub const SOURCE_PRODUCT: &str = "record";
/// Suffix of an input that reads the previous frame's value of a product.
pub const PREVIOUS_SUFFIX: &str = "@prev";
/// Frames buffered between two stages when the config does not say.
pub const DEFAULT_CHANNEL_CAPACITY: usize = 2;

/// The built-in default pipeline (`pipelines/default.toml`, compiled in).
pub const DEFAULT_PIPELINE_TOML: &str = include_str!("../../pipelines/default.toml");

/// A checked stage of a pipeline.
#[derive(Clone, Debug)]
pub struct ResolvedStage {
    pub name: String,
    pub kind: &'static str,
    pub params: Params,
    /// Role -> product (with `@prev` for previous-frame inputs).
    pub inputs: BTreeMap<String, String>,
    /// Role -> product.
    pub outputs: BTreeMap<String, String>,
    /// Line of the stage in its file.
    pub line: usize,
    /// The stage runs on every `every`-th frame and lends its last products to the
    /// frames between (see [`super::every`]); 1 = every frame.
    pub every: u32,
}

/// A feedback edge: `producer`'s `product` of frame t-1 goes to `consumer` at frame t.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Feedback {
    pub producer: usize,
    pub consumer: usize,
    pub product: String,
}

/// A pipeline ready to build and run.
#[derive(Clone, Debug)]
pub struct Pipeline {
    pub name: String,
    pub description: String,
    /// Where it was loaded from.
    pub file: String,
    pub channel_capacity: usize,
    pub stages: Vec<ResolvedStage>,
    pub feedback: Vec<Feedback>,
    /// The virtual objects of the `[[object]]` tables, in world space, BVH built (empty
    /// when the config has none). Objects anchored to the scene join it when
    /// [`Pipeline::place_objects`] places them against a recording.
    pub objects: std::sync::Arc<crate::objects::VirtualScene>,
    /// Every `[[object]]` table as declared, in order.
    pub declared_objects: Vec<crate::objects::config::DeclaredObject>,
}

impl Pipeline {
    /// Loads and checks the pipeline file at `path`.
    pub fn load(path: &Path, registry: &Registry) -> Result<Pipeline, ConfigError> {
        Pipeline::load_with(path, registry, &[])
    }

    /// [`Pipeline::load`] with `--set` overrides.
    pub fn load_with(
        path: &Path,
        registry: &Registry,
        overrides: &[super::ParamOverride],
    ) -> Result<Pipeline, ConfigError> {
        let name = path.display().to_string();
        let text = crate::files::read_regular_to_string(path).map_err(|e| {
            ConfigError::whole_file(&name, format!("cannot read the pipeline: {e}"))
        })?;
        Pipeline::parse_with(&SourceFile { name, text }, registry, overrides)
    }

    /// The built-in default pipeline.
    pub fn builtin_default(registry: &Registry) -> Result<Pipeline, ConfigError> {
        Pipeline::builtin_default_with(registry, &[])
    }

    /// [`Pipeline::builtin_default`] with `--set` overrides.
    pub fn builtin_default_with(
        registry: &Registry,
        overrides: &[super::ParamOverride],
    ) -> Result<Pipeline, ConfigError> {
        let src = SourceFile {
            name: "<built-in pipelines/default.toml>".into(),
            text: DEFAULT_PIPELINE_TOML.into(),
        };
        Pipeline::parse_with(&src, registry, overrides)
    }

    /// Parses and checks a pipeline from text.
    pub fn parse(src: &SourceFile, registry: &Registry) -> Result<Pipeline, ConfigError> {
        Pipeline::parse_with(src, registry, &[])
    }

    /// [`Pipeline::parse`] with stages' parameters changed by `overrides` (`--set`;
    /// see [`super::overrides`]), checked as if the file said so.
    pub fn parse_with(
        src: &SourceFile,
        registry: &Registry,
        overrides: &[super::ParamOverride],
    ) -> Result<Pipeline, ConfigError> {
        let mut decl = config::parse(src)?;
        if overrides.is_empty() {
            return Pipeline::resolve(&decl, src, registry);
        }
        let src = super::overrides::apply(&mut decl, src, overrides)?;
        Pipeline::resolve(&decl, &src, registry)
    }

    /// Checks a parsed pipeline against the registry.
    pub fn resolve(
        decl: &PipelineDecl,
        src: &SourceFile,
        registry: &Registry,
    ) -> Result<Pipeline, ConfigError> {
        let channel_capacity = match &decl.channel_capacity {
            None => DEFAULT_CHANNEL_CAPACITY,
            Some(c) if (1..=1024).contains(&c.value) => c.value as usize,
            Some(c) => {
                return Err(src.error(
                    c.span.clone(),
                    format!(
                        "channel_capacity must be between 1 and 1024, got {}",
                        c.value
                    ),
                    None,
                ));
            }
        };
        // Pass 1: kinds, names, parameters, ports.
        let mut stages = Vec::new();
        let mut port_sets = Vec::new();
        for d in &decl.stages {
            let info = registry.get(&d.kind.value).ok_or_else(|| {
                let hint =
                    match did_you_mean(&d.kind.value, registry.kinds().iter().map(|k| k.kind)) {
                        Some(s) => format!("did you mean `{s}`? `relume stages` lists every kind"),
                        None => "`relume stages` lists every kind".to_string(),
                    };
                src.error(
                    d.kind.span.clone(),
                    format!("unknown stage kind `{}`", d.kind.value),
                    Some(hint),
                )
            })?;
            let name = d
                .name
                .as_ref()
                .map_or(info.kind.to_string(), |n| n.value.clone());
            if let Some(n) = &d.name
                && n.value.trim().is_empty()
            {
                return Err(src.error(
                    n.span.clone(),
                    "a stage name may not be blank: errors and timing tables name stages by it"
                        .to_string(),
                    Some(format!("leave `name` out to use the kind, `{}`", info.kind)),
                ));
            }
            if let Some(prev) = stages.iter().find(|s: &&ResolvedStage| s.name == name) {
                let span = d
                    .name
                    .as_ref()
                    .map_or(d.kind.span.clone(), |n| n.span.clone());
                return Err(src.error(
                    span,
                    format!(
                        "a second stage named `{name}` (the first is on line {})",
                        prev.line
                    ),
                    Some("give each stage a unique `name`".into()),
                ));
            }
            let params = check_params(src, d, info.params, &name)?;
            let ports = (info.ports)(&params);
            let inputs = bind_ports(src, &d.inputs, &ports.inputs, &name, "input")?;
            let outputs = bind_ports(src, &d.outputs, &ports.outputs, &name, "output")?;
            let every = match &d.every {
                None => 1,
                Some(v) => match v.value {
                    RawValue::Int(k) if (1..=super::every::MAX_EVERY as i64).contains(&k) => {
                        k as u32
                    }
                    _ => {
                        return Err(src.error(
                            v.span.clone(),
                            format!(
                                "`every` of stage `{name}` must be an integer from 1 to {}",
                                super::every::MAX_EVERY
                            ),
                            Some("every = 8 runs the stage on frames 0, 8, 16, ...; the frames between reuse its products".into()),
                        ));
                    }
                },
            };
            stages.push(ResolvedStage {
                name,
                kind: info.kind,
                params,
                inputs,
                outputs,
                line: src.line_col(d.span.start).0,
                every,
            });
            port_sets.push(ports);
        }
        // Pass 2: every product is produced once, and inputs are produced upstream or
        // (with @prev) anywhere in the pipeline.
        let mut producers: BTreeMap<String, (usize, ProductKind)> = BTreeMap::new();
        let mut available: Vec<BTreeMap<String, (usize, ProductKind)>> = Vec::new();
        producers.insert(SOURCE_PRODUCT.into(), (usize::MAX, ProductKind::Record));
        for (i, (stage, ports)) in stages.iter().zip(&port_sets).enumerate() {
            available.push(producers.clone());
            for port in &ports.outputs {
                let product = &stage.outputs[&port.role];
                if let Some(&(p, _)) = producers.get(product) {
                    let by = if p == usize::MAX {
                        "the source".to_string()
                    } else {
                        format!("stage `{}`", stages[p].name)
                    };
                    let span = located_span(&decl.stages[i].outputs, &port.role)
                        .unwrap_or(decl.stages[i].kind.span.clone());
                    return Err(src.error(
                        span,
                        format!(
                            "stage `{}` writes product `{product}`, which {by} already produces",
                            stage.name
                        ),
                        Some(format!(
                            "rename it: outputs = {{ {} = \"another_name\" }}",
                            port.role
                        )),
                    ));
                }
                producers.insert(product.clone(), (i, port.kinds[0]));
            }
        }
        let mut feedback = Vec::new();
        for (i, (stage, ports)) in stages.iter().zip(&port_sets).enumerate() {
            let d = &decl.stages[i];
            for port in &ports.inputs {
                let bound = &stage.inputs[&port.role];
                let span = located_span(&d.inputs, &port.role).unwrap_or(d.kind.span.clone());
                let (product, previous) = match bound.strip_suffix(PREVIOUS_SUFFIX) {
                    Some(p) => (p, true),
                    None => (bound.as_str(), false),
                };
                let found = if previous {
                    producers.get(product)
                } else {
                    available[i].get(product)
                };
                let Some(&(producer, kind)) = found else {
                    return Err(missing_product(
                        src,
                        span,
                        &stages,
                        &available[i],
                        &producers,
                        i,
                        port,
                        product,
                        previous,
                    ));
                };
                if !port.kinds.contains(&kind) {
                    let expected: Vec<&str> = port.kinds.iter().map(|k| k.name()).collect();
                    return Err(src.error(span, format!("stage `{}` reads `{product}` as its `{}` input, but `{product}` is {}; it needs {}", stage.name, port.role, a(kind.name()), expected.iter().map(|k| a(k)).collect::<Vec<_>>().join(" or ")), None));
                }
                if previous {
                    if !port.optional {
                        return Err(src.error(
                            span,
                            format!(
                                "stage `{}` cannot read `{bound}` as its `{}` input: it needs that input at every frame, and the first frame has no previous one",
                                stage.name, port.role
                            ),
                            Some(format!("read `{product}` from this frame, produced upstream")),
                        ));
                    }
                    if producer == usize::MAX {
                        return Err(src.error(span, format!("`{product}` comes from the source and has no previous-frame value to feed back"), None));
                    }
                    feedback.push(Feedback {
                        producer,
                        consumer: i,
                        product: product.to_string(),
                    });
                }
            }
        }
        // Objects last: meshes are read from disk only for an otherwise valid pipeline.
        let objects = crate::objects::config::resolve(&decl.objects, src)?;
        Ok(Pipeline {
            name: decl.name.clone().unwrap_or_else(|| src.name.clone()),
            description: decl.description.clone().unwrap_or_default(),
            file: src.name.clone(),
            channel_capacity,
            stages,
            feedback,
            objects: std::sync::Arc::new(objects.world_scene),
            declared_objects: objects.declared,
        })
    }

    /// The names of the objects anchored to the scene that have not been placed yet.
    pub fn unplaced_objects(&self) -> Vec<&str> {
        self.declared_objects
            .iter()
            .filter(|d| d.spec.placement_frame().is_err())
            .map(|d| d.spec.name.as_str())
            .collect()
    }

    /// Places the objects anchored to the scene (`anchor = "floor"`, `at_pixel`) on
    /// `replay`'s surfaces and rebuilds [`Pipeline::objects`] with every object; says
    /// where each was placed. Nothing to do (and an empty list) when none is anchored.
    /// Errors stand at the anchor's keys in the config.
    pub fn place_objects(
        &mut self,
        replay: &crate::recording::Replay,
    ) -> Result<Vec<crate::objects::anchor::Placement>, ConfigError> {
        if self.declared_objects.iter().all(|d| d.sites.is_none()) {
            return Ok(Vec::new());
        }
        let placements = crate::objects::anchor::place_objects(&mut self.declared_objects, replay)?;
        let scene = crate::objects::anchor::place::scene_of(&self.declared_objects, &self.file)?;
        let mut placements = placements;
        for placed in &mut placements {
            // Object k has material k (VirtualScene::from_specs).
            let k = self
                .declared_objects
                .iter()
                .position(|d| d.spec.name == placed.object);
            let corners = scene
                .triangles
                .iter()
                .filter(|t| Some(t.material as usize) == k)
                .flat_map(|t| t.vertices);
            placed.bounds = corners.fold(None, |b, p| match b {
                None => Some((p, p)),
                Some((lo, hi)) => Some((p.min(lo), p.max(hi))),
            });
        }
        self.objects = std::sync::Arc::new(scene);
        Ok(placements)
    }

    /// Builds every stage for a run over a recording with `header` (the one-branch
    /// case of [`super::tree::StageGraph::build`]).
    pub fn build(
        &self,
        registry: &Registry,
        header: &Header,
        out_dir: &Path,
        seed: u64,
    ) -> Result<Vec<Box<dyn Stage>>, (String, StageError)> {
        super::tree::StageGraph::linear(self)
            .build(registry, header, &[out_dir.to_path_buf()], seed)
            .map_err(|(node, e)| (self.stages[node].name.clone(), e))
    }
}

fn located_span(
    pairs: &[(Located<String>, Located<String>)],
    role: &str,
) -> Option<std::ops::Range<usize>> {
    pairs
        .iter()
        .find(|(k, _)| k.value == role)
        .map(|(_, v)| v.span.clone())
}

#[allow(clippy::too_many_arguments)]
fn missing_product(
    src: &SourceFile,
    span: std::ops::Range<usize>,
    stages: &[ResolvedStage],
    upstream: &BTreeMap<String, (usize, ProductKind)>,
    all: &BTreeMap<String, (usize, ProductKind)>,
    reader: usize,
    port: &super::stage::Port,
    product: &str,
    previous: bool,
) -> ConfigError {
    let stage = &stages[reader];
    let (role, optional) = (&port.role, port.optional);
    // A producer that reads, through other stages, what this stage writes: moving it
    // up cannot help.
    let cycle = match all.get(product) {
        Some(&(p, _)) if !previous && p < stages.len() => {
            super::cycle::read_chain(stages, all, p, reader).map(|rest| {
                let mut steps = vec![(reader, product.to_string(), p)];
                steps.extend(rest);
                super::cycle::describe(stages, &steps)
            })
        }
        _ => None,
    };
    let hint = match all.get(product) {
        Some(_) if let Some(cycle) = &cycle => {
            let way_out = if optional {
                format!("read `{product}{PREVIOUS_SUFFIX}` here for its previous-frame value")
            } else {
                "one of them must read the other's product of the previous frame (`@prev`, on an input that can do without it at the first frame)".to_string()
            };
            format!("these stages form a cycle ({cycle}): no order of them runs; {way_out}")
        }
        Some(&(p, _)) if !previous && optional => format!(
            "`{product}` is produced later, by stage `{}`: move that stage up, or read `{product}{PREVIOUS_SUFFIX}` for its previous-frame value",
            stages[p].name
        ),
        Some(&(p, _)) if !previous => format!(
            "`{product}` is produced later, by stage `{}`: move that stage up",
            stages[p].name
        ),
        _ => {
            let names: Vec<&str> = upstream.keys().map(|s| s.as_str()).collect();
            match did_you_mean(product, names.iter().copied()) {
                Some(s) => format!(
                    "did you mean `{s}`? products available here: {}",
                    names.join(", ")
                ),
                None => format!("products available here: {}", names.join(", ")),
            }
        }
    };
    let where_ = if previous { "stage" } else { "upstream stage" };
    src.error(
        span,
        format!(
            "stage `{}` reads `{product}` as its `{role}` input, but no {where_} produces it",
            stage.name
        ),
        Some(hint),
    )
}

/// Binds a stage's declared ports to product names from the config's role table.
fn bind_ports(
    src: &SourceFile,
    given: &[(Located<String>, Located<String>)],
    ports: &[super::stage::Port],
    stage: &str,
    what: &str,
) -> Result<BTreeMap<String, String>, ConfigError> {
    for (role, product) in given {
        if !ports.iter().any(|p| p.role == role.value) {
            let roles: Vec<&str> = ports.iter().map(|p| p.role.as_str()).collect();
            let hint = match did_you_mean(&role.value, roles.iter().copied()) {
                Some(s) => format!(
                    "did you mean `{s}`? {what}s of this stage: {}",
                    roles.join(", ")
                ),
                None if roles.is_empty() => format!("this stage has no {what}s"),
                None => format!("{what}s of this stage: {}", roles.join(", ")),
            };
            return Err(src.error(
                role.span.clone(),
                format!("stage `{stage}` has no {what} `{}`", role.value),
                Some(hint),
            ));
        }
        if product.value.trim().is_empty() || (what == "output" && product.value.contains('@')) {
            return Err(src.error(
                product.span.clone(),
                format!("invalid product name {:?}", product.value),
                Some("product names are non-empty and contain no `@`".into()),
            ));
        }
    }
    Ok(ports
        .iter()
        .map(|p| {
            let bound = given
                .iter()
                .find(|(r, _)| r.value == p.role)
                .map_or(p.default_product.clone(), |(_, v)| v.value.clone());
            (p.role.clone(), bound)
        })
        .collect())
}

/// Checks a stage's parameters against its declaration and fills in defaults.
fn check_params(
    src: &SourceFile,
    d: &StageDecl,
    specs: &[ParamSpec],
    stage: &str,
) -> Result<Params, ConfigError> {
    let mut params = Params::defaults(specs);
    for (key, value) in &d.params {
        let Some(spec) = specs.iter().find(|s| s.name == key.value) else {
            let names: Vec<&str> = specs.iter().map(|s| s.name).collect();
            let hint = match did_you_mean(&key.value, names.iter().copied()) {
                Some(s) => format!(
                    "did you mean `{s}`? parameters of {}: {}",
                    d.kind.value,
                    names.join(", ")
                ),
                None if names.is_empty() => format!("{} takes no parameters", d.kind.value),
                None => format!("parameters of {}: {}", d.kind.value, names.join(", ")),
            };
            return Err(src.error(
                key.span.clone(),
                format!(
                    "unknown parameter `{}` for stage `{stage}` ({})",
                    key.value, d.kind.value
                ),
                Some(hint),
            ));
        };
        params.set(spec.name, check_value(src, spec, value)?);
    }
    Ok(params)
}

fn check_value(
    src: &SourceFile,
    spec: &ParamSpec,
    value: &Located<RawValue>,
) -> Result<ParamValue, ConfigError> {
    let wrong_type = || {
        src.error(
            value.span.clone(),
            format!(
                "parameter `{}` must be {}, found {}",
                spec.name,
                a(spec.type_name()),
                a(value.value.type_name())
            ),
            Some(format!("{}; default {}", spec.doc, spec.default_value())),
        )
    };
    let in_range = |x: f64| -> Result<(), ConfigError> {
        let low = spec.min.is_some_and(|m| x < m);
        let high = spec.max.is_some_and(|m| x > m);
        if low || high || !x.is_finite() {
            let bounds = format!(
                "{} to {}",
                spec.min.map_or("-inf".into(), |m| m.to_string()),
                spec.max.map_or("inf".into(), |m| m.to_string())
            );
            return Err(src.error(
                value.span.clone(),
                format!("parameter `{}` = {x} is out of range ({bounds})", spec.name),
                Some(spec.doc.to_string()),
            ));
        }
        Ok(())
    };
    let choice = |s: &str, span: &std::ops::Range<usize>| -> Result<(), ConfigError> {
        if spec.choices.is_empty() || spec.choices.contains(&s) {
            return Ok(());
        }
        let hint = match did_you_mean(s, spec.choices.iter().copied()) {
            Some(c) => format!("did you mean {c:?}? choices: {}", spec.choices.join(", ")),
            None => format!("choices: {}", spec.choices.join(", ")),
        };
        Err(src.error(
            span.clone(),
            format!("parameter `{}` does not accept {s:?}", spec.name),
            Some(hint),
        ))
    };
    Ok(match (&spec.default, &value.value) {
        (ParamDefault::Bool(_), RawValue::Bool(b)) => ParamValue::Bool(*b),
        (ParamDefault::Int(_), RawValue::Int(i)) => {
            in_range(*i as f64)?;
            ParamValue::Int(*i)
        }
        (ParamDefault::Float(_), RawValue::Float(f)) => {
            in_range(*f)?;
            ParamValue::Float(*f)
        }
        (ParamDefault::Float(_), RawValue::Int(i)) => {
            in_range(*i as f64)?;
            ParamValue::Float(*i as f64)
        }
        (ParamDefault::Str(_), RawValue::Str(s)) => {
            choice(s, &value.span)?;
            if let Some(check) = spec.check {
                check(s).map_err(|message| {
                    src.error(value.span.clone(), message, Some(spec.doc.to_string()))
                })?;
            }
            if spec.is_file_path && !s.is_empty() {
                let resolved = src.base_dir().join(s);
                ParamValue::Str(resolved.to_string_lossy().into_owned())
            } else {
                ParamValue::Str(s.clone())
            }
        }
        (ParamDefault::StrList(_), RawValue::Array(items)) => {
            let mut out = Vec::new();
            for item in items {
                match &item.value {
                    RawValue::Str(s) => {
                        choice(s, &item.span)?;
                        // A list names things (products to save, formats): twice would
                        // do the same work twice, and two writers race for one file.
                        if out.contains(s) {
                            return Err(src.error(
                                item.span.clone(),
                                format!("parameter `{}` names {s:?} twice", spec.name),
                                None,
                            ));
                        }
                        out.push(s.clone());
                    }
                    other => {
                        return Err(src.error(
                            item.span.clone(),
                            format!(
                                "parameter `{}` must hold strings, found {}",
                                spec.name,
                                a(other.type_name())
                            ),
                            None,
                        ));
                    }
                }
            }
            // A list names what to do; an empty one would make its stage do nothing.
            if out.is_empty() {
                return Err(src.error(
                    value.span.clone(),
                    format!("parameter `{}` is empty: name at least one", spec.name),
                    Some(format!("{}; default {}", spec.doc, spec.default_value())),
                ));
            }
            ParamValue::StrList(out)
        }
        _ => return Err(wrong_type()),
    })
}
