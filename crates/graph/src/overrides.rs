//! `--set STAGE.PARAM=VALUE`: a stage's parameter changed from the command line, for
//! one run, without editing the pipeline file (sweeps, `relume bench` variants).
//!
//! Each override is written into the pipeline's text as a trailing comment line,
//! `# --set STAGE.PARAM = VALUE`, and its key and value take their spans from that
//! line: a bad override is reported like a bad line of the file, with the same checks
//! (unknown parameter, wrong type, out of range) and the same hints.

use super::config::{self, ConfigError, Located, PipelineDecl, RawValue, SourceFile};

/// One `--set STAGE.PARAM=VALUE`: the stage's name (its `name`, or its kind when it
/// has none: `sample.path`), the parameter and the value as TOML (`vct` may be
/// written bare: a value that is not TOML is taken as a string).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParamOverride {
    pub stage: String,
    pub param: String,
    pub value: String,
}

impl std::str::FromStr for ParamOverride {
    type Err = String;

    /// Parses `STAGE.PARAM=VALUE`; the parameter is the part after the last dot
    /// before `=` (stage names hold dots, parameter names do not).
    fn from_str(text: &str) -> Result<Self, String> {
        let usage = || format!("`{text}` is not STAGE.PARAM=VALUE (e.g. sample.path.query=vct)");
        let (target, value) = text.split_once('=').ok_or_else(usage)?;
        let (stage, param) = target.trim().rsplit_once('.').ok_or_else(usage)?;
        let (stage, param, value) = (stage.trim(), param.trim(), value.trim());
        if stage.is_empty() || param.is_empty() || value.is_empty() {
            return Err(usage());
        }
        Ok(ParamOverride {
            stage: stage.into(),
            param: param.into(),
            value: value.into(),
        })
    }
}

/// Applies `overrides` to `decl`, parsed from `src`, and returns the source the
/// overrides' spans point into (`src` with one comment line per override).
pub fn apply(
    decl: &mut PipelineDecl,
    src: &SourceFile,
    overrides: &[ParamOverride],
) -> Result<SourceFile, ConfigError> {
    let mut text = src.text.clone();
    if !text.ends_with('\n') {
        text.push('\n');
    }
    for o in overrides {
        let line_start = text.len();
        let prefix = format!("# --set {}.", o.stage);
        let key_start = line_start + prefix.len();
        let key_span = key_start..key_start + o.param.len();
        let value_start = key_span.end + 3;
        let (written, raw) = match config::raw_value(&o.value, value_start) {
            Ok(raw) => (o.value.clone(), raw),
            // Not TOML (a bare word, as the shell passed it): a string.
            Err(_) => {
                let quoted = toml::Value::String(o.value.clone()).to_string();
                let span = value_start..value_start + quoted.len();
                let raw = Located {
                    value: RawValue::Str(o.value.clone()),
                    span,
                };
                (quoted, raw)
            }
        };
        text.push_str(&format!("{prefix}{} = {written}\n", o.param));
        let Some(stage) = decl.stages.iter_mut().find(|d| stage_name(d) == o.stage) else {
            let names: Vec<String> = decl.stages.iter().map(stage_name).collect();
            let with_line = SourceFile {
                name: src.name.clone(),
                text,
            };
            return Err(with_line.error(
                line_start + 8..key_start - 1,
                format!("--set: no stage named `{}` in the pipeline", o.stage),
                Some(format!("its stages: {}", names.join(", "))),
            ));
        };
        let key = Located {
            value: o.param.clone(),
            span: key_span,
        };
        match stage.params.iter_mut().find(|(k, _)| k.value == o.param) {
            Some(entry) => *entry = (key, raw),
            None => stage.params.push((key, raw)),
        }
    }
    Ok(SourceFile {
        name: src.name.clone(),
        text,
    })
}

/// A stage's name as `--set` and messages use it: its `name`, else its kind.
fn stage_name(d: &config::StageDecl) -> String {
    d.name.as_ref().unwrap_or(&d.kind).value.clone()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overrides_parse_stage_names_with_dots() {
        let o: ParamOverride = "sample.path.query=vct".parse().unwrap();
        assert_eq!(
            o,
            ParamOverride {
                stage: "sample.path".into(),
                param: "query".into(),
                value: "vct".into()
            }
        );
        assert!("sample.path=3".parse::<ParamOverride>().is_ok());
        assert!("query".parse::<ParamOverride>().is_err());
        assert!("sample.path.query=".parse::<ParamOverride>().is_err());
    }
}
