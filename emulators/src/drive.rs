//! A land vehicle driving a waypoint route on a level road: exact attitude, rate, specific
//! force, velocity and position as functions of time.
//!
//! The route is planned once into segments, each with constant longitudinal acceleration and
//! constant turn rate: a stop at the start (for alignment), acceleration to the cruise speed,
//! straight legs, constant-rate turns at each waypoint (the turn rate limited by the lateral
//! acceleration limit at cruise speed; the legs shortened by the turn's tangent length, so the
//! path passes inside each corner), the loop repeated `laps` times, deceleration to a stop.
//!
//! Speed, heading and their rates are analytic per segment; the horizontal position is the exact
//! integral of the velocity in the local level plane at the start, mapped to latitude and longitude
//! with the start's radii of curvature (over a few kilometres the radii change by less than 1e-6,
//! i.e. under a millimetre per kilometre). The body rate and specific force follow from the
//! navigation equations with WGS-84 earth rate, transport rate and normal gravity:
//! `w_ib^b = C_n^b (w_ie^n + w_en^n) + w_nb^b`,
//! `f^b = C_n^b (dv^n/dt + (2 w_ie^n + w_en^n) x v^n - g^n)`.

use crate::geodesy as earth;
use crate::road::Road;
use crate::truth::{Increments, Motion, c_b_n};
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// A route (the `[drive]` table of a scenario).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DriveSpec {
    /// Start latitude, deg (a track's start is its own: not given with `track`).
    #[serde(default = "not_given", skip_serializing_if = "is_nan")]
    pub lat_deg: f64,
    /// Start longitude, deg.
    #[serde(default = "not_given", skip_serializing_if = "is_nan")]
    pub lon_deg: f64,
    /// Height, m.
    #[serde(default)]
    pub height_m: f64,
    /// Waypoints, metres east and north of the start. The route runs start -> waypoints; with
    /// `laps` > 1 it is a loop that must end at the start. None with `track`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub waypoints: Vec<[f64; 2]>,
    /// Cruise speed, m/s (a track's speeds are its own: not given with `track`).
    #[serde(default = "not_given", skip_serializing_if = "is_nan")]
    pub speed_mps: f64,
    /// Longitudinal acceleration limit, m/s^2.
    #[serde(default = "default_accel")]
    pub accel_mps2: f64,
    /// Turn-rate limit, deg/s.
    #[serde(default = "default_turn")]
    pub turn_rate_dps: f64,
    /// Lateral acceleration limit, m/s^2.
    #[serde(default = "default_lat")]
    pub lateral_accel_mps2: f64,
    /// Times round the loop.
    #[serde(default = "one")]
    pub laps: u32,
    /// Standing still before driving off, s.
    #[serde(default)]
    pub start_wait_s: f64,
    /// A road's fields (any of them makes the route a road: `crate::road`).
    /// Height of each waypoint, m (as many as `waypoints`; the start is at `height_m`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub heights_m: Vec<f64>,
    /// Speed on the leg to each waypoint, m/s (as many as `waypoints`); none: `speed_mps`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub leg_speeds_mps: Vec<f64>,
    /// Stops: [waypoint number (1 = the first), seconds standing there], in every lap.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stops: Vec<[f64; 2]>,
    /// Braking limit, m/s^2 (default: `accel_mps2`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub brake_mps2: Option<f64>,
    /// Jerk limit, m/s^3 (default 1.0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jerk_mps3: Option<f64>,
    /// Vertical acceleration limit over a crest or a dip, m/s^2 (default 0.5): sets the
    /// vertical curves' length.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertical_accel_mps2: Option<f64>,
    /// The body's pitch per m/s^2 of longitudinal acceleration (squat, and dive under braking),
    /// deg (default 0.3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pitch_per_accel_deg: Option<f64>,
    /// The body's roll out of a turn per m/s^2 of lateral acceleration, deg (default 0.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roll_per_lateral_accel_deg: Option<f64>,
    /// The radius of every turn at its sharpest, m, driven at the speed it allows within the
    /// lateral-acceleration and turn-rate limits (default: each turn as wide as the faster of
    /// its legs needs at its speed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corner_radius_m: Option<f64>,
    /// The road's bank into a turn at its sharpest, deg (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bank_deg: Option<f64>,
    /// The road's roughness: 1 a typical paved road, whose bumps pitch and roll the body by
    /// about 0.1 deg and lift it by millimetres over waves of 3 to 31 m, so that its rates grow
    /// with its speed and its vertical acceleration with the speed squared (about 0.1 m/s^2
    /// RMS at 10 m/s, 0.9 at 30); 2 a poor one; 0 smooth (default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roughness: Option<f64>,
    /// A recorded track to drive instead of waypoints: a GPX, NMEA or CSV file (relative to
    /// the scenario's folder), fitted into a road (`crate::road::track`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub track: Option<String>,
    /// The track's jitter, m (default: estimated from the track).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub track_jitter_m: Option<f64>,
    /// The fastest the vehicle drives, m/s: a step of the track faster is a jump no vehicle
    /// makes (default 70).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub track_max_speed_mps: Option<f64>,
}

