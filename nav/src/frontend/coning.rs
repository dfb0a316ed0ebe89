//! Coning and sculling compensation for n = 2..5 sub-samples, and the coefficients tuned to the
//! dither-demodulation filter (paper 000).
//!
//! Rotation vector over one update interval of `n` gyro increments `theta(1..n)`:
//! `Phi = sum theta(i) + sum_{i=1}^{n-1} k_{n-i} theta(i) x theta(n)` (paper 000, eq. 4).
//! The velocity increment uses the same coefficients (Savage's coning/sculling equivalence):
//! `dV = sum v + 1/2 theta_tot x v_tot + sum k_{n-i} (theta(i) x v(n) + v(i) x theta(n))`.
//!
//! ## Tuning to the filter
//! Under classical coning of half-angle `a` at `Omega`, with `lambda = Omega h` (h the sample
//! interval), the cross product of sub-interval increments is
//! `theta(i) x theta(j) = 4 sin^2 a sin^2(lambda/2) sin((j-i) lambda)` along the cone axis.
//! A linear-phase filter with zero-phase amplitude `F(lambda)` multiplies the oscillating
//! increments by `F` and delays them all alike, but passes the constant cone-axis rate
//! `-Omega a^2 / 2` unchanged (unit DC gain). The filtered data are then the increments of a
//! narrower cone (half-angle `F a`) plus an excess cone-axis rate `-Omega a^2 (1 - F^2) / 2`,
//! which the quaternion chain would integrate as drift: all of the coning, not only its
//! intra-interval part, shrinks by `F^2`. The coning term must make up for both, so per
//! update interval of `n` samples (to order `a^2`):
//!
//! `F^2 4 sin^2(lambda/2) sum_{j=1}^{n-1} k_j sin(j lambda) = (n lambda - F^2 sin(n lambda)) / 2`.
//!
//! With `F = 1` this is the classical condition `(n lambda - sin n lambda) / 2`. Expanding
//! `F = 1 - c lambda^2 + ...` shows the filter enters at the leading order (`n c lambda^3`),
//! which is why the tuned coefficients differ so much from the classical ones (paper 000, Table
//! 1; its eq. 14 is damaged in our copy, this is our derivation).
//!
//! * `classical`: `F = 1`, Taylor coefficients matched (Table 1 of paper 000, exact rationals).
//! * `taylor`: the paper's method for the filtered data: equate the Taylor coefficients of
//!   `lambda^3 .. lambda^(2n-1)` of both sides with the filter's own `F`.
//! * `fitted` (our default): a minimax fit over the whole passband (see [`ConingCoefficients::fitted`]).

use crate::frontend::dither_filter::{Fir, FirSpec};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Which coefficient set to use.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum ConingMethod {
    /// Classical coefficients (exact for unfiltered data at low frequency).
    Classical,
    /// Taylor-matched to the filter (paper 000's method).
    Taylor,
    /// Least-squares fit over the passband to the filter (default).
    #[default]
    Fitted,
}

impl std::fmt::Display for ConingMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Classical => "classical",
            Self::Taylor => "taylor",
            Self::Fitted => "fitted",
        })
    }
}

/// Coning / sculling coefficients `k_1 .. k_{n-1}` for an `n`-sample algorithm.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConingCoefficients {
    /// Sub-samples per update.
    pub n: usize,
    /// `k[j-1]` multiplies `theta(n-j) x theta(n)`.
    pub k: Vec<f64>,
}

/// Paper 000's Table 1, classical coefficients (numerators over a common denominator).
pub fn classical(n: usize) -> ConingCoefficients {
    let k: Vec<f64> = match n {
        2 => vec![2.0 / 3.0],
        3 => vec![27.0 / 20.0, 9.0 / 20.0],
        4 => vec![214.0 / 105.0, 92.0 / 105.0, 54.0 / 105.0],
        5 => vec![1375.0 / 504.0, 650.0 / 504.0, 525.0 / 504.0, 250.0 / 504.0],
        _ => panic!("coning algorithms exist for n = 2..=5, not {n}"),
    };
    ConingCoefficients { n, k }
}

