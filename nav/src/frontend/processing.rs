//! The IMU processing chain after the front end: dither-demodulation FIR, coning and sculling
//! compensation over `n` sub-samples, and the attitude update (rotation vector -> quaternion).
//!
//! The attitude kept here is the body attitude relative to the body at the first sample, in
//! inertial space; the navigation frame update (earth and transport rate) uses the per-interval
//! rotation vectors and velocity increments this produces.
//!
//! Irregular input never becomes a silent angle error:
//! * a span of several samples (frames lost in between) carries the whole angle of the span,
//!   which is spread evenly over the missing samples, so the total angle is kept;
//! * an ambiguous span (too long to difference the counters) loses angle: the attitude is marked
//!   invalid from that sample on, counted and reported;
//! * saturated and BIT-failed samples are integrated but counted as suspect with the first
//!   sample number, and reported.

use crate::frontend::coning::{ConingCoefficients, ConingMethod};
use crate::frontend::dither_filter::{Fir, FirBank, FirError, FirResponse, FirSpec};
use crate::frontend::imu_frames::ImuSample;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Processing options (the `[processing]` table of the config file).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ProcessingConfig {
    /// Run the dither-demodulation FIR (off only for IMUs without mechanical dither).
    pub dither_filter: bool,
    /// The FIR's specification.
    pub fir: FirSpec,
    /// Sub-samples per attitude update (2..=5).
    pub coning_samples: usize,
    /// Coefficient set.
    pub coning: ConingMethod,
}

impl Default for ProcessingConfig {
    fn default() -> Self {
        Self {
            dither_filter: true,
            fir: FirSpec::default(),
            coning_samples: 4,
            coning: ConingMethod::Fitted,
        }
    }
}

/// One attitude/velocity update interval.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Update {
    /// The input sample at the end of the interval, minus the filter delay: the sample whose
    /// time this update is valid at.
    pub valid_sample: i64,
    /// Rotation vector over the interval (coning compensated), rad, body axes.
    pub phi: [f64; 3],
    /// Velocity increment over the interval (rotation and sculling compensated), m/s, body axes
    /// at the start of the interval.
    pub dv: [f64; 3],
}

/// Integrity counters of the chain.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
pub struct ProcessingStats {
    /// Samples pushed (including those filled in across gaps).
    pub samples: u64,
    /// Samples filled in evenly across gaps (their angle came with the next sample).
    pub filled_samples: u64,
    /// Samples whose angle was unknown (ambiguous span): the attitude is invalid after them.
    pub lost_samples: u64,
    /// Saturated or BIT-failed samples integrated.
    pub suspect_samples: u64,
    /// First suspect sample.
    pub first_suspect: Option<u64>,
    /// First sample whose angle was lost.
    pub invalid_since: Option<u64>,
    /// Attitude updates made.
    pub updates: u64,
}

/// The chain.
#[derive(Debug)]
pub struct ImuProcessor {
    fir: Option<FirBank<6>>,
    fir_response: Option<FirResponse>,
    delay: i64,
    coeffs: ConingCoefficients,
    th: [[f64; 3]; 5],
    dv: [[f64; 3]; 5],
    fill: usize,
    q: UnitQuaternion<f64>,
    baseline: Option<u64>,
    origin: Option<i64>,
    last: u64,
    valid_at: i64,
    stats: ProcessingStats,
}

impl ImuProcessor {
    /// A chain with this configuration.
    pub fn new(cfg: &ProcessingConfig) -> Result<Self, FirError> {
        if !crate::frontend::coning::valid_n(cfg.coning_samples) {
            return Err(FirError::BadSpec(format!(
                "coning_samples must be 2..=5, got {}",
                cfg.coning_samples
            )));
        }
        let fir = if cfg.dither_filter {
            Some(Fir::design(cfg.fir)?)
        } else {
            None
        };
        let coeffs = ConingCoefficients::for_method(cfg.coning, cfg.coning_samples, fir.as_ref())?;
        Ok(Self::with(fir.as_ref(), coeffs))
    }

