//! Typed stage parameters: each stage kind declares its parameters (name, default,
//! bounds or choices, doc); configs are checked against the declaration at load time and
//! `relume stages` prints it.

use std::collections::BTreeMap;

/// A parameter's default, which also fixes its type.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ParamDefault {
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(&'static str),
    StrList(&'static [&'static str]),
}

/// A check of a string parameter's form: `Err` says what is wrong with the value.
pub type StrCheck = fn(&str) -> Result<(), String>;

/// The declaration of one parameter of a stage kind.
#[derive(Clone, Copy, Debug)]
pub struct ParamSpec {
    pub name: &'static str,
    pub default: ParamDefault,
    /// Inclusive bounds for numbers.
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// Allowed values for strings and string lists (empty: any).
    pub choices: &'static [&'static str],
    /// A string that names a file: a relative value resolves against the pipeline
    /// file's directory when the config is loaded, as mesh paths do.
    pub is_file_path: bool,
    /// A check of a string's form beyond its choices (e.g. "x,y,z"), run when the
    /// config is loaded, on each item of a string list; the error says what is wrong
    /// with the value.
    pub check: Option<StrCheck>,
    pub doc: &'static str,
}

impl ParamSpec {
    /// A parameter with no bounds or choices.
    pub const fn new(name: &'static str, default: ParamDefault, doc: &'static str) -> ParamSpec {
        ParamSpec {
            name,
            default,
            min: None,
            max: None,
            choices: &[],
            is_file_path: false,
            check: None,
            doc,
        }
    }

    /// The same parameter with inclusive numeric bounds.
    pub const fn range(self, min: f64, max: f64) -> ParamSpec {
        ParamSpec {
            min: Some(min),
            max: Some(max),
            ..self
        }
    }

    /// The same parameter restricted to `choices`.
    pub const fn choices(self, choices: &'static [&'static str]) -> ParamSpec {
        ParamSpec { choices, ..self }
    }

    /// The same string parameter with its form checked by `check` at load time.
    pub const fn checked(self, check: StrCheck) -> ParamSpec {
        ParamSpec {
            check: Some(check),
            ..self
        }
    }

    /// The same string parameter naming a file, relative to the pipeline file's
    /// directory ([`SourceFile::base_dir`](crate::config::SourceFile::base_dir)).
    pub const fn file_path(self) -> ParamSpec {
        ParamSpec {
            is_file_path: true,
            ..self
        }
    }

    /// The TOML type name of the parameter.
    pub fn type_name(&self) -> &'static str {
        match self.default {
            ParamDefault::Bool(_) => "boolean",
            ParamDefault::Int(_) => "integer",
            ParamDefault::Float(_) => "float",
            ParamDefault::Str(_) => "string",
            ParamDefault::StrList(_) => "array of strings",
        }
    }

    /// The default as a value.
    pub fn default_value(&self) -> ParamValue {
        match self.default {
            ParamDefault::Bool(b) => ParamValue::Bool(b),
            ParamDefault::Int(i) => ParamValue::Int(i),
            ParamDefault::Float(f) => ParamValue::Float(f),
            ParamDefault::Str(s) => ParamValue::Str(s.to_string()),
            ParamDefault::StrList(l) => {
                ParamValue::StrList(l.iter().map(|s| s.to_string()).collect())
            }
        }
    }
}

/// A parameter's value in a loaded config.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    StrList(Vec<String>),
}

impl std::fmt::Display for ParamValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ParamValue::Bool(b) => write!(f, "{b}"),
            ParamValue::Int(i) => write!(f, "{i}"),
            ParamValue::Float(x) => write!(f, "{x:?}"),
            ParamValue::Str(s) => write!(f, "{s:?}"),
            ParamValue::StrList(l) => write!(f, "{l:?}"),
        }
    }
}

/// The checked parameters of one stage, defaults filled in.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Params {
    values: BTreeMap<String, ParamValue>,
}

impl Params {
    /// The defaults of `specs`.
    pub fn defaults(specs: &[ParamSpec]) -> Params {
        Params {
            values: specs
                .iter()
                .map(|s| (s.name.to_string(), s.default_value()))
                .collect(),
        }
    }

    pub fn set(&mut self, name: &str, value: ParamValue) {
        self.values.insert(name.to_string(), value);
    }

    pub fn get(&self, name: &str) -> Option<&ParamValue> {
        self.values.get(name)
    }

    pub fn iter(&self) -> impl Iterator<Item = (&str, &ParamValue)> {
        self.values.iter().map(|(k, v)| (k.as_str(), v))
    }

    // Typed getters. The registry checks every value against the stage's declaration
    // before a stage is built, so a missing or mistyped value here is a bug in the
    // stage's declaration, caught by the registry's tests of every built-in kind.

    pub fn bool(&self, name: &str) -> bool {
        match self.values.get(name) {
            Some(ParamValue::Bool(b)) => *b,
            other => declared_wrong(name, other),
        }
    }

    pub fn int(&self, name: &str) -> i64 {
        match self.values.get(name) {
            Some(ParamValue::Int(i)) => *i,
            other => declared_wrong(name, other),
        }
    }

    pub fn float(&self, name: &str) -> f64 {
        match self.values.get(name) {
            Some(ParamValue::Float(f)) => *f,
            Some(ParamValue::Int(i)) => *i as f64,
            other => declared_wrong(name, other),
        }
    }

    pub fn str(&self, name: &str) -> &str {
        match self.values.get(name) {
            Some(ParamValue::Str(s)) => s,
            other => declared_wrong(name, other),
        }
    }

    pub fn str_list(&self, name: &str) -> &[String] {
        match self.values.get(name) {
            Some(ParamValue::StrList(l)) => l,
            other => declared_wrong(name, other),
        }
    }
}

fn declared_wrong(name: &str, found: Option<&ParamValue>) -> ! {
    panic!(
        "stage parameter `{name}` read with the wrong type or undeclared (found {found:?}): fix the stage's ParamSpec list"
    )
}

/// `noun` with its indefinite article: "a string", "an integer".
pub fn a(noun: &str) -> String {
    let vowel = noun.starts_with(['a', 'e', 'i', 'o', 'u']);
    format!("{} {noun}", if vowel { "an" } else { "a" })
}

/// The closest of `candidates` to `word` by edit distance, if close enough to suggest.
pub fn did_you_mean<'a>(
    word: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    candidates
        .into_iter()
        .map(|c| (edit_distance(word, c), c))
        .filter(|&(d, c)| d <= c.len().max(word.len()).div_ceil(3))
        .min()
        .map(|(_, c)| c)
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + (ca != cb) as usize).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suggestions_pick_close_names_only() {
        assert_eq!(did_you_mean("radus", ["radius", "step"]), Some("radius"));
        assert_eq!(
            did_you_mean("normals.crss", ["normals.cross", "decode"]),
            Some("normals.cross")
        );
        assert_eq!(did_you_mean("zzz", ["radius", "step"]), None);
    }
}
