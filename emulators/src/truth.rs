//! Truth motion: exact attitude, angular rate and specific force as pure functions of time.
//!
//! Frames: navigation frame ENU (east, north, up); body frame x right, y forward, z up.
//! Heading is clockwise from north, pitch nose up, roll right wing down positive.

use nalgebra::{Rotation3, Vector3};
use nav::earth;
use serde::{Deserialize, Serialize};

/// Exact sensor-frame increments over one interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Increments {
    /// Angle increment of the body w.r.t. inertial space, rad (body axes).
    pub dtheta: Vector3<f64>,
    /// Specific-force velocity increment, m/s (body axes).
    pub dv: Vector3<f64>,
}

/// A motion the IMU undergoes.
pub trait Motion: Send {
    /// Exact increments over `(t0, t1]`, integrated (not rate times dt).
    fn increments(&self, t0: f64, t1: f64) -> Increments;
    /// Geodetic latitude (rad) at `t`.
    fn latitude(&self, t: f64) -> f64;
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
    /// Body angular rate w.r.t. inertial space, rad/s.
    pub fn omega_ib_b(&self) -> Vector3<f64> {
        let cbn = c_b_n(
            self.heading_deg.to_radians(),
            self.pitch_deg.to_radians(),
            self.roll_deg.to_radians(),
        );
        cbn.inverse() * Vector3::from(earth::earth_rate_enu(self.lat_deg.to_radians()))
    }

    /// Specific force in the body frame, m/s^2.
    pub fn f_b(&self) -> Vector3<f64> {
        let cbn = c_b_n(
            self.heading_deg.to_radians(),
            self.pitch_deg.to_radians(),
            self.roll_deg.to_radians(),
        );
        let g = earth::gravity(self.lat_deg.to_radians(), self.height_m);
        cbn.inverse() * Vector3::new(0.0, 0.0, g)
    }
}

impl Motion for Static {
    fn increments(&self, t0: f64, t1: f64) -> Increments {
        // constant rate about a fixed axis: the integral is exact
        let dt = t1 - t0;
        Increments {
            dtheta: self.omega_ib_b() * dt,
            dv: self.f_b() * dt,
        }
    }

    fn latitude(&self, _t: f64) -> f64 {
        self.lat_deg.to_radians()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_north_facing_static_sees_earth_rate_and_gravity() {
        let s = Static {
            lat_deg: 28.2,
            lon_deg: 0.0,
            height_m: 0.0,
            heading_deg: 0.0,
            pitch_deg: 0.0,
            roll_deg: 0.0,
        };
        let w = s.omega_ib_b();
        let lat = 28.2f64.to_radians();
        assert!(w.x.abs() < 1e-15);
        assert!((w.y - earth::OMEGA_IE * lat.cos()).abs() < 1e-15);
        assert!((w.z - earth::OMEGA_IE * lat.sin()).abs() < 1e-15);
        assert!((s.f_b().z - earth::gravity(lat, 0.0)).abs() < 1e-12);
    }

    #[test]
    fn heading_east_puts_north_rate_on_minus_x() {
        let s = Static {
            lat_deg: 0.0,
            lon_deg: 0.0,
            height_m: 0.0,
            heading_deg: 90.0,
            pitch_deg: 0.0,
            roll_deg: 0.0,
        };
        let w = s.omega_ib_b();
        // facing east, north is to the left (-x)
        assert!((w.x + earth::OMEGA_IE).abs() < 1e-12, "{w}");
        assert!(w.y.abs() < 1e-12);
    }

    #[test]
    fn nose_up_pitch_tilts_gravity_onto_forward_axis() {
        let s = Static {
            lat_deg: 0.0,
            lon_deg: 0.0,
            height_m: 0.0,
            heading_deg: 0.0,
            pitch_deg: 10.0,
            roll_deg: 0.0,
        };
        let f = s.f_b();
        let g = earth::gravity(0.0, 0.0);
        assert!((f.y - g * 10f64.to_radians().sin()).abs() < 1e-9, "{f}");
    }
}