/// Paper 000's Table 1, "optimized" (filter-tuned) row, for printing beside ours.
pub fn paper_000_tuned(n: usize) -> Vec<f64> {
    match n {
        2 => vec![-1.3830],
        3 => vec![81.979, -41.402],
        4 => vec![-1117.08, 926.373, -244.81],
        5 => vec![26350.80, -26588.81, 11585.94, -1981.4],
        _ => vec![],
    }
}

const FIT_ITERATIONS: usize = 300;

/// [`ConingCoefficients::fitted`] to the default dither filter ([`FirSpec::default`]) over its
/// passband, for `n` = 2..=5, as the bits of each coefficient.
const DEFAULT_FITTED: [&[u64]; 4] = [
    &[0x3fe415b4e53c689a],
    &[0x404308c665207ae3, 0xc032ae196790baa5],
    &[0x403fe472a5f28b2c, 0xc0222b2da9688b12, 0xc00be22987d11e9b],
    &[
        0x40a43f9ffdbb79d6,
        0xc0a4484e8909f1a6,
        0x4091a091ffc0cf93,
        0xc06841023a99825a,
    ],
];

/// Check `n` is supported.
pub fn valid_n(n: usize) -> bool {
    (2..=5).contains(&n)
}

/// Truncated power series in `lambda`: `c[p]` is the coefficient of `lambda^p`.
fn series_mul(a: &[f64], b: &[f64], len: usize) -> Vec<f64> {
    let mut c = vec![0.0; len];
    for (i, ai) in a.iter().enumerate().take(len) {
        for (j, bj) in b.iter().enumerate() {
            if i + j < len {
                c[i + j] += ai * bj;
            }
        }
    }
    c
}

/// Series of `sin(x lambda)`.
fn sin_series(x: f64, len: usize) -> Vec<f64> {
    let mut c = vec![0.0; len];
    let mut term = x; // x^p / p!
    for (p, cp) in c.iter_mut().enumerate().skip(1) {
        if p > 1 {
            term *= x / p as f64;
        }
        if p % 2 == 1 {
            *cp = if (p / 2) % 2 == 0 { term } else { -term };
        }
    }
    c
}

/// `F(lambda)^2 4 sin^2(lambda/2) sin(j lambda)`: what coefficient `k_j` contributes.
fn basis(fir: Option<&Fir>, j: usize, lambda: f64) -> f64 {
    let f = fir.map_or(1.0, |f| f.amplitude_w(lambda));
    f * f * 4.0 * (lambda / 2.0).sin().powi(2) * (j as f64 * lambda).sin()
}

/// The true coning per interval, per `sin^2 a`: `(n lambda - sin n lambda) / 2`.
pub fn true_coning(n: usize, lambda: f64) -> f64 {
    let x = n as f64 * lambda;
    if x < 1.0 {
        // series (x - sin x)/2 = sum_m (-1)^(m+1) x^(2m+1) / (2 (2m+1)!): no cancellation
        let mut term = x; // x^(2m+1)/(2m+1)!
        let mut sum = 0.0;
        for m in 1..12 {
            term *= x * x / ((2 * m) as f64 * (2 * m + 1) as f64);
            sum += if m % 2 == 1 { term } else { -term };
        }
        sum / 2.0
    } else {
        (x - x.sin()) / 2.0
    }
}

/// What the coning term must supply per interval on data filtered by `fir`, per `sin^2 a`:
/// `(n lambda - F^2 sin n lambda) / 2`.
pub fn required_coning(n: usize, fir: Option<&Fir>, lambda: f64) -> f64 {
    let base = true_coning(n, lambda);
    match fir {
        None => base,
        Some(f) => {
            let d = f.droop_w(lambda); // 1 - F
            let one_minus_f2 = d * (2.0 - d);
            base + one_minus_f2 * (n as f64 * lambda).sin() / 2.0
        }
    }
}

