//! Navigation scored against truth: a solution's errors at a simulated time with the truth
//! side's geodesy (ECEF), never with nav's, and a bench run's recording scored sample by sample
//! with its NEES; the same scoring serves the in-process runs ([`super::navigate`]) and the
//! bench's runs on vcan.

use crate::stats::wrap180;
use emulators::drive::Drive;
use emulators::geodesy::enu_offset;
use emulators::imu::ImuTimescale;
use nalgebra::Vector3;
use nav::navigation::strapdown::NavOutput;
use serde::Serialize;

/// A navigation output's errors against the drive at simulated time `t`: horizontal position
/// (m, through ECEF), velocity (east, north, up, m/s), heading (deg).
pub(crate) fn errors(drive: &Drive, t: f64, o: &NavOutput) -> (f64, [f64; 3], f64) {
    let (e, dv, dh) = errors_enu(drive, t, o);
    (e[0].hypot(e[1]), dv, dh)
}

/// [`errors`] with the position error per axis (east, north, up, m).
pub(crate) fn errors_enu(drive: &Drive, t: f64, o: &NavOutput) -> ([f64; 3], [f64; 3], f64) {
    let truth = drive.position(t);
    let e = enu_offset(
        truth,
        (o.lat_deg.to_radians(), o.lon_deg.to_radians(), o.h_m),
    );
    let v = drive.velocity(t);
    let dv = [
        o.vel_enu_mps[0] - v.x,
        o.vel_enu_mps[1] - v.y,
        o.vel_enu_mps[2] - v.z,
    ];
    let dh = wrap180(o.hpr_deg[0] - drive.heading(t).to_degrees());
    (e, dv, dh)
}

/// nav's navigation output scored against truth.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct NavScore {
    /// IMU time of the output, s.
    pub t_s: f64,
    /// Horizontal position error, m.
    pub position_error_m: f64,
    /// Velocity error, m/s.
    pub velocity_error_mps: f64,
    /// Heading error, deg.
    pub heading_error_deg: f64,
    /// nav's own horizontal position sigma at that output (from its recording), m.
    #[serde(default)]
    pub position_sigma_m: Option<f64>,
    /// nav's own heading sigma at that output, deg.
    #[serde(default)]
    pub heading_sigma_deg: Option<f64>,
    /// The wall time nav logged that output at (from its recording), ns since the epoch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub logged_wall_ns: Option<u64>,
    /// Where nav and the truth are (east, north of the drive's start; m): the track.
    #[serde(default)]
    pub track_en_m: Option<[[f64; 2]; 2]>,
    /// Position error (east, north, up), m.
    #[serde(default)]
    pub position_error_enu_m: Option<[f64; 3]>,
    /// Velocity error (east, north, up), m/s.
    #[serde(default)]
    pub velocity_error_enu_mps: Option<[f64; 3]>,
    /// Pitch and roll errors, deg (a drive is level: truth 0 and 0).
    #[serde(default)]
    pub tilt_error_deg: Option<[f64; 2]>,
    /// nav's own velocity sigmas (east, north, up), m/s.
    #[serde(default)]
    pub velocity_sigma_enu_mps: Option<[f64; 3]>,
    /// nav's own tilt sigma (the mean of its east and north ones), deg.
    #[serde(default)]
    pub tilt_sigma_deg: Option<f64>,
    /// NEES of the position and of the velocity (3 degrees of freedom each), against nav's own
    /// covariances.
    #[serde(default)]
    pub nees: Option<[f64; 2]>,
}

/// Score the navigation output in a nav summary against the drive (none when nav did not
/// navigate). nav counts time in the IMU's samples from its first one: `imu` maps that time to
/// the simulation's (the IMU's oscillator need not run at its nominal rate).
pub fn score_summary(
    drive: &Drive,
    nav: &nav::summary::Summary,
    imu: &ImuTimescale,
) -> Option<NavScore> {
    let n = nav.navigation.as_ref()?;
    Some(score_output(
        drive,
        imu.sim_time(n.output_t_s),
        n.output.as_ref()?,
    ))
}

