//! Minimal SVG line charts for experiment reports (no plotting stack needed to view them: any
//! browser opens the file).

use crate::report::page::esc;
use std::fmt::Write;

/// One series of a chart.
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Stroke colour (CSS).
    pub color: &'static str,
    /// Points (x, y); non-finite or non-positive y are skipped on a log axis.
    pub points: Vec<(f64, f64)>,
    /// Draw markers instead of a line.
    pub markers: bool,
}

/// A line chart with a linear x axis and a logarithmic ([`LogChart::svg`]) or linear
/// ([`LogChart::svg_linear`]) y axis.
pub struct LogChart {
    /// Title.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label.
    pub y_label: String,
    /// Series.
    pub series: Vec<Series>,
}

const W: f64 = 900.0;
const H: f64 = 560.0;
const L: f64 = 80.0;
const R: f64 = 230.0;
const T: f64 = 50.0;
const B: f64 = 60.0;

impl LogChart {
    /// Render as SVG text, the y axis logarithmic (points with y <= 0 are left out).
    pub fn svg(&self) -> String {
        self.render(true)
    }

    /// Render as SVG text, the y axis linear (from zero when every y is positive).
    pub fn svg_linear(&self) -> String {
        self.render(false)
    }

    fn render(&self, log: bool) -> String {
        let fy = |y: f64| if log { y.log10() } else { y };
        let usable = |y: f64| y.is_finite() && (!log || y > 0.0);
        let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
        for &(x, y) in self.series.iter().flat_map(|s| s.points.iter()) {
            if usable(y) && x.is_finite() {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(fy(y));
                y1 = y1.max(fy(y));
            }
        }
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        let (y0, y1, ticks) = y_axis(log, y0, y1);
        let x1 = if x1 > x0 { x1 } else { x0 + 1.0 };
        let px = |x: f64| L + (x - x0) / (x1 - x0) * (W - L - R);
        let py = |y: f64| T + (y1 - fy(y)) / (y1 - y0) * (H - T - B);
        let mut s = svg_start(H, &self.title);
        // grid: decades or even steps
        for (v, label) in &ticks {
            let y = T + (y1 - v) / (y1 - y0) * (H - T - B);
            let _ = writeln!(
                s,
                r##"<line x1="{L}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
                W - R,
                L - 6.0,
                y + 4.0,
                esc(label)
            );
        }
        // x ticks at round steps inside the range
        let xs = nice_step((x1 - x0) / 5.0);
        let first = (x0 / xs).ceil() as i64;
        let last = (x1 / xs + 1e-9).floor() as i64;
        for i in first..=last.min(first + 20) {
            let x = i as f64 * xs;
            let _ = writeln!(
                s,
                r##"<line x1="{:.1}" y1="{T}" x2="{:.1}" y2="{:.1}" stroke="#eee"/><text x="{:.1}" y="{:.1}" text-anchor="middle">{x:.0}</text>"##,
                px(x),
                px(x),
                H - B,
                px(x),
                H - B + 18.0
            );
        }
        let _ = writeln!(
            s,
            r#"<rect x="{L}" y="{T}" width="{:.1}" height="{:.1}" fill="none" stroke="black"/>"#,
            W - L - R,
            H - T - B
        );
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            (L + W - R) / 2.0,
            H - 15.0,
            esc(&self.x_label)
        );
        let _ = writeln!(
            s,
            r#"<text x="18" y="{:.1}" text-anchor="middle" transform="rotate(-90 18 {:.1})">{}</text>"#,
            (T + H - B) / 2.0,
            (T + H - B) / 2.0,
            esc(&self.y_label)
        );
        self.series_svg(&mut s, &px, &py, &usable);
        s.push_str("</svg>\n");
        s
    }
    /// Each series as a line or markers, and its legend entry, at plot coordinates `px`, `py`
    /// (points `usable` leaves out are not drawn).
    fn series_svg(
        &self,
        s: &mut String,
        px: &dyn Fn(f64) -> f64,
        py: &dyn Fn(f64) -> f64,
        usable: &dyn Fn(f64) -> bool,
    ) {
        for (k, ser) in self.series.iter().enumerate() {
            let good: Vec<(f64, f64)> = ser
                .points
                .iter()
                .filter(|(x, y)| x.is_finite() && usable(*y))
                .map(|&(x, y)| (px(x), py(y)))
                .collect();
            if ser.markers {
                for (x, y) in &good {
                    let _ = writeln!(
                        s,
                        r#"<circle cx="{x:.1}" cy="{y:.1}" r="3.5" fill="none" stroke="{}" stroke-width="1.5"/>"#,
                        ser.color
                    );
                }
            } else if !good.is_empty() {
                let path: Vec<String> =
                    good.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
                let _ = writeln!(
                    s,
                    r#"<polyline points="{}" fill="none" stroke="{}" stroke-width="1.6"/>"#,
                    path.join(" "),
                    ser.color
                );
            }
            let ly = T + 10.0 + 20.0 * k as f64;
            let lx = W - R + 15.0;
            if ser.markers {
                let _ = writeln!(
                    s,
                    r#"<circle cx="{:.1}" cy="{ly:.1}" r="3.5" fill="none" stroke="{}" stroke-width="1.5"/>"#,
                    lx + 10.0,
                    ser.color
                );
            } else {
                let _ = writeln!(
                    s,
                    r#"<line x1="{lx:.1}" y1="{ly:.1}" x2="{:.1}" y2="{ly:.1}" stroke="{}" stroke-width="2"/>"#,
                    lx + 20.0,
                    ser.color
                );
            }
            let _ = writeln!(
                s,
                r#"<text x="{:.1}" y="{:.1}">{}</text>"#,
                lx + 26.0,
                ly + 4.0,
                esc(&ser.name)
            );
        }
    }
}