/// A start or a speed a track gives instead of the scenario.
fn not_given() -> f64 {
    f64::NAN
}

fn is_nan(x: &f64) -> bool {
    x.is_nan()
}

impl Default for DriveSpec {
    /// No route (a plan refuses it): for code that names only the fields it sets.
    fn default() -> Self {
        Self {
            lat_deg: 0.0,
            lon_deg: 0.0,
            height_m: 0.0,
            waypoints: Vec::new(),
            speed_mps: 10.0,
            accel_mps2: default_accel(),
            turn_rate_dps: default_turn(),
            lateral_accel_mps2: default_lat(),
            laps: 1,
            start_wait_s: 0.0,
            heights_m: Vec::new(),
            leg_speeds_mps: Vec::new(),
            stops: Vec::new(),
            brake_mps2: None,
            jerk_mps3: None,
            vertical_accel_mps2: None,
            pitch_per_accel_deg: None,
            roll_per_lateral_accel_deg: None,
            corner_radius_m: None,
            bank_deg: None,
            roughness: None,
            track: None,
            track_jitter_m: None,
            track_max_speed_mps: None,
        }
    }
}

impl DriveSpec {
    /// No route, with a driver's limits rather than the level route's gentle ones: 2 m/s^2 of
    /// acceleration, 3 of braking and of lateral acceleration, 2 m/s^3 of jerk, 40 deg/s of
    /// turn rate (a recorded track driven as it was, where no scenario says otherwise).
    pub fn driver() -> Self {
        Self {
            accel_mps2: 2.0,
            brake_mps2: Some(3.0),
            jerk_mps3: Some(2.0),
            turn_rate_dps: 40.0,
            lateral_accel_mps2: 3.0,
            ..Self::default()
        }
    }

    /// The route names a road's fields: it is planned as a road (`crate::road`), not as the
    /// level route of one speed.
    pub fn is_road(&self) -> bool {
        !(self.heights_m.is_empty() && self.leg_speeds_mps.is_empty() && self.stops.is_empty())
            || self.brake_mps2.is_some()
            || self.jerk_mps3.is_some()
            || self.vertical_accel_mps2.is_some()
            || self.pitch_per_accel_deg.is_some()
            || self.roll_per_lateral_accel_deg.is_some()
            || self.corner_radius_m.is_some()
            || self.bank_deg.is_some()
            || self.roughness.is_some()
            || self.track.is_some()
    }
}

fn default_accel() -> f64 {
    1.5
}
fn default_turn() -> f64 {
    15.0
}
fn default_lat() -> f64 {
    2.5
}
fn one() -> u32 {
    1
}

/// One piece of the plan.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Segment {
    t0: f64,
    dur: f64,
    /// Position at the start, m (east, north).
    p0: [f64; 2],
    s0: f64,
    accel: f64,
    psi0: f64,
    /// `psi0.sin()` and `psi0.cos()`, kept from the plan: a segment's start heading is asked
    /// for its sine and cosine at every quadrature node.
    sin_psi0: f64,
    cos_psi0: f64,
    rate: f64,
}

/// The planned level route.
#[derive(Debug, Clone)]
pub(crate) struct Level {
    spec: DriveSpec,
    segs: Vec<Segment>,
    /// For each segment, standing still where it ends (after the plan's end, or in a rounding
    /// gap between two segments), built once here rather than at every quadrature node.
    after: Vec<Segment>,
    lat0: f64,
    /// `lat0.cos()`, asked at every quadrature node.
    cos_lat0: f64,
    lon0: f64,
    rm: f64,
    rn: f64,
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

impl Level {
    /// Plan the route; errors name what is wrong with the spec.
    pub fn plan(spec: &DriveSpec) -> Result<Self, crate::ParamError> {
        check_spec(spec)?;
        let pts = route_points(spec)?;
        let Geometry {
            rate,
            r,
            legs,
            turns,
            tangent,
        } = geometry(spec, &pts)?;
        let mut out = Segments {
            segs: Vec::new(),
            t: 0.0,
            p: [0.0, 0.0],
            psi: legs[0].1,
        };
        out.push(spec.start_wait_s, 0.0, 0.0, 0.0);
        drive_legs(spec, &mut out, rate, r, &legs, &turns, &tangent)?;
        let segs = out.segs;
        let after = segs.iter().map(Segment::standing_after).collect();
        let lat0 = spec.lat_deg.to_radians();
        let (rm, rn) = earth::radii(lat0);
        Ok(Self {
            spec: spec.clone(),
            segs,
            after,
            lat0,
            cos_lat0: lat0.cos(),
            lon0: spec.lon_deg.to_radians(),
            rm: rm + spec.height_m,
            rn: rn + spec.height_m,
        })
    }

    /// Duration of the plan, s (the vehicle stands still after it).
    pub fn duration(&self) -> f64 {
        self.segs.last().map_or(0.0, |s| s.t0 + s.dur)
    }

