//! A land vehicle on a road as it is: climbing and descending, stopping at junctions, changing
//! speed within acceleration, braking and jerk limits, its body pitching and rolling on its
//! suspension and with the road's grade and bank, anywhere on the WGS-84 ellipsoid and over any
//! distance. Exact attitude, rate, specific force, velocity and position as functions of time.
//!
//! The plan has three layers, each pure: the road's shape along its length ([`path`]: heading,
//! grade and bank as functions of the distance `s`), where that shape lies on the ellipsoid
//! ([`geo`]: latitude, longitude and height as the exact integral along `s`), and the speed
//! along it in time ([`speed`]). The body's attitude is the road's heading, its pitch plus
//! `pitch_per_accel` times the longitudinal acceleration (squat and dive), its bank less
//! `roll_per_lateral_accel` times the lateral acceleration (the body leans out of a turn).
//! Rate and specific force follow from the navigation equations with WGS-84 earth rate,
//! transport rate and normal gravity at the current latitude and height:
//! `w_ib^b = C_n^b (w_ie^n + w_en^n) + w_nb^b`,
//! `f^b = C_n^b (dv^n/dt + (2 w_ie^n + w_en^n) x v^n - g^n)`.
//!
//! `Drive` plans a route this way when its `[drive]` table names any of the fields of a road
//! (heights, speeds per leg, stops, limits, suspension, bank); without them the level route of
//! [`crate::drive`] is driven as before.

pub(crate) mod geo;
pub(crate) mod path;
mod plan;
pub mod reference;
mod rough;
pub(crate) mod speed;
pub mod track;

use crate::geodesy as earth;
use crate::truth::{Increments, Motion, c_b_n};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

pub use plan::RoadNotes;

/// A planned road drive.
#[derive(Debug, Clone)]
pub struct Road {
    path: path::Path,
    placed: geo::Placed,
    phases: Vec<speed::Phase>,
    /// Pitch per m/s^2 of longitudinal acceleration, rad.
    pitch_per_accel: f64,
    /// Roll per m/s^2 of lateral acceleration, rad.
    roll_per_lateral: f64,
    /// The road's bumps (none: smooth).
    roughness: Option<rough::Roughness>,
    notes: RoadNotes,
    /// What was done with the recorded track it was fitted to, when it was.
    track: Option<Box<track::TrackNotes>>,
}

/// Everything of the motion at one time.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RoadState {
    /// Distance, speed, acceleration and jerk along the road.
    pub along: speed::Along,
    /// Heading, pitch, roll of the body, rad.
    pub hpr: [f64; 3],
    /// Their rates, rad/s.
    pub hpr_rate: [f64; 3],
    /// Velocity, ENU, m/s.
    pub v: Vector3<f64>,
    /// Its rate of change (components in the local level frame), m/s^2.
    pub dv: Vector3<f64>,
    /// The sines and cosines of heading and pitch (taken once: a node's largest cost).
    sc: [(f64, f64); 2],
}

impl Road {
    /// Duration of the plan, s (the vehicle stands still after it).
    pub fn duration(&self) -> f64 {
        self.phases.last().map_or(0.0, |p| p.t0 + p.dur)
    }

    /// Length of the road, m.
    pub fn length(&self) -> f64 {
        self.path.length
    }

    /// What the plan had to do and assume (speeds lowered, limits not met, how close it passes
    /// its waypoints).
    pub fn notes(&self) -> &RoadNotes {
        &self.notes
    }

    /// What was done with the recorded track the road was fitted to, when it was.
    pub fn track_notes(&self) -> Option<&track::TrackNotes> {
        self.track.as_deref()
    }

    pub(crate) fn state(&self, t: f64) -> RoadState {
        let a = speed::along(&self.phases, t);
        let r = self.path.at(a.s);
        let (v, acc, j) = (a.v, a.a, a.j);
        let lateral = v * v * r.kappa;
        let mut hpr = [
            r.psi,
            r.gamma + self.pitch_per_accel * acc,
            r.bank - self.roll_per_lateral * lateral,
        ];
        let mut hpr_rate = [
            r.kappa * v,
            r.dgamma * v + self.pitch_per_accel * j,
            r.dbank * v - self.roll_per_lateral * (2.0 * v * acc * r.kappa + v * v * v * r.dkappa),
        ];
        let (sg, cg) = r.gamma.sin_cos();
        let (sp, cp) = r.psi.sin_cos();
        let u = Vector3::new(cg * sp, cg * cp, sg);
        let du = Vector3::new(
            -sg * r.dgamma * sp + cg * cp * r.kappa,
            -sg * r.dgamma * cp - cg * sp * r.kappa,
            cg * r.dgamma,
        );
        // the pitch is the road's when the vehicle does not accelerate: its sine and cosine
        let sc_pitch = if hpr[1] == r.gamma {
            (sg, cg)
        } else {
            hpr[1].sin_cos()
        };
        let mut state = RoadState {
            along: a,
            hpr,
            hpr_rate,
            v: u * v,
            dv: u * acc + du * (v * v),
            sc: [(sp, cp), sc_pitch],
        };
        if let Some(rough) = &self.roughness {
            // the bumps: pitch and roll on top, the heave straight up (its rate d/ds times the
            // speed, its acceleration d2/ds2 times the speed squared plus d/ds times the
            // acceleration along the road)
            let [p, q, z] = rough.at(a.s);
            hpr[1] += p.value;
            hpr[2] += q.value;
            hpr_rate[1] += p.d1 * v;
            hpr_rate[2] += q.d1 * v;
            state.hpr = hpr;
            state.hpr_rate = hpr_rate;
            state.sc[1] = hpr[1].sin_cos();
            state.v.z += z.d1 * v;
            state.dv.z += z.d2 * v * v + z.d1 * acc;
        }
        state
    }

