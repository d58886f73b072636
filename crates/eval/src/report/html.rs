//! `index.html`: the comparison as a static page. Everything is in the file or beside
//! it (images by relative path, charts as inline SVG, no script from elsewhere), so it
//! opens from the file system with no network.
//!
//! A short inline script checks on load that every image decoded and records any
//! script error: it sets `data-images` ("ok" or the broken ones) and `data-errors` on
//! `<body>`, which the tests read from the rendered page.

use super::markdown::number;
use super::svg::{self, escape};
use super::{Comparison, images};
use std::fmt::Write as _;

const STYLE: &str = "body{font:14px/1.4 system-ui,sans-serif;margin:24px;color:#222}\
table{border-collapse:collapse;margin:8px 0 20px}td,th{border:1px solid #ccc;padding:3px 8px;\
text-align:right}th:first-child,td:first-child{text-align:left}.best{font-weight:bold;\
background:#e8f4e8}figure{display:inline-block;margin:4px;vertical-align:top}figure img{\
width:320px;image-rendering:pixelated;display:block}figcaption{font-size:12px}\
.variant{display:inline-block;margin-right:16px}.charts svg{margin:8px;border:1px solid #eee}.ramp{display:inline-block;width:200px;\
height:12px;vertical-align:middle}";

const CHECK: &str = "<script>\
window.addEventListener('error',function(e){var b=document.body;\
b.dataset.errors=(b.dataset.errors||'')+e.message+';';});\
window.addEventListener('load',function(){var bad=[];\
document.querySelectorAll('img').forEach(function(i){if(!i.complete||i.naturalWidth===0)\
bad.push(i.getAttribute('src'));});var b=document.body;\
b.dataset.images=bad.length?bad.join(' '):'ok';if(!b.dataset.errors)b.dataset.errors='';});\
</script>";

/// The text of `index.html`.
pub fn render(c: &Comparison) -> String {
    let mut h = String::new();
    let labels: Vec<&str> = c.variants.iter().map(|v| v.label.as_str()).collect();
    let title = format!("relume compare: {}", labels.join(", "));
    let _ = write!(
        h,
        "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\
         <style>{STYLE}</style>{CHECK}</head><body><h1>{}</h1>",
        escape(&title),
        escape(&title)
    );
    let _ = write!(
        h,
        "<p>Recording <code>{}</code>, frames {}..{}, seed {}, references on every {} \
         pixel(s) in x and y; the run took {:.1} s. Scores are those <code>relume eval</code> \
         gives each pipeline alone; the best of each column is marked. Times are measured \
         with the branches running at once on the machine's cores: they compare the \
         variants, they are not each one's time alone (<code>relume bench</code>).</p>",
        escape(&c.recording),
        c.frames[0],
        c.frames[1],
        c.seed,
        c.reference_stride,
        c.wall_s
    );
    summary(&mut h, c);
    charts(&mut h, c);
    frames(&mut h, c);
    scores(&mut h, c);
    h.push_str("</body></html>\n");
    h
}

fn td(value: Option<f64>, best: bool) -> String {
    match value {
        None => "<td>–</td>".into(),
        Some(x) if best => format!("<td class=\"best\">{}</td>", number(x)),
        Some(x) => format!("<td>{}</td>", number(x)),
    }
}

/// Per variant: its pipeline, composite PSNR (against the references, and against the
/// true frame where the recording has one) and cost.
fn summary(h: &mut String, c: &Comparison) {
    let psnr: Vec<Option<f64>> = (0..c.variants.len()).map(|v| c.composite_psnr(v)).collect();
    let truth: Vec<Option<f64>> = (0..c.variants.len())
        .map(|v| c.composite_score(v, "psnr_db_truth"))
        .collect();
    let cost: Vec<Option<f64>> = c.variants.iter().map(|v| Some(v.cost_ms)).collect();
    let (bp, bt, bc) = (
        Comparison::best("psnr_db", &psnr),
        Comparison::best("psnr_db", &truth),
        Comparison::best("median_ms", &cost),
    );
    let with_truth = truth.iter().any(Option::is_some);
    h.push_str(
        "<table id=\"summary\"><tr><th>variant</th><th>pipeline</th><th>composite \
         psnr_db</th>",
    );
    if with_truth {
        h.push_str("<th>psnr_db against the truth</th>");
    }
    h.push_str("<th>cost ms/frame</th></tr>");
    for (v, variant) in c.variants.iter().enumerate() {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td>{}",
            escape(&variant.label),
            escape(&variant.file),
            td(psnr[v], bp.contains(&v)),
        );
        if with_truth {
            h.push_str(&td(truth[v], bt.contains(&v)));
        }
        let _ = write!(h, "{}</tr>", td(cost[v], bc.contains(&v)));
    }
    h.push_str("</table>");
}