    fn seg(&self, t: f64) -> (Segment, f64) {
        let i = self.segs.partition_point(|s| s.t0 <= t).saturating_sub(1);
        match self.segs.get(i) {
            Some(s) if t <= s.t0 + s.dur => (*s, (t - s.t0).max(0.0)),
            Some(_) => {
                let st = self.after[i];
                (st, t - st.t0)
            }
            None => (
                Segment::new(0.0, f64::INFINITY, [0.0, 0.0], 0.0, 0.0, 0.0, 0.0),
                t,
            ),
        }
    }

    /// Speed (m/s), heading (rad), their rates, and the horizontal position (m east, north).
    pub fn kinematics(&self, t: f64) -> (f64, f64, f64, f64, [f64; 2]) {
        let k = self.state(t);
        (k.speed, k.psi, k.accel, k.rate, k.p)
    }

    /// The kinematics at `t` with the heading's sine and cosine.
    fn state(&self, t: f64) -> State {
        let (s, tau) = self.seg(t);
        let (psi, sin_psi, cos_psi, p) = s.at(tau);
        State {
            speed: s.s0 + s.accel * tau,
            psi,
            sin_psi,
            cos_psi,
            accel: s.accel,
            rate: s.rate,
            p,
        }
    }

    /// Velocity in ENU, m/s.
    pub fn velocity(&self, t: f64) -> Vector3<f64> {
        let k = self.state(t);
        Vector3::new(k.speed * k.sin_psi, k.speed * k.cos_psi, 0.0)
    }

    /// Latitude, longitude (rad) and height (m).
    pub fn position(&self, t: f64) -> (f64, f64, f64) {
        let (.., p) = self.kinematics(t);
        (
            self.lat0 + p[1] / self.rm,
            self.lon0 + p[0] / (self.rn * self.cos_lat0),
            self.spec.height_m,
        )
    }

    /// Heading, rad (clockwise from north).
    pub fn heading(&self, t: f64) -> f64 {
        self.kinematics(t).1
    }
}

/// See [`Level::state`].
struct State {
    speed: f64,
    psi: f64,
    sin_psi: f64,
    cos_psi: f64,
    accel: f64,
    rate: f64,
    p: [f64; 2],
}

impl Segment {
    fn new(t0: f64, dur: f64, p0: [f64; 2], s0: f64, accel: f64, psi0: f64, rate: f64) -> Self {
        let (sin_psi0, cos_psi0) = psi0.sin_cos();
        Self {
            t0,
            dur,
            p0,
            s0,
            accel,
            psi0,
            sin_psi0,
            cos_psi0,
            rate,
        }
    }

    /// Standing still, for good, where this segment ends.
    fn standing_after(&self) -> Self {
        Self::new(
            self.t0 + self.dur,
            f64::INFINITY,
            self.position(self.dur),
            (self.s0 + self.accel * self.dur).max(0.0),
            0.0,
            wrap(self.psi0 + self.rate * self.dur),
            0.0,
        )
    }

    /// Position after `tau` seconds in the segment.
    fn position(&self, tau: f64) -> [f64; 2] {
        self.at(tau).3
    }

    /// Heading, its sine and cosine, and position after `tau` seconds in the segment; each
    /// sine and cosine taken once (on a straight leg none: the start's, kept from the plan).
    fn at(&self, tau: f64) -> (f64, f64, f64, [f64; 2]) {
        let psi = self.psi0 + self.rate * tau;
        let dist = self.s0 * tau + 0.5 * self.accel * tau * tau;
        if self.rate.abs() < 1e-12 {
            let p = [
                self.p0[0] + dist * self.sin_psi0,
                self.p0[1] + dist * self.cos_psi0,
            ];
            if psi.to_bits() == self.psi0.to_bits() {
                // a straight leg (psi0 + 0 * tau, which is psi0 but for the sign of a zero)
                (psi, self.sin_psi0, self.cos_psi0, p)
            } else {
                let (sin_psi, cos_psi) = psi.sin_cos();
                (psi, sin_psi, cos_psi, p)
            }
        } else {
            // constant speed on an arc (turns are planned at constant speed)
            let r = self.s0 / self.rate;
            let (sin_psi, cos_psi) = psi.sin_cos();
            let p = [
                self.p0[0] + r * (self.cos_psi0 - cos_psi),
                self.p0[1] + r * (sin_psi - self.sin_psi0),
            ];
            (psi, sin_psi, cos_psi, p)
        }
    }
}

impl Level {
    /// Everything rate and force have in common at `t`, each from one trajectory lookup:
    /// the body-from-ENU rotation, earth and transport rate, and the kinematics.
    /// Each sine and cosine is taken once (they were the truth's largest cost in an emulated
    /// guest, where floating point is slow): the same values as computed apart.
    fn frame(&self, t: f64) -> DriveFrame {
        let State {
            speed,
            psi,
            sin_psi,
            cos_psi,
            accel,
            rate,
            p,
        } = self.state(t);
        let lat = self.lat0 + p[1] / self.rm;
        let (sin_lat, cos_lat) = lat.sin_cos();
        let v = Vector3::new(speed * sin_psi, speed * cos_psi, 0.0);
        let lon_rate = v.x / (self.rn * self.cos_lat0);
        DriveFrame {
            speed,
            sin_psi,
            cos_psi,
            accel,
            rate,
            sin_lat,
            cos_lat,
            v,
            cnb: c_b_n_heading(psi, sin_psi, cos_psi),
            wie: Vector3::from(earth::earth_rate_enu_sc(sin_lat, cos_lat)),
            wen: Vector3::new(-v.y / self.rm, lon_rate * cos_lat, lon_rate * sin_lat),
        }
    }

