//! Checks of one `[[stage]]` table against its kind's declaration: its role tables bound
//! to the kind's ports, its parameters against their types, bounds and choices, and its
//! `every` and `lag` keys.

use super::config::{ConfigError, Located, RawValue, SourceFile, StageDecl};
use super::params::{ParamDefault, ParamSpec, ParamValue, Params, a, did_you_mean};
use std::collections::BTreeMap;

/// Binds a stage's declared ports to product names from the config's role table.
pub(super) fn bind_ports(
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
pub(super) fn check_params(
    src: &SourceFile,
    d: &StageDecl,
    specs: &[ParamSpec],
    stage: &str,
) -> Result<Params, ConfigError> {
    let mut params = Params::defaults(specs);
    for (key, value) in &d.params {
        let Some(spec) = specs.iter().find(|s| s.name == key.value) else {
            let names: Vec<&str> = specs.iter().map(|s| s.name).collect();
            let rate_key = matches!(key.value.as_str(), "every" | "lag");
            let hint = match did_you_mean(&key.value, names.iter().copied()) {
                _ if rate_key => format!(
                    "`{}` is a key of the [[stage]] table, not a parameter: write `{} = ...` beside `kind` in the pipeline file (--set changes parameters only)",
                    key.value, key.value
                ),
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
                        if let Some(check) = spec.check {
                            check(s).map_err(|message| {
                                src.error(item.span.clone(), message, Some(spec.doc.to_string()))
                            })?;
                        }
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
/// The value of a stage's `every` or `lag` key (the start of `range` when absent), an
/// error at the value when it is not an integer in `range`.
pub(super) fn rate_key(
    src: &SourceFile,
    value: &Option<Located<RawValue>>,
    stage: &str,
    key: &str,
    range: std::ops::RangeInclusive<u32>,
) -> Result<u32, ConfigError> {
    let Some(v) = value else {
        return Ok(*range.start());
    };
    match v.value {
        RawValue::Int(k) if k >= 0 && range.contains(&(k.min(u32::MAX as i64) as u32)) => {
            Ok(k as u32)
        }
        _ => {
            let hint = match key {
                "every" => {
                    "every = 8 runs the stage on frames 0, 8, 16, ...; the frames between reuse its products"
                }
                _ => {
                    "lag = 2 runs the stage on its own thread: frame t reads its products of frame t - 2"
                }
            };
            Err(src.error(
                v.span.clone(),
                format!(
                    "`{key}` of stage `{stage}` must be an integer from {} to {}",
                    range.start(),
                    range.end()
                ),
                Some(hint.into()),
            ))
        }
    }
}
