//! The truth side's own earth model (WGS-84), written apart from nav's so that an error in nav's
//! geodesy is never made again by the truth and cancelled: radii from the ellipse's two axes,
//! normal gravity from Somigliana's closed form with the equatorial and polar values, the earth's
//! rotation as a vector.

/// Semi-major axis, m.
pub const A: f64 = 6_378_137.0;
/// Semi-minor axis, m (b = a (1 - f), 1/f = 298.257223563).
pub const B: f64 = 6_356_752.314_245_179;
/// Earth rotation rate, rad/s.
pub const OMEGA: f64 = 7.292_115e-5;
/// Normal gravity at the equator and at the poles, m/s^2 (WGS-84).
pub const GAMMA_EQUATOR: f64 = 9.780_325_335_9;
/// See [`GAMMA_EQUATOR`].
pub const GAMMA_POLE: f64 = 9.832_184_937_8;
/// Geocentric gravitational constant, m^3/s^2.
pub const GM: f64 = 3.986_004_418e14;

/// (meridian, prime-vertical) radii of curvature at geodetic latitude `lat` (rad), m.
pub fn radii(lat: f64) -> (f64, f64) {
    let (s, c) = lat.sin_cos();
    radii_sc(s, c)
}

/// [`radii`] from the latitude's sine and cosine (the same operations, so the same bits).
pub fn radii_sc(s: f64, c: f64) -> (f64, f64) {
    let d = (A * c).powi(2) + (B * s).powi(2);
    let rn = A * A / d.sqrt();
    let rm = (A * B).powi(2) / (d * d.sqrt());
    (rm, rn)
}

/// Normal gravity (m/s^2) at geodetic latitude `lat` (rad) and height `h` (m): Somigliana's
/// closed form on the ellipsoid, then the second-order free-air reduction.
pub fn gravity(lat: f64, h: f64) -> f64 {
    let (s, c) = lat.sin_cos();
    gravity_sc(s, c, h)
}

/// [`gravity`] from the latitude's sine and cosine (a caller that has them saves computing
/// them again: the same operations, so the same bits).
pub fn gravity_sc(s: f64, c: f64, h: f64) -> f64 {
    let g0 = (A * GAMMA_EQUATOR * c * c + B * GAMMA_POLE * s * s)
        / ((A * c).powi(2) + (B * s).powi(2)).sqrt();
    let f = (A - B) / A;
    let m = OMEGA * OMEGA * A * A * B / GM;
    g0 * (1.0 - 2.0 / A * (1.0 + f + m - 2.0 * f * s * s) * h + 3.0 * h * h / (A * A))
}

/// The earth's rotation in ENU axes at latitude `lat` (rad), rad/s.
pub fn earth_rate_enu(lat: f64) -> [f64; 3] {
    let (s, c) = lat.sin_cos();
    earth_rate_enu_sc(s, c)
}

/// [`earth_rate_enu`] from the latitude's sine and cosine.
pub fn earth_rate_enu_sc(s: f64, c: f64) -> [f64; 3] {
    [0.0, OMEGA * c, OMEGA * s]
}

/// Earth-centred, earth-fixed coordinates (m) of geodetic latitude, longitude (rad), height (m).
pub fn ecef(lat: f64, lon: f64, h: f64) -> [f64; 3] {
    let (_, rn) = radii(lat);
    let (sl, cl) = lat.sin_cos();
    let (so, co) = lon.sin_cos();
    let e2 = 1.0 - (B * B) / (A * A);
    [
        (rn + h) * cl * co,
        (rn + h) * cl * so,
        (rn * (1.0 - e2) + h) * sl,
    ]
}

/// Where point `to` lies from point `from` (both latitude, longitude in rad, height in m), in
/// east, north, up axes at `from`, m: the straight line between them through ECEF, exact at any
/// distance (the bench's ruler for nav's position errors, independent of nav's earth model).
pub fn enu_offset(from: (f64, f64, f64), to: (f64, f64, f64)) -> [f64; 3] {
    let a = ecef(from.0, from.1, from.2);
    let b = ecef(to.0, to.1, to.2);
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let (sl, cl) = from.0.sin_cos();
    let (so, co) = from.1.sin_cos();
    [
        -so * d[0] + co * d[1],
        -sl * co * d[0] - sl * so * d[1] + cl * d[2],
        cl * co * d[0] + cl * so * d[1] + sl * d[2],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Published WGS-84 values (NIMA TR8350.2): normal gravity at the equator and the pole, the
    /// radii there.
    #[test]
    fn published_wgs84_values() {
        let half_pi = std::f64::consts::FRAC_PI_2;
        assert!((gravity(0.0, 0.0) - 9.780_325_335_9).abs() < 1e-10);
        assert!((gravity(half_pi, 0.0) - 9.832_184_937_8).abs() < 1e-10);
        assert!((gravity(-half_pi, 0.0) - 9.832_184_937_8).abs() < 1e-10);
        // 45 deg: 9.806 197 77 (Somigliana with the WGS-84 constants)
        assert!((gravity(45f64.to_radians(), 0.0) - 9.806_197_77).abs() < 1e-8);
        let (rm, rn) = radii(0.0);
        assert!(
            (rn - A).abs() < 1e-6 && (rm - 6_335_439.327).abs() < 1e-3,
            "{rm} {rn}"
        );
        let (rm, rn) = radii(half_pi);
        assert!((rm - 6_399_593.626).abs() < 1e-3 && (rn - rm).abs() < 1e-6);
        // free air: about -3.086e-6 m/s^2 per metre at mid latitudes
        let dg = gravity(0.5, 1000.0) - gravity(0.5, 0.0);
        assert!((dg + 3.086e-3).abs() < 2e-5, "{dg}");
        // hemispheres are mirror images
        for l in [-80.0f64, -33.9, -5.0, 28.2, 60.0] {
            let (a, b) = (l.to_radians(), (-l).to_radians());
            assert!((gravity(a, 100.0) - gravity(b, 100.0)).abs() < 1e-12);
            assert!((earth_rate_enu(a)[2] + earth_rate_enu(b)[2]).abs() < 1e-18);
        }
    }

    /// ECEF of published points, and offsets against the radii for short distances.
    #[test]
    fn ecef_and_local_offsets() {
        let p = ecef(0.0, 0.0, 0.0);
        assert!((p[0] - A).abs() < 1e-6 && p[1].abs() < 1e-6 && p[2].abs() < 1e-6);
        let n = ecef(std::f64::consts::FRAC_PI_2, 0.0, 0.0);
        assert!((n[2] - B).abs() < 1e-6 && n[0].abs() < 1e-6, "{n:?}");
        for lat_deg in [-77.0, -33.92, 0.0, 28.2, 64.0] {
            let lat = f64::to_radians(lat_deg);
            let (rm, rn) = radii(lat);
            let from = (lat, 1.0, 40.0);
            // 1e-5 rad of latitude and longitude: about 64 m north, up to 64 m east
            let e = enu_offset(from, (lat + 1e-5, 1.0 + 1e-5, 40.0));
            assert!((e[1] - 1e-5 * (rm + 40.0)).abs() < 1e-3, "{lat_deg}: {e:?}");
            assert!(
                (e[0] - 1e-5 * (rn + 40.0) * lat.cos()).abs() < 1e-3,
                "{lat_deg}: {e:?}"
            );
            let up = enu_offset(from, (lat, 1.0, 52.5));
            assert!((up[2] - 12.5).abs() < 1e-9 && up[0].abs() < 1e-9 && up[1].abs() < 1e-9);
        }
    }
}
