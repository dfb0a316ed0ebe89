//! Strapdown navigation in the local-level frame.
//!
//! Frame: ENU (east, north, up) at the vehicle; body x right, y forward, z up. State: attitude
//! `q_nb` (body to navigation), velocity `v^n`, geodetic latitude, longitude and height on
//! WGS-84. Each update takes the processing chain's rotation vector `phi` (coning compensated)
//! and velocity increment `dv` (rotation and sculling compensated) over `T = n h`:
//!
//! - attitude: `q_nb <- exp(-w_in^n T) * q_nb * exp(phi)`, with `w_in = w_ie + w_en` (earth rate
//!   and transport rate at the mid-interval state);
//! - velocity: `v += (I - [zeta x] / 2) C_nb dv + (g^n - (2 w_ie + w_en) x v) T`,
//!   `zeta = w_in T` (the navigation frame's own turn over the interval), normal gravity;
//! - position: trapezoidal integration of the velocity (old and new) through the radii of
//!   curvature. At 500 updates per second its error is far below the sensors' (a 4th-order
//!   Runge-Kutta, as paper 003 uses, would change the position by micrometres).

use crate::navigation::earth;
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// The navigation state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavState {
    /// Body to navigation (ENU) attitude.
    pub q_nb: UnitQuaternion<f64>,
    /// Velocity, ENU, m/s.
    pub v: Vector3<f64>,
    /// Latitude, rad.
    pub lat: f64,
    /// Longitude, rad.
    pub lon: f64,
    /// Height, m.
    pub h: f64,
}

/// A printable snapshot.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct NavOutput {
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
    /// Height, m.
    pub h_m: f64,
    /// Velocity east, north, up, m/s.
    pub vel_enu_mps: [f64; 3],
    /// Heading (clockwise from north), pitch, roll, deg.
    pub hpr_deg: [f64; 3],
}

impl NavState {
    /// From heading, pitch, roll (rad), velocity and position.
    pub fn from_euler(
        heading: f64,
        pitch: f64,
        roll: f64,
        v: Vector3<f64>,
        lat: f64,
        lon: f64,
        h: f64,
    ) -> Self {
        let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -heading)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), pitch)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), roll);
        Self {
            q_nb: q,
            v,
            lat,
            lon,
            h,
        }
    }

    /// Heading (clockwise from north), pitch, roll, rad.
    pub fn euler(&self) -> (f64, f64, f64) {
        let c = self.q_nb.to_rotation_matrix();
        let m = c.matrix();
        // C = Rz(-psi) Rx(theta) Ry(phi): column y of C is the forward axis in ENU
        let pitch = m[(2, 1)].clamp(-1.0, 1.0).asin();
        let heading = m[(0, 1)].atan2(m[(1, 1)]);
        let roll = (-m[(2, 0)]).atan2(m[(2, 2)]);
        (heading, pitch, roll)
    }

    /// Snapshot in degrees.
    pub fn output(&self) -> NavOutput {
        let (h, p, r) = self.euler();
        NavOutput {
            lat_deg: self.lat.to_degrees(),
            lon_deg: self.lon.to_degrees(),
            h_m: self.h,
            vel_enu_mps: self.v.into(),
            hpr_deg: [
                h.to_degrees().rem_euclid(360.0),
                p.to_degrees(),
                r.to_degrees(),
            ],
        }
    }

    /// Earth rate and transport rate in the navigation frame at this state.
    pub fn rates(&self) -> (Vector3<f64>, Vector3<f64>) {
        let (rm, rn) = earth::radii(self.lat);
        let wie = Vector3::from(earth::earth_rate_enu(self.lat));
        let wen = Vector3::new(
            -self.v.y / (rm + self.h),
            self.v.x / (rn + self.h),
            self.v.x * self.lat.tan() / (rn + self.h),
        );
        (wie, wen)
    }

    /// One update over `t` seconds with rotation vector `phi` and velocity increment `dv`
    /// (body axes, from the processing chain).
    pub fn update(&mut self, phi: [f64; 3], dv: [f64; 3], t: f64) {
        let (wie, wen) = self.rates();
        let win = wie + wen;
        let zeta = win * t;
        // velocity: specific force rotated with the attitude at the start of the interval and
        // the navigation frame's own turn over it
        let dv_n = self.q_nb * Vector3::from(dv);
        let dv_sf = dv_n - 0.5 * zeta.cross(&dv_n);
        let g = Vector3::new(0.0, 0.0, -earth::gravity(self.lat, self.h));
        let v_old = self.v;
        let v_new = v_old + dv_sf + (g - (2.0 * wie + wen).cross(&v_old)) * t;
        // attitude
        self.q_nb = UnitQuaternion::from_scaled_axis(-zeta)
            * self.q_nb
            * crate::frontend::processing::rotation_vector_to_quaternion(phi);
        self.q_nb.renormalize_fast();
        // position: trapezoid
        let va = 0.5 * (v_old + v_new);
        let (rm, rn) = earth::radii(self.lat);
        let dlat = va.y / (rm + self.h) * t;
        let lat_mid = self.lat + 0.5 * dlat;
        self.lat += dlat;
        self.lon += va.x / ((rn + self.h) * lat_mid.cos()) * t;
        self.h += va.z * t;
        self.v = v_new;
    }

    /// Position error against another state, metres east, north, up.
    pub fn position_error_m(&self, truth: &NavState) -> Vector3<f64> {
        let (rm, rn) = earth::radii(truth.lat);
        Vector3::new(
            (self.lon - truth.lon) * (rn + truth.h) * truth.lat.cos(),
            (self.lat - truth.lat) * (rm + truth.h),
            self.h - truth.h,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_round_trip() {
        let s = NavState::from_euler(0.7, 0.05, -0.03, Vector3::zeros(), 0.5, 2.0, 10.0);
        let (h, p, r) = s.euler();
        assert!((h - 0.7).abs() < 1e-12 && (p - 0.05).abs() < 1e-12 && (r + 0.03).abs() < 1e-12);
    }

    #[test]
    fn a_perfect_static_imu_stays_put() {
        // exact earth rate and gravity in the body: the state must not move
        let lat = 28.2f64.to_radians();
        let mut s = NavState::from_euler(0.3, 0.0, 0.0, Vector3::zeros(), lat, 1.0, 0.0);
        let c_bn = s.q_nb.inverse();
        let w_b = c_bn * Vector3::from(earth::earth_rate_enu(lat));
        let f_b = c_bn * Vector3::new(0.0, 0.0, earth::gravity(lat, 0.0));
        let t = 0.002;
        // the chain's rotation compensation: dv = f t + (w t) x (f t) / 2
        let dv = f_b * t + 0.5 * (w_b * t).cross(&(f_b * t));
        for _ in 0..(600.0 / t) as usize {
            s.update((w_b * t).into(), dv.into(), t);
        }
        let truth = NavState::from_euler(0.3, 0.0, 0.0, Vector3::zeros(), lat, 1.0, 0.0);
        let e = s.position_error_m(&truth);
        assert!(e.norm() < 1e-3, "{e}");
        assert!(s.v.norm() < 1e-5, "{}", s.v);
        assert!((s.euler().0 - 0.3).abs() < 1e-9);
    }
}