impl ConingCoefficients {
    /// The coefficient set `method` for `n` sub-samples on data filtered by `fir`
    /// (`None`: unfiltered data).
    /// Fails when the fit over the filter's passband has no unique solution (a filter spec
    /// whose passband makes the basis degenerate), naming the way out.
    pub fn for_method(
        method: ConingMethod,
        n: usize,
        fir: Option<&Fir>,
    ) -> Result<Self, crate::frontend::dither_filter::FirError> {
        Ok(match (method, fir) {
            (ConingMethod::Classical, _) | (_, None) => classical(n),
            (ConingMethod::Taylor, Some(f)) => Self::taylor(n, f),
            (ConingMethod::Fitted, Some(f)) if *f.spec() == FirSpec::default() && valid_n(n) => {
                // the fit to the default filter, worked out in advance (a unit test checks it
                // against the fit to the last bit): on an emulated CPU the fit takes a tenth of
                // a second, and every process that navigates asks for it
                Self {
                    n,
                    k: DEFAULT_FITTED[n - 2].iter().map(|b| f64::from_bits(*b)).collect(),
                }
            }
            (ConingMethod::Fitted, Some(f)) => Self::fitted(n, f, f.spec().passband_hz)
                .ok_or_else(|| {
                    crate::frontend::dither_filter::FirError::BadSpec(format!(
                        "the fitted coning coefficients have no unique solution over a {} Hz passband: choose coning = \"taylor\" or another [processing.fir]",
                        f.spec().passband_hz
                    ))
                })?,
        })
    }

    /// Paper 000's method: match the Taylor coefficients of `lambda^3 .. lambda^(2n-1)`.
    pub fn taylor(n: usize, fir: &Fir) -> Self {
        assert!(valid_n(n), "n must be 2..=5");
        let len = 2 * n + 2;
        // F^2 as a series in lambda
        let fc = fir.amplitude_taylor(len / 2 + 1);
        let mut f = vec![0.0; len];
        for (j, c) in fc.iter().enumerate() {
            if 2 * j < len {
                f[2 * j] = *c;
            }
        }
        let f2 = series_mul(&f, &f, len);
        // 4 sin^2(l/2) = 2 - 2 cos l
        let mut s = vec![0.0; len];
        let mut fact = 1.0;
        for (p, sp) in s.iter_mut().enumerate().skip(1) {
            fact *= p as f64;
            if p % 2 == 0 {
                *sp = if (p / 2) % 2 == 1 {
                    2.0 / fact
                } else {
                    -2.0 / fact
                };
            }
        }
        let f2s = series_mul(&f2, &s, len);
        let rhs_series: Vec<f64> = {
            // (n l - F^2 sin n l)/2
            let f2sn = series_mul(&f2, &sin_series(n as f64, len), len);
            (0..len)
                .map(|p| {
                    let lin = if p == 1 { n as f64 } else { 0.0 };
                    (lin - f2sn[p]) / 2.0
                })
                .collect()
        };
        let m = n - 1;
        let mut a = DMatrix::<f64>::zeros(m, m);
        let mut b = DVector::<f64>::zeros(m);
        for j in 1..=m {
            let g = series_mul(&f2s, &sin_series(j as f64, len), len);
            for (r, p) in (3..=2 * n - 1).step_by(2).enumerate() {
                a[(r, j - 1)] = g[p];
            }
        }
        for (r, p) in (3..=2 * n - 1).step_by(2).enumerate() {
            b[r] = rhs_series[p];
        }
        let k = a
            .lu()
            .solve(&b)
            .expect("Taylor system is regular for 2..=5")
            .iter()
            .cloned()
            .collect();
        Self { n, k }
    }