/// One panel of a [`BandChart`]: an error and its bound.
pub struct Panel {
    /// The panel's name (a filter, an axis).
    pub name: String,
    /// Its colour (CSS).
    pub color: &'static str,
    /// The error, (x, y).
    pub error: Vec<(f64, f64)>,
    /// The bound the error should stay under (3 sigma), (x, y): drawn as a shaded band from
    /// zero.
    pub bound: Vec<(f64, f64)>,
}

/// Errors against their bounds, one panel each, stacked over a shared x axis: the bound a
/// shaded band, the error a line, spans of interest (a receiver's outages) shaded across every
/// panel. Long series are decimated by min/max per pixel column ([`decimate`]), so a spike
/// survives and a two-hour drive is a file of some 100 KB, not megabytes.
pub struct BandChart {
    /// Title.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label (every panel).
    pub y_label: String,
    /// What the band is ("3 sigma").
    pub band_label: String,
    /// The panels, top to bottom.
    pub panels: Vec<Panel>,
    /// Spans shaded across the panels, [from, to] in x.
    pub spans: Vec<[f64; 2]>,
    /// What the spans are ("receiver outage").
    pub span_label: String,
}

/// A [`BandChart`] panel's height, and the gap between two.
const PH: f64 = 170.0;
const GAP: f64 = 28.0;

/// Columns a [`BandChart`]'s series are decimated to.
pub const BAND_COLUMNS: usize = 700;

impl BandChart {
    /// Render as SVG text.
    pub fn svg(&self) -> String {
        let n = self.panels.len().max(1) as f64;
        let h = T + n * (PH + GAP) - GAP + B;
        let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
        let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in &self.panels {
            for &(x, _) in p.error.iter().chain(&p.bound).filter(finite) {
                x0 = x0.min(x);
                x1 = x1.max(x);
            }
        }
        if !x0.is_finite() {
            (x0, x1) = (0.0, 1.0);
        }
        let x1 = if x1 > x0 { x1 } else { x0 + 1.0 };
        let pw = W - L - R;
        let px = |x: f64| L + (x - x0) / (x1 - x0) * pw;
        let mut s = svg_start(h, &self.title);
        for (k, p) in self.panels.iter().enumerate() {
            self.panel(&mut s, p, T + k as f64 * (PH + GAP), &px, (x0, x1));
        }
        self.footer(&mut s, h, &px, (x0, x1));
        s.push_str("</svg>\n");
        s
    }