/// A bench run's navigation over time (from nav's recording).
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct SeriesStats {
    /// Seconds scored.
    pub samples: usize,
    /// RMS horizontal position error, m.
    pub rms_position_error_m: f64,
    /// Largest horizontal position error, m.
    pub max_position_error_m: f64,
    /// Records that could not be read.
    pub bad_records: u64,
    /// Mean NEES per degree of freedom over the run, position and velocity (1 when nav's
    /// covariance is consistent with its errors; none without nav's covariances).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_nees_per_dof: Option<[f64; 2]>,
}

impl SeriesStats {
    /// Statistics of `scores`.
    pub fn of(scores: &[NavScore], bad_records: u64) -> Self {
        let n = scores.len();
        Self {
            samples: n,
            rms_position_error_m: (scores
                .iter()
                .map(|x| x.position_error_m.powi(2))
                .sum::<f64>()
                / n.max(1) as f64)
                .sqrt(),
            max_position_error_m: scores
                .iter()
                .map(|x| x.position_error_m)
                .fold(0.0, f64::max),
            bad_records,
            mean_nees_per_dof: {
                let v: Vec<[f64; 2]> = scores.iter().filter_map(|x| x.nees).collect();
                (!v.is_empty()).then(|| {
                    let k = 3.0 * v.len() as f64;
                    [
                        v.iter().map(|x| x[0]).sum::<f64>() / k,
                        v.iter().map(|x| x[1]).sum::<f64>() / k,
                    ]
                })
            },
        }
    }
}

/// One navigation output at simulated time `t` against the drive's truth.
pub fn score_output(drive: &Drive, t: f64, o: &NavOutput) -> NavScore {
    let (e, dv, dh) = errors_enu(drive, t, o);
    let origin = drive.position(0.0);
    let truth = drive.position(t);
    let to_en = |p: (f64, f64, f64)| {
        let x = enu_offset(origin, p);
        [x[0], x[1]]
    };
    NavScore {
        t_s: t,
        position_error_m: e[0].hypot(e[1]),
        velocity_error_mps: Vector3::from(dv).norm(),
        heading_error_deg: dh,
        position_sigma_m: None,
        heading_sigma_deg: None,
        logged_wall_ns: None,
        track_en_m: Some([
            to_en((o.lat_deg.to_radians(), o.lon_deg.to_radians(), o.h_m)),
            to_en(truth),
        ]),
        position_error_enu_m: Some(e),
        velocity_error_enu_mps: Some(dv),
        // against the body's pitch and roll (a level route's are zero)
        tilt_error_deg: {
            let [_, p, r] = drive.hpr(t);
            Some([o.hpr_deg[1] - p.to_degrees(), o.hpr_deg[2] - r.to_degrees()])
        },
        velocity_sigma_enu_mps: None,
        tilt_sigma_deg: None,
        nees: None,
    }
}

/// A 3x3 covariance from a row-major JSON array.
pub(crate) fn cov3(v: &serde_json::Value) -> Option<nalgebra::Matrix3<f64>> {
    let a = v.as_array()?;
    (a.len() == 9).then_some(())?;
    let x: Vec<f64> = a.iter().map(|x| x.as_f64()).collect::<Option<_>>()?;
    Some(nalgebra::Matrix3::from_row_slice(&x))
}

/// nav's recording read against a drive, message by message ([`RecordingScorer::message`]),
/// so that one reading of the recording serves the replay and the scoring alike.
pub struct RecordingScorer<'a> {
    drive: &'a Drive,
    imu: ImuTimescale,
    origin: (f64, f64, f64),
    scored: ScoredRecording,
}

/// What [`RecordingScorer`] found in nav's recording.
#[derive(Debug, Default, Serialize, serde::Deserialize)]
pub struct ScoredRecording {
    /// nav's recorded solution (`/nav/solution`, 1 Hz) against the drive: one score per second
    /// (nav's time plus the first sample's).
    pub scores: Vec<NavScore>,
    /// Solution records that could not be read, and one more when the recording was cut
    /// short.
    pub bad: u64,
    /// The receiver's fixes nav took (`/gps/fix`, GGA) and those its filter refused
    /// (`/nav/event` `fix_rejected`): IMU time of the record (s), east and north of the
    /// drive's start (m), and their fate.
    pub fixes: Vec<(f64, [f64; 2], FixFate)>,
}

impl<'a> RecordingScorer<'a> {
    /// A scorer of nav's recording against `drive`; `imu`: the IMU's time scale (nav's time
    /// to the simulation's).
    pub fn new(drive: &'a Drive, imu: ImuTimescale) -> Self {
        Self {
            drive,
            imu,
            origin: drive.position(0.0),
            scored: ScoredRecording::default(),
        }
    }