    /// Minimax fit over `(0, f_max_hz]` of the coning error weighted by the inverse square root
    /// of the true coning: pure relative weighting spends the coefficients on low frequencies
    /// where every set's drift is negligible, pure absolute weighting on the band edge only; the
    /// square root balances the two. Solved by Lawson's iteratively re-weighted least squares.
    /// None when the fit has no unique solution (a degenerate band).
    pub fn fitted(n: usize, fir: &Fir, f_max_hz: f64) -> Option<Self> {
        assert!(valid_n(n), "n must be 2..=5");
        let lmax = 2.0 * std::f64::consts::PI * f_max_hz / fir.spec().fs_hz;
        let m = n - 1;
        let grid = 400;
        // grid rows (weighted) and targets
        let pts: Vec<(Vec<f64>, f64)> = (1..=grid)
            .map(|i| {
                let l = lmax * i as f64 / grid as f64;
                let t = true_coning(n, l).sqrt();
                let row = (1..=m).map(|j| basis(Some(fir), j, l) / t).collect();
                (row, required_coning(n, Some(fir), l) / t)
            })
            .collect();
        // Lawson's iteratively re-weighted least squares: towards the smallest largest relative
        // error over the band (the least-squares start alone leaves the band edge worst)
        let mut w = vec![1.0; grid];
        let mut sol = DVector::<f64>::zeros(m);
        for _ in 0..FIT_ITERATIONS {
            let mut kkt = DMatrix::<f64>::zeros(m, m);
            let mut rhs = DVector::<f64>::zeros(m);
            for ((row, target), wi) in pts.iter().zip(&w) {
                for r in 0..m {
                    rhs[r] += wi * row[r] * target;
                    for cc in 0..m {
                        kkt[(r, cc)] += wi * row[r] * row[cc];
                    }
                }
            }
            sol = kkt.lu().solve(&rhs)?;
            if sol.iter().any(|k| !k.is_finite()) {
                return None;
            }
            let errs: Vec<f64> = pts
                .iter()
                .map(|(row, target)| {
                    (row.iter().zip(sol.iter()).map(|(a, k)| a * k).sum::<f64>() - target).abs()
                })
                .collect();
            let total: f64 = w.iter().zip(&errs).map(|(a, e)| a * e).sum();
            if total <= 0.0 {
                break;
            }
            for (wi, e) in w.iter_mut().zip(&errs) {
                *wi = *wi * e / total * grid as f64;
            }
        }
        Some(Self {
            n,
            k: sol.iter().take(m).cloned().collect(),
        })
    }

    /// Algorithm coning estimate minus true coning per interval, per `sin^2 a`, at `lambda`
    /// on data filtered by `fir` (or unfiltered).
    pub fn coning_error(&self, fir: Option<&Fir>, lambda: f64) -> f64 {
        let est: f64 = self
            .k
            .iter()
            .enumerate()
            .map(|(j, k)| k * basis(fir, j + 1, lambda))
            .sum();
        est - required_coning(self.n, fir, lambda)
    }

    /// Predicted drift of the cone axis (rad/s) under classical coning of half-angle `a` (rad) at
    /// `f_hz`, sample rate `fs_hz`, data filtered by `fir`.
    pub fn predicted_drift(&self, fir: Option<&Fir>, a: f64, f_hz: f64, fs_hz: f64) -> f64 {
        let lambda = 2.0 * std::f64::consts::PI * f_hz / fs_hz;
        self.coning_error(fir, lambda) * a.sin().powi(2) * fs_hz / self.n as f64
    }

    /// Coning correction for increments `th[0..n]`.
    #[inline]
    pub fn coning(&self, th: &[[f64; 3]]) -> [f64; 3] {
        let n = self.n;
        let last = th[n - 1];
        let mut d = [0.0; 3];
        for (j, k) in self.k.iter().enumerate() {
            let c = cross(th[n - 2 - j], last);
            for a in 0..3 {
                d[a] += k * c[a];
            }
        }
        d
    }