    /// Panel `p` with its top at `top`: its spans, grid, band, error line and legend (`px` the
    /// x axis's mapping over `xs`).
    fn panel(&self, s: &mut String, p: &Panel, top: f64, px: &dyn Fn(f64) -> f64, xs: (f64, f64)) {
        let (x0, x1) = xs;
        let pw = W - L - R;
        let err = decimate(&p.error, x0, x1, BAND_COLUMNS);
        let bound = decimate(&p.bound, x0, x1, BAND_COLUMNS);
        let ymax = err.iter().chain(&bound).map(|q| q.1).fold(0.0, f64::max);
        let (_, b, ticks) = y_axis(false, 0.0, ymax.max(1e-9));
        let py = |y: f64| top + (b - y) / b * PH;
        // the spans under everything
        for sp in &self.spans {
            let (a, z) = (px(sp[0].max(x0)), px(sp[1].min(x1)));
            if z > a {
                let _ = writeln!(
                    s,
                    r##"<rect x="{a:.1}" y="{top:.1}" width="{:.1}" height="{PH}" fill="#e8e8e8"/>"##,
                    z - a
                );
            }
        }
        for (v, label) in &ticks {
            let _ = writeln!(
                s,
                r##"<line x1="{L}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
                W - R,
                L - 6.0,
                py(*v) + 4.0,
                esc(label),
                y = py(*v)
            );
        }
        if !bound.is_empty() {
            let mut path = format!("{:.1},{:.1}", px(bound[0].0), py(0.0));
            for &(x, y) in &bound {
                let _ = write!(path, " {:.1},{:.1}", px(x), py(y));
            }
            let _ = write!(path, " {:.1},{:.1}", px(bound[bound.len() - 1].0), py(0.0));
            let _ = writeln!(
                s,
                r#"<polygon points="{path}" fill="{}" fill-opacity="0.18" stroke="{}" stroke-opacity="0.5" stroke-width="0.8"/>"#,
                p.color, p.color
            );
        }
        if !err.is_empty() {
            let path: Vec<String> = err
                .iter()
                .map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y)))
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{}" stroke-width="1.2"/>"#,
                path.join(" "),
                p.color
            );
        }
        let _ = writeln!(
            s,
            r#"<rect x="{L}" y="{top:.1}" width="{pw:.1}" height="{PH}" fill="none" stroke="black"/>"#
        );
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{:.1}" font-weight="bold">{}</text>"#,
            W - R + 12.0,
            top + 16.0,
            esc(&p.name)
        );
        for (i, (what, opacity, width)) in
            [("error", 1.0, 2.0), (self.band_label.as_str(), 0.18, 10.0)]
                .into_iter()
                .enumerate()
        {
            let ly = top + 38.0 + 20.0 * i as f64;
            let _ = writeln!(
                s,
                r#"<line x1="{:.1}" y1="{ly:.1}" x2="{:.1}" y2="{ly:.1}" stroke="{}" stroke-opacity="{opacity}" stroke-width="{width}"/><text x="{:.1}" y="{:.1}">{}</text>"#,
                W - R + 12.0,
                W - R + 32.0,
                p.color,
                W - R + 38.0,
                ly + 4.0,
                esc(what)
            );
        }
        let _ = writeln!(
            s,
            r#"<text x="18" y="{:.1}" text-anchor="middle" transform="rotate(-90 18 {:.1})">{}</text>"#,
            top + PH / 2.0,
            top + PH / 2.0,
            esc(&self.y_label)
        );
    }

    /// Below the panels: the spans' legend, the x axis's ticks and label (`h` the chart's
    /// height, `px` the x axis's mapping over `xs`).
    fn footer(&self, s: &mut String, h: f64, px: &dyn Fn(f64) -> f64, xs: (f64, f64)) {
        let (x0, x1) = xs;
        let bottom = h - B;
        if !self.spans.is_empty() {
            let _ = writeln!(
                s,
                r##"<rect x="{:.1}" y="{:.1}" width="20" height="10" fill="#e8e8e8"/><text x="{:.1}" y="{:.1}">{}</text>"##,
                W - R + 12.0,
                bottom - 10.0,
                W - R + 38.0,
                bottom,
                esc(&self.span_label)
            );
        }
        let xs = nice_step((x1 - x0) / 6.0);
        let first = (x0 / xs).ceil() as i64;
        let last = (x1 / xs + 1e-9).floor() as i64;
        for i in first..=last.min(first + 20) {
            let x = i as f64 * xs;
            let _ = writeln!(
                s,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{x:.0}</text>"#,
                px(x),
                bottom + 18.0
            );
        }
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            (L + W - R) / 2.0,
            h - 15.0,
            esc(&self.x_label)
        );
    }
}

