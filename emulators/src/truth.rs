//! Truth motion: exact attitude, angular rate and specific force as pure functions of time.
//!
//! Frames: navigation frame ENU (east, north, up); body frame x right, y forward, z up.
//! Heading is clockwise from north, pitch nose up, roll right wing down positive.
//!
//! Every motion gives its attitude `q(t)` (body relative to the motion's reference frame), the
//! body rate w.r.t. inertial space and the specific force, both in body axes. Sensor increments
//! over a sample interval are integrals of those, not rate times dt: analytic where the motion
//! allows (static, classical coning), otherwise 6-point Gauss-Legendre quadrature, which on a
//! 0.5 ms interval is exact to rounding for the smooth motions here (vibration up to a few
//! hundred hertz).
//!
//! Motions compose: [`Composed`] puts a relative rotation (the indexing mechanism's angle,
//! angular vibration) and linear vibration on top of any base motion, so the gyros see every
//! move of the mechanism.

use crate::geodesy as earth;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Exact sensor-frame increments over one interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Increments {
    /// Angle increment of the body w.r.t. inertial space, rad (body axes).
    pub dtheta: Vector3<f64>,
    /// Specific-force velocity increment, m/s (body axes).
    pub dv: Vector3<f64>,
}

/// Gauss-Legendre nodes and weights on [-1, 1], 6 points.
#[allow(clippy::excessive_precision)]
pub(crate) const GL6: [(f64, f64); 6] = [
    (-0.932_469_514_203_152_1, 0.171_324_492_379_170_3),
    (-0.661_209_386_466_264_5, 0.360_761_573_048_138_6),
    (-0.238_619_186_083_196_9, 0.467_913_934_572_691_0),
    (0.238_619_186_083_196_9, 0.467_913_934_572_691_0),
    (0.661_209_386_466_264_5, 0.360_761_573_048_138_6),
    (0.932_469_514_203_152_1, 0.171_324_492_379_170_3),
];

/// A motion the IMU undergoes.
pub trait Motion: Send {
    /// Body rate w.r.t. inertial space at `t`, rad/s, body axes.
    fn omega_ib_b(&self, t: f64) -> Vector3<f64>;
    /// Specific force at `t`, m/s^2, body axes.
    fn f_b(&self, t: f64) -> Vector3<f64>;
    /// Attitude at `t`: body relative to the motion's reference frame.
    fn attitude(&self, t: f64) -> UnitQuaternion<f64>;
    /// Attitude at `t` relative to inertial space (the frame the gyros integrate in). Equal to
    /// [`Motion::attitude`] for motions whose reference frame is inertial.
    fn inertial_attitude(&self, t: f64) -> UnitQuaternion<f64> {
        self.attitude(t)
    }
    /// Geodetic latitude (rad) at `t`.
    fn latitude(&self, t: f64) -> f64;
    /// Body rate and specific force at `t` together (motions override it to share the work the
    /// two have in common: one attitude chain, one trajectory lookup).
    fn rate_and_force(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        (self.omega_ib_b(t), self.f_b(t))
    }
    /// Exact increments over `(t0, t1]` (default: Gauss-Legendre quadrature of rate and force).
    fn increments(&self, t0: f64, t1: f64) -> Increments {
        gauss_legendre(t0, t1, |t| self.rate_and_force(t))
    }
}

/// Below this (rad) a decaying motion is over: its rate then moves an increment by less than
/// rounding (1e-12 rad decaying over a 0.08 s settle is 1e-11 rad/s, 6e-15 rad per sample).
pub const STILL_RAD: f64 = 1e-12;

/// 3-point Gauss-Legendre quadrature over `(t0, t1]`: exact for polynomials to degree 5, so to
/// rounding for motions whose rate and force are smooth and slow beside the sample interval
/// (a vehicle's speed and heading), when no corner of the motion falls inside the interval.
pub fn gauss_legendre3(
    t0: f64,
    t1: f64,
    f: impl Fn(f64) -> (Vector3<f64>, Vector3<f64>),
) -> Increments {
    #[allow(clippy::excessive_precision)]
    const X: f64 = 0.774_596_669_241_483_4;
    let (c, h) = ((t0 + t1) / 2.0, (t1 - t0) / 2.0);
    let mut dtheta = Vector3::zeros();
    let mut dv = Vector3::zeros();
    for (x, w) in [(-X, 5.0 / 9.0), (0.0, 8.0 / 9.0), (X, 5.0 / 9.0)] {
        let (r, a) = f(c + h * x);
        dtheta += r * (w * h);
        dv += a * (w * h);
    }
    Increments { dtheta, dv }
}

/// 6-point Gauss-Legendre quadrature over `(t0, t1]` of a rate and a force given together.
pub fn gauss_legendre(
    t0: f64,
    t1: f64,
    f: impl Fn(f64) -> (Vector3<f64>, Vector3<f64>),
) -> Increments {
    let (c, h) = ((t0 + t1) / 2.0, (t1 - t0) / 2.0);
    let mut dtheta = Vector3::zeros();
    let mut dv = Vector3::zeros();
    for (x, w) in GL6 {
        let (r, a) = f(c + h * x);
        dtheta += r * (w * h);
        dv += a * (w * h);
    }
    Increments { dtheta, dv }
}

/// [`gauss_legendre3`] over `(t0, t1]` on a planned motion, split where its plan has a corner
/// (a step in a rate's derivative): at `next_start`, the start of the plan's next piece after
/// `t0`, or, past its last piece, at the plan's `end`. Each half is then smooth, so exact.
pub fn gauss_legendre3_split(
    t0: f64,
    t1: f64,
    next_start: Option<f64>,
    end: f64,
    f: impl Fn(f64) -> (Vector3<f64>, Vector3<f64>),
) -> Increments {
    let corner = next_start.or_else(|| (t0 < end).then_some(end));
    match corner.filter(|&c| c < t1) {
        Some(c) => {
            let (a, b) = (gauss_legendre3(t0, c, &f), gauss_legendre3(c, t1, &f));
            Increments {
                dtheta: a.dtheta + b.dtheta,
                dv: a.dv + b.dv,
            }
        }
        None => gauss_legendre3(t0, t1, f),
    }
}