    fn omega_of(fr: &DriveFrame) -> Vector3<f64> {
        fr.cnb * (fr.wie + fr.wen) + Vector3::new(0.0, 0.0, -fr.rate)
    }

    fn force_of(&self, fr: &DriveFrame) -> Vector3<f64> {
        let (s, sin_psi, cos_psi) = (fr.speed, fr.sin_psi, fr.cos_psi);
        let a = Vector3::new(
            fr.accel * sin_psi + s * fr.rate * cos_psi,
            fr.accel * cos_psi - s * fr.rate * sin_psi,
            0.0,
        );
        let g = Vector3::new(
            0.0,
            0.0,
            -earth::gravity_sc(fr.sin_lat, fr.cos_lat, self.spec.height_m),
        );
        fr.cnb * (a + (2.0 * fr.wie + fr.wen).cross(&fr.v) - g)
    }
}

/// `c_b_n(psi, 0, 0)` (the zero pitch and roll rotations are exact identities), i.e.
/// `Rotation3::from_axis_angle(&Vector3::z_axis(), -psi).inverse()`, from the heading's sine and
/// cosine: nalgebra's formula for an axis and angle term by term, with `sin(-psi) = -sin(psi)`
/// and `cos(-psi) = cos(psi)` (glibc's `sin` is odd and its `cos` even to the bit), so the same
/// bits without a third sine and cosine per quadrature node.
fn c_b_n_heading(psi: f64, sin_psi: f64, cos_psi: f64) -> nalgebra::Rotation3<f64> {
    let angle = -psi;
    if angle == 0.0 {
        return nalgebra::Rotation3::identity();
    }
    let (ux, uy, uz) = (0.0_f64, 0.0_f64, 1.0_f64);
    let (sqx, sqy, sqz) = (ux * ux, uy * uy, uz * uz);
    let (sin, cos) = (-sin_psi, cos_psi);
    let one_m_cos = 1.0 - cos;
    nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
        sqx + (1.0 - sqx) * cos,
        ux * uy * one_m_cos - uz * sin,
        ux * uz * one_m_cos + uy * sin,
        ux * uy * one_m_cos + uz * sin,
        sqy + (1.0 - sqy) * cos,
        uy * uz * one_m_cos - ux * sin,
        ux * uz * one_m_cos - uy * sin,
        uy * uz * one_m_cos + ux * sin,
        sqz + (1.0 - sqz) * cos,
    ))
    .inverse()
}

/// See [`Level::frame`].
struct DriveFrame {
    speed: f64,
    sin_psi: f64,
    cos_psi: f64,
    accel: f64,
    rate: f64,
    sin_lat: f64,
    cos_lat: f64,
    v: Vector3<f64>,
    cnb: nalgebra::Rotation3<f64>,
    wie: Vector3<f64>,
    wen: Vector3<f64>,
}

impl Motion for Level {
    fn omega_ib_b(&self, t: f64) -> Vector3<f64> {
        Self::omega_of(&self.frame(t))
    }

    fn f_b(&self, t: f64) -> Vector3<f64> {
        self.force_of(&self.frame(t))
    }

    fn rate_and_force(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let fr = self.frame(t);
        (Self::omega_of(&fr), self.force_of(&fr))
    }

    fn increments(&self, t0: f64, t1: f64) -> Increments {
        // within a segment speed is quadratic-free and heading linear: 3 nodes are exact to
        // rounding; a segment's corner (a step in acceleration or turn rate) splits the interval
        let i = self.segs.partition_point(|s| s.t0 <= t0);
        crate::truth::gauss_legendre3_split(
            t0,
            t1,
            self.segs.get(i).map(|s| s.t0),
            self.duration(),
            |t| self.rate_and_force(t),
        )
    }

    fn attitude(&self, t: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_rotation_matrix(&c_b_n(self.heading(t), 0.0, 0.0))
    }

    fn inertial_attitude(&self, t: f64) -> UnitQuaternion<f64> {
        let (lat, lon, _) = self.position(t);
        crate::truth::inertial_from_enu(lat, lon, t, self.attitude(t))
    }

    fn latitude(&self, t: f64) -> f64 {
        self.position(t).0
    }
}

/// A planned drive: the level route of one speed, or a road (`crate::road`) where the
/// `[drive]` table names a road's fields.
#[derive(Debug, Clone)]
pub struct Drive(Kind);

// one per run; the level route, read at every quadrature node, is kept inline
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
enum Kind {
    Level(Level),
    Road(Box<Road>),
}

