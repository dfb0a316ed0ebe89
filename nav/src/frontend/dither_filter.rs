//! The dither-demodulation filter: a linear-phase low-pass FIR designed in code.
//!
//! Mechanically dithered RLGs carry their dither (300-430 Hz) in the sampled increments. A
//! symmetric (type I) FIR removes it. The specification is paper 000's: fs = 2 kHz, passband to
//! 100 Hz within +-0.1 dB, at least 40 dB of attenuation from 300 Hz.
//!
//! ## Why order 22 and not the paper's 20
//! No linear-phase FIR of order 20 (21 taps) meets that specification: the Chebyshev (minimax)
//! optimum for 21 taps is +-0.104 dB with 39.75 dB (Parks-McClellan, `scipy.signal.remez`),
//! and with the DC gain held at exactly 1, which a navigation system needs, it is +-0.12 dB with
//! 38.4 dB (linear programming; this module's design reaches the same). Order 22 is the lowest
//! that meets it with unit DC gain: +-0.09 dB, 40.8 dB, delay 11 samples (5.5 ms). An order-20
//! filter can still be configured with a relaxed specification (`FirSpec`).
//!
//! Design: weighted least squares on the zero-phase amplitude
//! `A(w) = a0 + sum_k a_k cos(k w)`, followed by Lawson's iteratively re-weighted least squares,
//! which converges towards the minimax (equiripple) solution. The taps are finally scaled so the
//! DC gain is exactly 1: the filtered increments then sum to the raw ones (no angle is created
//! or lost by the filter, only delayed by `order / 2` samples).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// What the filter must do.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct FirSpec {
    /// Filter order (taps - 1); even, so the delay is a whole number of samples.
    pub order: usize,
    /// Sample rate, Hz.
    pub fs_hz: f64,
    /// Passband edge, Hz.
    pub passband_hz: f64,
    /// Stopband edge, Hz.
    pub stopband_hz: f64,
    /// Largest passband deviation allowed, dB.
    pub ripple_db: f64,
    /// Smallest stopband attenuation allowed, dB.
    pub attenuation_db: f64,
}

impl Default for FirSpec {
    fn default() -> Self {
        Self {
            order: 22,
            fs_hz: wire::IMU_RATE_HZ,
            passband_hz: 100.0,
            stopband_hz: 300.0,
            ripple_db: 0.1,
            attenuation_db: 40.0,
        }
    }
}

/// Why a filter could not be designed.
#[derive(Debug, Clone, Error, PartialEq)]
pub enum FirError {
    /// The specification itself is inconsistent.
    #[error("invalid FIR specification: {0}")]
    BadSpec(String),
    /// The design does not meet the specification.
    #[error(
        "FIR of order {order} cannot meet the specification: passband deviation {ripple_db:.3} dB (allowed {allowed_ripple_db}), stopband attenuation {attenuation_db:.1} dB (required {required_db})"
    )]
    NotMet {
        /// Order tried.
        order: usize,
        /// Passband deviation reached, dB.
        ripple_db: f64,
        /// Allowed deviation, dB.
        allowed_ripple_db: f64,
        /// Attenuation reached, dB.
        attenuation_db: f64,
        /// Attenuation required, dB.
        required_db: f64,
    },
}

/// Measured response of a designed filter.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct FirResponse {
    /// Largest |20 log10 A(f)| over the passband, dB.
    pub passband_deviation_db: f64,
    /// Smallest -20 log10 |A(f)| over the stopband, dB.
    pub stopband_attenuation_db: f64,
    /// Group delay, samples.
    pub delay_samples: usize,
}

/// A designed linear-phase FIR.
#[derive(Debug, Clone, PartialEq)]
pub struct Fir {
    spec: FirSpec,
    taps: Vec<f64>,
}

const GRID: usize = 600;
const LAWSON_ITERATIONS: usize = 1000;
/// Multiply-adds the re-weighting may spend (grid x coefficients^2 per iteration): high orders
/// get fewer iterations (at least 20) so that a config with a 400th-order filter is checked in a
/// fraction of a second instead of ten (found by `hil fuzz`); the default order 22 keeps all
/// 1000.
const LAWSON_BUDGET: usize = 100_000_000;