/// [`gauss_legendre3`] over `(t0, t1]` split at every one of `cuts` (in increasing order) that
/// falls inside it: a plan's corners (steps in a rate's derivative), however many one sample
/// interval holds (a change of speed can be shorter than a sample). Each piece is then smooth,
/// so exact; with one cut it is [`gauss_legendre3_split`]'s sum, bit for bit.
pub fn gauss_legendre3_pieces(
    t0: f64,
    t1: f64,
    cuts: impl IntoIterator<Item = f64>,
    f: impl Fn(f64) -> (Vector3<f64>, Vector3<f64>),
) -> Increments {
    let mut a = t0;
    let mut sum: Option<Increments> = None;
    for c in cuts {
        if c <= a {
            continue;
        }
        if c >= t1 {
            break;
        }
        let piece = gauss_legendre3(a, c, &f);
        sum = Some(match sum {
            None => piece,
            Some(s) => Increments {
                dtheta: s.dtheta + piece.dtheta,
                dv: s.dv + piece.dv,
            },
        });
        a = c;
    }
    let last = gauss_legendre3(a, t1, &f);
    match sum {
        None => last,
        Some(s) => Increments {
            dtheta: s.dtheta + last.dtheta,
            dv: s.dv + last.dv,
        },
    }
}

/// The body's attitude relative to inertial space at `t` from its attitude `q_bn` relative to
/// ENU at latitude `lat` and longitude `lon` (rad): inertial <- earth (the earth's rotation
/// since 0) <- ENU <- body.
pub fn inertial_from_enu(
    lat: f64,
    lon: f64,
    t: f64,
    q_bn: UnitQuaternion<f64>,
) -> UnitQuaternion<f64> {
    let q_ie = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), earth::OMEGA * t);
    let q_en = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), lon + PI / 2.0)
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI / 2.0 - lat);
    q_ie * q_en * q_bn
}

/// Body-to-ENU rotation for heading, pitch, roll (rad).
pub fn c_b_n(heading: f64, pitch: f64, roll: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::z_axis(), -heading)
        * Rotation3::from_axis_angle(&Vector3::x_axis(), pitch)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), roll)
}

/// A vehicle parked on the ground: earth rate and gravity only.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Static {
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    #[serde(default)]
    pub lon_deg: f64,
    /// Height, m.
    #[serde(default)]
    pub height_m: f64,
    /// Heading, deg.
    #[serde(default)]
    pub heading_deg: f64,
    /// Pitch, deg.
    #[serde(default)]
    pub pitch_deg: f64,
    /// Roll, deg.
    #[serde(default)]
    pub roll_deg: f64,
}

impl Static {
    /// A level site at latitude `lat_deg`, facing north, at sea level on the prime meridian (a
    /// lab's table).
    pub fn level(lat_deg: f64) -> Self {
        Self {
            lat_deg,
            lon_deg: 0.0,
            height_m: 0.0,
            heading_deg: 0.0,
            pitch_deg: 0.0,
            roll_deg: 0.0,
        }
    }

    fn cbn(&self) -> Rotation3<f64> {
        c_b_n(
            self.heading_deg.to_radians(),
            self.pitch_deg.to_radians(),
            self.roll_deg.to_radians(),
        )
    }

    /// Body angular rate w.r.t. inertial space, rad/s (constant).
    pub fn rate(&self) -> Vector3<f64> {
        self.cbn().inverse() * Vector3::from(earth::earth_rate_enu(self.lat_deg.to_radians()))
    }

    /// Specific force in the body frame, m/s^2 (constant).
    pub fn force(&self) -> Vector3<f64> {
        let g = earth::gravity(self.lat_deg.to_radians(), self.height_m);
        self.cbn().inverse() * Vector3::new(0.0, 0.0, g)
    }
}

impl Motion for Static {
    fn omega_ib_b(&self, _t: f64) -> Vector3<f64> {
        self.rate()
    }
    fn f_b(&self, _t: f64) -> Vector3<f64> {
        self.force()
    }
    fn attitude(&self, _t: f64) -> UnitQuaternion<f64> {
        // body relative to ENU; the ENU frame itself turns with the earth (seen in the rate)
        UnitQuaternion::from_rotation_matrix(&self.cbn())
    }
    fn latitude(&self, _t: f64) -> f64 {
        self.lat_deg.to_radians()
    }
    fn inertial_attitude(&self, t: f64) -> UnitQuaternion<f64> {
        // the body turns with the earth at a constant body rate
        self.attitude(0.0) * UnitQuaternion::from_scaled_axis(self.rate() * t)
    }
    fn increments(&self, t0: f64, t1: f64) -> Increments {
        // constant rate about a fixed axis: the integral is exact
        let dt = t1 - t0;
        Increments {
            dtheta: self.rate() * dt,
            dv: self.force() * dt,
        }
    }
}

/// A [`Static`] site with its constant rate, force and attitude worked out once: the form the
/// IMU's truth uses, since a composed motion asks its base for the rate at every quadrature node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Site {
    spec: Static,
    rate: Vector3<f64>,
    force: Vector3<f64>,
    attitude: UnitQuaternion<f64>,
}

impl Static {
    /// This site with its constants worked out once (the same values [`Static`] computes).
    pub fn site(&self) -> Site {
        Site {
            spec: *self,
            rate: self.rate(),
            force: self.force(),
            attitude: UnitQuaternion::from_rotation_matrix(&self.cbn()),
        }
    }
}

