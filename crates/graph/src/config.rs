//! Pipeline config files (TOML) parsed with spans, so every error names the file, line
//! and column, shows the line, and gives a hint.
//!
//! ```toml
//! [pipeline]
//! name = "default"
//! channel_capacity = 2          # frames buffered between two stages
//!
//! [[stage]]
//! kind = "decode"               # the stage kind, see `relume stages`
//!
//! [[stage]]
//! name = "normals"              # optional; defaults to the kind
//! kind = "normals.cross"
//! params = { step = 1 }         # checked against the kind's declaration
//! inputs = { points = "points" }   # role = product; "name@prev" reads the previous
//!                                  # frame's value (optional inputs only: the first
//!                                  # frame has none)
//! outputs = { normals = "normals" }
//! every = 1                     # run on every k-th frame and lend the last products
//!                               # to the frames between (see `super::every`)
//! lag = 0                       # run n frames behind on a thread of its own: frame t
//!                               # reads its products of frame t - n (see `super::lag`)
//!
//! [[object]]                    # virtual objects, see `relume_stages::world`
//! shape = "torus"
//! translation = [0.0, 0.08, 0.0]
//! ```

use super::params::a;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// The text of a config and where it came from.
#[derive(Clone, Debug)]
pub struct SourceFile {
    /// Path as given, or a label such as `<built-in default.toml>`.
    pub name: String,
    pub text: String,
}

impl SourceFile {
    /// The directory that relative file names in the config resolve against: the
    /// config file's, or the current directory for built-in configs (named `<...>`).
    pub fn base_dir(&self) -> PathBuf {
        if self.name.starts_with('<') {
            return PathBuf::new();
        }
        Path::new(&self.name)
            .parent()
            .map_or(PathBuf::new(), Path::to_path_buf)
    }

    /// 1-based line and column of byte offset `at`.
    pub fn line_col(&self, at: usize) -> (usize, usize) {
        let at = at.min(self.text.len());
        let before = &self.text[..at];
        let line = before.matches('\n').count() + 1;
        let col = before.rfind('\n').map_or(at, |nl| at - nl - 1) + 1;
        (line, col)
    }

    /// An error at `span` with `message` and an optional hint.
    pub fn error(
        &self,
        span: Range<usize>,
        message: impl Into<String>,
        hint: Option<String>,
    ) -> ConfigError {
        let (line, column) = self.line_col(span.start);
        let source_line = self.text.lines().nth(line - 1).unwrap_or("").to_string();
        let width = span
            .end
            .saturating_sub(span.start)
            .clamp(1, source_line.len().saturating_sub(column - 1).max(1));
        ConfigError {
            file: self.name.clone(),
            line,
            column,
            message: message.into(),
            hint,
            source_line,
            width,
        }
    }
}

/// Line numbers of byte offsets in a text, by binary search over its line starts: for
/// callers that ask for many (one per stage), where [`SourceFile::line_col`] would scan
/// the text each time.
pub struct LineIndex {
    starts: Vec<usize>,
}

impl LineIndex {
    pub fn new(text: &str) -> LineIndex {
        let newlines = text.bytes().enumerate().filter(|&(_, b)| b == b'\n');
        let starts = std::iter::once(0)
            .chain(newlines.map(|(i, _)| i + 1))
            .collect();
        LineIndex { starts }
    }

    /// The 1-based line of byte offset `at`.
    pub fn line_of(&self, at: usize) -> usize {
        self.starts.partition_point(|&s| s <= at)
    }
}

/// An error in a pipeline config, located in its file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ConfigError {
    pub file: String,
    pub line: usize,
    pub column: usize,
    pub message: String,
    pub hint: Option<String>,
    source_line: String,
    width: usize,
}

impl ConfigError {
    /// An error at the same place as this one, with another message and hint: for
    /// values found wrong later, against a recording, at the place they were written.
    pub fn retold(&self, message: impl Into<String>, hint: Option<String>) -> ConfigError {
        ConfigError {
            message: message.into(),
            hint,
            ..self.clone()
        }
    }

    /// An error about a file as a whole (e.g. unreadable).
    pub fn whole_file(file: &str, message: impl Into<String>) -> ConfigError {
        ConfigError {
            file: file.to_string(),
            line: 0,
            column: 0,
            message: message.into(),
            hint: None,
            source_line: String::new(),
            width: 0,
        }
    }
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.line == 0 {
            write!(f, "{}: {}", self.file, self.message)?;
        } else {
            write!(
                f,
                "{}:{}:{}: {}",
                self.file, self.line, self.column, self.message
            )?;
            let gutter = self.line.to_string().len();
            let (shown, caret, width) = snippet(&self.source_line, self.column - 1, self.width);
            write!(
                f,
                "\n{:gutter$} |\n{} | {}\n{:gutter$} | {}{}",
                "",
                self.line,
                shown,
                "",
                " ".repeat(caret),
                "^".repeat(width)
            )?;
        }
        if let Some(h) = &self.hint {
            write!(f, "\n  = hint: {h}")?;
        }
        Ok(())
    }
}