/// The taps of `design(FirSpec::default())`, as IEEE-754 bits.
const DEFAULT_TAPS: [u64; 23] = [
    0x3F783E83E984C712,
    0x3F444955A5C58153,
    0xBF792B32ADE6F12E,
    0xBF9074F86007AC83,
    0xBF98447571044375,
    0xBF95AA39F855ADB0,
    0xBF57DF6298FC8EFE,
    0x3FA33A694F099CD5,
    0x3FB7329F45D24D10,
    0x3FC2A0EDC72180EE,
    0x3FC7F0C8B471F038,
    0x3FC9EB5ED938F37F,
    0x3FC7F0C8B471F038,
    0x3FC2A0EDC72180EE,
    0x3FB7329F45D24D10,
    0x3FA33A694F099CD5,
    0xBF57DF6298FC8EFE,
    0xBF95AA39F855ADB0,
    0xBF98447571044375,
    0xBF9074F86007AC83,
    0xBF792B32ADE6F12E,
    0x3F444955A5C58153,
    0x3F783E83E984C712,
];

/// The design's spec is one a filter can meet: an even order, and the bands in order below
/// the Nyquist frequency.
fn check_spec(spec: &FirSpec) -> Result<(), FirError> {
    if spec.order == 0 || !spec.order.is_multiple_of(2) || spec.order > 400 {
        return Err(FirError::BadSpec(format!(
            "order must be even and in 2..=400, got {}",
            spec.order
        )));
    }
    let nyq = spec.fs_hz / 2.0;
    if !(spec.fs_hz > 0.0
        && spec.passband_hz > 0.0
        && spec.passband_hz < spec.stopband_hz
        && spec.stopband_hz < nyq)
    {
        return Err(FirError::BadSpec(format!(
            "need 0 < passband ({} Hz) < stopband ({} Hz) < fs/2 ({nyq} Hz)",
            spec.passband_hz, spec.stopband_hz
        )));
    }
    Ok(())
}

/// The design's grid over the pass and stop bands (the transition band is free): (frequency,
/// rad/sample; desired gain; base weight).
fn band_grid(spec: &FirSpec) -> Vec<(f64, f64, f64)> {
    let nyq = spec.fs_hz / 2.0;
    let wp = std::f64::consts::PI * spec.passband_hz / nyq;
    let ws = std::f64::consts::PI * spec.stopband_hz / nyq;
    // grid over the pass and stop bands (the transition band is free)
    let mut pts: Vec<(f64, f64, f64)> = Vec::with_capacity(GRID);
    let np = GRID / 3;
    for i in 0..=np {
        pts.push((wp * i as f64 / np as f64, 1.0, 1.0));
    }
    let ns = GRID - np;
    // the stopband tolerance is ~10x looser than the passband one in linear terms
    let dp = 1.0 - 10f64.powf(-spec.ripple_db / 20.0);
    let ds = 10f64.powf(-spec.attenuation_db / 20.0);
    let ws_weight = dp / ds;
    for i in 0..=ns {
        let w = ws + (std::f64::consts::PI - ws) * i as f64 / ns as f64;
        pts.push((w, 0.0, ws_weight));
    }
    pts
}

