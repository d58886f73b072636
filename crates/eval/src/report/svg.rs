//! Small inline SVG charts for the report page: lines per series and a labelled
//! scatter, with axes and ticks. Hand-written: two chart types do not pay for a
//! plotting crate's build time.

use std::fmt::Write as _;

/// Series colours (Okabe-Ito, distinguishable with colour-vision deficiencies).
pub const PALETTE: [&str; 8] = [
    "#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442", "#000000",
];

const W: f64 = 560.0;
const H: f64 = 300.0;
const LEFT: f64 = 64.0;
const RIGHT: f64 = 16.0;
const TOP: f64 = 28.0;
const BOTTOM: f64 = 44.0;

/// Text made safe for XML and HTML.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A value range padded so that points do not sit on the frame; a single value gets
/// a unit-wide range around it.
fn padded(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let span = (hi - lo).max(hi.abs() * 1e-3).max(1e-9);
    if hi - lo < 1e-12 {
        return (lo - 0.5 * span.max(1.0), hi + 0.5 * span.max(1.0));
    }
    (lo - 0.08 * span, hi + 0.08 * span)
}

struct Frame {
    x: (f64, f64),
    y: (f64, f64),
}

impl Frame {
    fn px(&self, x: f64) -> f64 {
        LEFT + (x - self.x.0) / (self.x.1 - self.x.0) * (W - LEFT - RIGHT)
    }
    fn py(&self, y: f64) -> f64 {
        H - BOTTOM - (y - self.y.0) / (self.y.1 - self.y.0) * (H - TOP - BOTTOM)
    }

    /// The frame, five ticks per axis, the axis labels and the title.
    fn axes(&self, svg: &mut String, title: &str, x_label: &str, y_label: &str) {
        let _ = write!(
            svg,
            r##"<rect x="{LEFT}" y="{TOP}" width="{}" height="{}" fill="none" stroke="#888"/>"##,
            W - LEFT - RIGHT,
            H - TOP - BOTTOM
        );
        for i in 0..=4 {
            let t = i as f64 / 4.0;
            let (x, y) = (
                self.x.0 + t * (self.x.1 - self.x.0),
                self.y.0 + t * (self.y.1 - self.y.0),
            );
            let _ = write!(
                svg,
                r##"<text x="{:.1}" y="{:.1}" font-size="11" text-anchor="middle">{}</text><text x="{:.1}" y="{:.1}" font-size="11" text-anchor="end">{}</text>"##,
                self.px(x),
                H - BOTTOM + 16.0,
                tick(x),
                LEFT - 6.0,
                self.py(y) + 4.0,
                tick(y)
            );
        }
        let _ = write!(
            svg,
            r##"<text x="{:.1}" y="16" font-size="13" font-weight="bold" text-anchor="middle">{}</text><text x="{:.1}" y="{:.1}" font-size="12" text-anchor="middle">{}</text><text x="14" y="{:.1}" font-size="12" text-anchor="middle" transform="rotate(-90 14 {:.1})">{}</text>"##,
            W / 2.0,
            escape(title),
            (LEFT + W - RIGHT) / 2.0,
            H - 8.0,
            escape(x_label),
            (TOP + H - BOTTOM) / 2.0,
            (TOP + H - BOTTOM) / 2.0,
            escape(y_label)
        );
    }
}

fn tick(v: f64) -> String {
    let a = v.abs();
    if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.3}")
    }
}

fn open(id: &str) -> String {
    format!(
        r#"<svg id="{}" class="chart" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {H}" width="{W}" height="{H}" role="img">"#,
        escape(id)
    )
}

/// A line per series (label, points), with a dot at each point and a legend.
pub fn lines(
    id: &str,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> String {
    let all = || series.iter().flat_map(|(_, p)| p.iter());
    let frame = Frame {
        x: padded(all().map(|p| p.0)),
        y: padded(all().map(|p| p.1)),
    };
    let mut svg = open(id);
    frame.axes(&mut svg, title, x_label, y_label);
    for (i, (label, points)) in series.iter().enumerate() {
        let colour = PALETTE[i % PALETTE.len()];
        let path: Vec<String> = points
            .iter()
            .filter(|p| p.1.is_finite())
            .map(|&(x, y)| format!("{:.1},{:.1}", frame.px(x), frame.py(y)))
            .collect();
        let _ = write!(
            svg,
            r#"<polyline class="series" fill="none" stroke="{colour}" stroke-width="1.5" points="{}"/>"#,
            path.join(" ")
        );
        for p in &path {
            let (x, y) = p.split_once(',').unwrap_or(("0", "0"));
            let _ = write!(
                svg,
                r#"<circle cx="{x}" cy="{y}" r="2.5" fill="{colour}"/>"#
            );
        }
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" font-size="11" fill="{colour}">{}</text>"#,
            LEFT + 8.0,
            TOP + 14.0 + 13.0 * i as f64,
            escape(label)
        );
    }
    svg.push_str("</svg>");
    svg
}

/// One labelled point per (label, x, y).
pub fn scatter(
    id: &str,
    title: &str,
    x_label: &str,
    y_label: &str,
    points: &[(String, f64, f64)],
) -> String {
    let frame = Frame {
        x: padded(points.iter().map(|p| p.1)),
        y: padded(points.iter().map(|p| p.2)),
    };
    let mut svg = open(id);
    frame.axes(&mut svg, title, x_label, y_label);
    for (i, (label, x, y)) in points.iter().enumerate() {
        let colour = PALETTE[i % PALETTE.len()];
        let (px, py) = (frame.px(*x), frame.py(*y));
        let _ = write!(
            svg,
            r#"<circle class="point" cx="{px:.1}" cy="{py:.1}" r="5" fill="{colour}"><title>{}: {} ms, {} dB</title></circle><text x="{:.1}" y="{:.1}" font-size="11" text-anchor="{}">{}</text>"#,
            escape(label),
            tick(*x),
            tick(*y),
            if px > W - 140.0 { px - 8.0 } else { px + 8.0 },
            py - 6.0,
            if px > W - 140.0 { "end" } else { "start" },
            escape(label)
        );
    }
    svg.push_str("</svg>");
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn charts_hold_one_mark_per_point_and_escape_labels() {
        let svg = scatter(
            "s",
            "t",
            "x",
            "y",
            &[("a<b".into(), 1.0, 2.0), ("c".into(), 3.0, 4.0)],
        );
        assert_eq!(svg.matches("<circle class=\"point\"").count(), 2);
        assert!(svg.contains("a&lt;b") && !svg.contains("a<b"));
        let svg = lines(
            "l",
            "t",
            "x",
            "y",
            &[("a".into(), vec![(0.0, 1.0), (1.0, 2.0)])],
        );
        assert_eq!(svg.matches("<polyline").count(), 1);
        assert_eq!(svg.matches("<circle").count(), 2);
    }
}