impl Motion for Site {
    fn omega_ib_b(&self, _t: f64) -> Vector3<f64> {
        self.rate
    }
    fn f_b(&self, _t: f64) -> Vector3<f64> {
        self.force
    }
    fn rate_and_force(&self, _t: f64) -> (Vector3<f64>, Vector3<f64>) {
        (self.rate, self.force)
    }
    fn attitude(&self, _t: f64) -> UnitQuaternion<f64> {
        self.attitude
    }
    fn latitude(&self, _t: f64) -> f64 {
        self.spec.lat_deg.to_radians()
    }
    fn inertial_attitude(&self, t: f64) -> UnitQuaternion<f64> {
        self.attitude * UnitQuaternion::from_scaled_axis(self.rate * t)
    }
    fn increments(&self, t0: f64, t1: f64) -> Increments {
        let dt = t1 - t0;
        Increments {
            dtheta: self.rate * dt,
            dv: self.force * dt,
        }
    }
}

/// Classical coning in inertial space (paper 000, eq. 5): the rotation vector from the
/// reference frame is `[0, a cos(W t), a sin(W t)]`; the cone axis is body x.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Coning {
    /// Half-cone angle, deg.
    pub half_angle_deg: f64,
    /// Coning frequency, Hz.
    pub frequency_hz: f64,
}

impl Coning {
    fn a_w(&self) -> (f64, f64) {
        (
            self.half_angle_deg.to_radians(),
            2.0 * PI * self.frequency_hz,
        )
    }
}

impl Motion for Coning {
    fn omega_ib_b(&self, t: f64) -> Vector3<f64> {
        let (a, w) = self.a_w();
        Vector3::new(
            -2.0 * w * (a / 2.0).sin().powi(2),
            -w * a.sin() * (w * t).sin(),
            w * a.sin() * (w * t).cos(),
        )
    }
    fn f_b(&self, _t: f64) -> Vector3<f64> {
        Vector3::zeros()
    }
    fn attitude(&self, t: f64) -> UnitQuaternion<f64> {
        let (a, w) = self.a_w();
        UnitQuaternion::from_scaled_axis(Vector3::new(0.0, a * (w * t).cos(), a * (w * t).sin()))
    }
    fn latitude(&self, _t: f64) -> f64 {
        0.0
    }
    fn increments(&self, t0: f64, t1: f64) -> Increments {
        let (a, w) = self.a_w();
        Increments {
            dtheta: Vector3::new(
                -2.0 * w * (a / 2.0).sin().powi(2) * (t1 - t0),
                a.sin() * ((w * t1).cos() - (w * t0).cos()),
                a.sin() * ((w * t1).sin() - (w * t0).sin()),
            ),
            dv: Vector3::zeros(),
        }
    }
}

/// A rotation of the body relative to its base (an indexing mechanism, angular vibration).
pub trait RelativeRotation: Send {
    /// Rotation of the body relative to the base at `t`.
    fn rotation(&self, t: f64) -> UnitQuaternion<f64>;
    /// Rate of the body relative to the base at `t`, rad/s, body axes.
    fn rate(&self, t: f64) -> Vector3<f64>;
    /// Rotation and rate together (implementations share the work the two have in common).
    fn rotation_and_rate(&self, t: f64) -> (UnitQuaternion<f64>, Vector3<f64>) {
        (self.rotation(t), self.rate(t))
    }
    /// The rotation does not change over `[t0, t1]` (to within [`STILL_RAD`]).
    fn still(&self, _t0: f64, _t1: f64) -> bool {
        false
    }
}

/// Angle of one mechanism axis as a function of time.
pub trait AxisAngle: Send + Sync {
    /// Angle, rad.
    fn angle(&self, t: f64) -> f64;
    /// Rate, rad/s.
    fn rate(&self, t: f64) -> f64;
    /// Angle and rate together.
    fn angle_and_rate(&self, t: f64) -> (f64, f64) {
        (self.angle(t), self.rate(t))
    }
    /// The angle does not change over `[t0, t1]` (to within [`STILL_RAD`]).
    fn still(&self, _t0: f64, _t1: f64) -> bool {
        false
    }
}

/// Constant-rate rotation of an axis (a lab table in rate mode).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstantRate {
    /// Angle at t = 0, rad.
    pub angle0: f64,
    /// Rate, rad/s.
    pub rate: f64,
}

impl AxisAngle for ConstantRate {
    fn angle(&self, t: f64) -> f64 {
        self.angle0 + self.rate * t
    }
    fn rate(&self, _t: f64) -> f64 {
        self.rate
    }
    fn still(&self, _t0: f64, _t1: f64) -> bool {
        self.rate == 0.0
    }
}

/// Continuous rotation that reverses after every revolution (the rotating INS of paper 004:
/// each axis turns one way for a full turn, then back), starting from rest at `t = 0`. Each
/// reversal is a linear change of rate from `+rate` to `-rate` (or back) at `accel`, centred on
/// its midpoint; the angle swings through exactly one turn between reversals, with a period of
/// `2 (360 deg / rate + rate / accel)`. Rate and angle are continuous (quadrature over a sample
/// interval stays exact to rounding away from the reversals' corners).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reversing {
    /// Rate between reversals, rad/s (positive: the first turn is positive).
    pub rate: f64,
    /// Angular acceleration of each reversal, rad/s^2 (positive).
    pub accel: f64,
}

impl Reversing {
    /// Half the duration of a reversal, s.
    fn half_ramp(&self) -> f64 {
        self.rate.abs() / self.accel
    }

