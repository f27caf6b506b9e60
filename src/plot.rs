//! Minimal SVG charts for the measurement reports (error against time, error against eps):
//! a few series of points on linear or logarithmic axes, with optional connecting lines,
//! labels and a legend. Written by hand because the reports need nothing more and SVG is
//! plain text that diffs well in `docs/`.

use std::fmt::Write;

/// How an axis maps values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    Linear,
    Log,
}

/// One set of points drawn in one colour.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Join the points (in the order given) with a line.
    pub line: bool,
    /// Optional label per point, drawn beside it.
    pub labels: Vec<String>,
}

/// A chart: title, axis names and scales, series.
#[derive(Clone, Debug)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x_scale: Scale,
    pub y_scale: Scale,
    pub series: Vec<Series>,
}

const WIDTH: f64 = 900.0;
const HEIGHT: f64 = 600.0;
const MARGIN_LEFT: f64 = 90.0;
const MARGIN_RIGHT: f64 = 220.0;
const MARGIN_TOP: f64 = 50.0;
const MARGIN_BOTTOM: f64 = 70.0;
const COLOURS: [&str; 8] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2"];

fn transform(value: f64, scale: Scale) -> Option<f64> {
    match scale {
        Scale::Linear => value.is_finite().then_some(value),
        Scale::Log => (value > 0.0 && value.is_finite()).then(|| value.log10()),
    }
}

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-9);
    (lo - pad, hi + pad)
}

