//! Minimal SVG line charts for experiment reports (no plotting stack needed to view them: any
//! browser opens the file).

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

/// A chart with a linear x axis and a logarithmic y axis.
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
    /// Render as SVG text.
    pub fn svg(&self) -> String {
        let pts = || {
            self.series
                .iter()
                .flat_map(|s| s.points.iter())
                .filter(|(_, y)| y.is_finite() && *y > 0.0)
        };
        let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
        for &(x, y) in pts() {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y.log10());
            y1 = y1.max(y.log10());
        }
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        let (y0, y1) = (y0.floor(), y1.ceil().max(y0.floor() + 1.0));
        let x1 = if x1 > x0 { x1 } else { x0 + 1.0 };
        let px = |x: f64| L + (x - x0) / (x1 - x0) * (W - L - R);
        let py = |y: f64| T + (y1 - y.log10()) / (y1 - y0) * (H - T - B);
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
        // grid: decades
        let mut d = y0;
        while d <= y1 + 1e-9 {
            let y = py(10f64.powf(d));
            let _ = writeln!(
                s,
                r##"<line x1="{L}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">1e{d}</text>"##,
                W - R,
                L - 6.0,
                y + 4.0
            );
            d += 1.0;
        }
        for i in 0..=5 {
            let x = x0 + (x1 - x0) * f64::from(i) / 5.0;
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
        for (k, ser) in self.series.iter().enumerate() {
            let good: Vec<(f64, f64)> = ser
                .points
                .iter()
                .filter(|(_, y)| y.is_finite() && *y > 0.0)
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
        s.push_str("</svg>\n");
        s
    }
}

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
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
    }
}