    /// Angle and rate at `t`.
    fn eval(&self, t: f64) -> (f64, f64) {
        let w = self.rate.abs();
        let sign = self.rate.signum();
        if w == 0.0 || t <= 0.0 {
            return (0.0, 0.0);
        }
        let r = self.half_ramp();
        // between reversals: one whole turn from one reversal's stop to the next
        let half = 2.0 * PI / w + r;
        // the first start from rest takes the second half of a reversal: time shifted by r so
        // that the turn's constant-rate part starts at t = r
        let u = t.rem_euclid(2.0 * half);
        let (a, rate) = if t < r {
            (0.5 * w * t * t / r, w * t / r)
        } else if u < r {
            // end of the reversal from -w to +w
            (w * r / 2.0 + w * u * u / (2.0 * r), w * u / r)
        } else if u <= half - r {
            (w * u, w)
        } else if u < half + r {
            let d = u - half;
            (w * (half - r) + w / (2.0 * r) * (r * r - d * d), -w * d / r)
        } else if u <= 2.0 * half - r {
            (w * (2.0 * half - u), -w)
        } else {
            let d = u - 2.0 * half;
            (w * r + w / (2.0 * r) * (d * d - r * r), w * d / r)
        };
        // the start from rest ends at angle w r / 2 where a centred reversal would be at w r:
        // every later angle is w r / 2 lower than the triangle wave's
        let offset = if t < r { 0.0 } else { -w * r / 2.0 };
        let a = if t < r { a } else { a + offset };
        (sign * a, sign * rate)
    }
}

impl AxisAngle for Reversing {
    fn angle(&self, t: f64) -> f64 {
        self.eval(t).0
    }
    fn rate(&self, t: f64) -> f64 {
        self.eval(t).1
    }
    fn angle_and_rate(&self, t: f64) -> (f64, f64) {
        self.eval(t)
    }
}

/// An axis turned at set rates in set windows of time and still in between (a lab table in rate
/// mode running a profile): each window `[from s, to s, rate rad/s]` ramps up at `accel` from
/// `from`, holds, and ramps down to rest at `to`. Windows do not overlap.
#[derive(Debug, Clone, PartialEq)]
pub struct RateWindows {
    /// The windows, `[from, to, rate]`.
    pub windows: Vec<[f64; 3]>,
    /// Angular acceleration of the ramps, rad/s^2.
    pub accel: f64,
}

impl RateWindows {
    fn eval(&self, t: f64) -> (f64, f64) {
        let (mut a, mut w) = (0.0, 0.0);
        for &[from, to, rate] in &self.windows {
            if t <= from {
                continue;
            }
            let r = (rate.abs() / self.accel).min(0.5 * (to - from));
            let peak = rate.signum() * self.accel * r;
            // angle through the window up to min(t, to): ramp up, hold, ramp down
            let up = |u: f64| 0.5 * rate.signum() * self.accel * u * u;
            let u = (t - from).min(to - from);
            let hold = (to - from) - 2.0 * r;
            let (da, dw) = if u < r {
                (up(u), rate.signum() * self.accel * u)
            } else if u < r + hold {
                (up(r) + peak * (u - r), peak)
            } else {
                let v = u - r - hold; // into the ramp down
                (
                    up(r) + peak * hold + peak * v - 0.5 * rate.signum() * self.accel * v * v,
                    peak - rate.signum() * self.accel * v,
                )
            };
            a += da;
            if t < to {
                w += dw;
            }
        }
        (a, w)
    }
}

impl AxisAngle for RateWindows {
    fn angle(&self, t: f64) -> f64 {
        self.eval(t).0
    }
    fn rate(&self, t: f64) -> f64 {
        self.eval(t).1
    }
    fn angle_and_rate(&self, t: f64) -> (f64, f64) {
        self.eval(t)
    }
    fn still(&self, t0: f64, t1: f64) -> bool {
        self.windows.iter().all(|w| t1 <= w[0] || t0 >= w[1])
    }
}

/// One axis of the indexing mechanism: the IMU turns about a fixed axis of its base by the axis
/// angle, right-handed (the vehicle's azimuth indexer turns about z, up: positive is
/// counter-clockwise seen from above).
pub struct Indexer<A: AxisAngle> {
    /// The rotation axis in the base frame (unit).
    pub about: nalgebra::Unit<Vector3<f64>>,
    /// The mechanism's true angle.
    pub axis: A,
}

impl<A: AxisAngle> Indexer<A> {
    /// An azimuth (z) axis.
    pub fn azimuth(axis: A) -> Self {
        Self {
            about: Vector3::z_axis(),
            axis,
        }
    }
}

impl<A: AxisAngle> RelativeRotation for Indexer<A> {
    fn rotation(&self, t: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&self.about, self.axis.angle(t))
    }
    fn rate(&self, t: f64) -> Vector3<f64> {
        self.about.into_inner() * self.axis.rate(t)
    }
    fn rotation_and_rate(&self, t: f64) -> (UnitQuaternion<f64>, Vector3<f64>) {
        let (a, r) = self.axis.angle_and_rate(t);
        (
            UnitQuaternion::from_axis_angle(&self.about, a),
            self.about.into_inner() * r,
        )
    }
    fn still(&self, t0: f64, t1: f64) -> bool {
        self.axis.still(t0, t1)
    }
}

/// Something that shakes a parked vehicle (drill disturbance scripts).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Disturbance {
    /// A door slam: a damped roll oscillation on the suspension.
    DoorSlam {
        /// When, s.
        at_s: f64,
        /// Initial amplitude, deg.
        #[serde(default = "slam_amp")]
        amplitude_deg: f64,
        /// Suspension frequency, Hz.
        #[serde(default = "slam_f")]
        frequency_hz: f64,
        /// Decay time constant, s.
        #[serde(default = "slam_decay")]
        decay_s: f64,
    },
    /// Someone climbing in: the body rolls and pitches to a new rest over a few seconds.
    ClimbIn {
        /// When, s.
        at_s: f64,
        /// Roll at the new rest, deg.
        #[serde(default = "climb_tilt")]
        tilt_deg: f64,
        /// Time to settle, s.
        #[serde(default = "climb_dur")]
        duration_s: f64,
    },
    /// Wind gusts: a slow sway.
    Wind {
        /// Start, s.
        from_s: f64,
        /// End, s.
        to_s: f64,
        /// Sway amplitude, deg.
        #[serde(default = "wind_amp")]
        amplitude_deg: f64,
        /// Sway frequency, Hz.
        #[serde(default = "wind_f")]
        frequency_hz: f64,
    },
}

