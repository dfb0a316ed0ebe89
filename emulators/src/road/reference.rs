//! A reference strapdown integration of a motion's own ideal increments, written on the truth
//! side and sharing nothing with nav: the check that the truth's rate, specific force, attitude,
//! velocity and position are one motion. If the increments the IMU is given and the position
//! the receiver and the scoring are given disagree, this integration walks away from the truth.
//!
//! ENU local-level mechanisation: the attitude quaternion updated by the body's rotation vector
//! (with the two-sample coning term) and by the navigation frame's rotation over the interval
//! (earth rate and transport rate at the interval's middle), the velocity by the specific-force
//! increment (with rotation and sculling terms) less Coriolis and plus normal gravity at the
//! middle, the position by the trapezoid of the velocities over the radii of curvature. The
//! vertical channel of a free inertial integration diverges (its time constant is about 10
//! minutes) whatever its accuracy, so the height and vertical velocity are the truth's, as a
//! barometer would hold them, for long runs (`hold_vertical`); over minutes it is free too and
//! shows the vertical specific force and gravity agree.

use crate::geodesy as earth;
use crate::truth::Motion;
use nalgebra::{UnitQuaternion, Vector3};

/// The truth the integration starts from and is compared with.
pub trait Truth {
    /// Latitude, longitude (rad), height (m).
    fn llh(&self, t: f64) -> [f64; 3];
    /// Velocity, ENU, m/s.
    fn vel(&self, t: f64) -> Vector3<f64>;
    /// Body to ENU.
    fn q_bn(&self, t: f64) -> UnitQuaternion<f64>;
}

/// The integration's errors against the truth at one time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefError {
    /// Time, s.
    pub t: f64,
    /// Horizontal position error, m.
    pub horizontal_m: f64,
    /// Velocity error (horizontal), m/s.
    pub velocity_mps: f64,
    /// Attitude error (the angle of the rotation between the two), rad.
    pub attitude_rad: f64,
    /// Height error, m.
    pub vertical_m: f64,
}

/// Integrate `m`'s increments at `rate_hz` from the truth at 0 to `t_end`, reporting the errors
/// every `every_s`; the height and vertical velocity the truth's where `hold_vertical`.
pub fn integrate(
    m: &dyn Motion,
    truth: &dyn Truth,
    rate_hz: f64,
    t_end: f64,
    every_s: f64,
    hold_vertical: bool,
) -> Vec<RefError> {
    let dt = 1.0 / rate_hz;
    let mut q = truth.q_bn(0.0);
    let mut v = truth.vel(0.0);
    let mut llh = truth.llh(0.0);
    let mut prev: Option<(Vector3<f64>, Vector3<f64>)> = None;
    let mut v_prev = v;
    let mut out = Vec::new();
    let n = (t_end * rate_hz).round() as u64;
    let report = (every_s * rate_hz).round().max(1.0) as u64;
    for k in 0..n {
        let (t0, t1) = (k as f64 * dt, (k + 1) as f64 * dt);
        let inc = m.increments(t0, t1);
        let (dth, dv) = (inc.dtheta, inc.dv);
        let (pth, pdv) = prev.unwrap_or((dth, dv));
        let phi = dth + pth.cross(&dth) / 12.0;
        let dv_b = dv + 0.5 * dth.cross(&dv) + (pth.cross(&dv) + pdv.cross(&dth)) / 12.0;
        prev = Some((dth, dv));
        // the navigation frame's rates at the interval's middle (velocity extrapolated)
        let v_mid = v + 0.5 * (v - v_prev);
        let (lat, h) = (llh[0] + 0.5 * v_mid.y * dt / earth::radii(llh[0]).0, llh[2]);
        let (sl, cl) = lat.sin_cos();
        let (rm, rn) = earth::radii(lat);
        let wie = Vector3::from(earth::earth_rate_enu_sc(sl, cl));
        let wen = Vector3::new(
            -v_mid.y / (rm + h),
            v_mid.x / (rn + h),
            v_mid.x * sl / (cl * (rn + h)),
        );
        let zeta = (wie + wen) * dt;
        let g = Vector3::new(0.0, 0.0, -earth::gravity_sc(sl, cl, h));
        let dv_n = (q * dv_b) - 0.5 * zeta.cross(&(q * dv_b));
        let v_new = v + dv_n + (g - (2.0 * wie + wen).cross(&v_mid)) * dt;
        q = UnitQuaternion::from_scaled_axis(-zeta) * q * UnitQuaternion::from_scaled_axis(phi);
        // position: the trapezoid of the velocities; the vertical channel held to the truth
        let v_new = if hold_vertical {
            Vector3::new(v_new.x, v_new.y, truth.vel(t1).z)
        } else {
            v_new
        };
        let rm0 = earth::radii(llh[0]).0;
        let lat1 = llh[0] + 0.5 * (v.y + v_new.y) * dt / (rm0 + h);
        let lat_m = 0.5 * (llh[0] + lat1);
        let (rmm, rnm) = earth::radii(lat_m);
        let lat1 = llh[0] + 0.5 * (v.y + v_new.y) * dt / (rmm + h);
        let lon1 = llh[1] + 0.5 * (v.x + v_new.x) * dt / ((rnm + h) * lat_m.cos());
        let h1 = if hold_vertical {
            truth.llh(t1)[2]
        } else {
            h + 0.5 * (v.z + v_new.z) * dt
        };
        llh = [lat1, lon1, h1];
        v_prev = v;
        v = v_new;
        if (k + 1) % report == 0 || k + 1 == n {
            out.push(error_at(truth, t1, llh, v, q));
        }
    }
    out
}

