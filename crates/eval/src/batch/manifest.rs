//! The batch manifest: which recordings, which pipelines, the replay settings for every
//! run, and where the outputs go. Every recording runs through every pipeline.
//!
//! ```toml
//! # Paths are relative to this file's folder.
//! out = "runs"                        # optional; default: <manifest stem>-out beside it
//! recordings = ["data/room.relume", "data/lr.relume"]
//! pipelines = ["../pipelines/acquisition.toml", "geometry.toml"]
//!
//! [settings]                          # optional, for every run, as `relume replay` takes them
//! frames = "0..50"                    # A..B, A.., ..B or N (or [A, B])
//! save = ["reference", "normals"]     # products saved into OUT/<item id>/<product>/
//! save_format = ["png"]               # png, exr or both
//! seed = 1
//! skip_corrupt = false
//! set = ["normals.plane_fit.radius=0.03"]   # like --set STAGE.PARAM=VALUE
//! max_pose_gap_ms = 100.0
//! run_programs = false                # pipelines with external stages run only when true
//! ```
//!
//! Unknown keys, wrong types, missing files and entries listed twice are errors naming
//! the manifest's line and column.

use super::error::BatchError;
use relume_graph::ParamOverride;
use relume_graph::config::SourceFile;
use relume_graph::params::{a, did_you_mean};
use relume_recording::replay::parse_frames;
use std::ops::Range;
use std::path::{Component, Path, PathBuf};
use toml::de::{DeTable, DeValue};
use xxhash_rust::xxh3::xxh3_64;

/// A manifest, read and checked.
#[derive(Clone, Debug)]
pub struct Manifest {
    /// The manifest file as given.
    pub file: PathBuf,
    /// The output folder: `out` resolved against the manifest's folder, or the default
    /// `<manifest stem>-out` beside it.
    pub out: PathBuf,
    /// The settings of every run.
    pub settings: Settings,
    /// Every (recording, pipeline) pair, recordings outermost, in the manifest's order.
    pub items: Vec<Item>,
}

/// The replay settings of every run (`[settings]`), as `relume replay` takes them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Settings {
    /// Frames to replay; `None`: every frame.
    pub frames: Option<Range<usize>>,
    /// Products saved into the item's folder (`all` for every writable one).
    pub save: Vec<String>,
    /// File formats of saved images: `png`, `exr` (default `png`).
    pub save_format: Vec<String>,
    /// Seed of stages that draw random numbers (default 1).
    pub seed: u64,
    /// Skip frames with corrupt records instead of failing the item.
    pub skip_corrupt: bool,
    /// Parameter changes, as `--set STAGE.PARAM=VALUE`.
    pub set: Vec<ParamOverride>,
    /// `--max-pose-gap` in nanoseconds.
    pub max_pose_gap_ns: Option<i64>,
    /// Whether pipelines that start programs (external stages) may run: a manifest
    /// says so, since a batch runs unattended. Not part of [`Settings::canonical`]: it
    /// changes no output.
    pub run_programs: bool,
}

impl Settings {
    /// The settings as one canonical line, for the completion marker: an item run with
    /// other settings is not done.
    pub fn canonical(&self) -> String {
        let set: Vec<String> = self
            .set
            .iter()
            .map(|o| format!("{}.{}={}", o.stage, o.param, o.value))
            .collect();
        format!(
            "frames={:?} save={:?} save_format={:?} seed={} skip_corrupt={} set={:?} \
             max_pose_gap_ns={:?}",
            self.frames,
            self.save,
            self.save_format,
            self.seed,
            self.skip_corrupt,
            set,
            self.max_pose_gap_ns
        )
    }
}

/// One run: a recording through a pipeline.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Item {
    /// See [`item_id`].
    pub id: String,
    /// The recording as the manifest names it, normalized (`/`-separated, no `.`).
    pub recording: String,
    /// The pipeline as the manifest names it, normalized.
    pub pipeline: String,
    /// The recording's path (the manifest's folder joined with `recording`).
    pub recording_path: PathBuf,
    /// The pipeline's path.
    pub pipeline_path: PathBuf,
}