fn slam_amp() -> f64 {
    0.05
}
fn slam_f() -> f64 {
    1.8
}
fn slam_decay() -> f64 {
    0.6
}
fn climb_tilt() -> f64 {
    0.3
}
fn climb_dur() -> f64 {
    3.0
}
fn wind_amp() -> f64 {
    0.003
}
fn wind_f() -> f64 {
    0.7
}

impl Disturbance {
    /// Nothing moves over `[t0, t1]` (before it, after it, or decayed below [`STILL_RAD`]).
    fn still(&self, t0: f64, t1: f64) -> bool {
        match *self {
            Disturbance::DoorSlam {
                at_s,
                amplitude_deg,
                decay_s,
                ..
            } => {
                t1 <= at_s
                    || (t0 > at_s
                        && amplitude_deg.to_radians().abs() * (-(t0 - at_s) / decay_s).exp()
                            < STILL_RAD)
            }
            Disturbance::ClimbIn {
                at_s, duration_s, ..
            } => t1 <= at_s || t0 >= at_s + duration_s,
            Disturbance::Wind { from_s, to_s, .. } => t1 <= from_s || t0 >= to_s,
        }
    }

    /// (pitch, roll) in rad and their rates at `t`.
    fn angles(&self, t: f64) -> ([f64; 2], [f64; 2]) {
        match *self {
            Disturbance::DoorSlam {
                at_s,
                amplitude_deg,
                frequency_hz,
                decay_s,
            } => {
                if t <= at_s {
                    return ([0.0; 2], [0.0; 2]);
                }
                let tau = t - at_s;
                let w = 2.0 * PI * frequency_hz;
                let a = amplitude_deg.to_radians() * (-tau / decay_s).exp();
                let r = a * (w * tau).sin();
                let rd = a * (w * (w * tau).cos() - (w * tau).sin() / decay_s);
                ([0.0, r], [0.0, rd])
            }
            Disturbance::ClimbIn {
                at_s,
                tilt_deg,
                duration_s,
            } => {
                // smoothstep to the new roll, pitch a third of it
                let x = ((t - at_s) / duration_s).clamp(0.0, 1.0);
                let s = x * x * (3.0 - 2.0 * x);
                let sd = if (0.0..1.0).contains(&x) && t > at_s {
                    6.0 * x * (1.0 - x) / duration_s
                } else {
                    0.0
                };
                let r = tilt_deg.to_radians();
                ([r / 3.0 * s, r * s], [r / 3.0 * sd, r * sd])
            }
            Disturbance::Wind {
                from_s,
                to_s,
                amplitude_deg,
                frequency_hz,
            } => {
                if t <= from_s || t >= to_s {
                    return ([0.0; 2], [0.0; 2]);
                }
                // a window that starts and ends at rest: sin^2 envelope
                let span = to_s - from_s;
                let u = (t - from_s) / span;
                let env = (PI * u).sin().powi(2);
                let envd = PI / span * (2.0 * PI * u).sin();
                let w = 2.0 * PI * frequency_hz;
                let a = amplitude_deg.to_radians();
                let (sw, cw) = ((w * t).sin(), (w * t).cos());
                let r = a * env * sw;
                let rd = a * (envd * sw + env * w * cw);
                ([0.5 * r, r], [0.5 * rd, rd])
            }
        }
    }
}

/// The vehicle body rocking on its suspension under a script of disturbances.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct Disturbances(pub Vec<Disturbance>);

impl Disturbances {
    fn pitch_roll(&self, t: f64) -> ([f64; 2], [f64; 2]) {
        self.0.iter().fold(([0.0; 2], [0.0; 2]), |(a, d), e| {
            let (x, xd) = e.angles(t);
            ([a[0] + x[0], a[1] + x[1]], [d[0] + xd[0], d[1] + xd[1]])
        })
    }
}

impl RelativeRotation for Disturbances {
    fn rotation(&self, t: f64) -> UnitQuaternion<f64> {
        self.rotation_and_rate(t).0
    }
    fn rate(&self, t: f64) -> Vector3<f64> {
        self.rotation_and_rate(t).1
    }
    fn still(&self, t0: f64, t1: f64) -> bool {
        self.0.iter().all(|d| d.still(t0, t1))
    }
    fn rotation_and_rate(&self, t: f64) -> (UnitQuaternion<f64>, Vector3<f64>) {
        if self.0.is_empty() {
            return (UnitQuaternion::identity(), Vector3::zeros());
        }
        let ([p, r], [pd, rd]) = self.pitch_roll(t);
        let ry = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), r);
        (
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), p) * ry,
            ry.inverse() * Vector3::new(pd, 0.0, 0.0) + Vector3::new(0.0, rd, 0.0),
        )
    }
}

/// Sinusoidal vibration on one axis: amplitude, frequency and phase.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct Tone {
    /// Amplitude (deg for angular, m/s^2 for linear vibration).
    pub amplitude: f64,
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Phase, deg.
    #[serde(default)]
    pub phase_deg: f64,
}

impl Tone {
    fn value(&self, t: f64) -> f64 {
        self.amplitude * (2.0 * PI * self.frequency_hz * t + self.phase_deg.to_radians()).sin()
    }
    fn deriv(&self, t: f64) -> f64 {
        let w = 2.0 * PI * self.frequency_hz;
        self.amplitude * w * (w * t + self.phase_deg.to_radians()).cos()
    }
}

/// Engine and road vibration: angular tones about x, y, z (applied as the rotation sequence
/// x then y then z, so the rate is exact) and linear tones along x, y, z, each a sum of tones.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields, default)]
pub struct Vibration {
    /// Angular tones about x, y, z (amplitude in deg).
    pub angular: [Vec<Tone>; 3],
    /// Linear tones along x, y, z (amplitude in m/s^2).
    pub linear: [Vec<Tone>; 3],
}