impl Fir {
    /// Design the filter and check it against its specification. Designs are remembered per
    /// specification for the life of the process (a design costs tens of milliseconds, and
    /// config validation, the processing chain and in-process runs all ask for the same one).
    pub fn design(spec: FirSpec) -> Result<Self, FirError> {
        static CACHE: std::sync::Mutex<Vec<(FirSpec, Result<Fir, FirError>)>> =
            std::sync::Mutex::new(Vec::new());
        if spec == FirSpec::default() {
            // the design of the default specification, worked out in advance (a unit test
            // checks it against the design to the last bit): on an emulated CPU a design takes
            // seconds, and every process that navigates asks for this one
            return Ok(Self {
                spec,
                taps: DEFAULT_TAPS.iter().map(|b| f64::from_bits(*b)).collect(),
            });
        }
        let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, r)) = cache.iter().find(|(s, _)| *s == spec) {
            return r.clone();
        }
        let r = Self::design_uncached(spec);
        cache.push((spec, r.clone()));
        r
    }

    fn design_uncached(spec: FirSpec) -> Result<Self, FirError> {
        check_spec(&spec)?;
        let m = spec.order / 2;
        let pts = band_grid(&spec);
        // A(w) = 1 + sum_{k=1..m} a_k (cos(k w) - 1): the DC gain is exactly 1 by construction,
        // which keeps the filter from creating or losing angle.
        let basis = |w: f64, k: usize| ((k + 1) as f64 * w).cos() - 1.0;
        let rows: Vec<Vec<f64>> = pts
            .iter()
            .map(|&(w, _, _)| (0..m).map(|k| basis(w, k)).collect())
            .collect();
        let mut lawson = vec![1.0; pts.len()];
        let mut a = DVector::<f64>::zeros(m);
        let mut last_max = f64::INFINITY;
        let iterations =
            LAWSON_ITERATIONS.min((LAWSON_BUDGET / (pts.len() * m * m).max(1)).max(20));
        for _ in 0..iterations {
            let mut ata = DMatrix::<f64>::zeros(m, m);
            let mut atb = DVector::<f64>::zeros(m);
            for (j, &(_, d, bw)) in pts.iter().enumerate() {
                let wt = bw * bw * lawson[j];
                let row = &rows[j];
                for r in 0..m {
                    atb[r] += wt * row[r] * (d - 1.0);
                    for c in r..m {
                        ata[(r, c)] += wt * row[r] * row[c];
                    }
                }
            }
            for r in 0..m {
                for c in 0..r {
                    ata[(r, c)] = ata[(c, r)];
                }
            }
            let Some(sol) = ata.lu().solve(&atb) else {
                return Err(FirError::BadSpec("singular design system".into()));
            };
            a = sol;
            // Lawson update: weight ~ weight * |weighted error|
            let errs: Vec<f64> = pts
                .iter()
                .zip(&rows)
                .map(|(&(_, d, bw), row)| {
                    let v: f64 = 1.0 + row.iter().zip(a.iter()).map(|(b, x)| b * x).sum::<f64>();
                    bw * (v - d).abs()
                })
                .collect();
            let max = errs.iter().cloned().fold(0.0, f64::max);
            if (last_max - max).abs() <= 1e-7 * max {
                break; // converged to the equiripple solution
            }
            last_max = max;
            let s: f64 = lawson.iter().zip(&errs).map(|(l, e)| l * e).sum();
            if s <= 0.0 {
                break;
            }
            for (l, e) in lawson.iter_mut().zip(&errs) {
                *l = *l * e / s * pts.len() as f64;
            }
        }
        // taps from the cosine coefficients: a_k (cos(kw) - 1) puts a_k/2 at +-k, -a_k at 0
        let mut taps = vec![0.0; spec.order + 1];
        taps[m] = 1.0;
        for k in 1..=m {
            taps[m - k] = a[k - 1] / 2.0;
            taps[m + k] = a[k - 1] / 2.0;
            taps[m] -= a[k - 1];
        }
        let fir = Self { spec, taps };
        let r = fir.response();
        if r.passband_deviation_db > spec.ripple_db
            || r.stopband_attenuation_db < spec.attenuation_db
        {
            return Err(FirError::NotMet {
                order: spec.order,
                ripple_db: r.passband_deviation_db,
                allowed_ripple_db: spec.ripple_db,
                attenuation_db: r.stopband_attenuation_db,
                required_db: spec.attenuation_db,
            });
        }
        Ok(fir)
    }

    /// The default dither-demodulation filter (paper 000's specification, order 22).
    pub fn default_dither_filter() -> Self {
        Self::design(FirSpec::default()).expect("the default FIR specification is met")
    }

    /// The specification it was designed to.
    pub fn spec(&self) -> &FirSpec {
        &self.spec
    }

    /// Filter taps (symmetric, summing to 1).
    pub fn taps(&self) -> &[f64] {
        &self.taps
    }

    /// Group delay, samples.
    pub fn delay(&self) -> usize {
        self.spec.order / 2
    }

    /// Zero-phase amplitude `A(f)` (real, may be negative in the stopband).
    pub fn amplitude(&self, f_hz: f64) -> f64 {
        let w = 2.0 * std::f64::consts::PI * f_hz / self.spec.fs_hz;
        self.amplitude_w(w)
    }

    /// Zero-phase amplitude at normalised frequency `w` (rad/sample).
    pub fn amplitude_w(&self, w: f64) -> f64 {
        let m = self.delay();
        self.taps[m]
            + (1..=m)
                .map(|k| 2.0 * self.taps[m + k] * (k as f64 * w).cos())
                .sum::<f64>()
    }

    /// `1 - A(w)`, computed without cancellation (`4 sum h_k sin^2(k w / 2)`, as the taps sum
    /// to 1).
    pub fn droop_w(&self, w: f64) -> f64 {
        let m = self.delay();
        (1..=m)
            .map(|k| 4.0 * self.taps[m + k] * (k as f64 * w / 2.0).sin().powi(2))
            .sum()
    }

    /// Even Taylor coefficients of the amplitude in `w`: `A(w) = sum_j c[j] w^(2j)`.
    pub fn amplitude_taylor(&self, terms: usize) -> Vec<f64> {
        let m = self.delay();
        let mut c = vec![0.0; terms];
        let mut fact = 1.0; // (2j)!
        for (j, cj) in c.iter_mut().enumerate() {
            if j > 0 {
                fact *= (2 * j - 1) as f64 * (2 * j) as f64;
            }
            let sign = if j % 2 == 0 { 1.0 } else { -1.0 };
            let mut s = if j == 0 { self.taps[m] } else { 0.0 };
            for k in 1..=m {
                s += 2.0 * self.taps[m + k] * (k as f64).powi(2 * j as i32);
            }
            *cj = sign * s / fact;
        }
        c
    }

    /// Measure the response on a fine grid over both bands.
    pub fn response(&self) -> FirResponse {
        let n = 4000;
        let mut dev: f64 = 0.0;
        for i in 0..=n {
            let f = self.spec.passband_hz * i as f64 / n as f64;
            let a = self.amplitude(f);
            dev = dev.max((20.0 * a.abs().log10()).abs());
        }
        let nyq = self.spec.fs_hz / 2.0;
        let mut att = f64::INFINITY;
        for i in 0..=n {
            let f = self.spec.stopband_hz + (nyq - self.spec.stopband_hz) * i as f64 / n as f64;
            let a = self.amplitude(f).abs().max(1e-300);
            att = att.min(-20.0 * a.log10());
        }
        FirResponse {
            passband_deviation_db: dev,
            stopband_attenuation_db: att,
            delay_samples: self.delay(),
        }
    }
}

