//! The report of `relume compare`: several pipelines replayed together over one
//! recording, their scores and stage times side by side, in three files:
//! - `report.json`: everything ([`Comparison`] as JSON), per variant, stage and frame;
//! - `report.md`: a table per scored stage and one of stage times, the best of each
//!   column in bold ([`markdown`]);
//! - `index.html`: a static page that opens from the file system with no network: the
//!   composites of the scored frames beside the reference and the true frame (synthetic
//!   recordings), false-colour differences from both,
//!   per-frame curves and a quality-versus-cost scatter, in inline SVG ([`html`]).

pub mod html;
pub mod images;
pub mod markdown;
mod svg;

use serde::Serialize;
use serde_json::Value;

/// One comparison run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Comparison {
    pub recording: String,
    /// The frames replayed, `[first, end)`.
    pub frames: [usize; 2],
    pub reference_stride: u32,
    pub seed: u64,
    /// Wall-clock time of the whole run (replay and scoring), seconds.
    pub wall_s: f64,
    pub variants: Vec<Variant>,
    /// Every stage that ran, once: shared stages appear once, with every variant that
    /// used them.
    pub stages: Vec<StageRun>,
    /// The frames with references, and their images (paths relative to the report).
    pub images: Vec<FrameImages>,
}

/// One pipeline of the comparison.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Variant {
    /// Its name in the report: the pipeline's name, made unique.
    pub label: String,
    /// The pipeline's name and file.
    pub pipeline: String,
    pub file: String,
    /// `relume eval`'s scores of its stages: `{<stage name>: {kind, <score keys>}}`.
    pub scores: Value,
    /// Indices into [`Comparison::stages`] of its stages, in pipeline order.
    pub stages: Vec<usize>,
    /// The `composite.differential` stage whose image and scores the report shows (its
    /// first).
    pub composite_stage: Option<String>,
    /// Its cost per frame: the sum of its stages' median processing times, ms.
    pub cost_ms: f64,
    /// Per frame replayed: (frame, the sum of its stages' processing times, ms).
    pub frame_ms: Vec<(usize, f64)>,
}

/// One stage as it ran.
#[derive(Clone, Debug, Default, Serialize)]
pub struct StageRun {
    pub name: String,
    pub kind: String,
    /// The labels of the variants that ran it (more than one: shared, run once).
    pub variants: Vec<String>,
    pub median_ms: f64,
    pub p95_ms: f64,
    /// Processing time of each frame, ms, in frame order.
    pub frame_ms: Vec<f64>,
}

/// A scored frame's images.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FrameImages {
    pub frame: usize,
    /// The composite of the 1024-sample references.
    pub reference: String,
    /// The true frame with the objects in the room (synthetic recordings): the first
    /// variant's.
    pub truth: Option<String>,
    /// Per variant (label): its composite and its false-colour difference from the
    /// reference, and the PSNR of that frame.
    pub variants: Vec<VariantImages>,
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct VariantImages {
    pub label: String,
    /// The reference its composite is scored against (the frame's `reference` unless
    /// its renderer reads other products).
    pub reference: String,
    pub composite: String,
    pub difference: String,
    pub psnr_db: Option<f64>,
    /// The true frame it is scored against (the frame's `truth` unless its objects or
    /// virtual lamps differ).
    pub truth: Option<String>,
    /// Its false-colour difference from the true frame, and its PSNR against it.
    pub truth_difference: Option<String>,
    pub psnr_db_truth: Option<f64>,
}

/// One score across the variants, as the report tables show it.
pub struct ScoreColumn {
    /// Per variant, its value (`None` where it has none).
    pub values: Vec<Option<f64>>,
    /// The variants with the best value.
    pub best: Vec<usize>,
}

/// Which way a score is better, by its key: `Some(true)` higher, `Some(false)` lower,
/// `None` where neither is (counts, flags, frame lists).
pub fn higher_is_better(key: &str) -> Option<bool> {
    const LOWER: [&str; 9] = [
        "rmse",
        "mse",
        "error",
        "angle",
        "flicker",
        "holes",
        "drift",
        "_p95",
        "median_ms",
    ];
    if key.starts_with("psnr") || key == "coverage" || key.starts_with("valid_fraction") {
        return Some(true);
    }
    if key.contains("overlap") || key == "pdf_integral" || key == "unbiased_p" {
        return None;
    }
    LOWER.iter().any(|l| key.contains(l)).then_some(false)
}