/// The id of the item that runs `recording` through `pipeline` (both as the manifest
/// names them, normalized): `<recording stem>__<pipeline stem>__<hash>`, the stems with
/// every character other than ASCII letters, digits, `.`, `-` and `_` replaced by `_`,
/// and `<hash>` the low 32 bits of xxh3 of `recording + "\n" + pipeline` in 8 hex
/// digits, so that two recordings with one stem in different folders get different
/// ids. The id names the item's output folder and decides its shard.
pub fn item_id(recording: &str, pipeline: &str) -> String {
    let stem = |p: &str| {
        let s: String = Path::new(p)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || "._-".contains(c) {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        if s.is_empty() { "_".to_string() } else { s }
    };
    let hash = xxh3_64(format!("{recording}\n{pipeline}").as_bytes()) as u32;
    format!("{}__{}__{hash:08x}", stem(recording), stem(pipeline))
}

/// `path` with `/` between its parts and no `.` parts: how a manifest entry enters an
/// item id, so that `./a.relume` and `a.relume` are one recording.
pub fn normalize(path: &str) -> String {
    let parts: Vec<String> = Path::new(path)
        .components()
        .filter(|c| *c != Component::CurDir)
        .map(|c| match c {
            Component::RootDir => String::new(),
            other => other.as_os_str().to_string_lossy().into_owned(),
        })
        .collect();
    if parts.len() == 1 && parts[0].is_empty() {
        return "/".into();
    }
    parts.join("/")
}

const KEYS: &[&str] = &["out", "recordings", "pipelines", "settings"];
const SETTING_KEYS: &[&str] = &[
    "frames",
    "save",
    "save_format",
    "seed",
    "skip_corrupt",
    "set",
    "max_pose_gap_ms",
    "run_programs",
];

impl Manifest {
    /// Reads and checks the manifest at `path`.
    pub fn load(path: &Path) -> Result<Manifest, BatchError> {
        let text = relume_base::files::read_regular_to_string(path)
            .map_err(|e| BatchError::io(path, e))?;
        let src = SourceFile {
            name: path.display().to_string(),
            text,
        };
        Manifest::parse(&src, path)
    }

    /// Checks the manifest `src` (read from `path`), including that its files exist.
    pub fn parse(src: &SourceFile, path: &Path) -> Result<Manifest, BatchError> {
        let doc = DeTable::parse(&src.text).map_err(|e| {
            src.error(
                e.span().unwrap_or(0..0),
                format!("invalid TOML: {}", e.message().trim()),
                None,
            )
        })?;
        let doc_span = doc.span();
        let doc = doc.into_inner();
        check_keys(src, &doc, KEYS, "key in the manifest")?;
        let base = path.parent().map_or(PathBuf::new(), Path::to_path_buf);
        let out = match doc.get("out") {
            Some(v) => {
                let out = base.join(string(src, v, "out")?);
                // Items and the shard's lists are written and cleared there: never a
                // file system's root.
                if out.parent().is_none() {
                    return Err(src
                        .error(
                            v.span(),
                            format!(
                                "`out` = {:?} is the root of a file system: give a folder of \
                                 its own for the batch's items",
                                out.display().to_string()
                            ),
                            None,
                        )
                        .into());
                }
                out
            }
            None => {
                let stem = path
                    .file_stem()
                    .map_or("batch".into(), |s| s.to_string_lossy());
                base.join(format!("{stem}-out"))
            }
        };
        let recordings = files(
            src,
            &doc,
            "recordings",
            "recording",
            &base,
            doc_span.clone(),
        )?;
        let pipelines = files(src, &doc, "pipelines", "pipeline", &base, doc_span)?;
        let settings = match doc.get("settings") {
            None => Settings::default_run(),
            Some(v) => settings(src, v)?,
        };
        let mut items = Vec::new();
        for (recording, recording_path) in &recordings {
            for (pipeline, pipeline_path) in &pipelines {
                items.push(Item {
                    id: item_id(recording, pipeline),
                    recording: recording.clone(),
                    pipeline: pipeline.clone(),
                    recording_path: recording_path.clone(),
                    pipeline_path: pipeline_path.clone(),
                });
            }
        }
        // Two items under one id would share a folder and a DONE marker (the id's hash
        // is 32 bits): refuse rather than count one as the other.
        let mut seen = std::collections::BTreeMap::new();
        for item in &items {
            if let Some(other) = seen.insert(item.id.clone(), item) {
                return Err(BatchError::io(
                    path,
                    std::io::Error::other(format!(
                        "items ({} through {}) and ({} through {}) have the same id {}: \
                         rename one of the files",
                        other.recording, other.pipeline, item.recording, item.pipeline, item.id
                    )),
                ));
            }
        }
        Ok(Manifest {
            file: path.to_path_buf(),
            out,
            settings,
            items,
        })
    }
}

impl Settings {
    /// What `relume replay` does without options.
    pub fn default_run() -> Settings {
        Settings {
            save_format: vec!["png".into()],
            seed: 1,
            ..Settings::default()
        }
    }
}

type Value<'i> = toml::Spanned<DeValue<'i>>;

fn check_keys(
    src: &SourceFile,
    table: &DeTable<'_>,
    allowed: &[&str],
    what: &str,
) -> Result<(), BatchError> {
    for (k, _) in table.iter() {
        if !allowed.contains(&k.get_ref().as_ref()) {
            let hint = match did_you_mean(k.get_ref(), allowed.iter().copied()) {
                Some(s) => format!("did you mean `{s}`? allowed: {}", allowed.join(", ")),
                None => format!("allowed: {}", allowed.join(", ")),
            };
            let message = format!("unknown {what} `{}`", k.get_ref());
            return Err(src.error(k.span(), message, Some(hint)).into());
        }
    }
    Ok(())
}

fn wrong(src: &SourceFile, v: &Value<'_>, key: &str, expected: &str) -> BatchError {
    let found = a(v.get_ref().type_str());
    src.error(
        v.span(),
        format!("`{key}` must be {expected}, found {found}"),
        None,
    )
    .into()
}

fn string(src: &SourceFile, v: &Value<'_>, key: &str) -> Result<String, BatchError> {
    match v.get_ref() {
        DeValue::String(s) => Ok(s.to_string()),
        _ => Err(wrong(src, v, key, "a string")),
    }
}

fn strings<'a, 'i>(
    src: &SourceFile,
    v: &'a Value<'i>,
    key: &str,
) -> Result<Vec<(String, &'a Value<'i>)>, BatchError> {
    let DeValue::Array(list) = v.get_ref() else {
        return Err(wrong(src, v, key, "an array of strings"));
    };
    list.iter()
        .map(|item| match item.get_ref() {
            DeValue::String(s) => Ok((s.to_string(), item)),
            _ => Err(wrong(src, item, &format!("{key}[]"), "a string")),
        })
        .collect()
}

/// The files listed under `key`: each normalized and joined to `base`; an error at the
/// entry when it is missing or listed twice.
fn files(
    src: &SourceFile,
    doc: &DeTable<'_>,
    key: &str,
    what: &str,
    base: &Path,
    doc_span: Range<usize>,
) -> Result<Vec<(String, PathBuf)>, BatchError> {
    let Some(v) = doc.get(key) else {
        let hint = format!("add `{key} = [\"...\"]`, paths relative to the manifest's folder");
        let message = format!("the manifest has no `{key}`");
        return Err(src
            .error(doc_span.start..doc_span.start, message, Some(hint))
            .into());
    };
    let list = strings(src, v, key)?;
    if list.is_empty() {
        return Err(src
            .error(v.span(), format!("`{key}` lists no {what}"), None)
            .into());
    }
    let mut found: Vec<(String, PathBuf)> = Vec::new();
    for (written, item) in list {
        let name = normalize(&written);
        let path = base.join(&name);
        if found.iter().any(|(n, _)| *n == name) {
            let message = format!("{what} `{written}` is listed twice");
            return Err(src.error(item.span(), message, None).into());
        }
        if let Err(e) = std::fs::metadata(&path).and_then(|m| {
            if m.is_file() {
                Ok(())
            } else {
                Err(std::io::Error::other("is not a regular file"))
            }
        }) {
            let message = match e.kind() {
                std::io::ErrorKind::NotFound => {
                    format!(
                        "{what} `{written}` does not exist (looked for {})",
                        path.display()
                    )
                }
                _ => format!("{what} `{written}` ({}): {e}", path.display()),
            };
            let hint = Some("paths are relative to the manifest's folder".into());
            return Err(src.error(item.span(), message, hint).into());
        }
        found.push((name, path));
    }
    Ok(found)
}

fn settings(src: &SourceFile, v: &Value<'_>) -> Result<Settings, BatchError> {
    let DeValue::Table(table) = v.get_ref() else {
        return Err(wrong(src, v, "settings", "a table, written [settings]"));
    };
    check_keys(src, table, SETTING_KEYS, "key in [settings]")?;
    let mut s = Settings::default_run();
    let at = |v: &Value<'_>, message: String| -> BatchError {
        src.error(v.span(), message, None).into()
    };
    if let Some(v) = table.get("frames") {
        s.frames = Some(match v.get_ref() {
            DeValue::String(text) => parse_frames(text).map_err(|m| at(v, m))?,
            DeValue::Array(pair) => {
                let ints: Vec<usize> = pair
                    .iter()
                    .filter_map(|x| match x.get_ref() {
                        DeValue::Integer(i) => i.as_str().parse::<usize>().ok(),
                        _ => None,
                    })
                    .collect();
                match ints[..] {
                    [start, end] if pair.len() == 2 && start < end => start..end,
                    _ => {
                        return Err(at(
                            v,
                            "frames = [A, B] needs two whole numbers, A < B".into(),
                        ));
                    }
                }
            }
            _ => return Err(wrong(src, v, "frames", "a string such as \"0..50\"")),
        });
    }
    if let Some(v) = table.get("save") {
        s.save = strings(src, v, "save")?
            .into_iter()
            .map(|(s, _)| s)
            .collect();
        repeats(src, v, "save", &s.save)?;
    }
    if let Some(v) = table.get("save_format") {
        let list = strings(src, v, "save_format")?;
        if list.is_empty() {
            return Err(at(v, "`save_format` names no format (png, exr)".into()));
        }
        for (f, item) in &list {
            if f != "png" && f != "exr" {
                return Err(at(
                    item,
                    format!("unknown save_format {f:?}: expected png or exr"),
                ));
            }
        }
        s.save_format = list.into_iter().map(|(s, _)| s).collect();
        repeats(src, v, "save_format", &s.save_format)?;
    }
    if let Some(v) = table.get("seed") {
        s.seed = match v.get_ref() {
            DeValue::Integer(i) => i.as_str().parse::<u64>().ok(),
            _ => None,
        }
        .ok_or_else(|| wrong(src, v, "seed", "a whole number"))?;
    }
    if let Some(v) = table.get("run_programs") {
        s.run_programs = match v.get_ref() {
            DeValue::Boolean(b) => *b,
            _ => return Err(wrong(src, v, "run_programs", "a boolean")),
        };
    }
    if let Some(v) = table.get("skip_corrupt") {
        s.skip_corrupt = match v.get_ref() {
            DeValue::Boolean(b) => *b,
            _ => return Err(wrong(src, v, "skip_corrupt", "a boolean")),
        };
    }
    if let Some(v) = table.get("set") {
        for (text, item) in strings(src, v, "set")? {
            s.set
                .push(text.parse::<ParamOverride>().map_err(|m| at(item, m))?);
        }
    }
    if let Some(v) = table.get("max_pose_gap_ms") {
        let ms = match v.get_ref() {
            DeValue::Integer(i) => i.as_str().parse::<f64>().ok(),
            DeValue::Float(f) => f.as_str().parse::<f64>().ok(),
            _ => None,
        };
        match ms {
            Some(ms) if (1e-6..1e12).contains(&ms) => {
                s.max_pose_gap_ns = Some((ms * 1e6).round() as i64)
            }
            _ => {
                return Err(wrong(
                    src,
                    v,
                    "max_pose_gap_ms",
                    "a positive number of milliseconds",
                ));
            }
        }
    }
    Ok(s)
}

