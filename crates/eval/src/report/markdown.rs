//! `report.md`: one table per scored stage (a row per variant, a column per score) and
//! one of stage times (a row per variant, a column per stage, milliseconds per frame);
//! the best value of each column in bold where the score has a direction.

use super::Comparison;
use std::fmt::Write as _;

/// A number as the tables print it.
pub fn number(x: f64) -> String {
    if !x.is_finite() {
        return if x.is_nan() {
            "n/a".into()
        } else {
            format!("{x}")
        };
    }
    let a = x.abs();
    if x.fract() == 0.0 && a < 1e9 {
        format!("{x:.0}")
    } else if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{x:.3e}")
    } else if a >= 100.0 {
        format!("{x:.1}")
    } else {
        format!("{x:.4}")
    }
}

/// The text of `report.md`.
pub fn render(c: &Comparison) -> String {
    let mut md = String::new();
    let labels: Vec<&str> = c.variants.iter().map(|v| v.label.as_str()).collect();
    let _ = writeln!(md, "# relume compare: {}\n", labels.join(", "));
    let _ = writeln!(
        md,
        "Recording {}, frames {}..{}, seed {}, references on every {} pixel(s) in x and \
         y. Run took {:.1} s.\n",
        cell_text(&c.recording),
        c.frames[0],
        c.frames[1],
        c.seed,
        c.reference_stride,
        c.wall_s
    );
    let _ = writeln!(md, "| variant | pipeline | file |\n|---|---|---|");
    for v in &c.variants {
        let _ = writeln!(
            md,
            "| {} | {} | {} |",
            v.label,
            cell_text(&v.pipeline),
            cell_text(&v.file)
        );
    }
    let _ = writeln!(
        md,
        "\nBold: the best of a column (higher PSNR and coverage; lower errors, RMSE, \
         MSE, angles, flicker and times). Scores as `relume eval` gives them.\n"
    );
    for (stage, kind, keys) in c.score_tables() {
        let _ = writeln!(md, "## {stage} ({kind})\n");
        let _ = writeln!(md, "| variant | {} |", keys.join(" | "));
        let _ = writeln!(md, "|---|{}", "---|".repeat(keys.len()));
        let columns = c.score_columns(&stage, &keys);
        for (v, variant) in c.variants.iter().enumerate() {
            if variant.scores.get(&stage).is_none() {
                continue;
            }
            let cells: Vec<String> = columns
                .iter()
                .map(|col| cell(col.values[v], col.best.contains(&v)))
                .collect();
            let _ = writeln!(md, "| {} | {} |", variant.label, cells.join(" | "));
        }
        md.push('\n');
    }
    md.push_str(&times(c));
    md
}

/// Text (a name, a path) that stays inside its table cell: `|` and backticks escaped.
fn cell_text(text: &str) -> String {
    text.replace('\\', "\\\\")
        .replace('|', "\\|")
        .replace('`', "\\`")
}

fn cell(value: Option<f64>, best: bool) -> String {
    match value {
        None => "–".into(),
        Some(x) if best => format!("**{}**", number(x)),
        Some(x) => number(x),
    }
}

/// The stage-time table: median processing ms per frame, a column per stage name.
fn times(c: &Comparison) -> String {
    let mut md = String::from("## Stage times (median ms per frame)\n\n");
    let mut names: Vec<&str> = Vec::new();
    for v in &c.variants {
        for &s in &v.stages {
            let name = c.stages[s].name.as_str();
            if !names.contains(&name) {
                names.push(name);
            }
        }
    }
    let _ = writeln!(md, "| variant | {} | total |", names.join(" | "));
    let _ = writeln!(md, "|---|{}---|", "---|".repeat(names.len()));
    let value = |v: usize, name: &str| {
        c.variants[v]
            .stages
            .iter()
            .find(|&&s| c.stages[s].name == name)
            .map(|&s| c.stages[s].median_ms)
    };
    let mut columns: Vec<Vec<Option<f64>>> = names
        .iter()
        .map(|n| (0..c.variants.len()).map(|v| value(v, n)).collect())
        .collect();
    columns.push(c.variants.iter().map(|v| Some(v.cost_ms)).collect());
    let best: Vec<Vec<usize>> = columns
        .iter()
        .map(|col| Comparison::best("median_ms", col))
        .collect();
    for (v, variant) in c.variants.iter().enumerate() {
        let shared = |name: &str| {
            let mine = variant.stages.iter().map(|&s| &c.stages[s]);
            mine.filter(|s| s.name == name)
                .any(|s| s.variants.len() > 1)
        };
        let cells: Vec<String> = columns
            .iter()
            .zip(&best)
            .enumerate()
            .map(|(i, (col, b))| {
                let mark = match names.get(i) {
                    Some(n) if shared(n) => " ⇄",
                    _ => "",
                };
                format!("{}{mark}", cell(col[v], b.contains(&v)))
            })
            .collect();
        let _ = writeln!(md, "| {} | {} |", variant.label, cells.join(" | "));
    }
    md.push_str(
        "\n⇄: a stage the variants share, run once for all of them (its time counts in \
         each variant's total).\n",
    );
    md
}