impl Drive {
    /// Plan the route; errors name what is wrong with the spec.
    pub fn plan(spec: &DriveSpec) -> Result<Self, crate::ParamError> {
        if let Some(file) = &spec.track {
            return plan_track(spec, file);
        }
        if spec.lat_deg.is_nan() || spec.lon_deg.is_nan() {
            return Err(crate::ParamError::new(
                "drive",
                "lat_deg and lon_deg: the route's start (or a track to drive)",
            ));
        }
        Ok(Self(if spec.is_road() {
            Kind::Road(Box::new(Road::plan(spec)?))
        } else {
            Kind::Level(Level::plan(spec)?)
        }))
    }

    /// A drive on a road already planned (a recorded track fitted, say).
    pub fn from_road(road: Road) -> Self {
        Self(Kind::Road(Box::new(road)))
    }

    /// The road, when the route is one.
    pub fn road(&self) -> Option<&Road> {
        match &self.0 {
            Kind::Road(r) => Some(r),
            Kind::Level(_) => None,
        }
    }

    fn motion(&self) -> &dyn Motion {
        match &self.0 {
            Kind::Level(l) => l,
            Kind::Road(r) => r.as_ref(),
        }
    }

    /// Duration of the plan, s (the vehicle stands still after it).
    pub fn duration(&self) -> f64 {
        match &self.0 {
            Kind::Level(l) => l.duration(),
            Kind::Road(r) => r.duration(),
        }
    }

    /// Speed (m/s), heading (rad), acceleration along the road (m/s^2), heading rate (rad/s)
    /// and, on a level route, the horizontal position (m east, north of the start; a road's is
    /// [`Drive::position`]: here the start's).
    pub fn kinematics(&self, t: f64) -> (f64, f64, f64, f64, [f64; 2]) {
        match &self.0 {
            Kind::Level(l) => l.kinematics(t),
            Kind::Road(r) => {
                let (v, psi, a, w) = r.kinematics(t);
                (v, psi, a, w, [0.0, 0.0])
            }
        }
    }

    /// Velocity in ENU, m/s.
    pub fn velocity(&self, t: f64) -> Vector3<f64> {
        match &self.0 {
            Kind::Level(l) => l.velocity(t),
            Kind::Road(r) => r.velocity(t),
        }
    }

    /// Latitude, longitude (rad) and height (m).
    pub fn position(&self, t: f64) -> (f64, f64, f64) {
        match &self.0 {
            Kind::Level(l) => l.position(t),
            Kind::Road(r) => r.position(t),
        }
    }

    /// Heading, rad (clockwise from north).
    pub fn heading(&self, t: f64) -> f64 {
        match &self.0 {
            Kind::Level(l) => l.heading(t),
            Kind::Road(r) => r.hpr(t)[0],
        }
    }

    /// Heading, pitch and roll of the body, rad (a level route's pitch and roll are zero).
    pub fn hpr(&self, t: f64) -> [f64; 3] {
        match &self.0 {
            Kind::Level(l) => [l.heading(t), 0.0, 0.0],
            Kind::Road(r) => r.hpr(t),
        }
    }
}

impl Motion for Drive {
    fn omega_ib_b(&self, t: f64) -> Vector3<f64> {
        self.motion().omega_ib_b(t)
    }

    fn f_b(&self, t: f64) -> Vector3<f64> {
        self.motion().f_b(t)
    }

    fn rate_and_force(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        self.motion().rate_and_force(t)
    }

    fn increments(&self, t0: f64, t1: f64) -> Increments {
        self.motion().increments(t0, t1)
    }

    fn attitude(&self, t: f64) -> UnitQuaternion<f64> {
        self.motion().attitude(t)
    }

    fn inertial_attitude(&self, t: f64) -> UnitQuaternion<f64> {
        self.motion().inertial_attitude(t)
    }

    fn latitude(&self, t: f64) -> f64 {
        self.motion().latitude(t)
    }
}

/// A drive from the recorded track `file`: read and fitted once per process for the same
/// spec and the same file (its size and modification time), since a run plans its drive
/// several times (the truth, the reference, the scoring, the report) and a long track takes
/// seconds to fit.
fn plan_track(spec: &DriveSpec, file: &str) -> Result<Drive, crate::ParamError> {
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    static PLANNED: OnceLock<Mutex<HashMap<String, Drive>>> = OnceLock::new();
    let stamp = std::fs::metadata(file)
        .ok()
        .map(|m| (m.len(), m.modified().ok()));
    let key = format!("{spec:?} {stamp:?}");
    let cache = PLANNED.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(d) = cache.lock().ok().and_then(|c| c.get(&key).cloned()) {
        return Ok(d);
    }
    let road = crate::road::track::read(std::path::Path::new(file))
        .and_then(|t| Road::from_track(spec, &t))
        .map_err(|e| crate::ParamError::new("drive", e.to_string()))?;
    let d = Drive::from_road(road);
    if let Ok(mut c) = cache.lock() {
        // a few tracks per process at most; a bench that plans many keeps the latest
        if c.len() >= 8 {
            c.clear();
        }
        c.insert(key, d.clone());
    }
    Ok(d)
}