fn repeats(src: &SourceFile, v: &Value<'_>, key: &str, names: &[String]) -> Result<(), BatchError> {
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            return Err(src
                .error(v.span(), format!("`{key}` names {n:?} twice"), None)
                .into());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::Shard;

    fn manifest(dir: &Path, text: &str) -> Result<Manifest, String> {
        let path = dir.join("m.toml");
        std::fs::write(&path, text).unwrap();
        Manifest::load(&path).map_err(|e| e.to_string())
    }

    #[test]
    fn items_pair_every_recording_with_every_pipeline() {
        let tmp = tempfile::tempdir().unwrap();
        for f in ["a.relume", "sub/a.relume", "p.toml"] {
            let p = tmp.path().join(f);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, "").unwrap();
        }
        let m = manifest(
            tmp.path(),
            "recordings = [\"./a.relume\", \"sub/a.relume\"]\npipelines = [\"p.toml\"]\n\
             [settings]\nframes = \"2..5\"\nsave = [\"normals\"]\n",
        )
        .unwrap();
        let ids: Vec<&str> = m.items.iter().map(|i| i.id.as_str()).collect();
        assert_eq!(ids.len(), 2);
        assert!(ids[0].starts_with("a__p__") && ids[1].starts_with("a__p__"));
        assert_ne!(ids[0], ids[1], "one stem in two folders, two ids");
        assert_eq!(m.items[0].id, item_id("a.relume", "p.toml"));
        assert_eq!(m.out, tmp.path().join("m-out"));
        assert_eq!(m.settings.frames, Some(2..5));
        assert_eq!(m.settings.save_format, ["png"]);
    }

    #[test]
    fn errors_name_the_line() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join("p.toml"), "").unwrap();
        let e = manifest(
            tmp.path(),
            "pipelines = [\"p.toml\"]\nrecording = [\"x\"]\n",
        )
        .unwrap_err();
        assert!(
            e.contains("m.toml:2:1: unknown key in the manifest `recording`"),
            "{e}"
        );
        assert!(e.contains("did you mean `recordings`?"), "{e}");
        let e = manifest(
            tmp.path(),
            "pipelines = [\"p.toml\"]\nrecordings = [\n  \"gone.relume\",\n]\n",
        )
        .unwrap_err();
        assert!(e.contains("m.toml:3:3: recording `gone.relume`"), "{e}");
        let e = manifest(
            tmp.path(),
            "pipelines = [\"p.toml\", \"./p.toml\"]\nrecordings = [\"p.toml\"]\n",
        )
        .unwrap_err();
        assert!(
            e.contains("m.toml:1:24: pipeline `./p.toml` is listed twice"),
            "{e}"
        );
        let e = manifest(
            tmp.path(),
            "pipelines = [\"p.toml\"]\nrecordings = [\"p.toml\"]\n[settings]\nframs = \"1\"\n",
        )
        .unwrap_err();
        assert!(
            e.contains("m.toml:4:1: unknown key in [settings] `frams`"),
            "{e}"
        );
    }

    #[test]
    fn adding_items_moves_no_other_item_between_shards() {
        let before: Vec<String> = (0..40)
            .map(|i| item_id(&format!("data/r{i}.relume"), "pipelines/acquisition.toml"))
            .collect();
        let mut after = before.clone();
        let added = [
            item_id("data/new.relume", "pipelines/acquisition.toml"),
            item_id("data/r0.relume", "pipelines/geometry.toml"),
        ];
        after.insert(0, added[0].clone());
        after.insert(7, added[1].clone());
        for count in [2, 3, 5] {
            let mut seen = 0;
            for index in 0..count {
                let shard = Shard { index, count };
                let old = crate::batch::shard::select(&before, |s| s, shard);
                let new: Vec<&String> = crate::batch::shard::select(&after, |s| s, shard)
                    .into_iter()
                    .filter(|id| !added.contains(id))
                    .collect();
                assert_eq!(old, new, "shard {shard}");
                seen += old.len();
            }
            assert_eq!(seen, before.len());
        }
        // Ids are stable across versions: a change of the scheme would move finished
        // items' folders and shards.
        assert_eq!(
            item_id("data/r0.relume", "pipelines/acquisition.toml"),
            format!(
                "r0__acquisition__{:08x}",
                xxh3_64(b"data/r0.relume\npipelines/acquisition.toml") as u32
            )
        );
        assert_eq!(normalize("./a//b/./c.toml"), "a/b/c.toml");
    }
}
