//! What the receiver's antenna truly does: its position and velocity on the drive.

/// The truth the receiver sees at a fix: antenna position and velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AntennaTruth {
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
    /// Height above the ellipsoid, m.
    pub h_m: f64,
    /// Velocity east, north, up, m/s.
    pub vel_enu: [f64; 3],
}

/// The antenna's truth on a drive: the vehicle's position and velocity moved by the lever arm
/// (body frame: x right, y forward, z up; on a level route only the heading turns it, on a
/// road the body's whole attitude).
pub fn antenna_truth(drive: &crate::drive::Drive, t: f64, lever_arm_m: [f64; 3]) -> AntennaTruth {
    if let Some(r) = drive.road() {
        return road_antenna(r, t, lever_arm_m);
    }
    let (lat, lon, h) = drive.position(t);
    let (_, psi, _, psi_rate, _) = drive.kinematics(t);
    let v = drive.velocity(t);
    let [lx, ly, lz] = lever_arm_m;
    let (s, c) = psi.sin_cos();
    // lever arm in ENU and its rate as the vehicle turns
    let (de, dn) = (lx * c + ly * s, -lx * s + ly * c);
    let (ve, vn) = (psi_rate * (-lx * s + ly * c), psi_rate * (-lx * c - ly * s));
    let (rm, rn) = crate::geodesy::radii(lat);
    AntennaTruth {
        lat_deg: (lat + dn / (rm + h)).to_degrees(),
        lon_deg: (lon + de / ((rn + h) * lat.cos())).to_degrees(),
        h_m: h + lz,
        vel_enu: [v.x + ve, v.y + vn, v.z],
    }
}

/// [`antenna_truth`] on a road: the lever arm turned by the body's attitude, its rate by the
/// body's rate relative to ENU.
fn road_antenna(r: &crate::road::Road, t: f64, lever_arm_m: [f64; 3]) -> AntennaTruth {
    let (lat, lon, h) = r.position(t);
    let v = r.velocity(t);
    let (cbn, w_nb) = r.rotation(t);
    let l = nalgebra::Vector3::from(lever_arm_m);
    let d = cbn * l;
    let dv = cbn * w_nb.cross(&l);
    let (rm, rn) = crate::geodesy::radii(lat);
    AntennaTruth {
        lat_deg: (lat + d.y / (rm + h)).to_degrees(),
        lon_deg: (lon + d.x / ((rn + h) * lat.cos())).to_degrees(),
        h_m: h + d.z,
        vel_enu: [v.x + dv.x, v.y + dv.y, v.z + dv.z],
    }
}
