//! Small statistics the experiments, procedures and runs share.

/// The median (the mean of the middle two for an even count; NaN for none).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// Wrap an angle difference to (-180, 180].
pub fn wrap180(d: f64) -> f64 {
    let w = d.rem_euclid(360.0);
    if w > 180.0 { w - 360.0 } else { w }
}

/// A straight line fitted by least squares, with its uncertainties from the scatter.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Line {
    mean_x: f64,
    mean_y: f64,
    /// The slope.
    pub(crate) slope: f64,
    /// The slope's standard uncertainty.
    pub(crate) slope_sigma: f64,
}

impl Line {
    /// The line's value at `x`.
    pub(crate) fn at(&self, x: f64) -> f64 {
        self.mean_y + self.slope * (x - self.mean_x)
    }
}

/// Least squares through `p` (equal weights); none for fewer than 3 points or no spread in x.
pub(crate) fn fit_line(p: &[(f64, f64)]) -> Option<Line> {
    let n = p.len() as f64;
    if p.len() < 3 {
        return None;
    }
    let mx = p.iter().map(|q| q.0).sum::<f64>() / n;
    let my = p.iter().map(|q| q.1).sum::<f64>() / n;
    let sxx: f64 = p.iter().map(|q| (q.0 - mx).powi(2)).sum();
    if sxx <= 0.0 {
        return None;
    }
    let slope = p.iter().map(|q| (q.0 - mx) * (q.1 - my)).sum::<f64>() / sxx;
    let ss: f64 = p
        .iter()
        .map(|q| (q.1 - my - slope * (q.0 - mx)).powi(2))
        .sum();
    let s = (ss / (n - 2.0)).sqrt();
    Some(Line {
        mean_x: mx,
        mean_y: my,
        slope,
        slope_sigma: s / sxx.sqrt(),
    })
}
