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
        let mut s = String::new();
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="12">"#
        );
        let _ = writeln!(s, r#"<rect width="{W}" height="{H}" fill="white"/>"#);
        let _ = writeln!(
            s,
            r#"<text x="{}" y="25" font-size="15" text-anchor="middle">{}</text>"#,
            (L + W - R) / 2.0,
            esc(&self.title)
        );
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