    /// The heave of the road's bumps `s` metres along it, m (0 on a smooth road).
    fn heave(&self, s: f64) -> f64 {
        self.roughness.as_ref().map_or(0.0, |r| r.heave(s))
    }

    /// Distance driven along the road, m.
    pub fn distance(&self, t: f64) -> f64 {
        speed::along(&self.phases, t).s
    }

    /// Latitude, longitude (rad) and height (m).
    pub fn position(&self, t: f64) -> (f64, f64, f64) {
        let s = speed::along(&self.phases, t).s;
        let [lat, lon, h] = self.placed.llh(&self.path, s);
        (lat, lon, h + self.heave(s))
    }

    /// Velocity in ENU, m/s.
    pub fn velocity(&self, t: f64) -> Vector3<f64> {
        self.state(t).v
    }

    /// The vehicle's vertical acceleration, m/s^2 (over crests and dips, and the road's bumps
    /// on a rough road).
    pub fn vertical_accel(&self, t: f64) -> f64 {
        self.state(t).dv.z
    }

    /// Heading, pitch and roll of the body, rad.
    pub fn hpr(&self, t: f64) -> [f64; 3] {
        self.state(t).hpr
    }

    /// Speed (m/s), heading (rad), acceleration along the road (m/s^2) and heading rate
    /// (rad/s).
    pub fn kinematics(&self, t: f64) -> (f64, f64, f64, f64) {
        let s = self.state(t);
        (s.along.v, s.hpr[0], s.along.a, s.hpr_rate[0])
    }

    /// The body's rotation relative to ENU (body to ENU) and its rate relative to ENU in body
    /// axes, rad/s.
    pub fn rotation(&self, t: f64) -> (Rotation3<f64>, Vector3<f64>) {
        let f = Frames::of(&self.state(t));
        (Rotation3::from_matrix_unchecked(f.cbn), f.omega_nb)
    }

    fn rate_force(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let s = self.state(t);
        let (lat, h) = self.placed.lat_h(&self.path, s.along.s);
        let h = h + self.heave(s.along.s);
        let (sl, cl) = lat.sin_cos();
        let (rm, rn) = earth::radii_sc(sl, cl);
        let wie = Vector3::from(earth::earth_rate_enu_sc(sl, cl));
        let lon_rate = s.v.x / ((rn + h) * cl);
        let wen = Vector3::new(-s.v.y / (rm + h), lon_rate * cl, lon_rate * sl);
        let f = Frames::of(&s);
        let cnb = f.cbn.transpose();
        let omega = cnb * (wie + wen) + f.omega_nb;
        let g = Vector3::new(0.0, 0.0, -earth::gravity_sc(sl, cl, h));
        let force = cnb * (s.dv + (2.0 * wie + wen).cross(&s.v) - g);
        (omega, force)
    }
}

/// The body's attitude as matrices, from one sine and cosine of each angle:
/// `C_b^n = Rz(-psi) Rx(theta) Ry(phi)` (as [`c_b_n`]), and the body's rate relative to ENU
/// from the angles' rates.
struct Frames {
    cbn: Matrix3<f64>,
    omega_nb: Vector3<f64>,
}

impl Frames {
    fn of(s: &RoadState) -> Self {
        let ph = s.hpr[2];
        let [dpsi, dth, dph] = s.hpr_rate;
        let [(sp, cp), (st, ct)] = s.sc;
        let (sf, cf) = ph.sin_cos();
        let rz = Matrix3::new(cp, sp, 0.0, -sp, cp, 0.0, 0.0, 0.0, 1.0);
        let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, ct, -st, 0.0, st, ct);
        let ry = Matrix3::new(cf, 0.0, sf, 0.0, 1.0, 0.0, -sf, 0.0, cf);
        let omega_nb = ry.transpose()
            * (rx.transpose() * Vector3::new(0.0, 0.0, -dpsi) + Vector3::new(dth, 0.0, 0.0))
            + Vector3::new(0.0, dph, 0.0);
        Self {
            cbn: rz * rx * ry,
            omega_nb,
        }
    }
}

impl Motion for Road {
    fn omega_ib_b(&self, t: f64) -> Vector3<f64> {
        self.rate_force(t).0
    }

    fn f_b(&self, t: f64) -> Vector3<f64> {
        self.rate_force(t).1
    }

    fn rate_and_force(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        self.rate_force(t)
    }

    fn increments(&self, t0: f64, t1: f64) -> Increments {
        // smooth within a phase of the speed profile: 3 nodes are exact to rounding on a sample
        // interval; every phase's start inside it (a step in jerk, so in the pitch rate: a
        // change of speed may be shorter than a sample, two starts in one interval) and the
        // plan's end split the interval
        let i = self.phases.partition_point(|p| p.t0 <= t0);
        let starts = self.phases[i..].iter().map(|p| p.t0);
        crate::truth::gauss_legendre3_pieces(
            t0,
            t1,
            starts.chain(std::iter::once(self.duration())),
            |t| self.rate_force(t),
        )
    }

    fn attitude(&self, t: f64) -> UnitQuaternion<f64> {
        let s = self.state(t);
        UnitQuaternion::from_rotation_matrix(&c_b_n(s.hpr[0], s.hpr[1], s.hpr[2]))
    }

    fn inertial_attitude(&self, t: f64) -> UnitQuaternion<f64> {
        let (lat, lon, _) = self.position(t);
        crate::truth::inertial_from_enu(lat, lon, t, self.attitude(t))
    }

    fn latitude(&self, t: f64) -> f64 {
        let s = speed::along(&self.phases, t).s;
        self.placed.lat_h(&self.path, s).0
    }
}

#[cfg(test)]
mod tests;
