//! `relume diff`: the regression check. Two runs' saved products compared frame by
//! frame (see `relume::eval::diff`); the exit status says whether they match.

use clap::Parser;
use relume::eval::diff::{Tolerance, diff_runs};
use std::path::PathBuf;

const ABOUT: &str = "\
Exit status: 0 when every product matches within the tolerance, 1 when one differs or
is missing from a run, 2 when the runs cannot be read (a folder or file that cannot be
read, an image that does not decode or is over 16384 pixels a side or 64 megapixels).

Products are the sub-folders of each run (final/, depth/, ...), frames the files in
them, matched by name. PNGs are compared on their own scale (8-bit levels, or 16-bit:
millimetres for depth), EXRs in their linear values (PSNR peak: the largest value in
RUN_A's frame, at least 1); other files byte for byte.

Examples:
  relume replay --out a && relume replay --out b && relume diff a b
  relume diff cmp/runs/default cmp/runs/mixed-reality-fast --min-psnr 30
  relume diff golden/ out/ --tolerance 1       allow off-by-one 8-bit levels";

#[derive(Parser, Debug)]
#[command(after_help = ABOUT)]
pub struct DiffArgs {
    /// The first run's folder (e.g. a replay's --out).
    run_a: PathBuf,
    /// The second run's folder.
    run_b: PathBuf,
    /// The largest difference of one value that still counts as equal, on the file's
    /// scale (default 0: exact; ignored when only --min-psnr is given).
    #[arg(long, value_name = "VALUE")]
    tolerance: Option<f64>,
    /// A frame whose PSNR is below this differs.
    #[arg(long, value_name = "DB")]
    min_psnr: Option<f64>,
    /// Print the comparison as JSON: {products: [{product, frames, differing,
    /// first_differing, worst_psnr_db, max_abs, only_in_a, only_in_b}], only_in_a,
    /// only_in_b, differ}.
    #[arg(long)]
    json: bool,
}

fn db(x: f64) -> String {
    if x == f64::INFINITY {
        "equal".into()
    } else {
        format!("{x:.2}")
    }
}

pub fn diff(a: DiffArgs) -> anyhow::Result<i32> {
    for (flag, value) in [("--tolerance", a.tolerance), ("--min-psnr", a.min_psnr)] {
        if value.is_some_and(|v| !v.is_finite() || v < 0.0) {
            anyhow::bail!("{flag} must be a finite number, 0 or more");
        }
    }
    let tolerance = Tolerance {
        max_abs: a.tolerance,
        min_psnr_db: a.min_psnr,
    };
    let result = match diff_runs(&a.run_a, &a.run_b, tolerance) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return Ok(2);
        }
    };
    let differs = result.differs();
    if a.json {
        let mut doc = serde_json::to_value(&result)?;
        doc["differ"] = differs.into();
        // JSON has no infinities: equal frames' PSNR is null.
        outln!("{}", serde_json::to_string_pretty(&doc)?)?;
        return Ok(differs as i32);
    }
    outln!(
        "{:<24} {:>7} {:>10} {:>12} {:>12}  first differing",
        "product",
        "frames",
        "differing",
        "worst dB",
        "max diff"
    )?;
    for p in &result.products {
        outln!(
            "{:<24} {:>7} {:>10} {:>12} {:>12}  {}",
            p.product,
            p.frames,
            p.differing,
            db(p.worst_psnr_db),
            relume::eval::report::markdown::number(p.max_abs),
            p.first_differing.as_deref().unwrap_or("-")
        )?;
        for (run, files) in [("RUN_A", &p.only_in_a), ("RUN_B", &p.only_in_b)] {
            if !files.is_empty() {
                outln!("  only in {run}: {}", files.join(", "))?;
            }
        }
    }
    for (run, products) in [("RUN_A", &result.only_in_a), ("RUN_B", &result.only_in_b)] {
        if !products.is_empty() {
            outln!("products only in {run}: {}", products.join(", "))?;
        }
    }
    if result.products.is_empty() && result.only_in_a.is_empty() && result.only_in_b.is_empty() {
        outln!("no products in either run")?;
    }
    outln!(
        "{}",
        if differs {
            "the runs differ"
        } else {
            "the runs match"
        }
    )?;
    Ok(differs as i32)
}