    /// Sculling correction for gyro increments `th` and velocity increments `dv`.
    #[inline]
    pub fn sculling(&self, th: &[[f64; 3]], dv: &[[f64; 3]]) -> [f64; 3] {
        let n = self.n;
        let (tl, vl) = (th[n - 1], dv[n - 1]);
        let mut d = [0.0; 3];
        for (j, k) in self.k.iter().enumerate() {
            let a = cross(th[n - 2 - j], vl);
            let b = cross(dv[n - 2 - j], tl);
            for c in 0..3 {
                d[c] += k * (a[c] + b[c]);
            }
        }
        d
    }
}

/// Cross product of plain arrays.
#[inline]
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_default_fit_worked_out_in_advance_is_the_fit_to_the_last_bit() {
        let fir = Fir::design(FirSpec::default()).unwrap();
        for n in 2..=5 {
            let fitted = ConingCoefficients::fitted(n, &fir, fir.spec().passband_hz).unwrap();
            let kept = ConingCoefficients::for_method(ConingMethod::Fitted, n, Some(&fir)).unwrap();
            let bits = |c: &ConingCoefficients| c.k.iter().map(|k| k.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&fitted),
                bits(&kept),
                "the fit for n = {n} changed: put its new coefficients in DEFAULT_FITTED"
            );
        }
    }

    use super::*;

    #[test]
    fn classical_residual_is_of_order_2n_plus_1() {
        for n in 2..=5 {
            let c = classical(n);
            // the classical set cancels lambda^3 .. lambda^(2n-1) of unfiltered coning
            let e1 = c.coning_error(None, 0.1).abs();
            let e2 = c.coning_error(None, 0.2).abs();
            let order = (e2 / e1).log2();
            assert!(
                (order - (2 * n + 1) as f64).abs() < 0.3,
                "n={n}: error order {order} ({e1:e}, {e2:e})"
            );
        }
    }

    #[test]
    fn tuned_and_fitted_sets_beat_classical_on_filtered_data() {
        let fir = Fir::default_dither_filter();
        let lam = |hz: f64| 2.0 * std::f64::consts::PI * hz / 2000.0;
        for n in 2..=5 {
            let c = classical(n);
            let t = ConingCoefficients::taylor(n, &fir);
            let f = ConingCoefficients::fitted(n, &fir, 100.0).unwrap();
            for hz in [1.0, 10.0, 50.0, 80.0] {
                let e = |k: &ConingCoefficients| k.coning_error(Some(&fir), lam(hz)).abs();
                let (ec, et, ef) = (e(&c), e(&t), e(&f));
                // the fit beats classical everywhere in the band, by 10x at least where it has
                // more than one coefficient to work with
                let margin = if n == 2 { 1.0 } else { 10.0 };
                assert!(ef * margin < ec, "n={n} {hz} Hz fitted {ef} classical {ec}");
                // the Taylor set only at low frequency (its truncation error grows fast, as
                // paper 000 notes)
                if hz <= 10.0 {
                    assert!(et * 10.0 < ec, "n={n} {hz} Hz taylor {et} classical {ec}");
                }
            }
        }
    }

    #[test]
    fn taylor_set_cancels_the_leading_orders_on_filtered_data() {
        let fir = Fir::default_dither_filter();
        for n in 2..=5 {
            let t = ConingCoefficients::taylor(n, &fir);
            let e1 = t.coning_error(Some(&fir), 0.05).abs();
            let e2 = t.coning_error(Some(&fir), 0.1).abs();
            let order = (e2 / e1).log2();
            // the first order not matched is lambda^(2n+1)
            assert!(
                order > (2 * n + 1) as f64 - 0.3,
                "n={n}: error order {order}"
            );
        }
    }

    #[test]
    fn coning_term_is_the_weighted_cross_products_with_the_last_sample() {
        let c = classical(3);
        let th = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        // k1 th2 x th3 + k2 th1 x th3 = 27/20 [1,0,0] + 9/20 [0,-1,0]
        let d = c.coning(&th);
        assert!((d[0] - 27.0 / 20.0).abs() < 1e-15);
        assert!((d[1] + 9.0 / 20.0).abs() < 1e-15);
        assert_eq!(d[2], 0.0);
    }
}
