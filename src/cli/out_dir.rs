//! What a run finds where it writes: half-written files that a killed run left
//! (removed, and said), and frames of an earlier run in the folders this run writes
//! (a warning, or `--clean-out`).

use anyhow::Context;
use relume::graph::Pipeline;
use relume::recording::writer::is_stale_partial;
use std::path::{Path, PathBuf};

/// Removes the half-written files of processes no longer running in `dir` (and its
/// sub-folders, `depth` levels down), and says how many and how big.
pub fn remove_stale_partials(dir: &Path, depth: usize) {
    let mut found = Vec::new();
    collect_partials(dir, depth, &mut found);
    let mut bytes = 0;
    let mut removed = 0;
    for path in &found {
        let size = std::fs::metadata(path).map_or(0, |m| m.len());
        if std::fs::remove_file(path).is_ok() {
            removed += 1;
            bytes += size;
        }
    }
    if removed > 0 {
        eprintln!(
            "removed {removed} half-written file(s) ({:.1} MB) that an interrupted run left in {}",
            bytes as f64 / 1e6,
            dir.display()
        );
    }
}

fn collect_partials(dir: &Path, depth: usize, found: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        // Not through symbolic links: only what lies under the folder itself.
        let is_dir = std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_dir());
        if is_dir {
            if depth > 0 {
                collect_partials(&path, depth - 1, found);
            }
        } else if is_stale_partial(&path) {
            found.push(path);
        }
    }
}

/// The folders a replay of `pipeline` into `out` writes frames into: each `write`
/// stage's `out/<dir>/<product>`, and `out/<name>` for each `--save` name (`all`: none
/// known in advance).
pub fn frame_folders(pipeline: &Pipeline, out: &Path, save: &[String]) -> Vec<PathBuf> {
    let mut folders = Vec::new();
    for stage in pipeline.stages.iter().filter(|s| s.kind == "write") {
        let dir = out.join(stage.params.str("dir"));
        for product in stage.params.str_list("products") {
            folders.push(dir.join(product));
        }
    }
    folders.extend(save.iter().filter(|n| *n != "all").map(|n| out.join(n)));
    folders.sort();
    folders.dedup();
    folders
}

/// The frame index of `name` when it is a frame file as relume writes them: six
/// digits and an extension.
fn frame_index(name: &str) -> Option<usize> {
    let (stem, ext) = name.split_once('.')?;
    let known = ["png", "exr", "json", "ply"].contains(&ext);
    (stem.len() == 6 && stem.bytes().all(|b| b.is_ascii_digit()) && known)
        .then(|| stem.parse().ok())
        .flatten()
}

/// Frames an earlier run left in `folders`: with `clean`, all removed (and said); else
/// a warning per folder holding frames outside `frames`, which this run does not
/// replace, so that they would sit beside its own.
pub fn earlier_frames(
    folders: &[PathBuf],
    frames: &std::ops::Range<usize>,
    clean: bool,
) -> anyhow::Result<()> {
    for folder in folders {
        let Ok(entries) = std::fs::read_dir(folder) else {
            continue;
        };
        let found: Vec<(usize, PathBuf)> = entries
            .flatten()
            .filter_map(|e| Some((frame_index(&e.file_name().to_string_lossy())?, e.path())))
            .collect();
        if clean {
            for (_, f) in &found {
                std::fs::remove_file(f)
                    .with_context(|| format!("--clean-out: cannot remove {}", f.display()))?;
            }
            if !found.is_empty() {
                eprintln!(
                    "--clean-out: removed {} frame file(s) from {}",
                    found.len(),
                    folder.display()
                );
            }
            continue;
        }
        let mut outside: Vec<usize> = found
            .iter()
            .map(|(i, _)| *i)
            .filter(|i| !frames.contains(i))
            .collect();
        outside.sort_unstable();
        outside.dedup();
        if let (Some(first), Some(last)) = (outside.first(), outside.last()) {
            eprintln!(
                "warning: {} holds {} frame(s) of an earlier run that this run (frames \
                 {}..{}) does not replace, {first} to {last}: they stay beside its own \
                 (--clean-out removes them first)",
                folder.display(),
                outside.len(),
                frames.start,
                frames.end
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn frame_files_are_six_digits_and_a_known_extension() {
        for (name, i) in [("000000.png", 0), ("000123.exr", 123), ("000001.json", 1)] {
            assert_eq!(super::frame_index(name), Some(i), "{name}");
        }
        for name in [
            "notes.png",
            "00001.png",
            "000001.txt",
            ".000001.png.7.partial",
        ] {
            assert_eq!(super::frame_index(name), None, "{name}");
        }
    }
}
