//! Foxglove's well-known schemas on nav's recording: views of nav's own records that viewers
//! (Foxglove, Lichtblick and others that read MCAP) draw without being told our field names.
//!
//! The recorder's writer thread derives them from the records nav already makes, so the receive
//! path does no extra work and each view is made in one place:
//! - `/nav/location` (`foxglove.LocationFix`) from `/nav/solution`: position, the filter's
//!   position covariance (ENU, m^2, "known"), heading and ENU velocity: the Map panel's track;
//! - `/gps/location` (`foxglove.LocationFix`) from `/gps/fix` (valid GGA fixes): the
//!   receiver's track beside nav's; no covariance (the receiver does not report one);
//! - `/nav/pose` (`foxglove.PoseInFrame`) from `/nav/solution`: the vehicle in frame
//!   `nav_start_enu` (metres east, north and up of the first solution, nav's own earth model),
//!   oriented x forward, y left, z up, for the 3D panel;
//! - `/nav/log` (`foxglove.Log`) from `/nav/event`: every event as a log line, with a level
//!   (progress and recoveries are INFO, the rest WARNING), for the Log panel.
//!
//! Timestamps are IMU time (the message's publish time): nav's clock, as everywhere in the
//! recording. The schemas (`nav/schemas/foxglove/`) are Foxglove's JSON schemas, MIT licence.

use crate::frontend::gps_receiver::GpsFix;
use crate::record::channels::JsonChannel;
use nalgebra::UnitQuaternion;
use serde_json::{Value, json};

/// Frame of `/nav/pose`.
pub const POSE_FRAME: &str = "nav_start_enu";

/// `foxglove.Time` of a time in ns.
/// A Foxglove `time` of `ns` nanoseconds.
pub fn time(ns: u64) -> Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

/// `position_covariance_type` of a LocationFix: the full covariance is known.
pub const COVARIANCE_KNOWN: u8 = 3;
/// `position_covariance_type` of a LocationFix: its diagonal is known.
pub const COVARIANCE_DIAGONAL: u8 = 2;

/// Foxglove `Log` levels.
pub const LOG_INFO: u8 = 2;
/// Warning.
pub const LOG_WARNING: u8 = 3;

/// A `foxglove.Log` message at `ns` from `name`.
pub fn log(ns: u64, level: u8, name: &str, message: String) -> Value {
    json!({
        "timestamp": time(ns),
        "level": level,
        "message": message,
        "name": name,
        "file": "",
        "line": 0,
    })
}

/// Body (x forward, y left, z up) to ENU for a heading clockwise from north, pitch nose-up
/// and roll right-wing-down, all in degrees (nav's `hpr_deg`).
pub fn orientation_enu(hpr_deg: [f64; 3]) -> UnitQuaternion<f64> {
    let [h, p, r] = hpr_deg.map(f64::to_radians);
    // yaw from east, counter-clockwise; about the left axis a nose-up pitch is negative
    UnitQuaternion::from_euler_angles(r, -p, std::f64::consts::FRAC_PI_2 - h)
}

/// Derives the Foxglove views from nav's records; keeps the origin of `/nav/pose`.
#[derive(Debug, Default)]
pub struct Views {
    origin: Option<(f64, f64, f64)>,
}

impl Views {
    /// The Foxglove messages derived from one record on `channel` (published at `publish_ns`)
    /// go to `out` as (channel, JSON). A record that does not parse derives nothing.
    pub fn derive(
        &mut self,
        channel: JsonChannel,
        publish_ns: u64,
        text: &str,
        out: &mut Vec<(JsonChannel, String)>,
    ) {
        match channel {
            JsonChannel::Solution => self.solution(publish_ns, text, out),
            JsonChannel::Gps => {
                let Ok(f) = serde_json::from_str::<GpsFix>(text) else {
                    return;
                };
                if f.sentence != "GGA" || !f.valid || f.quality == 0 {
                    return;
                }
                let m = json!({
                    "timestamp": time(publish_ns),
                    "frame_id": "gps_antenna",
                    "latitude": f.lat_deg,
                    "longitude": f.lon_deg,
                    "altitude": f.ellipsoid_height_m().unwrap_or(0.0),
                    "position_covariance": vec![0.0; 9],
                    "position_covariance_type": 0,
                });
                out.push((JsonChannel::GpsLocation, m.to_string()));
            }
            JsonChannel::Event => {
                let Ok(v) = serde_json::from_str::<Value>(text) else {
                    return;
                };
                let kind = v["kind"].as_str().unwrap_or("event");
                let info = matches!(kind, "north_finding_progress" | "imu_back")
                    || (kind == "integrity" && v["alarm"] == false);
                let level = if info { LOG_INFO } else { LOG_WARNING };
                let m = log(publish_ns, level, "nav", format!("{kind}: {text}"));
                out.push((JsonChannel::Log, m.to_string()));
            }
            _ => {}
        }
    }