/// `points` (in x order) thinned to at most two per column of `columns` between `x0` and
/// `x1`: each column's lowest and highest point, in their order. A peak or a dip survives, as
/// dropping every n-th point would not let it; non-finite points are left out.
pub fn decimate(points: &[(f64, f64)], x0: f64, x1: f64, columns: usize) -> Vec<(f64, f64)> {
    let width = (x1 - x0) / columns.max(1) as f64;
    let mut out = Vec::new();
    /// A column: its index, its lowest and its highest point.
    type Column = (i64, (f64, f64), (f64, f64));
    let mut column: Option<Column> = None;
    let flush = |c: Column, out: &mut Vec<(f64, f64)>| {
        let (lo, hi) = (c.1, c.2);
        if lo == hi {
            out.push(lo);
        } else if lo.0 <= hi.0 {
            out.extend([lo, hi]);
        } else {
            out.extend([hi, lo]);
        }
    };
    for &p in points.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
        let last = columns.max(1) as i64 - 1;
        let i = if width > 0.0 {
            (((p.0 - x0) / width).floor() as i64).clamp(0, last)
        } else {
            0
        };
        column = match column {
            Some((j, lo, hi)) if j == i => Some((
                j,
                if p.1 < lo.1 { p } else { lo },
                if p.1 > hi.1 { p } else { hi },
            )),
            Some(c) => {
                flush(c, &mut out);
                Some((i, p, p))
            }
            None => Some((i, p, p)),
        };
    }
    if let Some(c) = column {
        flush(c, &mut out);
    }
    out
}

/// An SVG document's opening: its size (the charts' width, `h` high), a white ground and the
/// title over the plot area.
fn svg_start(h: f64, title: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="{W}" height="{h}" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="25" font-size="15" text-anchor="middle">{}</text>"#,
        (L + W - R) / 2.0,
        esc(title)
    );
    s
}

/// The y axis from `y0` to `y1` (log10 values when `log`): log, whole decades; linear, from
/// zero (or the lowest value below it) in 5 even steps. Its ends and its labelled ticks.
fn y_axis(log: bool, y0: f64, y1: f64) -> (f64, f64, Vec<(f64, String)>) {
    if log {
        let (a, b) = (y0.floor(), y1.ceil().max(y0.floor() + 1.0));
        let n = (b - a).round() as i32;
        (
            a,
            b,
            (0..=n)
                .map(|i| (a + f64::from(i), format!("1e{}", a as i32 + i)))
                .collect(),
        )
    } else {
        let a = y0.min(0.0);
        let step = nice_step((y1 - a).max(1e-12) / 5.0);
        let (a, b) = (
            (a / step).floor() * step,
            (y1 / step).ceil().max(1.0) * step,
        );
        let n = ((b - a) / step).round() as i32;
        let digits = (-step.log10().floor()).max(0.0) as usize;
        let ticks = (0..=n)
            .map(|i| {
                let v = a + step * f64::from(i);
                (v, format!("{v:.digits$}"))
            })
            .collect();
        (a, b, ticks)
    }
}

