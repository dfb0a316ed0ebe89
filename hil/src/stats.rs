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

/// The half-width of the 95 % interval of the mean of `x` (Student's t, `n - 1` degrees of
/// freedom); none for fewer than two values.
pub fn half_width_95(x: &[f64]) -> Option<f64> {
    let n = x.len();
    if n < 2 {
        return None;
    }
    let m = x.iter().sum::<f64>() / n as f64;
    let var = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1) as f64;
    Some(t_975(n - 1) * (var / n as f64).sqrt())
}

/// Student's t at 0.975 for `df` degrees of freedom: the table to 30, then the Cornish-Fisher
/// expansion about the normal quantile (within 0.001 beyond 30).
pub fn t_975(df: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    if (1..=30).contains(&df) {
        return TABLE[df - 1];
    }
    let z: f64 = 1.959_964;
    let v = df.max(1) as f64;
    z + (z.powi(3) + z) / (4.0 * v)
        + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * v * v)
}