impl Vibration {
    /// A typical land-vehicle spectrum: engine at `engine_hz` and its second harmonic, road
    /// bumps at a few hertz. `scale` multiplies every amplitude.
    pub fn vehicle(engine_hz: f64, scale: f64) -> Self {
        let t = |a: f64, f: f64, p: f64| Tone {
            amplitude: a * scale,
            frequency_hz: f,
            phase_deg: p,
        };
        Self {
            angular: [
                vec![t(0.02, 3.1, 0.0), t(0.002, engine_hz, 30.0)],
                vec![t(0.03, 2.3, 60.0), t(0.002, engine_hz, 90.0)],
                vec![t(0.01, 1.7, 120.0), t(0.001, 2.0 * engine_hz, 0.0)],
            ],
            linear: [
                vec![t(0.2, engine_hz, 10.0)],
                vec![t(0.3, engine_hz, 50.0), t(0.2, 2.0 * engine_hz, 0.0)],
                vec![t(0.5, 2.7, 0.0), t(0.4, engine_hz, 70.0)],
            ],
        }
    }

    fn angles(&self, t: f64) -> [(f64, f64); 3] {
        std::array::from_fn(|i| {
            self.angular[i].iter().fold((0.0, 0.0), |(a, r), tone| {
                (
                    a + tone.value(t).to_radians(),
                    r + tone.deriv(t).to_radians(),
                )
            })
        })
    }

    /// Linear vibration acceleration at `t`, m/s^2, body axes.
    pub fn accel(&self, t: f64) -> Vector3<f64> {
        Vector3::from_fn(|i, _| self.linear[i].iter().map(|x| x.value(t)).sum())
    }
}

impl RelativeRotation for Vibration {
    fn rotation(&self, t: f64) -> UnitQuaternion<f64> {
        self.rotation_and_rate(t).0
    }
    fn rate(&self, t: f64) -> Vector3<f64> {
        self.rotation_and_rate(t).1
    }
    fn rotation_and_rate(&self, t: f64) -> (UnitQuaternion<f64>, Vector3<f64>) {
        let [(x, xd), (y, yd), (z, zd)] = self.angles(t);
        let ry = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), y);
        let rz = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), z);
        (
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), x) * ry * rz,
            (ry * rz).inverse() * Vector3::new(xd, 0.0, 0.0)
                + rz.inverse() * Vector3::new(0.0, yd, 0.0)
                + Vector3::new(0.0, 0.0, zd),
        )
    }
}

/// A base motion with a relative rotation and linear vibration on top.
pub struct Composed {
    /// The base (vehicle, site, lab).
    pub base: Box<dyn Motion>,
    /// Rotations of the body relative to the base, applied in order (outermost first).
    pub relative: Vec<Box<dyn RelativeRotation>>,
    /// Linear vibration (its acceleration adds to the specific force, body axes).
    pub linear: Option<Vibration>,
}

impl Composed {
    /// The relative rotation and the body rate, walking out from the base whose rate is `w`.
    fn chain_from(&self, t: f64, mut w: Vector3<f64>) -> (UnitQuaternion<f64>, Vector3<f64>) {
        let mut q = UnitQuaternion::identity();
        for r in &self.relative {
            let (qr, rate) = r.rotation_and_rate(t);
            w = qr.inverse() * w + rate;
            q *= qr;
        }
        (q, w)
    }

    fn chain(&self, t: f64) -> (UnitQuaternion<f64>, Vector3<f64>) {
        self.chain_from(t, self.base.omega_ib_b(t))
    }
}