impl std::error::Error for ConfigError {}

/// The longest source line an error shows whole; a longer one is cut to a window of
/// this many bytes around the error, so that a 5,000-character line (a generated
/// config, a pasted blob) does not fill the terminal.
const SNIPPET_BYTES: usize = 100;

/// The part of `line` to show for an error at byte `column` (0-based) spanning `width`
/// bytes: the text, and the caret's offset and width within it in characters (what a
/// terminal lines up; an `é` before the error is two bytes but one column).
fn snippet(line: &str, column: usize, width: usize) -> (String, usize, usize) {
    let (shown, caret, width) = snippet_bytes(line, column, width);
    let chars =
        |bytes: Option<&str>, fallback: usize| bytes.map_or(fallback, |s| s.chars().count());
    let caret_chars = chars(shown.get(..caret), caret);
    let width_chars = chars(shown.get(caret..caret + width), width).max(1);
    (shown, caret_chars, width_chars)
}

/// [`snippet`] in bytes.
fn snippet_bytes(line: &str, column: usize, width: usize) -> (String, usize, usize) {
    if line.len() <= SNIPPET_BYTES {
        return (line.to_string(), column, width);
    }
    let floor = |mut i: usize| {
        while !line.is_char_boundary(i) {
            i -= 1;
        }
        i
    };
    let column = floor(column.min(line.len()));
    let start = floor(column.saturating_sub(SNIPPET_BYTES / 3));
    let end = floor((start + SNIPPET_BYTES).min(line.len()));
    let (before, after) = (
        if start > 0 { "..." } else { "" },
        if end < line.len() { "..." } else { "" },
    );
    let shown = format!("{before}{}{after}", &line[start..end]);
    let width = width.min(end.saturating_sub(column)).max(1);
    (shown, before.len() + column - start, width)
}

/// A value with the byte span it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct Located<T> {
    pub value: T,
    pub span: Range<usize>,
}

/// A TOML value as written, before checking against a declaration.
#[derive(Clone, Debug, PartialEq)]
pub enum RawValue {
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Array(Vec<Located<RawValue>>),
    /// Tables and datetimes: named by type for error messages.
    Other(&'static str),
}

impl RawValue {
    pub fn type_name(&self) -> &'static str {
        match self {
            RawValue::Bool(_) => "boolean",
            RawValue::Int(_) => "integer",
            RawValue::Float(_) => "float",
            RawValue::Str(_) => "string",
            RawValue::Array(_) => "array",
            RawValue::Other(t) => t,
        }
    }
}

/// Role -> product pairs as written in `inputs` or `outputs`.
pub type RolePairs = Vec<(Located<String>, Located<String>)>;

/// One `[[stage]]` entry as written.
#[derive(Clone, Debug)]
pub struct StageDecl {
    pub name: Option<Located<String>>,
    pub kind: Located<String>,
    pub params: Vec<(Located<String>, Located<RawValue>)>,
    pub inputs: RolePairs,
    pub outputs: RolePairs,
    /// `every = k`: the stage runs on every k-th frame (checked in the pipeline).
    pub every: Option<Located<RawValue>>,
    /// `lag = n`: the stage runs n frames behind on its own thread (checked in the
    /// pipeline).
    pub lag: Option<Located<RawValue>>,
    /// Span of the whole stage table.
    pub span: Range<usize>,
}

/// One `[[object]]` or `[[light]]` entry as written; checked by the registry's world
/// resolver (`relume_stages::world::resolve`).
#[derive(Clone, Debug)]
pub struct TableDecl {
    pub entries: Vec<(Located<String>, Located<RawValue>)>,
    /// Span of the whole table.
    pub span: Range<usize>,
}

/// The tables of a pipeline file that declare its world, in file order: the virtual
/// objects (`[[object]]`) and the light sources the pipeline knows of (`[[light]]`).
#[derive(Clone, Debug, Default)]
pub struct WorldDecls {
    pub objects: Vec<TableDecl>,
    pub lights: Vec<TableDecl>,
}