    fn solution(&mut self, publish_ns: u64, text: &str, out: &mut Vec<(JsonChannel, String)>) {
        let Ok(v) = serde_json::from_str::<Value>(text) else {
            return;
        };
        let o = &v["output"];
        let (Some(lat), Some(lon), Some(h)) = (
            o["lat_deg"].as_f64(),
            o["lon_deg"].as_f64(),
            o["h_m"].as_f64(),
        ) else {
            return;
        };
        let three = |x: &Value| -> Option<[f64; 3]> {
            let a = x.as_array()?;
            Some([
                a.first()?.as_f64()?,
                a.get(1)?.as_f64()?,
                a.get(2)?.as_f64()?,
            ])
        };
        let (Some(hpr), Some(vel)) = (three(&o["hpr_deg"]), three(&o["vel_enu_mps"])) else {
            return;
        };
        let cov: Option<Vec<f64>> = v["pos_cov_enu_m2"]
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_f64).collect())
            .filter(|c: &Vec<f64>| c.len() == 9);
        let cov = cov.map(|c| (c, COVARIANCE_KNOWN));
        let (loc, pose) = self.location_and_pose(publish_ns, [lat, lon, h], hpr, vel, cov);
        out.push((JsonChannel::Location, loc.to_string()));
        out.push((JsonChannel::Pose, pose.to_string()));
    }

    /// A solution's `foxglove.LocationFix` (frame `nav`) and `foxglove.PoseInFrame` (frame
    /// [`POSE_FRAME`], whose origin is the first position given): position `llh` (deg, deg,
    /// m), heading, pitch, roll `hpr` (deg), ENU velocity (m/s), and the ENU position
    /// covariance (m^2, row-major) with its Foxglove type ([`COVARIANCE_KNOWN`],
    /// [`COVARIANCE_DIAGONAL`]) when known. nav's recorder and the bench's live view (from the
    /// NAV_* frames) make them here, so they look the same.
    pub fn location_and_pose(
        &mut self,
        publish_ns: u64,
        llh: [f64; 3],
        hpr: [f64; 3],
        vel: [f64; 3],
        cov: Option<(Vec<f64>, u8)>,
    ) -> (Value, Value) {
        let [lat, lon, h] = llh;
        let (cov, cov_type) = cov.unwrap_or_else(|| (vec![0.0; 9], 0));
        let loc = json!({
            "timestamp": time(publish_ns),
            "frame_id": "nav",
            "latitude": lat,
            "longitude": lon,
            "altitude": h,
            "position_covariance": cov,
            "position_covariance_type": cov_type,
            "heading": hpr[0].to_radians(),
            "velocity": {"x": vel[0], "y": vel[1], "z": vel[2]},
        });
        let [east, north, up] = self.offset(llh);
        let q = orientation_enu(hpr);
        let pose = json!({
            "timestamp": time(publish_ns),
            "frame_id": POSE_FRAME,
            "pose": {
                "position": {"x": east, "y": north, "z": up},
                "orientation": {"x": q.i, "y": q.j, "z": q.k, "w": q.w},
            },
        });
        (loc, pose)
    }

    /// Metres east, north and up of [`POSE_FRAME`]'s origin (the first position given; nav's
    /// own earth model), for position `llh` (deg, deg, m).
    pub fn offset(&mut self, llh: [f64; 3]) -> [f64; 3] {
        let [lat, lon, h] = llh;
        let (lat0, lon0, h0) = *self.origin.get_or_insert((lat, lon, h));
        let (rm, rn) = crate::navigation::earth::radii(lat0.to_radians());
        let east = (lon - lon0).to_radians() * (rn + h0) * lat0.to_radians().cos();
        let north = (lat - lat0).to_radians() * (rm + h0);
        [east, north, h - h0]
    }

    /// [`POSE_FRAME`]'s origin (latitude, longitude deg, height m), once a position came.
    pub fn origin(&self) -> Option<(f64, f64, f64)> {
        self.origin
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn the_pose_points_the_way_the_vehicle_heads() {
        let fwd = |hpr| orientation_enu(hpr) * Vector3::x();
        let close = |a: Vector3<f64>, b: [f64; 3]| (a - Vector3::from(b)).norm() < 1e-12;
        assert!(close(fwd([0.0, 0.0, 0.0]), [0.0, 1.0, 0.0]), "north");
        assert!(close(fwd([90.0, 0.0, 0.0]), [1.0, 0.0, 0.0]), "east");
        assert!(close(
            fwd([225.0, 0.0, 0.0]),
            [-0.5f64.sqrt(), -0.5f64.sqrt(), 0.0]
        ));
        let s = 10f64.to_radians().sin_cos();
        assert!(close(fwd([0.0, 10.0, 0.0]), [0.0, s.1, s.0]), "nose up");
        // right wing down: the left axis tilts up
        let left = orientation_enu([0.0, 0.0, 10.0]) * Vector3::y();
        assert!(close(left, [-s.1, 0.0, s.0]), "{left:?}");
    }

    #[test]
    fn views_of_a_solution_a_fix_and_an_event() {
        let mut v = Views::default();
        let mut out = Vec::new();
        let sol = |lat: f64| {
            json!({"t_s": 1.0, "mode": "GpsAided",
                "output": {"lat_deg": lat, "lon_deg": 18.4, "h_m": 5.0,
                           "vel_enu_mps": [1.0, 2.0, 0.0], "hpr_deg": [30.0, 0.0, 0.0]},
                "pos_sigma_m": 3.0, "heading_sigma_deg": 0.1,
                "pos_cov_enu_m2": [4.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 9.0]})
            .to_string()
        };
        v.derive(JsonChannel::Solution, 1_500_000_000, &sol(-33.9), &mut out);
        v.derive(
            JsonChannel::Solution,
            2_500_000_000,
            &sol(-33.9001),
            &mut out,
        );
        assert_eq!(out.len(), 4);
        let loc: Value = serde_json::from_str(&out[0].1).unwrap();
        assert_eq!(out[0].0, JsonChannel::Location);
        assert_eq!(loc["timestamp"], json!({"sec": 1, "nsec": 500_000_000}));
        assert_eq!(loc["position_covariance_type"], 3);
        assert_eq!(loc["position_covariance"][4], 5.0);
        let pose: Value = serde_json::from_str(&out[3].1).unwrap();
        let y = pose["pose"]["position"]["y"].as_f64().unwrap();
        assert!(
            (y + 11.09).abs() < 0.02,
            "0.0001 deg south is about 11.09 m: {y}"
        );
        out.clear();
        let fix = GpsFix {
            sentence: "GGA".into(),
            lat_deg: -33.9,
            lon_deg: 18.4,
            quality: 1,
            valid: true,
            ..GpsFix::default()
        };
        v.derive(
            JsonChannel::Gps,
            0,
            &serde_json::to_string(&fix).unwrap(),
            &mut out,
        );
        let rmc = GpsFix {
            sentence: "RMC".into(),
            ..fix
        };
        v.derive(
            JsonChannel::Gps,
            0,
            &serde_json::to_string(&rmc).unwrap(),
            &mut out,
        );
        v.derive(
            JsonChannel::Event,
            0,
            "{\"kind\":\"gap\",\"missing\":3}",
            &mut out,
        );
        v.derive(JsonChannel::Event, 0, "not json", &mut out);
        assert_eq!(
            out.iter().map(|x| x.0).collect::<Vec<_>>(),
            [JsonChannel::GpsLocation, JsonChannel::Log]
        );
        assert!(out[1].1.contains("\"level\":3"));
    }
}