/// Tick positions (in transformed units) and their labels.
fn ticks(lo: f64, hi: f64, scale: Scale) -> Vec<(f64, String)> {
    match scale {
        Scale::Log => {
            let mut out = Vec::new();
            let mut e = lo.floor() as i32;
            while (e as f64) <= hi {
                for m in [1.0, 2.0, 5.0] {
                    let t = (e as f64) + f64::log10(m);
                    if t >= lo && t <= hi {
                        out.push((t, format!("{}", m * 10f64.powi(e))));
                    }
                }
                e += 1;
            }
            out
        }
        Scale::Linear => {
            let span = hi - lo;
            let raw = span / 6.0;
            let magnitude = 10f64.powf(raw.log10().floor());
            let step = [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * magnitude).find(|s| *s >= raw).unwrap_or(raw);
            let mut t = (lo / step).ceil() * step;
            let mut out = Vec::new();
            while t <= hi {
                out.push((t, format!("{:.*}", (-step.log10().floor()).max(0.0) as usize, t)));
                t += step;
            }
            out
        }
    }
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

impl Chart {
    /// The chart as an SVG document.
    pub fn to_svg(&self) -> String {
        let all = || self.series.iter().flat_map(|s| s.points.iter());
        let (x0, x1) = range(all().filter_map(|p| transform(p.0, self.x_scale)));
        let (y0, y1) = range(all().filter_map(|p| transform(p.1, self.y_scale)));
        let plot_w = WIDTH - MARGIN_LEFT - MARGIN_RIGHT;
        let plot_h = HEIGHT - MARGIN_TOP - MARGIN_BOTTOM;
        let px = |x: f64| MARGIN_LEFT + (x - x0) / (x1 - x0) * plot_w;
        let py = |y: f64| MARGIN_TOP + (1.0 - (y - y0) / (y1 - y0)) * plot_h;
        let mut svg = String::new();
        let _ = writeln!(
            svg,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" font-family="sans-serif" font-size="12">"#
        );
        let _ = writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
        let _ = writeln!(
            svg,
            r#"<text x="{}" y="28" font-size="16" text-anchor="middle">{}</text>"#,
            WIDTH / 2.0,
            escape(&self.title)
        );
        let _ = writeln!(
            svg,
            r#"<rect x="{MARGIN_LEFT}" y="{MARGIN_TOP}" width="{plot_w}" height="{plot_h}" fill="none" stroke="black"/>"#
        );
        for (t, label) in ticks(x0, x1, self.x_scale) {
            let x = px(t);
            let _ = writeln!(
                svg,
                r##"<line x1="{x:.1}" y1="{MARGIN_TOP}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/>"##,
                MARGIN_TOP + plot_h
            );
            let _ = writeln!(
                svg,
                r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle">{label}</text>"#,
                MARGIN_TOP + plot_h + 18.0
            );
        }
        for (t, label) in ticks(y0, y1, self.y_scale) {
            let y = py(t);
            let _ = writeln!(
                svg,
                r##"<line x1="{MARGIN_LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/>"##,
                MARGIN_LEFT + plot_w
            );
            let _ = writeln!(
                svg,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{label}</text>"#,
                MARGIN_LEFT - 6.0,
                y + 4.0
            );
        }
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            MARGIN_LEFT + plot_w / 2.0,
            HEIGHT - 20.0,
            escape(&self.x_label)
        );
        let _ = writeln!(
            svg,
            r#"<text x="20" y="{:.1}" text-anchor="middle" transform="rotate(-90 20 {:.1})">{}</text>"#,
            MARGIN_TOP + plot_h / 2.0,
            MARGIN_TOP + plot_h / 2.0,
            escape(&self.y_label)
        );
        for (i, series) in self.series.iter().enumerate() {
            let colour = COLOURS[i % COLOURS.len()];
            let points: Vec<(f64, f64, usize)> = series
                .points
                .iter()
                .enumerate()
                .filter_map(|(k, p)| Some((px(transform(p.0, self.x_scale)?), py(transform(p.1, self.y_scale)?), k)))
                .collect();
            if series.line && points.len() > 1 {
                let path: Vec<String> = points.iter().map(|(x, y, _)| format!("{x:.1},{y:.1}")).collect();
                let _ = writeln!(
                    svg,
                    r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="1.5"/>"#,
                    path.join(" ")
                );
            }
            for (x, y, k) in &points {
                let _ = writeln!(svg, r#"<circle cx="{x:.1}" cy="{y:.1}" r="3.5" fill="{colour}"/>"#);
                if let Some(label) = series.labels.get(*k).filter(|l| !l.is_empty()) {
                    let _ = writeln!(
                        svg,
                        r#"<text x="{:.1}" y="{:.1}" font-size="10" fill="{colour}">{}</text>"#,
                        x + 5.0,
                        y - 5.0,
                        escape(label)
                    );
                }
            }
            let ly = MARGIN_TOP + 14.0 + 18.0 * i as f64;
            let lx = MARGIN_LEFT + plot_w + 15.0;
            let _ = writeln!(svg, r#"<circle cx="{lx:.1}" cy="{:.1}" r="4" fill="{colour}"/>"#, ly - 4.0);
            let _ = writeln!(svg, r#"<text x="{:.1}" y="{ly:.1}">{}</text>"#, lx + 10.0, escape(&series.name));
        }
        svg.push_str("</svg>\n");
        svg
    }
}

/// Indices of the points on the lower-left Pareto front of `(cost, error)` pairs: no
/// other point is both cheaper and more accurate. Sorted by cost.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut order: Vec<usize> =
        (0..points.len()).filter(|&i| points[i].0.is_finite() && points[i].1.is_finite()).collect();
    order.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0).then(points[a].1.total_cmp(&points[b].1)));
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for i in order {
        if points[i].1 < best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_only_undominated_points() {
        let points = [(1.0, 0.5), (2.0, 0.4), (2.5, 0.45), (3.0, 0.1), (0.5, 0.9), (4.0, 0.1)];
        assert_eq!(pareto_front(&points), vec![4, 0, 1, 3]);
    }

    #[test]
    fn svg_names_every_series_and_skips_non_positive_log_values() {
        let chart = Chart {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            x_scale: Scale::Log,
            y_scale: Scale::Log,
            series: vec![Series {
                name: "a<b".into(),
                points: vec![(1.0, 1.0), (0.0, 2.0), (10.0, 0.1)],
                line: true,
                labels: vec![],
            }],
        };
        let svg = chart.to_svg();
        assert!(svg.starts_with("<svg") && svg.contains("a&lt;b") && svg.trim_end().ends_with("</svg>"));
        assert_eq!(svg.matches("<circle").count(), 2 + 1);
    }
}