fn error_at(
    truth: &dyn Truth,
    t: f64,
    llh: [f64; 3],
    v: Vector3<f64>,
    q: UnitQuaternion<f64>,
) -> RefError {
    let tl = truth.llh(t);
    let (rm, rn) = earth::radii(tl[0]);
    let dn = (llh[0] - tl[0]) * (rm + tl[2]);
    let de = (llh[1] - tl[1]) * (rn + tl[2]) * tl[0].cos();
    let tv = truth.vel(t);
    RefError {
        t,
        horizontal_m: dn.hypot(de),
        velocity_mps: (v.x - tv.x).hypot(v.y - tv.y),
        attitude_rad: (truth.q_bn(t).inverse() * q).angle(),
        vertical_m: llh[2] - tl[2],
    }
}

impl Truth for crate::drive::Drive {
    fn llh(&self, t: f64) -> [f64; 3] {
        let (a, b, c) = self.position(t);
        [a, b, c]
    }
    fn vel(&self, t: f64) -> Vector3<f64> {
        self.velocity(t)
    }
    fn q_bn(&self, t: f64) -> UnitQuaternion<f64> {
        self.attitude(t)
    }
}

/// How far a drive's truth may depart from the reference integration of its own increments
/// and still be one motion: the bench's promise about its truth, checked on every drive it
/// scores in process.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Bound {
    /// Horizontal position, m.
    pub horizontal_m: f64,
    /// Horizontal velocity, m/s.
    pub velocity_mps: f64,
    /// Attitude, rad.
    pub attitude_rad: f64,
}

/// A road's bound (exact on the ellipsoid): the shipped roads and tracks depart by at most
/// 3 mm, 1e-6 m/s and 1e-9 rad (the 2.3-hour highway, the pass), ten to a hundred times within.
pub const ROAD_BOUND: Bound = Bound {
    horizontal_m: 0.1,
    velocity_mps: 1e-4,
    attitude_rad: 2e-8,
};

/// A level route's bound: its latitude and longitude come from metres on the plane of its
/// start (the radii and the parallel's scale of the start held), an approximation that grows
/// with the distance north or south driven; the shipped level routes depart by at most 4.3 m,
/// 8.4 mm/s and 1.4e-6 rad (an hour at 61 N). A level route beyond it is better driven as a
/// road (any field of a road, `heights_m` for one, plans it on the ellipsoid).
pub const LEVEL_BOUND: Bound = Bound {
    horizontal_m: 10.0,
    velocity_mps: 0.02,
    attitude_rad: 1e-5,
};

