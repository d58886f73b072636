//! The state of every item of a batch's output folder, for `relume batch --summary`.
//!
//! Each batch run writes [`ITEMS`] into the output folder: the manifest's full list of
//! items, so that a summary of the folder alone also lists the items no shard has run
//! yet.

use super::error::BatchError;
use super::manifest::Item;
use super::marker::{self, Marker, MarkerState};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The list of the manifest's items in the output folder.
pub const ITEMS: &str = "items.json";

/// An item as [`ITEMS`] lists it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ListedItem {
    /// [`super::item_id`].
    pub id: String,
    /// The recording as the manifest names it.
    pub recording: String,
    /// The pipeline as the manifest names it.
    pub pipeline: String,
}

/// Writes [`ITEMS`] into `out` (atomically: the shards of a batch all write the same
/// list).
pub fn write_items(out: &Path, items: &[Item]) -> Result<(), BatchError> {
    let listed: Vec<ListedItem> = items
        .iter()
        .map(|i| ListedItem {
            id: i.id.clone(),
            recording: i.recording.clone(),
            pipeline: i.pipeline.clone(),
        })
        .collect();
    let path = out.join(ITEMS);
    let mut bytes = serde_json::to_vec_pretty(&serde_json::json!({ "items": listed }))
        .map_err(|e| BatchError::io(&path, std::io::Error::other(e)))?;
    bytes.push(b'\n');
    // Shards write this at once on a shared volume, maybe all as PID 1 (one container
    // each): a temporary name of this process's own, not the pid alone.
    let nonce = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    let tmp = out.join(format!(".{ITEMS}.{nonce:x}.{}.partial", std::process::id()));
    let result = std::fs::write(&tmp, &bytes).and_then(|()| std::fs::rename(&tmp, &path));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(|e| BatchError::io(path, e))
}

/// The items [`ITEMS`] in `out` lists; `None` when there is no such file.
pub fn read_items(out: &Path) -> Result<Option<Vec<ListedItem>>, BatchError> {
    #[derive(Deserialize)]
    struct List {
        items: Vec<ListedItem>,
    }
    let path = out.join(ITEMS);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(BatchError::io(path, e)),
    };
    let list: List =
        serde_json::from_str(&text).map_err(|e| BatchError::io(&path, std::io::Error::other(e)))?;
    Ok(Some(list.items))
}

/// Where an item stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ItemStatus {
    /// A valid `DONE` marker.
    Done,
    /// The run failed (its folder holds `FAILED`).
    Failed,
    /// Not run, or not finished (killed, still running, or a marker that does not fit).
    Missing,
}

impl ItemStatus {
    /// `done`, `failed` or `missing`.
    pub fn name(self) -> &'static str {
        match self {
            ItemStatus::Done => "done",
            ItemStatus::Failed => "failed",
            ItemStatus::Missing => "missing",
        }
    }
}

/// One item's line of a summary.
#[derive(Clone, Debug, Serialize)]
pub struct ItemSummary {
    /// The item's id (its folder's name).
    pub id: String,
    /// The recording, when [`ITEMS`] names it.
    pub recording: Option<String>,
    /// The pipeline, when [`ITEMS`] names it.
    pub pipeline: Option<String>,
    /// Done, failed or missing.
    pub status: ItemStatus,
    /// Why an item is missing, or a failed item's error (its first line).
    pub note: Option<String>,
    /// Frames replayed.
    pub frames: Option<u64>,
    /// Frames skipped as corrupt.
    pub skipped_corrupt: Option<u64>,
    /// Output files (as the marker counts them).
    pub files: Option<u64>,
    /// Their total size.
    pub bytes: Option<u64>,
    /// Seconds the item took (loading included).
    pub wall_s: Option<f64>,
    /// Frames per second of its run.
    pub fps: Option<f64>,
}

/// The summary of every item of `out`: those [`ITEMS`] lists when there is one (in its
/// order, then any other item folder), else every item folder found.
pub fn summarize(out: &Path) -> Result<Vec<ItemSummary>, BatchError> {
    let listed = read_items(out)?.unwrap_or_default();
    let mut found: Vec<String> = std::fs::read_dir(out)
        .map_err(|e| BatchError::io(out, e))?
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with('.') && !listed.iter().any(|l| l.id == *n))
        .collect();
    found.sort();
    let all = listed
        .into_iter()
        .map(|l| (l.id, Some(l.recording), Some(l.pipeline)))
        .chain(found.into_iter().map(|id| (id, None, None)));
    Ok(all
        .map(|(id, recording, pipeline)| summarize_item(out, id, recording, pipeline))
        .collect())
}

fn summarize_item(
    out: &Path,
    id: String,
    recording: Option<String>,
    pipeline: Option<String>,
) -> ItemSummary {
    let dir = out.join(&id);
    let read_json = |name: &str| -> Option<serde_json::Value> {
        serde_json::from_str(&std::fs::read_to_string(dir.join(name)).ok()?).ok()
    };
    let mut s = ItemSummary {
        recording,
        pipeline,
        status: ItemStatus::Missing,
        note: None,
        frames: None,
        skipped_corrupt: None,
        files: None,
        bytes: None,
        wall_s: None,
        fps: None,
        id,
    };
    if !dir.is_dir() {
        s.note = Some("not run".into());
        return s;
    }
    match Marker::check(&dir, &s.id, None) {
        MarkerState::Valid(m) => {
            s.status = ItemStatus::Done;
            s.files = Some(m.files);
            s.bytes = Some(m.bytes);
        }
        MarkerState::Invalid(why) => s.note = Some(why),
        MarkerState::Absent => match std::fs::read_to_string(dir.join(marker::FAILED)) {
            Ok(error) => {
                s.status = ItemStatus::Failed;
                s.note = Some(error.lines().next().unwrap_or("").to_string());
            }
            Err(_) => s.note = Some("no DONE marker: interrupted, or still running".into()),
        },
    }
    if s.status == ItemStatus::Done {
        if let Some(report) = read_json(marker::REPORT) {
            s.frames = report["frames_out"].as_u64();
            s.skipped_corrupt = report["skipped_corrupt"].as_array().map(|a| a.len() as u64);
        }
        if let Some(timings) = read_json(marker::TIMINGS) {
            s.wall_s = timings["wall_s"].as_f64();
            s.fps = timings["run"]["fps"].as_f64();
        }
    }
    s
}
