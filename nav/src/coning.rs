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
//! `theta(i) x theta(j) = 4 sin^2 a sin^2(lambda/2) sin((j-i) lambda)` along the cone axis,
//! and the true coning over the interval is `sin^2 a (n lambda - sin n lambda) / 2`
//! (to order `a^2`). A linear-phase filter with zero-phase amplitude `F(lambda)` multiplies every
//! increment at `Omega` by `F(lambda)` and delays them all alike, so the cross products scale by
//! `F(lambda)^2` while the true coning of the motion does not. The coefficients must therefore
//! satisfy, as well as possible over the passband,
//!
//! `F(lambda)^2 4 sin^2(lambda/2) sum_{j=1}^{n-1} k_j sin(j lambda) = (n lambda - sin n lambda) / 2`.
//!
//! * `classical`: `F = 1`, Taylor coefficients matched (Table 1 of paper 000, exact rationals).
//! * `taylor`: the paper's method for the filtered data: equate the Taylor coefficients of
//!   `lambda^3 .. lambda^(2n-1)` of both sides with the filter's own `F`.
//! * `fitted` (our default): weighted least squares of the relative error over the passband,
//!   keeping the `lambda^3` term exact so the error vanishes towards DC.

use crate::fir::Fir;
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

impl ConingCoefficients {
    /// The coefficient set `method` for `n` sub-samples on data filtered by `fir`
    /// (`None`: unfiltered data).
    pub fn for_method(method: ConingMethod, n: usize, fir: Option<&Fir>) -> Self {
        match (method, fir) {
            (ConingMethod::Classical, _) | (_, None) => classical(n),
            (ConingMethod::Taylor, Some(f)) => Self::taylor(n, f),
            (ConingMethod::Fitted, Some(f)) => Self::fitted(n, f, f.spec().passband_hz),
        }
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
        for p in 1..len {
            fact *= p as f64;
            if p % 2 == 0 {
                s[p] = if (p / 2) % 2 == 1 { 2.0 / fact } else { -2.0 / fact };
            }
        }
        let f2s = series_mul(&f2, &s, len);
        let rhs_series: Vec<f64> = {
            // (n l - sin n l)/2
            let sn = sin_series(n as f64, len);
            (0..len)
                .map(|p| {
                    let lin = if p == 1 { n as f64 } else { 0.0 };
                    (lin - sn[p]) / 2.0
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

    /// Least-squares fit of the relative coning error over `(0, f_max_hz]`, with the `lambda^3`
    /// term held exact (the error goes to zero at DC).
    pub fn fitted(n: usize, fir: &Fir, f_max_hz: f64) -> Self {
        assert!(valid_n(n), "n must be 2..=5");
        let lmax = 2.0 * std::f64::consts::PI * f_max_hz / fir.spec().fs_hz;
        let m = n - 1;
        let grid = 400;
        // with one coefficient (n = 2) the constraint would leave nothing to fit
        let constrained = m > 1;
        // constraint: sum_j k_j j F(0)^2 = n^3/12 (the lambda^3 coefficient; F(0) = 1)
        let c: Vec<f64> = (1..=m).map(|j| j as f64).collect();
        let c0 = (n * n * n) as f64 / 12.0;
        // KKT system [A^T A  c; c^T 0]
        let mut kkt = DMatrix::<f64>::zeros(m + 1, m + 1);
        let mut rhs = DVector::<f64>::zeros(m + 1);
        for i in 1..=grid {
            let l = lmax * i as f64 / grid as f64;
            let t = true_coning(n, l);
            let row: Vec<f64> = (1..=m).map(|j| basis(Some(fir), j, l) / t).collect();
            for r in 0..m {
                rhs[r] += row[r];
                for cc in 0..m {
                    kkt[(r, cc)] += row[r] * row[cc];
                }
            }
        }
        if constrained {
            for r in 0..m {
                kkt[(r, m)] = c[r];
                kkt[(m, r)] = c[r];
            }
            rhs[m] = c0;
        } else {
            kkt[(m, m)] = 1.0;
        }
        let sol = kkt.lu().solve(&rhs).expect("fit system is regular");
        Self {
            n,
            k: sol.iter().take(m).cloned().collect(),
        }
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
        est - true_coning(self.n, lambda)
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
            let f = ConingCoefficients::fitted(n, &fir, 100.0);
            for hz in [10.0, 80.0] {
                let e = |k: &ConingCoefficients| k.coning_error(Some(&fir), lam(hz)).abs();
                let (ec, et, ef) = (e(&c), e(&t), e(&f));
                if n == 2 {
                    // one coefficient, pinned by the lambda^3 term: F(0) = 1 gives back 2/3;
                    // the unconstrained fit trades low frequencies for high ones
                    assert!((t.k[0] - 2.0 / 3.0).abs() < 1e-12);
                    if hz > 50.0 {
                        assert!(ef < ec, "n={n} {hz} Hz fitted {ef} classical {ec}");
                    }
                } else {
                    // the Taylor set is only good at low frequency (its truncation error grows
                    // fast: at 80 Hz it can be worse than classical, as paper 000 notes)
                    if hz < 50.0 {
                        assert!(et < ec, "n={n} {hz} Hz taylor {et} classical {ec}");
                    }
                    assert!(ef < ec, "n={n} {hz} Hz fitted {ef} classical {ec}");
                }
            }
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