/// A streaming bank of identical FIRs over `N` channels (e.g. 3 gyros + 3 accelerometers).
#[derive(Debug, Clone)]
pub struct FirBank<const N: usize> {
    half: Vec<f64>,
    hist: Vec<[f64; N]>,
    pos: usize,
    filled: usize,
}

impl<const N: usize> FirBank<N> {
    /// A bank running `fir`, with empty (zero) history.
    pub fn new(fir: &Fir) -> Self {
        let len = fir.taps.len();
        Self {
            half: fir.taps[..=fir.delay()].to_vec(),
            hist: vec![[0.0; N]; len],
            pos: 0,
            filled: 0,
        }
    }

    /// Inputs consumed so far (saturates at the filter length).
    pub fn filled(&self) -> usize {
        self.filled
    }

    /// Filter length (taps).
    pub fn len(&self) -> usize {
        self.hist.len()
    }

    /// Always false: a filter has at least one tap.
    pub fn is_empty(&self) -> bool {
        self.hist.is_empty()
    }

    /// Push one input vector, get the filtered output (delayed by the group delay).
    #[inline]
    pub fn push(&mut self, x: [f64; N]) -> [f64; N] {
        let len = self.hist.len();
        self.hist[self.pos] = x;
        self.filled = (self.filled + 1).min(len);
        let m = self.half.len() - 1;
        let newest = self.pos;
        self.pos = (self.pos + 1) % len;
        let at = |age: usize| (newest + len - age) % len;
        let mut y = [0.0; N];
        // symmetric taps: pair the samples `age` and `len-1-age`
        for age in 0..m {
            let (p, q) = (&self.hist[at(age)], &self.hist[at(len - 1 - age)]);
            let h = self.half[age];
            for c in 0..N {
                y[c] += h * (p[c] + q[c]);
            }
        }
        let mid = &self.hist[at(m)];
        for c in 0..N {
            y[c] += self.half[m] * mid[c];
        }
        y
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_default_design_worked_out_in_advance_is_the_design_to_the_last_bit() {
        let designed = Fir::design_uncached(FirSpec::default()).unwrap();
        let kept = Fir::design(FirSpec::default()).unwrap();
        let bits = |f: &Fir| f.taps.iter().map(|t| t.to_bits()).collect::<Vec<_>>();
        assert_eq!(
            bits(&designed),
            bits(&kept),
            "the design changed: put its new taps in DEFAULT_TAPS"
        );
    }

    use super::*;

    #[test]
    fn default_filter_meets_paper_000_specification() {
        let fir = Fir::default_dither_filter();
        let r = fir.response();
        assert_eq!(fir.taps().len(), 23);
        assert!(r.passband_deviation_db <= 0.1, "{r:?}");
        assert!(r.stopband_attenuation_db >= 40.0, "{r:?}");
        assert_eq!(r.delay_samples, 11);
        // independent measurement: drive sinusoids through the streaming filter
        let measure = |f: f64| {
            let mut bank = FirBank::<1>::new(&fir);
            let mut peak: f64 = 0.0;
            for k in 0..4000 {
                let y = bank.push([(2.0 * std::f64::consts::PI * f * k as f64 / 2000.0).sin()]);
                if k > 100 {
                    peak = peak.max(y[0].abs());
                }
            }
            20.0 * peak.log10()
        };
        for f in [1.0, 20.0, 50.0, 80.0, 100.0] {
            let g = measure(f);
            assert!(g.abs() <= 0.1 + 1e-3, "{f} Hz: {g} dB");
        }
        for f in [300.0, 330.0, 370.0, 400.0, 430.0, 600.0, 990.0] {
            let g = measure(f);
            assert!(g <= -40.0 + 1e-3, "{f} Hz: {g} dB");
        }
    }

    #[test]
    fn dc_gain_is_exactly_one_so_no_angle_is_lost() {
        let fir = Fir::default_dither_filter();
        let s: f64 = fir.taps().iter().sum();
        assert!((s - 1.0).abs() < 1e-14);
        let mut bank = FirBank::<3>::new(&fir);
        let (mut sin, mut sout) = (0.0, 0.0);
        for k in 0..1000 {
            let x = (k as f64 * 0.37).sin() + 0.2;
            sin += x;
            sout += bank.push([x, 0.0, 0.0])[0];
        }
        for _ in 0..fir.delay() * 2 {
            sout += bank.push([0.0; 3])[0];
        }
        assert!((sin - sout).abs() < 1e-9, "{sin} vs {sout}");
    }

    #[test]
    fn taylor_series_matches_the_amplitude_at_low_frequency() {
        let fir = Fir::default_dither_filter();
        let c = fir.amplitude_taylor(12);
        for w in [0.01f64, 0.05, 0.1] {
            let t: f64 = c
                .iter()
                .enumerate()
                .map(|(j, cj)| cj * w.powi(2 * j as i32))
                .sum();
            assert!((t - fir.amplitude_w(w)).abs() < 1e-9, "w {w}");
        }
    }

    #[test]
    fn impossible_specifications_are_refused_with_the_reason() {
        // order 20 cannot meet +-0.1 dB / 40 dB with unit DC gain (the minimax bound)
        let e = Fir::design(FirSpec {
            order: 20,
            ..FirSpec::default()
        })
        .unwrap_err();
        assert!(matches!(e, FirError::NotMet { order: 20, .. }), "{e}");
        // ... but meets a relaxed stopband
        let f20 = Fir::design(FirSpec {
            order: 20,
            ripple_db: 0.125,
            attenuation_db: 38.0,
            ..FirSpec::default()
        })
        .unwrap();
        assert_eq!(f20.delay(), 10);
        let e = Fir::design(FirSpec {
            order: 21,
            ..FirSpec::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("even"), "{e}");
        let e = Fir::design(FirSpec {
            stopband_hz: 50.0,
            ..FirSpec::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("passband"), "{e}");
    }
}