/// Where the truth's departure was largest or first passed its bound.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Place {
    /// Time on the drive's clock, s.
    pub t: f64,
    /// Latitude and longitude, deg.
    pub lat_lon_deg: [f64; 2],
    /// The departure there.
    pub horizontal_m: f64,
    /// See [`Place::horizontal_m`].
    pub velocity_mps: f64,
    /// See [`Place::horizontal_m`].
    pub attitude_rad: f64,
}

/// The truth's self-check over one drive: the reference integration of the truth's ideal
/// increments at the IMU's rate against the truth's position, velocity and attitude (the
/// vertical channel held, as for any run longer than minutes).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SelfCheck {
    /// Seconds of the drive checked.
    pub checked_s: f64,
    /// The integration's rate, Hz.
    pub rate_hz: f64,
    /// Largest horizontal position departure, m.
    pub horizontal_m: f64,
    /// Largest horizontal velocity departure, m/s.
    pub velocity_mps: f64,
    /// Largest attitude departure, rad.
    pub attitude_rad: f64,
    /// The bound it is held to (a road's or a level route's).
    pub bound: Bound,
    /// The first place where a departure passed the bound (none: the truth is one motion).
    pub first_past: Option<Place>,
}

impl SelfCheck {
    /// Within its bound all along.
    pub fn holds(&self) -> bool {
        self.first_past.is_none()
    }

    /// One line for people: the departures against the bound, and where it first broke.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "the truth's self-check over {:.0} s at {:.0} Hz: horizontal {:.2e} m, velocity {:.2e} m/s, attitude {:.2e} rad (bound {:e} m, {:e} m/s, {:e} rad)",
            self.checked_s,
            self.rate_hz,
            self.horizontal_m,
            self.velocity_mps,
            self.attitude_rad,
            self.bound.horizontal_m,
            self.bound.velocity_mps,
            self.bound.attitude_rad
        );
        if let Some(p) = &self.first_past {
            s += &format!(
                "; past its bound from {:.3} s at {:.6} {:.6} deg ({:.2e} m, {:.2e} m/s, {:.2e} rad): the bench's truth disagrees with itself there, not the navigator",
                p.t,
                p.lat_lon_deg[0],
                p.lat_lon_deg[1],
                p.horizontal_m,
                p.velocity_mps,
                p.attitude_rad
            );
        }
        s
    }
}

/// Check `drive`'s truth against the reference integration of its own increments at `rate_hz`
/// over its first `t_end` s, every 10 ms, with the bound of its kind.
pub fn self_check(drive: &crate::drive::Drive, rate_hz: f64, t_end: f64) -> SelfCheck {
    let bound = if drive.road().is_some() {
        ROAD_BOUND
    } else {
        LEVEL_BOUND
    };
    check_motion(drive, drive, bound, rate_hz, t_end)
}

/// [`self_check`] of the increments of any motion `m` against any `truth`, held to `bound`.
pub fn check_motion(
    m: &dyn Motion,
    truth: &dyn Truth,
    bound: Bound,
    rate_hz: f64,
    t_end: f64,
) -> SelfCheck {
    let t_end = t_end.max(0.0);
    let e = integrate(m, truth, rate_hz, t_end, 0.01, true);
    let past = |x: &RefError| {
        !(x.horizontal_m <= bound.horizontal_m
            && x.velocity_mps <= bound.velocity_mps
            && x.attitude_rad <= bound.attitude_rad)
    };
    let first_past = e.iter().find(|x| past(x)).map(|x| {
        let [lat, lon, _] = truth.llh(x.t);
        Place {
            t: x.t,
            lat_lon_deg: [lat.to_degrees(), lon.to_degrees()],
            horizontal_m: x.horizontal_m,
            velocity_mps: x.velocity_mps,
            attitude_rad: x.attitude_rad,
        }
    });
    let worst = |f: fn(&RefError) -> f64| e.iter().map(f).fold(0.0, f64::max);
    SelfCheck {
        checked_s: t_end,
        rate_hz,
        horizontal_m: worst(|x| x.horizontal_m),
        velocity_mps: worst(|x| x.velocity_mps),
        attitude_rad: worst(|x| x.attitude_rad),
        bound,
        first_past,
    }
}