impl WorldDecls {
    /// True when the file declares neither objects nor lights.
    pub fn is_empty(&self) -> bool {
        self.objects.is_empty() && self.lights.is_empty()
    }

    /// The first table written, for errors about the tables as a whole.
    pub fn first(&self) -> Option<&TableDecl> {
        let by_start = |t: &&TableDecl| t.span.start;
        self.objects.iter().chain(&self.lights).min_by_key(by_start)
    }
}

/// A pipeline file as written.
#[derive(Clone, Debug)]
pub struct PipelineDecl {
    pub name: Option<String>,
    pub description: Option<String>,
    pub channel_capacity: Option<Located<i64>>,
    pub stages: Vec<StageDecl>,
    pub world: WorldDecls,
}

type DeTable<'i> = toml::de::DeTable<'i>;
type DeValue<'i> = toml::de::DeValue<'i>;
type Spanned<T> = toml::Spanned<T>;

/// Parses the structure of a pipeline file; stage kinds and parameters are checked
/// against the registry later, in [`super::pipeline::Pipeline::resolve`].
pub fn parse(src: &SourceFile) -> Result<PipelineDecl, ConfigError> {
    let doc = DeTable::parse(&src.text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        src.error(span, format!("invalid TOML: {}", e.message().trim()), None)
    })?;
    let doc_span = doc.span();
    let doc = doc.into_inner();
    check_keys(
        src,
        &doc,
        &["pipeline", "stage", "object", "light"],
        "top-level key",
    )?;
    let mut decl = PipelineDecl {
        name: None,
        description: None,
        channel_capacity: None,
        stages: Vec::new(),
        world: WorldDecls {
            objects: parse_tables(src, &doc, "object")?,
            lights: parse_tables(src, &doc, "light")?,
        },
    };
    if let Some(p) = doc.get("pipeline") {
        let table = expect_table(src, p, "[pipeline]")?;
        check_keys(
            src,
            table,
            &["name", "description", "channel_capacity"],
            "key in [pipeline]",
        )?;
        decl.name = opt_string(src, table, "name")?.map(|l| l.value);
        decl.description = opt_string(src, table, "description")?.map(|l| l.value);
        if let Some(v) = table.get("channel_capacity") {
            match raw(v).value {
                RawValue::Int(i) => {
                    decl.channel_capacity = Some(Located {
                        value: i,
                        span: v.span(),
                    })
                }
                other => {
                    return Err(src.error(
                        v.span(),
                        format!(
                            "channel_capacity must be an integer, found {}",
                            a(other.type_name())
                        ),
                        None,
                    ));
                }
            }
        }
    }
    let Some(stages) = doc.get("stage") else {
        return Err(src.error(
            doc_span.start..doc_span.start,
            "the pipeline has no stages",
            Some(
                "add stages as [[stage]] tables with a `kind`; `relume stages` lists the kinds"
                    .into(),
            ),
        ));
    };
    let DeValue::Array(list) = stages.get_ref() else {
        return Err(src.error(
            stages.span(),
            "`stage` must be an array of tables, written [[stage]]",
            None,
        ));
    };
    for item in list.iter() {
        decl.stages.push(parse_stage(src, item)?);
    }
    Ok(decl)
}

/// The `[[object]]` or `[[light]]` tables (`key`), each as its raw key-value pairs.
fn parse_tables(
    src: &SourceFile,
    doc: &DeTable<'_>,
    key: &str,
) -> Result<Vec<TableDecl>, ConfigError> {
    let Some(tables) = doc.get(key) else {
        return Ok(Vec::new());
    };
    let DeValue::Array(list) = tables.get_ref() else {
        return Err(src.error(
            tables.span(),
            format!("`{key}` must be an array of tables, written [[{key}]]"),
            None,
        ));
    };
    let article = if key.starts_with(['a', 'e', 'i', 'o', 'u']) {
        "an"
    } else {
        "a"
    };
    list.iter()
        .map(|item| {
            let table = expect_table(src, item, &format!("{article} [[{key}]] entry"))?;
            Ok(TableDecl {
                entries: table
                    .iter()
                    .map(|(k, v)| (located_key(k), raw(v)))
                    .collect(),
                span: item.span(),
            })
        })
        .collect()
}