    /// Take the recording's next message.
    pub fn message(&mut self, m: &mcap::Message) {
        match m.channel.topic.as_str() {
            "/nav/solution" => self.solution(m),
            "/gps/fix" => {
                let Ok(f) = serde_json::from_slice::<nav::frontend::gps_receiver::GpsFix>(&m.data)
                else {
                    return;
                };
                if f.sentence == "GGA" {
                    let fate = if f.valid {
                        FixFate::Valid
                    } else {
                        FixFate::Void
                    };
                    self.fix(m, f.lat_deg, f.lon_deg, fate);
                }
            }
            "/nav/event" => {
                let Ok(e) = serde_json::from_slice::<serde_json::Value>(&m.data) else {
                    return;
                };
                if e["kind"] == "fix_rejected"
                    && let (Some(lat), Some(lon)) = (e["lat_deg"].as_f64(), e["lon_deg"].as_f64())
                {
                    self.fix(m, lat, lon, FixFate::Rejected);
                }
            }
            _ => {}
        }
    }

    fn fix(&mut self, m: &mcap::Message, lat_deg: f64, lon_deg: f64, fate: FixFate) {
        let o = self.origin;
        let x = enu_offset(o, (lat_deg.to_radians(), lon_deg.to_radians(), o.2));
        let t = m.publish_time as f64 * 1e-9;
        self.scored.fixes.push((t, [x[0], x[1]], fate));
    }

    fn solution(&mut self, m: &mcap::Message) {
        let j: Option<serde_json::Value> = serde_json::from_slice(&m.data).ok();
        let parsed = j.as_ref().and_then(|j| {
            let o: nav::navigation::strapdown::NavOutput =
                serde_json::from_value(j["output"].clone()).ok()?;
            Some((j["t_s"].as_f64()?, o))
        });
        let Some((t, o)) = parsed else {
            self.scored.bad += 1;
            return;
        };
        // the sigmas nav sent with the solution (zero: not yet known)
        let sigma = |k: &str| j.as_ref().and_then(|j| j[k].as_f64()).filter(|v| *v > 0.0);
        let cov = |k: &str| j.as_ref().and_then(|j| cov3(&j[k]));
        let sc = score_output(self.drive, self.imu.sim_time(t), &o);
        let (pc, vc) = (cov("pos_cov_enu_m2"), cov("vel_cov_enu_m2s2"));
        let nees = match (pc, vc, sc.position_error_enu_m, sc.velocity_error_enu_mps) {
            (Some(pc), Some(vc), Some(e), Some(dv)) => nees(&e, &pc).zip(nees(&dv, &vc)),
            _ => None,
        };
        let tilt = j.as_ref().and_then(|j| {
            let a = j["att_sigma_enu_deg"].as_array()?;
            Some(0.5 * (a.first()?.as_f64()? + a.get(1)?.as_f64()?))
        });
        self.scored.scores.push(NavScore {
            position_sigma_m: sigma("pos_sigma_m"),
            heading_sigma_deg: sigma("heading_sigma_deg"),
            logged_wall_ns: Some(m.log_time),
            velocity_sigma_enu_mps: vc.map(|c| std::array::from_fn(|i| c[(i, i)].max(0.0).sqrt())),
            tilt_sigma_deg: tilt,
            nees: nees.map(|(a, b)| [a, b]),
            ..sc
        });
    }

    /// What was found; `cut`: the recording ended cut short (a recording cut short still
    /// gives what it has).
    pub fn finish(mut self, cut: bool) -> ScoredRecording {
        self.scored.bad += u64::from(cut);
        self.scored
    }
}

/// What became of a fix nav took.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
pub enum FixFate {
    /// The receiver said it had no fix (quality 0, status V).
    Void,
    /// A fix (used, unless a rejection at the same place follows).
    Valid,
    /// The filter's gate refused it (`fix_rejected` in nav's events).
    Rejected,
}

pub(crate) fn nees(e: &[f64; 3], p: &nalgebra::Matrix3<f64>) -> Option<f64> {
    let e = Vector3::from(*e);
    p.try_inverse().map(|pi| (e.transpose() * pi * e)[(0, 0)])
}
