//! WGS-84 earth model: radii of curvature, earth rate, normal gravity.
//!
//! Local-level frame: east, north, up (ENU). Body frame: x right, y forward, z up.

/// Semi-major axis, m.
pub const A: f64 = 6_378_137.0;
/// Flattening.
pub const F: f64 = 1.0 / 298.257_223_563;
/// First eccentricity squared.
pub const E2: f64 = F * (2.0 - F);
/// Earth rotation rate, rad/s.
pub const OMEGA_IE: f64 = 7.292_115e-5;
/// Equatorial normal gravity, m/s^2.
const GAMMA_E: f64 = 9.780_325_335_9;
/// Somigliana constant k = (b gamma_p) / (a gamma_e) - 1.
const SOMIGLIANA_K: f64 = 0.001_931_852_652_41;
/// m = omega^2 a^2 b / GM.
const M_RATIO: f64 = 0.003_449_786_506_84;

/// Meridian radius of curvature R_M and transverse (prime vertical) radius R_N at latitude `lat` (rad).
pub fn radii(lat: f64) -> (f64, f64) {
    let s2 = lat.sin().powi(2);
    let w = (1.0 - E2 * s2).sqrt();
    let rn = A / w;
    let rm = A * (1.0 - E2) / (w * w * w);
    (rm, rn)
}

/// Normal gravity magnitude at latitude `lat` (rad) and height `h` (m): Somigliana with the
/// second-order free-air correction.
pub fn gravity(lat: f64, h: f64) -> f64 {
    let s2 = lat.sin().powi(2);
    let g0 = GAMMA_E * (1.0 + SOMIGLIANA_K * s2) / (1.0 - E2 * s2).sqrt();
    g0 * (1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 * h * h / (A * A))
}

/// The vertical gradient of normal gravity `d gravity / d h` at latitude `lat` (rad) and height
/// `h` (m), 1/s^2 (negative: about -3.09e-6, gravity weakening upwards).
pub fn gravity_gradient(lat: f64, h: f64) -> f64 {
    let s2 = lat.sin().powi(2);
    let g0 = GAMMA_E * (1.0 + SOMIGLIANA_K * s2) / (1.0 - E2 * s2).sqrt();
    g0 * (-2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) + 6.0 * h / (A * A))
}

/// Earth rate in the ENU frame at latitude `lat` (rad), rad/s.
pub fn earth_rate_enu(lat: f64) -> [f64; 3] {
    [0.0, OMEGA_IE * lat.cos(), OMEGA_IE * lat.sin()]
}

/// Degrees per hour in one rad/s.
pub const DEG_PER_HOUR_PER_RAD_S: f64 = 180.0 / std::f64::consts::PI * 3600.0;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gravity_matches_wgs84_reference_values() {
        // WGS-84 normal gravity on the ellipsoid: equator 9.7803253359, pole 9.8321849378
        assert!((gravity(0.0, 0.0) - 9.780_325_335_9).abs() < 1e-9);
        assert!((gravity(std::f64::consts::FRAC_PI_2, 0.0) - 9.832_184_937_8).abs() < 1e-7);
        // about -3.086e-6 s^-2 per metre of height
        let dg = gravity(0.5, 1000.0) - gravity(0.5, 0.0);
        assert!((dg + 3.086e-3).abs() < 2e-5, "{dg}");
    }

    #[test]
    fn the_gravity_gradient_is_the_derivative_of_gravity() {
        for (lat, h) in [(0.0, 0.0), (0.97, 200.0), (1.4, 2500.0), (-0.6, -400.0)] {
            let d = 0.5;
            let fd = (gravity(lat, h + d) - gravity(lat, h - d)) / (2.0 * d);
            let g = gravity_gradient(lat, h);
            assert!((g - fd).abs() < 1e-12, "{lat} {h}: {g} against {fd}");
            assert!((-3.1e-6..-3.07e-6).contains(&g), "{g}");
        }
    }

    #[test]
    fn radii_at_equator_and_pole() {
        let (rm, rn) = radii(0.0);
        assert!((rn - A).abs() < 1e-6);
        assert!((rm - A * (1.0 - E2)).abs() < 1e-6);
        let (rm, rn) = radii(std::f64::consts::FRAC_PI_2);
        assert!((rm - rn).abs() < 1e-6);
    }

    #[test]
    fn earth_rate_is_15_041_deg_per_hour() {
        let w = earth_rate_enu(0.3);
        let n = (w[1] * w[1] + w[2] * w[2]).sqrt() * DEG_PER_HOUR_PER_RAD_S;
        assert!((n - 15.041).abs() < 1e-3, "{n}");
    }
}