    /// A chain with an explicit filter (or none) and coefficient set.
    pub fn with(fir: Option<&Fir>, coeffs: ConingCoefficients) -> Self {
        Self {
            fir: fir.map(FirBank::new),
            fir_response: fir.map(Fir::response),
            delay: fir.map_or(0, |f| f.delay() as i64),
            coeffs,
            th: [[0.0; 3]; 5],
            dv: [[0.0; 3]; 5],
            fill: 0,
            q: UnitQuaternion::identity(),
            baseline: None,
            origin: None,
            last: 0,
            valid_at: 0,
            stats: ProcessingStats::default(),
        }
    }

    /// The coefficient set in use.
    pub fn coefficients(&self) -> &ConingCoefficients {
        &self.coeffs
    }

    /// The dither filter's measured response (none when the filter is off).
    pub fn fir_response(&self) -> Option<FirResponse> {
        self.fir_response
    }

    /// Filter delay, samples.
    pub fn delay(&self) -> i64 {
        self.delay
    }

    /// Counters.
    pub fn stats(&self) -> ProcessingStats {
        self.stats
    }

    /// Attitude of the body relative to the body at the origin sample (inertial).
    pub fn attitude(&self) -> UnitQuaternion<f64> {
        self.q
    }

    /// The sample before the first input (the front end's baseline), if any.
    pub fn baseline(&self) -> Option<u64> {
        self.baseline
    }

    /// The sample the attitude is counted from: the first one after the filter has filled with
    /// real data (the filter's start-up transient, which would carry the dither angle of the
    /// first sample into the attitude, is not integrated).
    pub fn origin(&self) -> Option<i64> {
        self.origin
    }

    /// The sample the current attitude is valid at (last input minus the filter delay, at the
    /// end of the last complete update).
    pub fn valid_sample(&self) -> i64 {
        self.valid_at
    }

    /// Feed a sample from the IMU front end.
    pub fn push_sample(&mut self, s: &ImuSample, out: &mut Vec<Update>) {
        let span = u64::from(s.span.max(1));
        let first = (s.sample + 1).saturating_sub(span).max(1);
        if self.baseline.is_none() {
            self.baseline = Some(first - 1);
            self.last = first - 1;
        }
        if s.saturated || s.bit_fail {
            self.stats.suspect_samples += span;
            self.stats.first_suspect.get_or_insert(s.sample);
        }
        if s.ambiguous {
            self.stats.lost_samples += span;
            self.stats.invalid_since.get_or_insert(first);
            for k in 0..span {
                self.push_at(first + k, [0.0; 3], [0.0; 3], out);
            }
            return;
        }
        let f = 1.0 / span as f64;
        let th = s.dtheta.map(|x| x * f);
        let dv = s.dv.map(|x| x * f);
        self.stats.filled_samples += span - 1;
        for k in 0..span {
            self.push_at(first + k, th, dv, out);
        }
    }

    /// Feed raw increments of the next sample (no front end: exact data, experiments).
    pub fn push_increment(&mut self, th: [f64; 3], dv: [f64; 3], out: &mut Vec<Update>) {
        self.baseline.get_or_insert(0);
        let k = self.last + 1;
        self.push_at(k, th, dv, out);
    }

    #[inline]
    fn push_at(&mut self, k: u64, th: [f64; 3], dv: [f64; 3], out: &mut Vec<Update>) {
        self.last = k;
        self.stats.samples += 1;
        let (th, dv) = match &mut self.fir {
            Some(b) => {
                let y = b.push([th[0], th[1], th[2], dv[0], dv[1], dv[2]]);
                if b.filled() < b.len() {
                    return; // start-up transient
                }
                ([y[0], y[1], y[2]], [y[3], y[4], y[5]])
            }
            None => (th, dv),
        };
        if self.origin.is_none() {
            let o = k as i64 - 1 - self.delay;
            self.origin = Some(o);
            self.valid_at = o;
        }
        self.th[self.fill] = th;
        self.dv[self.fill] = dv;
        self.fill += 1;
        let n = self.coeffs.n;
        if self.fill < n {
            return;
        }
        self.fill = 0;
        let (ths, dvs) = (&self.th[..n], &self.dv[..n]);
        let mut tt = [0.0; 3];
        let mut vt = [0.0; 3];
        for i in 0..n {
            for a in 0..3 {
                tt[a] += ths[i][a];
                vt[a] += dvs[i][a];
            }
        }
        let c = self.coeffs.coning(ths);
        let s = self.coeffs.sculling(ths, dvs);
        let r = crate::frontend::coning::cross(tt, vt);
        let phi = [tt[0] + c[0], tt[1] + c[1], tt[2] + c[2]];
        let dvc = std::array::from_fn(|a| vt[a] + 0.5 * r[a] + s[a]);
        self.q = rotate(self.q, phi);
        self.valid_at = k as i64 - self.delay;
        self.stats.updates += 1;
        out.push(Update {
            valid_sample: self.valid_at,
            phi,
            dv: dvc,
        });
    }
}