impl Comparison {
    /// The score `key` of the stage named `stage` in variant `v` (`None` when absent or
    /// not a number).
    pub fn score(&self, v: usize, stage: &str, key: &str) -> Option<f64> {
        self.variants[v].scores.get(stage)?.get(key)?.as_f64()
    }

    /// The composite's PSNR of variant `v`: that of its
    /// [`Variant::composite_stage`].
    pub fn composite_psnr(&self, v: usize) -> Option<f64> {
        self.composite_score(v, "psnr_db")
    }

    /// The finite score `key` of variant `v`'s [`Variant::composite_stage`].
    pub fn composite_score(&self, v: usize, key: &str) -> Option<f64> {
        let stage = self.variants[v].composite_stage.as_deref()?;
        self.score(v, stage, key).filter(|p| p.is_finite())
    }

    /// The scores of variant `v`'s composite stage.
    pub fn composite_scores(&self, v: usize) -> Option<&Value> {
        let stage = self.variants[v].composite_stage.as_deref()?;
        self.variants[v].scores.get(stage)
    }

    /// The scored stages' names, in the order the variants list them, each once, with
    /// their numeric score keys (a key in any variant).
    pub fn score_tables(&self) -> Vec<(String, String, Vec<String>)> {
        let mut tables: Vec<(String, String, Vec<String>)> = Vec::new();
        for v in &self.variants {
            let Some(stages) = v.scores.as_object() else {
                continue;
            };
            for (name, scores) in stages {
                let kind = scores["kind"].as_str().unwrap_or("").to_string();
                let keys = scores
                    .as_object()
                    .into_iter()
                    .flatten()
                    .filter(|(_, value)| value.is_number())
                    .map(|(k, _)| k.clone());
                let at = match tables.iter().position(|(n, _, _)| n == name) {
                    Some(i) => i,
                    None => {
                        tables.push((name.clone(), kind, Vec::new()));
                        tables.len() - 1
                    }
                };
                for key in keys {
                    if !tables[at].2.contains(&key) {
                        tables[at].2.push(key);
                    }
                }
            }
        }
        tables
    }

    /// For each of `keys`, the score column of the stage named `stage` (one value per
    /// variant) and the variants that are best in it ([`Comparison::best`]).
    pub fn score_columns(&self, stage: &str, keys: &[String]) -> Vec<ScoreColumn> {
        keys.iter()
            .map(|k| {
                let values: Vec<Option<f64>> = (0..self.variants.len())
                    .map(|v| self.score(v, stage, k))
                    .collect();
                let best = Comparison::best(k, &values);
                ScoreColumn { values, best }
            })
            .collect()
    }

    /// The indices among `values` of the best, by `key`'s direction: every one that
    /// ties for best, none when the key has no direction, fewer than two values exist,
    /// or all of them are equal.
    pub fn best(key: &str, values: &[Option<f64>]) -> Vec<usize> {
        let Some(higher) = higher_is_better(key) else {
            return Vec::new();
        };
        let present: Vec<(usize, f64)> = values
            .iter()
            .enumerate()
            .filter_map(|(i, v)| v.filter(|x| x.is_finite()).map(|x| (i, x)))
            .collect();
        let Some(&(_, first)) = present.first() else {
            return Vec::new();
        };
        if present.len() < 2 || present.iter().all(|p| p.1 == first) {
            return Vec::new();
        }
        let top = present
            .iter()
            .map(|p| p.1)
            .fold(first, |a, b| match higher {
                true => a.max(b),
                false => a.min(b),
            });
        present.iter().filter(|p| p.1 == top).map(|p| p.0).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scores_know_which_way_is_better() {
        assert_eq!(higher_is_better("psnr_db"), Some(true));
        assert_eq!(higher_is_better("ratio_rmse"), Some(false));
        assert_eq!(higher_is_better("mean_angle_deg"), Some(false));
        assert_eq!(higher_is_better("temporal_flicker"), Some(false));
        assert_eq!(higher_is_better("frames_scored"), None);
        assert_eq!(higher_is_better("warp_overlap_fused"), None);
        assert_eq!(
            Comparison::best("psnr_db", &[Some(30.0), None, Some(31.0)]),
            [2]
        );
        assert_eq!(
            Comparison::best("ratio_rmse", &[Some(0.1), Some(0.05), Some(0.05)]),
            [1, 2]
        );
        assert!(Comparison::best("psnr_db", &[Some(30.0), None]).is_empty());
        assert!(Comparison::best("psnr_db", &[Some(30.0), Some(30.0)]).is_empty());
        assert!(Comparison::best("frames", &[Some(1.0), Some(2.0)]).is_empty());
    }
}