impl Motion for Composed {
    fn omega_ib_b(&self, t: f64) -> Vector3<f64> {
        self.chain(t).1
    }
    fn f_b(&self, t: f64) -> Vector3<f64> {
        let (q, _) = self.chain(t);
        let lin = self
            .linear
            .as_ref()
            .map_or(Vector3::zeros(), |v| v.accel(t));
        q.inverse() * self.base.f_b(t) + lin
    }
    fn increments(&self, t0: f64, t1: f64) -> Increments {
        // the mechanism locked and nothing shaking: the body is fixed to its base over the
        // interval, so its increments are the base's own, turned into the body frame
        if self.linear.is_none() && self.relative.iter().all(|r| r.still(t0, t1)) {
            let (q, _) = self.chain_from(0.5 * (t0 + t1), Vector3::zeros());
            let b = self.base.increments(t0, t1);
            return Increments {
                dtheta: q.inverse() * b.dtheta,
                dv: q.inverse() * b.dv,
            };
        }
        gauss_legendre(t0, t1, |t| self.rate_and_force(t))
    }
    fn rate_and_force(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let (w_base, f_base) = self.base.rate_and_force(t);
        let (q, w) = self.chain_from(t, w_base);
        let lin = self
            .linear
            .as_ref()
            .map_or(Vector3::zeros(), |v| v.accel(t));
        (w, q.inverse() * f_base + lin)
    }
    fn attitude(&self, t: f64) -> UnitQuaternion<f64> {
        self.base.attitude(t) * self.chain(t).0
    }
    fn inertial_attitude(&self, t: f64) -> UnitQuaternion<f64> {
        self.base.inertial_attitude(t) * self.chain(t).0
    }
    fn latitude(&self, t: f64) -> f64 {
        self.base.latitude(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn site(heading_deg: f64, pitch_deg: f64, lat_deg: f64) -> Static {
        Static {
            lat_deg,
            lon_deg: 0.0,
            height_m: 0.0,
            heading_deg,
            pitch_deg,
            roll_deg: 0.0,
        }
    }

    #[test]
    fn level_north_facing_static_sees_earth_rate_and_gravity() {
        let s = site(0.0, 0.0, 28.2);
        let w = s.rate();
        let lat = 28.2f64.to_radians();
        assert!(w.x.abs() < 1e-15);
        assert!((w.y - earth::OMEGA * lat.cos()).abs() < 1e-15);
        assert!((w.z - earth::OMEGA * lat.sin()).abs() < 1e-15);
        assert!((s.force().z - earth::gravity(lat, 0.0)).abs() < 1e-12);
    }

    #[test]
    fn heading_east_puts_north_rate_on_minus_x() {
        let w = site(90.0, 0.0, 0.0).rate();
        // facing east, north is to the left (-x)
        assert!((w.x + earth::OMEGA).abs() < 1e-12, "{w}");
        assert!(w.y.abs() < 1e-12);
    }

    #[test]
    fn nose_up_pitch_tilts_gravity_onto_forward_axis() {
        let f = site(0.0, 10.0, 0.0).force();
        let g = earth::gravity(0.0, 0.0);
        assert!((f.y - g * 10f64.to_radians().sin()).abs() < 1e-9, "{f}");
    }

    /// `a`'s rate is its angle's central difference, and its angle has no jump, every `step` s
    /// over `[t0, t1)`, to `tol` rad/s.
    fn rate_is_the_angles_derivative(a: &dyn AxisAngle, t0: f64, t1: f64, step: f64, tol: f64) {
        let h = 1e-5;
        let mut t = t0;
        while t < t1 {
            let num = (a.angle(t + h) - a.angle(t - h)) / (2.0 * h);
            assert!(
                (num - a.rate(t)).abs() < tol,
                "t {t}: {num} vs {}",
                a.rate(t)
            );
            assert!((a.angle(t + 1e-9) - a.angle(t)).abs() < 1e-9, "t {t}");
            t += step;
        }
    }

    /// Rate is the angle's derivative everywhere (reversals and the start from rest included),
    /// the angle is continuous, and each turn is a whole revolution.
    #[test]
    fn a_reversing_axis_turns_one_revolution_each_way() {
        let a = Reversing {
            rate: 5f64.to_radians(),
            accel: 5f64.to_radians(),
        };
        rate_is_the_angles_derivative(&a, 0.0005, 400.0, 0.0137, 1e-6);
        // the constant-rate parts: +5 deg/s, then -5 deg/s after the first reversal (72 s of
        // turn and the 1 s ramp's half, centred at 73 s)
        assert!((a.rate(30.0) - a.rate).abs() < 1e-15);
        assert!((a.rate(100.0) + a.rate).abs() < 1e-15);
        assert!(a.rate(73.0).abs() < 1e-12);
        // from one reversal (where the axis stops) to the next: one whole turn
        let turn = a.angle(73.0) - a.angle(146.0);
        assert!((turn - 2.0 * PI).abs() < 1e-12, "{turn}");
        assert!((a.angle(219.0) - a.angle(73.0)).abs() < 1e-12);
    }

    /// A rate window's rate is its angle's derivative, holds its rate, and ends at rest.
    #[test]
    fn a_rate_window_ramps_holds_and_stops() {
        let a = RateWindows {
            windows: vec![[10.0, 85.0, 20f64.to_radians()], [90.0, 100.0, -0.1]],
            accel: 20f64.to_radians(),
        };
        rate_is_the_angles_derivative(&a, 0.0, 110.0, 0.0731, 1e-5);
        assert!((a.rate(50.0) - 20f64.to_radians()).abs() < 1e-15);
        assert_eq!(a.rate(87.0), 0.0);
        // the turn: 75 s at 20 deg/s less the ramps' lost second
        assert!((a.angle(87.0).to_degrees() - 20.0 * 74.0).abs() < 1e-9);
        assert!(a.still(86.0, 89.0) && !a.still(80.0, 86.0));
    }

    /// Rate from attitude by central differences (independent check of the analytic rates).
    fn numeric_rate(m: &dyn Motion, t: f64) -> Vector3<f64> {
        let h = 1e-6;
        let d = m.attitude(t - h).inverse() * m.attitude(t + h);
        d.scaled_axis() / (2.0 * h)
    }

    #[test]
    fn coning_rate_and_increments_agree_with_its_attitude() {
        let c = Coning {
            half_angle_deg: 1.0,
            frequency_hz: 50.0,
        };
        for t in [0.0, 0.0031, 0.7] {
            let e = (c.omega_ib_b(t) - numeric_rate(&c, t)).norm();
            assert!(e < 1e-7, "t={t}: {e:e}");
        }
        // analytic increments equal the quadrature of the rate
        let analytic = c.increments(0.1, 0.1005).dtheta;
        let quad = Motion::increments(
            &Composed {
                base: Box::new(c),
                relative: vec![],
                linear: None,
            },
            0.1,
            0.1005,
        )
        .dtheta;
        assert!(
            (analytic - quad).norm() < 1e-15,
            "{:e}",
            (analytic - quad).norm()
        );
    }

    #[test]
    fn the_indexer_turn_is_seen_by_the_gyros_and_rotates_gravity_not() {
        let base = site(0.0, 0.0, 45.0);
        let m = Composed {
            base: Box::new(base),
            relative: vec![Box::new(Indexer::azimuth(ConstantRate {
                angle0: 0.0,
                rate: 10f64.to_radians(),
            }))],
            linear: None,
        };
        // after 9 s at 10 deg/s the IMU faces 90 deg left of the vehicle
        let t = 9.0;
        let w = m.omega_ib_b(t);
        assert!((w.z - (10f64.to_radians() + base.rate().z)).abs() < 1e-12);
        // the north (horizontal) earth rate is now on +x of the turned body
        assert!((w.x - base.rate().y).abs() < 1e-12, "{w}");
        assert!((m.f_b(t) - base.force()).norm() < 1e-9);
        // integrated increments over a second match the turn
        let mut sum = Vector3::zeros();
        for k in 0..2000 {
            sum += m
                .increments(k as f64 / 2000.0, (k + 1) as f64 / 2000.0)
                .dtheta;
        }
        assert!((sum.z - 10f64.to_radians() - base.rate().z).abs() < 1e-12);
        let turned = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 33f64.to_radians());
        let e = (m.omega_ib_b(3.3) - numeric_rate(&m, 3.3) - turned.inverse() * base.rate()).norm();
        assert!(e < 1e-8, "{e:e}");
    }

    #[test]
    fn disturbance_rates_are_exact_for_their_attitude() {
        let d = Composed {
            base: Box::new(site(30.0, 0.0, 28.2)),
            relative: vec![Box::new(Disturbances(vec![
                Disturbance::DoorSlam {
                    at_s: 1.0,
                    amplitude_deg: 0.05,
                    frequency_hz: 1.8,
                    decay_s: 0.6,
                },
                Disturbance::ClimbIn {
                    at_s: 2.0,
                    tilt_deg: 0.3,
                    duration_s: 3.0,
                },
                Disturbance::Wind {
                    from_s: 0.5,
                    to_s: 8.0,
                    amplitude_deg: 0.003,
                    frequency_hz: 0.7,
                },
            ]))],
            linear: None,
        };
        for t in [0.7, 1.3, 2.9, 4.4, 7.0] {
            let e = (d.omega_ib_b(t) - numeric_rate(&d, t)).norm();
            // numeric_rate is relative to ENU: earth rate is left out of it (1e-4 rad/s)
            assert!(e < 1e-4, "t={t}: {e:e}");
            let base = site(30.0, 0.0, 28.2);
            let rel = d.omega_ib_b(t) - d.attitude(t).inverse() * base.attitude(0.0) * base.rate();
            assert!((rel - numeric_rate(&d, t)).norm() < 1e-8, "t={t}");
        }
        // after the climb the vehicle rests tilted
        let f = d.f_b(10.0);
        assert!((f.x / f.z).abs() > 0.004, "{f}");
    }

    /// The shared-work paths (one chain per node, a site's constants worked out once) give the
    /// very same numbers, bit for bit, as rate and force evaluated apart the way they always were.
    #[test]
    fn rate_and_force_together_equal_them_apart_bit_for_bit() {
        let site = site(123.4, 0.2, -33.9);
        let make = |base: Box<dyn Motion>| Composed {
            base,
            relative: vec![
                Box::new(Disturbances(vec![Disturbance::DoorSlam {
                    at_s: 0.1,
                    amplitude_deg: 0.05,
                    frequency_hz: 1.8,
                    decay_s: 0.6,
                }])),
                Box::new(Vibration::vehicle(40.0, 1.0)),
                Box::new(Indexer::azimuth(ConstantRate {
                    angle0: 0.3,
                    rate: 0.5,
                })),
            ],
            linear: Some(Vibration::vehicle(40.0, 1.0)),
        };
        let fast = make(Box::new(site.site()));
        let slow = make(Box::new(site));
        for k in 0..50 {
            let (t0, t1) = (k as f64 * 0.0123, k as f64 * 0.0123 + 0.0005);
            // the reference: every node evaluated apart, through the separate trait methods
            let reference = gauss_legendre(t0, t1, |t| {
                let mut q = UnitQuaternion::identity();
                let mut w = slow.base.omega_ib_b(t);
                for r in &slow.relative {
                    let qr = r.rotation(t);
                    w = qr.inverse() * w + r.rate(t);
                    q *= qr;
                }
                let lin = slow
                    .linear
                    .as_ref()
                    .map_or(Vector3::zeros(), |v| v.accel(t));
                (w, q.inverse() * slow.base.f_b(t) + lin)
            });
            assert_eq!(fast.increments(t0, t1), reference, "k={k}");
            assert_eq!(slow.increments(t0, t1), reference, "k={k}");
        }
    }

    /// A locked mechanism on a parked vehicle (after a door slam has died away) takes the
    /// base's own increments; they agree with the quadrature to rounding.
    #[test]
    fn a_still_mechanism_on_a_parked_base_integrates_to_rounding() {
        let m = Composed {
            base: Box::new(site(30.0, 0.1, 45.0).site()),
            relative: vec![
                Box::new(Disturbances(vec![Disturbance::DoorSlam {
                    at_s: 1.0,
                    amplitude_deg: 0.05,
                    frequency_hz: 1.8,
                    decay_s: 0.6,
                }])),
                Box::new(Indexer::azimuth(ConstantRate {
                    angle0: 1.2,
                    rate: 0.0,
                })),
            ],
            linear: None,
        };
        for (t0, still) in [(0.5, true), (1.2, false), (30.0, true)] {
            let t1 = t0 + 0.0005;
            assert_eq!(m.relative.iter().all(|r| r.still(t0, t1)), still, "t0={t0}");
            let quad = gauss_legendre(t0, t1, |t| m.rate_and_force(t));
            let got = m.increments(t0, t1);
            assert!((got.dtheta - quad.dtheta).norm() < 1e-19, "t0={t0}");
            assert!((got.dv - quad.dv).norm() < 1e-15, "t0={t0}");
        }
    }

    #[test]
    fn vibration_rate_is_exact_for_its_attitude() {
        let v = Composed {
            base: Box::new(Coning {
                half_angle_deg: 0.0,
                frequency_hz: 1.0,
            }),
            relative: vec![Box::new(Vibration::vehicle(40.0, 10.0))],
            linear: Some(Vibration::vehicle(40.0, 1.0)),
        };
        for t in [0.01, 0.123, 1.5] {
            let e = (v.omega_ib_b(t) - numeric_rate(&v, t)).norm();
            assert!(e < 1e-7 * v.omega_ib_b(t).norm().max(1e-3), "t={t}: {e:e}");
        }
        assert!(v.f_b(0.3).norm() > 0.0);
    }
}