/// `q * exp(phi)`: the attitude update by a rotation vector, renormalised.
#[inline]
pub fn rotate(q: UnitQuaternion<f64>, phi: [f64; 3]) -> UnitQuaternion<f64> {
    q * rotation_vector_to_quaternion(phi)
}

/// Exact quaternion of a rotation vector.
#[inline]
pub fn rotation_vector_to_quaternion(phi: [f64; 3]) -> UnitQuaternion<f64> {
    let p = Vector3::from(phi);
    let a2 = p.norm_squared();
    let a = a2.sqrt();
    // sin(a/2)/a by series near 0
    let (c, s) = if a < 1e-4 {
        (1.0 - a2 / 8.0, 0.5 - a2 / 48.0)
    } else {
        ((a / 2.0).cos(), (a / 2.0).sin() / a)
    };
    UnitQuaternion::new_unchecked(Quaternion::new(c, s * p.x, s * p.y, s * p.z))
}

/// Rotation vector of a quaternion (the shorter way round), rad.
pub fn quaternion_to_rotation_vector(q: &UnitQuaternion<f64>) -> [f64; 3] {
    let v = q.scaled_axis();
    [v.x, v.y, v.z]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frontend::coning::ConingMethod;
    use crate::frontend::coning::classical;

    /// Exact increments of classical coning (half-angle a, rate w) over (t0, t1].
    fn cone(a: f64, w: f64, t0: f64, t1: f64) -> [f64; 3] {
        [
            -2.0 * w * (a / 2.0).sin().powi(2) * (t1 - t0),
            a.sin() * ((w * t1).cos() - (w * t0).cos()),
            a.sin() * ((w * t1).sin() - (w * t0).sin()),
        ]
    }

    fn cone_truth(a: f64, w: f64, t: f64) -> UnitQuaternion<f64> {
        let s = (a / 2.0).sin();
        UnitQuaternion::new_normalize(Quaternion::new(
            (a / 2.0).cos(),
            0.0,
            s * (w * t).cos(),
            s * (w * t).sin(),
        ))
    }

    #[test]
    fn classical_coning_without_filter_tracks_the_true_attitude() {
        let (a, f) = (1f64.to_radians(), 10.0);
        let w = 2.0 * std::f64::consts::PI * f;
        let dt = 1.0 / 2000.0;
        let mut p = ImuProcessor::with(None, classical(4));
        let mut out = Vec::new();
        let n = 20_000;
        for k in 0..n {
            p.push_increment(
                cone(a, w, k as f64 * dt, (k + 1) as f64 * dt),
                [0.0; 3],
                &mut out,
            );
        }
        assert_eq!(p.origin(), Some(0));
        let truth = cone_truth(a, w, 0.0).inverse() * cone_truth(a, w, n as f64 * dt);
        let err = quaternion_to_rotation_vector(&(truth.inverse() * p.attitude()));
        let e = Vector3::from(err).norm();
        assert!(e < 1e-10, "error {e:e} rad");
        // without compensation the cone axis drifts visibly
        let mut raw = UnitQuaternion::identity();
        for k in 0..n {
            raw = rotate(raw, cone(a, w, k as f64 * dt, (k + 1) as f64 * dt));
        }
        let e_raw = Vector3::from(quaternion_to_rotation_vector(&(truth.inverse() * raw))).norm();
        assert!(e_raw > 1e-5, "uncompensated error {e_raw:e}");
    }

    #[test]
    fn a_gap_keeps_the_angle_and_an_ambiguous_one_invalidates_the_attitude() {
        let fir = Fir::default_dither_filter();
        let mut p = ImuProcessor::with(Some(&fir), classical(4));
        let mut q = ImuProcessor::with(Some(&fir), classical(4));
        let mut out = Vec::new();
        let rate = [1e-4, -2e-4, 3e-4];
        let mk = |sample: u64, span: u32, ambiguous: bool| ImuSample {
            sample,
            span,
            dtheta: rate.map(|r| r * f64::from(span)),
            dv: [0.0; 3],
            pps_offset: None,
            accel_missing: false,
            ambiguous,
            bit_fail: false,
            saturated: false,
        };
        for k in 1..=400 {
            p.push_sample(&mk(k, 1, false), &mut out);
        }
        // same stream with samples 101..=103 lost: 104 carries a span of 4
        for k in (1..=100).chain(104..=400) {
            let span = if k == 104 { 4 } else { 1 };
            q.push_sample(&mk(k, span, false), &mut out);
        }
        let d = (p.attitude().inverse() * q.attitude()).angle();
        assert!(d < 1e-15, "constant rate: the gap costs nothing ({d:e})");
        assert_eq!(q.stats().filled_samples, 3);
        assert_eq!(q.stats().invalid_since, None);
        q.push_sample(&mk(500, 100, true), &mut out);
        assert_eq!(q.stats().invalid_since, Some(401));
        assert_eq!(q.stats().lost_samples, 100);
    }

    #[test]
    fn rotation_vector_round_trip() {
        for phi in [
            [0.0, 0.0, 0.0],
            [1e-9, 2e-9, -1e-9],
            [0.3, -0.2, 0.1],
            [1e-5, 0.0, 0.0],
        ] {
            let q = rotation_vector_to_quaternion(phi);
            assert!((q.norm() - 1.0).abs() < 1e-15);
            let back = quaternion_to_rotation_vector(&q);
            for i in 0..3 {
                assert!((back[i] - phi[i]).abs() < 1e-15, "{phi:?} -> {back:?}");
            }
        }
    }

    /// Classical sculling: angular oscillation about x in phase with linear acceleration along
    /// y rectifies into a steady velocity along z. On filtered data the coning-tuned coefficients
    /// serve for sculling too (the same condition holds, see the `coning` module).
    fn sculling_z_error(fir: Option<&Fir>, method: ConingMethod, f_hz: f64) -> f64 {
        let (amp, b) = (1f64.to_radians(), 1.0);
        let w = 2.0 * std::f64::consts::PI * f_hz;
        let dt = 1.0 / 2000.0;
        let mut p =
            ImuProcessor::with(fir, ConingCoefficients::for_method(method, 4, fir).unwrap());
        let mut out = Vec::new();
        let mut v = Vector3::zeros();
        let mut q = UnitQuaternion::identity();
        let n = 20_000;
        for k in 0..n {
            let (t0, t1) = (k as f64 * dt, (k + 1) as f64 * dt);
            let th = [amp * ((w * t1).sin() - (w * t0).sin()), 0.0, 0.0];
            let dv = [0.0, b / w * ((w * t0).cos() - (w * t1).cos()), 0.0];
            p.push_increment(th, dv, &mut out);
            for u in out.drain(..) {
                v += q * Vector3::from(u.dv);
                q = rotate(q, u.phi);
            }
        }
        // truth in the frame of the body at the origin: integral of f_y sin(theta - theta_o)
        let (to, tv) = (
            p.origin().unwrap() as f64 * dt,
            p.valid_sample() as f64 * dt,
        );
        let th_o = amp * (w * to).sin();
        let steps = 400_000;
        let h = (tv - to) / steps as f64;
        let g = |t: f64| b * (w * t).sin() * (amp * (w * t).sin() - th_o).sin();
        let mut truth = g(to) + g(tv);
        for i in 1..steps {
            truth += g(to + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        truth *= h / 3.0;
        v.z - truth
    }

    #[test]
    fn sculling_on_filtered_data_needs_the_tuned_coefficients_too() {
        let fir = Fir::default_dither_filter();
        let ideal = sculling_z_error(None, ConingMethod::Classical, 50.0).abs();
        let classical = sculling_z_error(Some(&fir), ConingMethod::Classical, 50.0).abs();
        let fitted = sculling_z_error(Some(&fir), ConingMethod::Fitted, 50.0).abs();
        // 10 s of 1 deg x 1 m/s^2 sculling at 50 Hz rectifies 87 mm/s
        assert!(ideal < 1e-6, "unfiltered classical {ideal:e} m/s");
        assert!(classical > 1e-3, "filtered classical {classical:e} m/s");
        assert!(
            fitted * 50.0 < classical,
            "fitted {fitted:e} vs classical {classical:e} m/s"
        );
    }
}
