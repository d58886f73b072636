//! A pipeline config checked against the registry: kinds exist, parameters have the
//! declared types and bounds, every input is produced upstream (or, with `@prev`,
//! anywhere, as a feedback edge delivering the previous frame's value), and kinds match.

use super::build::build_stage;
use super::config::{self, ConfigError, Located, PipelineDecl, SourceFile};
use super::frame::ProductKind;
use super::params::{a, did_you_mean};
use super::registry::Registry;
pub use super::resolved::{
    DEFAULT_CHANNEL_CAPACITY, Feedback, PREVIOUS_SUFFIX, ResolvedStage, SOURCE_PRODUCT,
};
use super::stage::{Stage, StageError};
use super::stage_checks::{bind_ports, check_params, rate_key};
use relume_recording::Header;
use std::collections::BTreeMap;
use std::path::Path;

/// The built-in default pipeline (`pipelines/default.toml`, compiled in).
pub const DEFAULT_PIPELINE_TOML: &str = include_str!("../../../pipelines/default.toml");

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
    /// What the `[[object]]` tables declare, resolved by the registry's
    /// [`super::world::WorldResolver`] ([`super::world::EmptyWorld`] without one).
    pub world: std::sync::Arc<dyn super::world::World>,
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
        let text = relume_base::files::read_regular_to_string(path).map_err(|e| {
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
        // Pass 1: kinds, names, parameters, ports. (Linear in the stage count: a map of
        // names, line numbers by search; a pipeline may be generated with thousands.)
        let mut stages: Vec<ResolvedStage> = Vec::new();
        let mut port_sets = Vec::new();
        let mut names: std::collections::HashMap<String, usize> = Default::default();
        let lines = config::LineIndex::new(&src.text);
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
            if let Some(prev) = names.get(&name).map(|&k| &stages[k]) {
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
            let every = rate_key(src, &d.every, &name, "every", 1..=super::every::MAX_EVERY)?;
            let lag = rate_key(src, &d.lag, &name, "lag", 0..=super::lag::MAX_LAG)?;
            names.insert(name.clone(), stages.len());
            stages.push(ResolvedStage {
                name,
                kind: info.kind,
                params,
                inputs,
                outputs,
                line: lines.line_of(d.span.start),
                every,
                lag,
            });
            port_sets.push(ports);
        }
        // Pass 2: every product is produced once, and inputs are produced upstream or
        // (with @prev) anywhere in the pipeline.
        let mut producers: BTreeMap<String, (usize, ProductKind)> = BTreeMap::new();
        producers.insert(
            SOURCE_PRODUCT.into(),
            (usize::MAX, relume_recording::RECORD),
        );
        for (i, (stage, ports)) in stages.iter().zip(&port_sets).enumerate() {
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
                // Upstream of stage i: the source and stages 0..i (each product has
                // one producer, so its index says whether it runs before i).
                let upstream = |&(p, _): &(usize, ProductKind)| p == usize::MAX || p < i;
                let found = match previous {
                    true => producers.get(product),
                    false => producers.get(product).filter(|e| upstream(e)),
                };
                let Some(&(producer, kind)) = found else {
                    let bound_here = located_span(&d.inputs, &port.role).is_some();
                    if port.when_made
                        && !previous
                        && !bound_here
                        && !producers.contains_key(product)
                    {
                        // Nothing makes it and the config did not ask for it: the stage
                        // does without.
                        continue;
                    }
                    let available: BTreeMap<String, (usize, ProductKind)> = producers
                        .iter()
                        .filter(|(_, e)| upstream(e))
                        .map(|(k, e)| (k.clone(), *e))
                        .collect();
                    return Err(missing_product(
                        src, span, &stages, &available, &producers, i, port, product, previous,
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
        let world = registry.resolve_world(&decl.world, src)?;
        Ok(Pipeline {
            name: decl.name.clone().unwrap_or_else(|| src.name.clone()),
            description: decl.description.clone().unwrap_or_default(),
            file: src.name.clone(),
            channel_capacity,
            stages,
            feedback,
            world,
        })
    }

    /// Why the pipeline cannot run yet ([`World::waiting`](super::world::World::waiting)).
    pub fn waiting(&self) -> Vec<String> {
        self.world.waiting()
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
        // What StageGraph::linear gives each node: the pipeline's world and the first
        // reason it cannot run yet.
        let waiting = self.waiting().into_iter().next();
        self.stages
            .iter()
            .map(|s| {
                build_stage(
                    s,
                    &self.world,
                    waiting.as_deref(),
                    registry,
                    header,
                    out_dir,
                    seed,
                )
                .map_err(|e| (s.name.clone(), e))
            })
            .collect()
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