/// The spec's speeds, rates and waypoints are usable.
fn check_spec(spec: &DriveSpec) -> Result<(), crate::ParamError> {
    let pos = |x: f64| x.is_finite() && x > 0.0;
    if !(pos(spec.speed_mps)
        && pos(spec.accel_mps2)
        && pos(spec.turn_rate_dps)
        && pos(spec.lateral_accel_mps2))
    {
        return Err(crate::ParamError::new(
            "drive",
            "speed_mps, accel_mps2, turn_rate_dps and lateral_accel_mps2 must be positive",
        ));
    }
    if spec.waypoints.is_empty() || spec.laps == 0 {
        return Err(crate::ParamError::new(
            "drive",
            "needs at least one waypoint and one lap",
        ));
    }
    Ok(())
}

/// The start, then the waypoints of every lap, repeated points dropped.
fn route_points(spec: &DriveSpec) -> Result<Vec<[f64; 2]>, crate::ParamError> {
    let mut pts = vec![[0.0, 0.0]];
    for _ in 0..spec.laps {
        pts.extend(spec.waypoints.iter().copied());
    }
    if spec.laps > 1 {
        let last = spec.waypoints[spec.waypoints.len() - 1];
        if last[0].hypot(last[1]) > 1.0 {
            return Err(crate::ParamError::new(
                "drive",
                "with laps > 1 the last waypoint must be the start [0, 0]",
            ));
        }
    }
    pts.dedup_by(|a, b| (a[0] - b[0]).hypot(a[1] - b[1]) < 1e-6);
    if pts.len() < 2 {
        return Err(crate::ParamError::new(
            "drive",
            "the waypoints do not leave the start",
        ));
    }
    Ok(pts)
}

/// The route's legs and turns at the planned speed.
struct Geometry {
    /// Turn rate, rad/s.
    rate: f64,
    /// Turn radius, m.
    r: f64,
    /// Each leg's length (m) and heading (rad, clockwise from north).
    legs: Vec<(f64, f64)>,
    /// The turn at each inner waypoint, rad.
    turns: Vec<f64>,
    /// Each turn's tangent length, m (off both legs).
    tangent: Vec<f64>,
}

/// Legs and turns of the route through `pts`; a U-turn is refused with where it is.
fn geometry(spec: &DriveSpec, pts: &[[f64; 2]]) -> Result<Geometry, crate::ParamError> {
    let v = spec.speed_mps;
    let rate = spec
        .turn_rate_dps
        .to_radians()
        .min(spec.lateral_accel_mps2 / v);
    let r = v / rate;
    let legs: Vec<(f64, f64)> = pts
        .windows(2)
        .map(|w| {
            let (de, dn) = (w[1][0] - w[0][0], w[1][1] - w[0][1]);
            (de.hypot(dn), de.atan2(dn)) // length, heading (clockwise from north)
        })
        .collect();
    // turn at each inner waypoint; its tangent length comes off both legs
    let turns: Vec<f64> = legs.windows(2).map(|w| wrap(w[1].1 - w[0].1)).collect();
    // a reversal has no arc to drive (its tangent is infinite): say where it is
    if let Some(i) = turns.iter().position(|d| d.abs() > 170f64.to_radians()) {
        let at = pts[i + 1];
        return Err(crate::ParamError::new(
            "drive",
            format!(
                "the route turns back on itself by {:.0} deg at [{:.1}, {:.1}] (waypoint {} of the laps); U-turns are not driven: add a waypoint to turn around, or end each lap heading the way the next begins",
                turns[i].abs().to_degrees(),
                at[0],
                at[1],
                i + 1
            ),
        ));
    }
    let tangent: Vec<f64> = turns.iter().map(|d| r * (d.abs() / 2.0).tan()).collect();
    Ok(Geometry {
        rate,
        r,
        legs,
        turns,
        tangent,
    })
}

/// The segments planned so far and where they end.
struct Segments {
    segs: Vec<Segment>,
    /// End time, s.
    t: f64,
    /// End position (east, north), m.
    p: [f64; 2],
    /// End heading, rad.
    psi: f64,
}

impl Segments {
    /// A segment of `dur` s from speed `s0` at `accel` m/s^2 turning at `rate` rad/s (none when
    /// `dur` is not positive).
    fn push(&mut self, dur: f64, s0: f64, accel: f64, rate: f64) {
        if dur <= 0.0 {
            return;
        }
        let seg = Segment::new(self.t, dur, self.p, s0, accel, self.psi, rate);
        self.p = seg.position(dur);
        self.psi = wrap(self.psi + rate * dur);
        self.t += dur;
        self.segs.push(seg);
    }
}