fn parse_stage(src: &SourceFile, item: &Spanned<DeValue<'_>>) -> Result<StageDecl, ConfigError> {
    let table = expect_table(src, item, "a [[stage]] entry")?;
    check_keys(
        src,
        table,
        &[
            "name", "kind", "params", "inputs", "outputs", "every", "lag",
        ],
        "key in [[stage]]",
    )?;
    let kind = opt_string(src, table, "kind")?.ok_or_else(|| {
        src.error(
            item.span(),
            "this stage has no `kind`",
            Some("e.g. kind = \"normals.cross\"; `relume stages` lists the kinds".into()),
        )
    })?;
    let params = match table.get("params") {
        Some(p) => expect_table(src, p, "params")?
            .iter()
            .map(|(k, v)| (located_key(k), raw(v)))
            .collect(),
        None => Vec::new(),
    };
    Ok(StageDecl {
        name: opt_string(src, table, "name")?,
        kind,
        params,
        inputs: string_table(src, table, "inputs")?,
        outputs: string_table(src, table, "outputs")?,
        every: table.get("every").map(raw),
        lag: table.get("lag").map(raw),
        span: item.span(),
    })
}

fn located_key(k: &Spanned<std::borrow::Cow<'_, str>>) -> Located<String> {
    Located {
        value: k.get_ref().to_string(),
        span: k.span(),
    }
}

fn expect_table<'a, 'i>(
    src: &SourceFile,
    v: &'a Spanned<DeValue<'i>>,
    what: &str,
) -> Result<&'a DeTable<'i>, ConfigError> {
    match v.get_ref() {
        DeValue::Table(t) => Ok(t),
        other => Err(src.error(
            v.span(),
            format!("{what} must be a table, found {}", a(other.type_str())),
            None,
        )),
    }
}

fn check_keys(
    src: &SourceFile,
    table: &DeTable<'_>,
    allowed: &[&str],
    what: &str,
) -> Result<(), ConfigError> {
    for (k, _) in table.iter() {
        if !allowed.contains(&k.get_ref().as_ref()) {
            let hint = match super::params::did_you_mean(k.get_ref(), allowed.iter().copied()) {
                Some(s) => format!("did you mean `{s}`? allowed: {}", allowed.join(", ")),
                None => format!("allowed: {}", allowed.join(", ")),
            };
            return Err(src.error(
                k.span(),
                format!("unknown {what} `{}`", k.get_ref()),
                Some(hint),
            ));
        }
    }
    Ok(())
}

fn opt_string(
    src: &SourceFile,
    table: &DeTable<'_>,
    key: &str,
) -> Result<Option<Located<String>>, ConfigError> {
    match table.get(key) {
        None => Ok(None),
        Some(v) => match v.get_ref() {
            DeValue::String(s) => Ok(Some(Located {
                value: s.to_string(),
                span: v.span(),
            })),
            other => Err(src.error(
                v.span(),
                format!("`{key}` must be a string, found {}", a(other.type_str())),
                None,
            )),
        },
    }
}

fn string_table(
    src: &SourceFile,
    table: &DeTable<'_>,
    key: &str,
) -> Result<RolePairs, ConfigError> {
    let Some(v) = table.get(key) else {
        return Ok(Vec::new());
    };
    let t = expect_table(src, v, key)?;
    t.iter()
        .map(|(k, v)| match v.get_ref() {
            DeValue::String(s) => Ok((
                located_key(k),
                Located {
                    value: s.to_string(),
                    span: v.span(),
                },
            )),
            other => Err(src.error(
                v.span(),
                format!(
                    "{key}.{} must be a product name (a string), found {}",
                    k.get_ref(),
                    a(other.type_str())
                ),
                None,
            )),
        })
        .collect()
}

/// `text` parsed as one TOML value, its span shifted by `offset` (where it stands in
/// the text errors quote); the error is toml's message.
pub fn raw_value(text: &str, offset: usize) -> Result<Located<RawValue>, String> {
    let doc = format!("v = {text}");
    let table =
        DeTable::parse(&doc).map_err(|e| format!("invalid TOML value: {}", e.message().trim()))?;
    let table = table.into_inner();
    let v = table.get("v").ok_or("invalid TOML value")?;
    if table.len() != 1 {
        return Err("invalid TOML value: more than one value".into());
    }
    let mut located = raw(v);
    shift(&mut located, offset as isize - 4);
    Ok(located)
}

/// Moves a value's spans (and its elements') by `by` bytes.
fn shift(v: &mut Located<RawValue>, by: isize) {
    let at = |i: usize| (i as isize + by).max(0) as usize;
    v.span = at(v.span.start)..at(v.span.end);
    if let RawValue::Array(items) = &mut v.value {
        for item in items {
            shift(item, by);
        }
    }
}