/// A round step (1, 2 or 5 times a power of ten) at least `raw`.
fn nice_step(raw: f64) -> f64 {
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|s| *s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * p)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two hours at 1 Hz in three panels stay small; a one-second spike survives decimation;
    /// outages are shaded in every panel.
    #[test]
    fn a_band_chart_of_two_hours_is_small_and_keeps_its_spikes() {
        let t: Vec<f64> = (0..7200).map(f64::from).collect();
        let err: Vec<(f64, f64)> = t
            .iter()
            .map(|&x| {
                (
                    x,
                    if x == 4321.0 {
                        50.0
                    } else {
                        1.0 + (x * 0.1).sin()
                    },
                )
            })
            .collect();
        let bound: Vec<(f64, f64)> = t.iter().map(|&x| (x, 3.0 + x / 1000.0)).collect();
        let d = decimate(&err, 0.0, 7199.0, BAND_COLUMNS);
        assert!(d.len() <= 2 * BAND_COLUMNS, "{}", d.len());
        assert!(d.contains(&(4321.0, 50.0)), "the spike survives");
        assert!(d.windows(2).all(|w| w[0].0 <= w[1].0), "in x order");
        let c = BandChart {
            title: "velocity".into(),
            x_label: "time, s".into(),
            y_label: "m/s".into(),
            band_label: "3 sigma".into(),
            panels: ["Standard", "Fading", "Adaptive"]
                .iter()
                .map(|n| Panel {
                    name: n.to_string(),
                    color: "#1f77b4",
                    error: err.clone(),
                    bound: bound.clone(),
                })
                .collect(),
            spans: vec![[600.0, 645.0], [2000.0, 2150.0]],
            span_label: "receiver outage".into(),
        };
        let s = c.svg();
        assert!(s.starts_with("<svg") && s.trim_end().ends_with("</svg>"));
        assert!(s.len() < 200_000, "{} bytes", s.len());
        assert_eq!(s.matches("<polygon").count(), 3);
        assert_eq!(s.matches("<polyline").count(), 3);
        assert_eq!(s.matches(r##"fill="#e8e8e8""##).count(), 2 * 3 + 1);
        assert!(s.contains("3 sigma") && s.contains("receiver outage") && !s.contains("NaN"));
    }

    #[test]
    fn chart_is_well_formed_svg_with_every_series() {
        let c = LogChart {
            title: "a < b".into(),
            x_label: "f".into(),
            y_label: "drift".into(),
            series: vec![
                Series {
                    name: "one".into(),
                    color: "red",
                    points: vec![(1.0, 1e-3), (2.0, 1e-1), (3.0, f64::NAN)],
                    markers: false,
                },
                Series {
                    name: "two".into(),
                    color: "blue",
                    points: vec![(1.0, 1e-5)],
                    markers: true,
                },
            ],
        };
        let s = c.svg();
        assert!(s.starts_with("<svg") && s.trim_end().ends_with("</svg>"));
        assert!(s.contains("a &lt; b") && s.contains("one") && s.contains("two"));
        assert_eq!(s.matches("<polyline").count(), 1);
        assert!(!s.contains("NaN"));
        // linear: negative values kept, ticks at round steps through zero
        let mut c = c;
        c.series[1].points = vec![(1.0, -2.5), (3.0, 7.0)];
        let s = c.svg_linear();
        assert!(
            !s.contains("NaN") && s.contains(">0<") && s.contains(">-4<"),
            "{s}"
        );
        assert_eq!(s.matches("<polyline").count(), 1);
        assert_eq!(nice_step(0.13), 0.2);
        c.series[1].points = vec![(1.0, 0.0), (3.0, 0.95)];
        let s = c.svg_linear();
        assert!(s.contains(">0.6<") && !s.contains("0000"), "{s}");
        assert_eq!(nice_step(3.0), 5.0);
        assert_eq!(nice_step(1.0), 1.0);
    }
}