/// Drive the legs: accelerate at the start, cruise, brake at the end, turn at each waypoint.
fn drive_legs(
    spec: &DriveSpec,
    out: &mut Segments,
    rate: f64,
    r: f64,
    legs: &[(f64, f64)],
    turns: &[f64],
    tangent: &[f64],
) -> Result<(), crate::ParamError> {
    let v = spec.speed_mps;
    let d_acc = v * v / (2.0 * spec.accel_mps2);
    let total: f64 = legs.iter().map(|l| l.0).sum::<f64>() - 2.0 * tangent.iter().sum::<f64>();
    if total < 2.0 * d_acc {
        return Err(crate::ParamError::new(
            "drive",
            format!(
                "the route ({total:.0} m of straight road) is too short to reach {v} m/s and stop"
            ),
        ));
    }
    let mut speed = 0.0;
    let mut to_accel = d_acc; // distance of acceleration still to do
    let mut straight_left = total; // straight road still ahead
    for (i, (len, _)) in legs.iter().enumerate() {
        let before = if i > 0 { tangent[i - 1] } else { 0.0 };
        let after = tangent.get(i).copied().unwrap_or(0.0);
        let mut d = (len - before - after).max(0.0);
        // acceleration at the start
        if to_accel > 0.0 && d > 0.0 {
            let da = to_accel.min(d);
            let s1 = (speed * speed + 2.0 * spec.accel_mps2 * da).sqrt();
            out.push((s1 - speed) / spec.accel_mps2, speed, spec.accel_mps2, 0.0);
            speed = s1;
            to_accel -= da;
            d -= da;
            straight_left -= da;
        }
        // cruise, keeping the braking distance for the end
        let cruise = (d - (d_acc - (straight_left - d)).max(0.0)).max(0.0);
        if cruise > 0.0 {
            out.push(cruise / speed, speed, 0.0, 0.0);
            d -= cruise;
            straight_left -= cruise;
        }
        // braking at the end
        if d > 1e-9 {
            let s1 = (speed * speed - 2.0 * spec.accel_mps2 * d).max(0.0).sqrt();
            out.push((speed - s1) / spec.accel_mps2, speed, -spec.accel_mps2, 0.0);
            speed = s1;
            straight_left -= d;
        }
        if let Some(dpsi) = turns.get(i) {
            if speed > 0.0 {
                let w = rate.min(speed / r.max(1e-9)) * dpsi.signum();
                let w = if w == 0.0 { rate } else { w };
                out.push(dpsi.abs() / w.abs(), speed, 0.0, w);
            }
            out.psi = legs[i + 1].1;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> DriveSpec {
        DriveSpec {
            lat_deg: 28.218157,
            lon_deg: 112.989583,
            height_m: 0.0,
            waypoints: vec![[0.0, 250.0], [250.0, 250.0], [250.0, 0.0], [0.0, 0.0]],
            speed_mps: 10.0,
            accel_mps2: 1.5,
            turn_rate_dps: 15.0,
            lateral_accel_mps2: 2.5,
            laps: 2,
            start_wait_s: 5.0,
            ..Default::default()
        }
    }

    /// Three nodes per interval, split at the route's corners, agree with six to rounding
    /// (away from corners) and beat six across a corner.
    #[test]
    fn three_nodes_split_at_corners_integrate_to_rounding() {
        let d = Level::plan(&square()).unwrap();
        let six = |t0: f64, t1: f64| crate::truth::gauss_legendre(t0, t1, |t| d.rate_and_force(t));
        let mut worst = (0.0f64, 0.0f64);
        for k in 0..400_000u64 {
            let (t0, t1) = (k as f64 * 0.0005, (k + 1) as f64 * 0.0005);
            let end = d.duration();
            if d.segs.iter().any(|s| s.t0 > t0 && s.t0 < t1) || (t0 < end && end < t1) {
                continue;
            }
            let (a, b) = (d.increments(t0, t1), six(t0, t1));
            worst.0 = worst.0.max((a.dtheta - b.dtheta).norm());
            worst.1 = worst.1.max((a.dv - b.dv).norm());
        }
        assert!(worst.0 < 1e-17 && worst.1 < 1e-14, "{worst:?}");
        // across a corner the split integral is the sum of the two exact halves
        let c = d.segs[3].t0;
        let (t0, t1) = (c - 0.0002, c + 0.0003);
        let a = d.increments(t0, t1);
        let halves = |f: &dyn Fn(f64, f64) -> Increments| {
            let (x, y) = (f(t0, c), f(c, t1));
            x.dv + y.dv
        };
        assert!((a.dv - halves(&six)).norm() < 1e-14);
    }

    #[test]
    fn the_loop_closes_respects_the_limits_and_ends_at_rest() {
        let d = Level::plan(&square()).unwrap();
        let end = d.duration();
        // 2 x 1 km square with 40 m radius corners (1.88 km) at 10 m/s, plus 5 s waiting and
        // 6.7 s lost accelerating and braking
        assert!((end - 199.65).abs() < 0.1, "{end}");
        let (s, _, _, _, p) = d.kinematics(end + 1.0);
        assert!(s.abs() < 1e-9);
        assert!(p[0].hypot(p[1]) < 30.0, "ends near the start: {p:?}");
        // and stays where and as it ended, an hour on
        let (_, psi_end, _, _, p_end) = d.kinematics(end);
        for dt in [1e-9, 1.0, 3600.0] {
            let (s, psi, a, w, p) = d.kinematics(end + dt);
            assert!(s.abs() < 1e-9 && a == 0.0 && w == 0.0, "{dt}: {s} {a} {w}");
            assert!(
                wrap(psi - psi_end).abs() < 1e-12,
                "{dt}: {psi} vs {psi_end}"
            );
            assert!(
                (p[0] - p_end[0]).hypot(p[1] - p_end[1]) < 1e-6,
                "{dt}: {p:?}"
            );
        }
        let mut t = 0.0;
        while t < end {
            let (s, _, a, w, _) = d.kinematics(t);
            assert!((-1e-9..=10.0 + 1e-9).contains(&s));
            assert!(a.abs() <= 1.5 + 1e-9);
            assert!(w.abs() <= 15f64.to_radians() + 1e-12);
            assert!((s * w).abs() <= 2.5 + 1e-9, "lateral {}", s * w);
            t += 0.05;
        }
        // standing still at the start: only earth rate and gravity
        let w = d.omega_ib_b(1.0);
        assert!((w.norm() - earth::OMEGA).abs() < 1e-12);
    }

    #[test]
    fn position_is_the_integral_of_velocity_and_rate_matches_attitude() {
        let d = Level::plan(&square()).unwrap();
        // integrate the velocity numerically and compare with the analytic position
        let (mut e, mut n) = (0.0, 0.0);
        let h = 0.001;
        let mut t = 0.0;
        while t < 120.0 {
            let v = d.velocity(t + h / 2.0);
            e += v.x * h;
            n += v.y * h;
            t += h;
        }
        let (.., p) = d.kinematics(120.0);
        assert!(
            (p[0] - e).abs() < 1e-3 && (p[1] - n).abs() < 1e-3,
            "{p:?} vs {e},{n}"
        );
        // body rate from the inertial attitude by differences, in a turn
        for t in [30.0, 60.0, 100.0] {
            let k = 1e-4;
            let dq = d.inertial_attitude(t - k).inverse() * d.inertial_attitude(t + k);
            let w_num = dq.scaled_axis() / (2.0 * k);
            let w = d.omega_ib_b(t);
            assert!((w - w_num).norm() < 1e-8, "t={t}: {w} vs {w_num}");
        }
    }

    #[test]
    fn specific_force_holds_the_centripetal_acceleration_in_turns() {
        let d = Level::plan(&square()).unwrap();
        let mut seen = false;
        let mut t = 0.0;
        while t < d.duration() {
            let (s, _, _, w, _) = d.kinematics(t);
            if w.abs() > 0.0 {
                // turning right (w > 0): the centripetal force points right, +x in the body
                let f = d.f_b(t);
                assert!((f.x - s * w).abs() < 1e-3, "t={t}: {f} vs {}", s * w);
                seen = true;
            }
            t += 0.1;
        }
        assert!(seen);
    }

    #[test]
    fn bad_routes_say_what_is_wrong() {
        // a lap that ends heading south into a lap that starts heading north: a reversal
        let mut s = square();
        s.waypoints = vec![[0.0, 200.0], [0.0, 0.0]];
        let e = Level::plan(&s).unwrap_err().to_string();
        assert!(
            e.contains("turns back on itself by 180 deg at [0.0, 200.0]"),
            "{e}"
        );
        let mut s = square();
        s.waypoints = vec![[0.0, 30.0], [30.0, 30.0], [30.0, 0.0], [0.0, 0.0]];
        assert!(
            Level::plan(&s)
                .unwrap_err()
                .to_string()
                .contains("too short")
        );
        s = square();
        s.waypoints.pop();
        assert!(
            Level::plan(&s)
                .unwrap_err()
                .to_string()
                .contains("must be the start")
        );
        s = square();
        s.speed_mps = 0.0;
        assert!(
            Level::plan(&s)
                .unwrap_err()
                .to_string()
                .contains("positive")
        );
    }

    /// The heading's rotation built from its sine and cosine is nalgebra's from the angle, to
    /// the bit (this libm's `sin` odd and `cos` even): headings in every quadrant, either sign,
    /// zeros, multiples of pi/2, large angles and random ones.
    #[test]
    fn the_heading_rotation_from_its_sine_and_cosine_is_nalgebras_to_the_bit() {
        let mut angles = vec![
            0.0,
            -0.0,
            PI,
            -PI,
            PI / 2.0,
            -PI / 2.0,
            1e-300,
            -1e-300,
            1e6,
            -1e6,
        ];
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(0x9e37_79b9);
        for k in 0..20_000 {
            let u: f64 = rng.random();
            angles.push((u - 0.5) * if k % 2 == 0 { 2.0 * PI } else { 1e4 });
        }
        for psi in angles {
            let (sin_psi, cos_psi) = psi.sin_cos();
            let ours = c_b_n_heading(psi, sin_psi, cos_psi);
            let theirs = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), -psi).inverse();
            for (a, b) in ours.matrix().iter().zip(theirs.matrix().iter()) {
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "psi {psi:e}: {ours} against {theirs}"
                );
            }
        }
    }
}