/// Converts a TOML value to a [`RawValue`] with its span.
fn raw(v: &Spanned<DeValue<'_>>) -> Located<RawValue> {
    let value = match v.get_ref() {
        DeValue::Boolean(b) => RawValue::Bool(*b),
        DeValue::Integer(i) => parse_int(i.as_str(), i.radix())
            .map_or(RawValue::Other("integer out of range"), RawValue::Int),
        DeValue::Float(f) => {
            parse_float(f.as_str()).map_or(RawValue::Other("float"), RawValue::Float)
        }
        DeValue::String(s) => RawValue::Str(s.to_string()),
        DeValue::Array(a) => RawValue::Array(a.iter().map(raw).collect()),
        DeValue::Table(_) => RawValue::Other("table"),
        DeValue::Datetime(_) => RawValue::Other("datetime"),
    };
    Located {
        value,
        span: v.span(),
    }
}

/// `text` is toml's `from_str_radix`-ready form: sign and digits, no prefix or `_`.
fn parse_int(text: &str, radix: u32) -> Option<i64> {
    i64::from_str_radix(text, radix).ok()
}

fn parse_float(text: &str) -> Option<f64> {
    let clean: String = text.chars().filter(|&c| c != '_').collect();
    clean.parse::<f64>().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_index_agrees_with_line_col() {
        let text = "a\n\nbb\nccc\n";
        let index = LineIndex::new(text);
        for at in 0..=text.len() {
            assert_eq!(index.line_of(at), src(text).line_col(at).0, "offset {at}");
        }
    }

    #[test]
    fn a_long_line_is_shown_as_a_window_around_the_error() {
        let value = "x".repeat(5000);
        let text = format!("name = \"{value}\" bad\n");
        let at = text.find("bad").unwrap();
        let e = src(&text)
            .error(at..at + 3, "expected a newline", None)
            .to_string();
        let lines: Vec<&str> = e.lines().collect();
        assert_eq!(lines[0], format!("p.toml:1:{}: expected a newline", at + 1));
        let shown = format!("...{}\" bad", "x".repeat(31));
        assert_eq!(lines[2], format!("1 | {shown}"));
        assert_eq!(lines[3], format!("  | {}^^^", " ".repeat(shown.len() - 3)));
        // The start of a long line: no leading cut; a short line: whole.
        let e = src(&text).error(0..4, "m", None).to_string();
        assert_eq!(
            e.lines().nth(2).unwrap(),
            format!("1 | name = \"{}...", "x".repeat(92))
        );
        let e = src("a = 1\n").error(4..5, "m", None).to_string();
        assert_eq!(e.lines().nth(2).unwrap(), "1 | a = 1");
        // The caret counts characters, not bytes.
        let text = "a = \"éé\" xy\n";
        let at = text.find("xy").unwrap();
        let e = src(text).error(at..at + 2, "m", None).to_string();
        assert_eq!(
            e.lines().nth(3).unwrap(),
            format!("  | {}^^", " ".repeat(9))
        );
    }

    fn src(text: &str) -> SourceFile {
        SourceFile {
            name: "p.toml".into(),
            text: text.into(),
        }
    }

    #[test]
    fn errors_carry_line_column_and_caret() {
        let s = src("[[stage]]\nkind = \"decode\"\nparms = 3\n");
        let e = parse(&s).unwrap_err();
        assert_eq!((e.line, e.column), (3, 1));
        let text = e.to_string();
        assert!(
            text.starts_with("p.toml:3:1: unknown key in [[stage]] `parms`"),
            "{text}"
        );
        assert!(text.contains("did you mean `params`?"), "{text}");
        assert!(text.contains("3 | parms = 3\n  | ^^^^^"), "{text}");
    }

    #[test]
    fn numbers_in_all_toml_spellings() {
        let s = src(
            "[[stage]]\nkind = \"x\"\nparams = { a = 1_000, b = 0x10, c = -2.5e1, d = [\"p\", \"q\"] }\n",
        );
        let d = parse(&s).unwrap();
        let values: Vec<RawValue> = d.stages[0]
            .params
            .iter()
            .map(|(_, v)| v.value.clone())
            .collect();
        assert_eq!(values[0], RawValue::Int(1000));
        assert_eq!(values[1], RawValue::Int(16));
        assert_eq!(values[2], RawValue::Float(-25.0));
        assert!(matches!(&values[3], RawValue::Array(a) if a.len() == 2));
    }

    #[test]
    fn syntax_errors_are_located() {
        let e = parse(&src("[[stage]]\nkind = \"decode\n")).unwrap_err();
        assert_eq!(e.line, 2, "{e}");
        assert!(e.message.starts_with("invalid TOML"), "{e}");
    }
}