fn charts(h: &mut String, c: &Comparison) {
    h.push_str("<h2>Quality and cost</h2><div class=\"charts\">");
    let points: Vec<(String, f64, f64)> = (0..c.variants.len())
        .filter_map(|v| {
            Some((
                c.variants[v].label.clone(),
                c.variants[v].cost_ms,
                c.composite_psnr(v)?,
            ))
        })
        .collect();
    h.push_str(&svg::scatter(
        "scatter",
        "Quality versus cost",
        "cost per frame (ms, sum of stage medians)",
        "composite PSNR (dB)",
        &points,
    ));
    let quality: Vec<(String, Vec<(f64, f64)>)> = c
        .variants
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let composite = c.composite_scores(i);
            let frames = composite.map(|x| &x["scored_frames"]);
            let values = composite.map(|x| &x["psnr_db_by_frame"]);
            let pairs = match (
                frames.and_then(|f| f.as_array()),
                values.and_then(|f| f.as_array()),
            ) {
                (Some(f), Some(p)) => f
                    .iter()
                    .zip(p)
                    .filter_map(|(f, p)| Some((f.as_f64()?, p.as_f64()?)))
                    .collect(),
                _ => Vec::new(),
            };
            (v.label.clone(), pairs)
        })
        .collect();
    h.push_str(&svg::lines(
        "quality-curve",
        "Composite PSNR per scored frame",
        "frame",
        "PSNR (dB)",
        &quality,
    ));
    let time: Vec<(String, Vec<(f64, f64)>)> = c
        .variants
        .iter()
        .map(|v| {
            (
                v.label.clone(),
                v.frame_ms.iter().map(|&(f, ms)| (f as f64, ms)).collect(),
            )
        })
        .collect();
    h.push_str(&svg::lines(
        "time-curve",
        "Processing time per frame",
        "frame",
        "ms (sum over the variant's stages)",
        &time,
    ));
    h.push_str("</div>");
}

/// The scored frames: the reference, each variant's composite, its difference.
fn frames(h: &mut String, c: &Comparison) {
    h.push_str("<h2>Scored frames</h2>");
    if c.images.is_empty() {
        h.push_str(
            "<p>No frame was scored: the replay held none of frames 14, 29 or its last \
             with the renderer's inputs, or no variant composites.</p>",
        );
        return;
    }
    let stops: Vec<String> = (0..=8)
        .map(|i| {
            let [r, g, b] = images::ramp(i as f32 / 8.0);
            format!("rgb({r},{g},{b})")
        })
        .collect();
    let _ = write!(
        h,
        "<p>Differences: mean absolute difference from the reference over the channels, \
         0 <span class=\"ramp\" style=\"background:linear-gradient(to right,{})\"></span> \
         {} levels of 255 and above.{}</p>",
        stops.join(","),
        images::DIFFERENCE_SCALE,
        if c.reference_stride > 1 {
            " Images are shown on the reference's pixel lattice."
        } else {
            ""
        }
    );
    for f in &c.images {
        let _ = write!(
            h,
            "<section class=\"frame\" id=\"frame-{}\"><h3>Frame {}</h3><div>\
             <figure><img src=\"{}\" alt=\"reference composite, frame {}\">\
             <figcaption>reference (1024 samples)</figcaption></figure>",
            f.frame,
            f.frame,
            escape(&f.reference),
            f.frame
        );
        if let Some(truth) = &f.truth {
            let _ = write!(
                h,
                "<figure><img src=\"{}\" alt=\"true frame, frame {}\">\
                 <figcaption>truth (the objects really in the room)</figcaption></figure>",
                escape(truth),
                f.frame
            );
        }
        h.push_str("</div>");
        for v in &f.variants {
            let psnr = v
                .psnr_db
                .map(|p| format!(", {:.2} dB", p))
                .unwrap_or_default();
            let own_reference = match v.reference != f.reference {
                true => format!(
                    "<figure><img src=\"{}\" alt=\"{} reference\"><figcaption>its reference \
                     (its renderer reads other products)</figcaption></figure>",
                    escape(&v.reference),
                    escape(&v.label)
                ),
                false => String::new(),
            };
            let own_truth = match &v.truth {
                Some(path) if Some(path) != f.truth.as_ref() => format!(
                    "<figure><img src=\"{}\" alt=\"{} truth\"><figcaption>its truth \
                     (other objects or virtual lamps)</figcaption></figure>",
                    escape(path),
                    escape(&v.label)
                ),
                _ => String::new(),
            };
            let against_truth = match &v.truth_difference {
                Some(path) => format!(
                    "<figure><img src=\"{}\" alt=\"{} difference from the truth\">\
                     <figcaption>{} − truth{}</figcaption></figure>",
                    escape(path),
                    escape(&v.label),
                    escape(&v.label),
                    v.psnr_db_truth
                        .map(|p| format!(", {p:.2} dB"))
                        .unwrap_or_default()
                ),
                None => String::new(),
            };
            let _ = write!(
                h,
                "<div class=\"variant\">{own_reference}{own_truth}<figure><img src=\"{}\" alt=\"{} composite\">\
                 <figcaption>{}{}</figcaption></figure><figure><img src=\"{}\" \
                 alt=\"{} difference\"><figcaption>{} − reference</figcaption></figure>\
                 {against_truth}</div>",
                escape(&v.composite),
                escape(&v.label),
                escape(&v.label),
                psnr,
                escape(&v.difference),
                escape(&v.label),
                escape(&v.label)
            );
        }
        h.push_str("</section>");
    }
}

/// The score tables of report.md, as HTML.
fn scores(h: &mut String, c: &Comparison) {
    h.push_str("<h2>Scores</h2>");
    for (stage, kind, keys) in c.score_tables() {
        let _ = write!(
            h,
            "<h3>{} ({})</h3><table class=\"scores\"><tr><th>variant</th>",
            escape(&stage),
            escape(&kind)
        );
        for k in &keys {
            let _ = write!(h, "<th>{}</th>", escape(k));
        }
        h.push_str("</tr>");
        let columns = c.score_columns(&stage, &keys);
        for (v, variant) in c.variants.iter().enumerate() {
            if variant.scores.get(&stage).is_none() {
                continue;
            }
            let _ = write!(h, "<tr><td>{}</td>", escape(&variant.label));
            for col in &columns {
                h.push_str(&td(col.values[v], col.best.contains(&v)));
            }
            h.push_str("</tr>");
        }
        h.push_str("</table>");
    }
}
