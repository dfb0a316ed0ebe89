//! What `nav` reports at exit: one typed summary, written as `nav-summary.json`, recorded on
//! `/nav/summary` and printed for people. The bench reads the JSON back into these types, so a
//! missing or renamed field is an error naming it.

use crate::frontend::coning::ConingMethod;
use crate::frontend::dither_filter::FirResponse;
use crate::frontend::imu_frames::{Housekeeping, ImuStats};
use crate::frontend::processing::ProcessingStats;
use crate::procedures::common::Reporting;
use crate::procedures::mission::Mission;
use crate::procedures::north_finding::NorthFinding;
use crate::procedures::self_calibration::SelfCalibration;
use crate::procedures::tetra_calibration::TetraCalibration;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

pub use crate::procedures::north_finding::NorthFindingSummary;
pub use crate::procedures::self_calibration::SelfCalibrationSummary;
pub use crate::procedures::tetra_calibration::TetraCalibrationSummary;

/// The run summary.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Summary {
    /// CAN interface (`none` without a bus).
    pub interface: String,
    /// Data frames received.
    pub frames_total: u64,
    /// Frames received by message name.
    pub frames_by_message: BTreeMap<String, u64>,
    /// Frames with an id the wire contract does not have.
    pub unknown_id_frames: u64,
    /// Those ids, `0x...`.
    pub unknown_ids: Vec<String>,
    /// Frames of a known id with the wrong length.
    pub bad_length_frames: u64,
    /// Frames with a value outside its signal's range.
    pub invalid_value_frames: u64,
    /// Remote frames and other non-data frames (error frames: [`Summary::can_bus`]).
    pub non_data_frames: u64,
    /// What nav's CAN controller reported in error frames.
    #[serde(default)]
    pub can_bus: CanBusHealth,
    /// Socket read errors.
    pub read_errors: u64,
    /// Turntable commands the CAN socket refused (sent again by north-finding).
    #[serde(default)]
    pub command_send_errors: u64,
    /// Frames the kernel dropped because nav's receive buffer was full (the socket's drop
    /// counter, `SO_RXQ_OVFL`'s count): what reached the bus but not nav, counted exactly.
    #[serde(default)]
    pub kernel_dropped_frames: u64,
    /// The user id nav's process ran as (none in in-process runs). nav needs no privilege:
    /// a raw CAN socket and the serial port it is given.
    #[serde(default)]
    pub process_uid: Option<u32>,
    /// Front-end counters.
    pub imu: ImuStats,
    /// Longest counter gap the front end can difference, samples.
    pub max_safe_gap_samples: u32,
    /// First sample processed.
    pub first_sample: Option<u64>,
    /// Last sample processed.
    pub last_sample: Option<u64>,
    /// IMU time covered, s.
    pub imu_seconds: f64,
    /// Wall time of the run, s.
    pub wall_seconds: f64,
    /// Liveness timeouts (no IMU frame for the watchdog's time).
    pub imu_timeouts: u64,
    /// Mean of the filtered, coning-compensated rate over the run, deg/h.
    pub mean_rate_dph: [f64; 3],
    /// Mean of the filtered, sculling-compensated specific force, m/s^2.
    pub mean_specific_force_mps2: [f64; 3],
    /// Norm of the mean rate, deg/h.
    pub rate_norm_dph: f64,
    /// Norm of the mean specific force, m/s^2.
    pub specific_force_norm_mps2: f64,
    /// Processing-chain counters.
    pub processing: ProcessingStats,
    /// The integrated attitude.
    pub attitude: AttitudeSummary,
    /// North-finding, when it ran.
    pub north_finding: Option<NorthFindingSummary>,
    /// Self-calibration (calibration mode), when it ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub self_calibration: Option<SelfCalibrationSummary>,
    /// The redundant unit's calibration, when it ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tetra_calibration: Option<TetraCalibrationSummary>,
    /// The GPS receiver, when there is one.
    pub gps: Option<GpsSummary>,
    /// Navigation, when enabled.
    pub navigation: Option<crate::navigation::navigator::NavigatorSummary>,
    /// The IMU's last housekeeping.
    pub housekeeping: Housekeeping,
    /// The navigation solution sent on the bus (NAV_TIME..NAV_HGT at 50 Hz of IMU time).
    pub solution: SolutionSummary,
    /// Frames nav could not encode (a value the contract cannot carry): never silently lost.
    pub encode_errors: u64,
    /// Recording file.
    pub mcap: Option<PathBuf>,
    /// Messages recorded.
    pub mcap_messages: u64,
}

/// The solution output on the bus at exit.
#[derive(Debug, Clone, Serialize, Deserialize, Default, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SolutionSummary {
    /// Epochs encoded.
    pub epochs: u64,
    /// Frames written.
    pub frames_sent: u64,
    /// Frames the socket refused (the bus full); navigation is never held up by its output.
    pub send_errors: u64,
    /// The last epoch's mode.
    pub last_mode: Option<String>,
    /// A hash over every frame sent (solution and turntable commands) with the IMU sample each
    /// went at ([`crate::pipeline::Pipeline::sent_hash`]): equal for two runs that sent the
    /// same frames at the same samples.
    #[serde(default)]
    pub sent_hash: String,
    /// Solutions not sent because they named an earlier sample than one already sent (none
    /// expected; [`crate::navigation::solution_frames::SolutionEncoder::backwards`]).
    #[serde(default)]
    pub backwards: u64,
}

/// The GPS receiver at exit.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GpsSummary {
    /// Serial device.
    pub port: PathBuf,
    /// Stream counters.
    pub stats: crate::frontend::gps_receiver::GpsStats,
    /// Port trouble (read errors, the device vanishing), and re-opens.
    pub port_errors: u64,
    /// Times the port was (re)opened.
    pub opens: u64,
    /// Reads of the port that went into the pipeline because their wait for a frame received
    /// after them ended (`nav::shell::arrival`): 0 in a run whose IMU never stopped; more, and a
    /// lockstep run's frames may depend on the host's pace.
    #[serde(default)]
    pub reads_released_by_wait: u64,
    /// Fixes handed to navigation.
    pub fixes: u64,
    /// The last fix.
    pub last_fix: Option<crate::frontend::gps_receiver::GpsFix>,
    /// Export file.
    pub fixes_jsonl: Option<PathBuf>,
}

/// What only the shell around the pipeline knows: its devices, their I/O counts and the files
/// it wrote. [`crate::pipeline::Pipeline::summary_with`] builds the summary with them.
#[derive(Debug, Clone, Default)]
pub struct ShellCounts {
    /// CAN interface.
    pub interface: String,
    /// Socket read errors.
    pub read_errors: u64,
    /// Turntable commands the socket refused.
    pub command_send_errors: u64,
    /// Frames the kernel dropped at the socket (its receive buffer full).
    pub kernel_dropped_frames: u64,
    /// The user id nav ran as.
    pub process_uid: Option<u32>,
    /// Wall time from start to exit, s.
    pub wall_seconds: f64,
    /// Solution frames sent.
    pub frames_sent: u64,
    /// Solution frames the socket refused.
    pub send_errors: u64,
    /// The receiver's port, when nav reads one.
    pub gps: Option<GpsPortCounts>,
    /// The recording's file, when nav records.
    pub mcap: Option<PathBuf>,
    /// The parameter files written (where, when written, and what).
    pub parameter_files: Vec<(
        Option<PathBuf>,
        crate::procedures::unit_parameters::ParameterFile,
    )>,
}

/// The receiver's port as the shell saw it.
#[derive(Debug, Clone, Default)]
pub struct GpsPortCounts {
    /// Serial device.
    pub port: PathBuf,
    /// Port trouble (read errors, the device vanishing).
    pub port_errors: u64,
    /// Times the port was (re)opened.
    pub opens: u64,
    /// Reads released by their wait, not by a later frame.
    pub reads_released_by_wait: u64,
    /// Export file of the fixes.
    pub fixes_jsonl: Option<PathBuf>,
}

/// The integrated attitude at exit.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AttitudeSummary {
    /// The front end's first (baseline) sample.
    pub baseline_sample: Option<u64>,
    /// Sample the attitude is counted from (once the dither filter has filled).
    pub origin_sample: Option<i64>,
    /// Sample the attitude is valid at (last input minus the filter delay).
    pub valid_sample: i64,
    /// Samples between the two.
    pub span_samples: i64,
    /// Rotation of the body from origin to valid sample (inertial), as a rotation vector, deg.
    pub rotation_vector_deg: [f64; 3],
    /// Its angle, deg.
    pub angle_deg: f64,
    /// False when angle was lost (an ambiguous gap): the attitude is then unusable.
    pub valid: bool,
    /// Filter delay, samples.
    pub delay_samples: i64,
    /// The dither filter's measured response (none when it is off).
    pub fir: Option<FirResponse>,
    /// Coning algorithm.
    pub coning_method: ConingMethod,
    /// Coning coefficients k_1..k_(n-1).
    pub coning_coefficients: Vec<f64>,
}

fn v3(v: [f64; 3], prec: usize) -> String {
    format!("[{:.p$}, {:.p$}, {:.p$}]", v[0], v[1], v[2], p = prec)
}

fn opt<T: std::fmt::Display>(x: Option<T>) -> String {
    x.map_or_else(|| "-".into(), |v| v.to_string())
}

/// Procedure `m`'s section of summary `s` (`rep`: what the pipeline counted for it): the one
/// place that knows which field each procedure's section goes in.
pub(crate) fn put_section(s: &mut Summary, m: &dyn Mission, rep: &Reporting) {
    let any = m.as_any();
    if let Some(x) = any.downcast_ref::<NorthFinding>() {
        s.north_finding = Some(x.section(rep));
    } else if let Some(x) = any.downcast_ref::<SelfCalibration>() {
        s.self_calibration = Some(x.section(rep));
    } else if let Some(x) = any.downcast_ref::<TetraCalibration>() {
        s.tetra_calibration = Some(x.section(rep));
    }
}

impl Summary {
    /// The parameter files nav's procedures wrote, as the summary names them (to be moved
    /// along with nav's other files).
    pub fn written_files_mut(&mut self) -> impl Iterator<Item = &mut PathBuf> {
        let sc = self
            .self_calibration
            .as_mut()
            .and_then(|c| c.parameters_file.as_mut());
        let tc = self
            .tetra_calibration
            .as_mut()
            .and_then(|c| c.parameters_file.as_mut());
        sc.into_iter().chain(tc)
    }

    /// The summary for people, one aspect per line.
    pub fn text(&self) -> String {
        let mut o = String::new();
        let _ = writeln!(o, "nav summary ({})", self.interface);
        self.bus_text(&mut o);
        self.imu_text(&mut o);
        self.north_finding_text(&mut o);
        self.navigation_text(&mut o);
        self.outputs_text(&mut o);
        o
    }

    /// What came over the bus: frames by message, drops, IMU samples and gaps, bad frames.
    fn bus_text(&self, o: &mut String) {
        let s = self;
        let by: Vec<String> = s
            .frames_by_message
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect();
        let _ = writeln!(
            o,
            "  frames received   {} ({})",
            s.frames_total,
            by.join(", ")
        );
        let _ = writeln!(
            o,
            "  dropped by kernel {} (receive buffer full)",
            s.kernel_dropped_frames
        );
        let _ = writeln!(
            o,
            "  IMU samples       {} over {:.3} s of IMU time ({:.1} s wall)",
            s.imu.samples, s.imu_seconds, s.wall_seconds
        );
        let _ = writeln!(
            o,
            "  gaps              {} ({} samples lost, {} too long to difference), duplicates {}, backwards {}",
            s.imu.gaps,
            s.imu.missing_samples,
            s.imu.ambiguous_gaps,
            s.imu.duplicates,
            s.imu.backwards
        );
        let _ = writeln!(
            o,
            "  bad frames        unknown id {} [{}], wrong length {}, invalid {}, non-data {}, read errors {}, not encodable {}",
            s.unknown_id_frames,
            s.unknown_ids.join(", "),
            s.bad_length_frames,
            s.invalid_value_frames,
            s.non_data_frames,
            s.read_errors,
            s.encode_errors
        );
    }

    /// The IMU's own flags, its mean rate and force, the attitude, the integrity of the processing.
    fn imu_text(&self, o: &mut String) {
        let s = self;
        let _ = writeln!(
            o,
            "  accel frames      missing {}, unpaired {}; BIT-fail samples {}, saturated {}, PPS edges {}",
            s.imu.accel_missing,
            s.imu.accel_unpaired,
            s.imu.bit_fail_samples,
            s.imu.saturated_samples,
            s.imu.pps_edges
        );
        let _ = writeln!(
            o,
            "  mean rate         {} deg/h, |w| = {:.3} deg/h",
            v3(s.mean_rate_dph, 3),
            s.rate_norm_dph
        );
        let _ = writeln!(
            o,
            "  mean spec. force  {} m/s^2, |f| = {:.5} m/s^2",
            v3(s.mean_specific_force_mps2, 5),
            s.specific_force_norm_mps2
        );
        let a = &s.attitude;
        let _ = writeln!(
            o,
            "  attitude          {:.6} deg about {} deg over {} samples ({}), filter delay {} samples, coning {} n={}",
            a.angle_deg,
            v3(a.rotation_vector_deg, 6),
            a.span_samples,
            if a.valid {
                "valid"
            } else {
                "INVALID: angle lost in a gap"
            },
            a.delay_samples,
            a.coning_method,
            a.coning_coefficients.len() + 1
        );
        let _ = writeln!(
            o,
            "  integrity         {} samples filled across gaps, {} lost, {} suspect (saturated/BIT) from sample {}",
            s.processing.filled_samples,
            s.processing.lost_samples,
            s.processing.suspect_samples,
            opt(s.processing.first_suspect)
        );
        let _ = writeln!(o, "  IMU timeouts      {}", s.imu_timeouts);
    }

    /// North-finding's result or why it has none.
    fn north_finding_text(&self, o: &mut String) {
        let s = self;
        if let Some(nf) = &s.north_finding {
            match (&nf.result, &nf.abort) {
                (Some(r), _) => {
                    let _ = writeln!(
                        o,
                        "  north-finding     heading {:.4} deg, sigma {:.4} deg, {:.1} s, {} dwell(s) repeated; {} commands, {} turntable frames",
                        r.heading_deg,
                        r.sigma_deg,
                        r.duration_s,
                        r.repeats,
                        nf.commands_sent,
                        nf.turntable_frames
                    );
                }
                (None, Some(why)) => {
                    let _ = writeln!(o, "  north-finding     ABORTED: {why}");
                }
                (None, None) => {
                    let _ = writeln!(o, "  north-finding     not finished (phase {:?})", nf.phase);
                }
            }
        }
    }

    /// Navigation: the last output, the fixes, the filter, the integrity alarms.
    fn navigation_text(&self, o: &mut String) {
        let s = self;
        if let Some(n) = &s.navigation {
            match &n.output {
                Some(x) => {
                    let _ = writeln!(
                        o,
                        "  navigation        {:?} since {} s: lat {:.7} lon {:.7} h {:.1} m, vel {} m/s, heading {:.3} deg",
                        n.phase,
                        n.started_at_s
                            .map_or_else(|| "-".into(), |t| format!("{t:.2}")),
                        x.lat_deg,
                        x.lon_deg,
                        x.h_m,
                        v3(x.vel_enu_mps, 2),
                        x.hpr_deg[0]
                    );
                }
                None => {
                    let _ = writeln!(o, "  navigation        {:?} (not started)", n.phase);
                }
            }
            let _ = writeln!(
                o,
                "  fixes             {} seen, {} ignored, {} late, {} without a PPS edge; PPS edges {}, {} rejected",
                n.fixes_seen,
                n.fixes_ignored,
                n.late_fixes,
                n.untied_fixes,
                n.pps_edges,
                n.pps_rejected
            );
            if let Some(f) = &n.filter {
                let _ = writeln!(
                    o,
                    "  filter            {} fixes used, {} rejected, mean NIS {:.2}, {} re-anchored, {} relinearised; white noise now {:.1}/{:.1}/{:.1} m; gyro drift {} deg/h, accel bias {} m/s^2",
                    f.updates,
                    f.rejected,
                    f.mean_nis,
                    f.reanchors,
                    f.relinearised,
                    f.gps_sigma_now_m[0],
                    f.gps_sigma_now_m[1],
                    f.gps_sigma_now_m[2],
                    v3(f.gyro_bias_dph, 3),
                    v3(f.accel_bias_mps2, 5)
                );
            }
            let i = &n.integrity;
            let _ = writeln!(
                o,
                "  integrity         {} alarms (innovations {}, rejections {}, velocity {}, covariance {}){}; largest INS-receiver velocity difference {:.2} m/s",
                i.alarms,
                i.nis_alarms,
                i.rejection_alarms,
                i.velocity_alarms,
                i.covariance_alarms,
                if i.alarm { ", ON at the end" } else { "" },
                i.max_velocity_diff_mps
            );
        }
    }

    /// The receiver's port, the solution frames sent, the recording.
    fn outputs_text(&self, o: &mut String) {
        let s = self;
        if let Some(g) = &s.gps {
            let t = &g.stats;
            let _ = writeln!(
                o,
                "  GPS {}  fixes {} ({} no-fix, {} out of range, {} time backwards); sentences {}, bad checksum {}, unparsed {}, garbage bytes {}, binary lines {}, overlong {}; port errors {}, opens {}",
                g.port.display(),
                t.fixes,
                t.no_fix,
                t.out_of_range,
                t.time_backwards,
                t.accepted,
                t.bad_checksum,
                t.unparsed,
                t.garbage_bytes,
                t.binary_lines,
                t.overlong_lines,
                g.port_errors,
                g.opens
            );
        }
        let so = &s.solution;
        let _ = writeln!(
            o,
            "  solution          {} epochs, {} frames sent, {} refused, last mode {}",
            so.epochs,
            so.frames_sent,
            so.send_errors,
            so.last_mode.as_deref().unwrap_or("-")
        );
        if let Some(p) = &s.mcap {
            let _ = writeln!(
                o,
                "  recording         {} ({} messages)",
                p.display(),
                s.mcap_messages
            );
        }
    }

    /// Read a summary file (`nav-summary.json`).
    pub fn read(path: &std::path::Path) -> Result<Self, SummaryError> {
        let text = std::fs::read_to_string(path).map_err(|source| SummaryError::Read {
            path: path.into(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|source| SummaryError::Parse {
            path: path.into(),
            source,
        })
    }
}

/// Reading a summary failed.
#[derive(Debug, thiserror::Error)]
pub enum SummaryError {
    /// The file could not be read.
    #[error("cannot read nav's summary {path}")]
    Read {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// It is not a summary of this nav (a field missing, renamed or of the wrong type).
    #[error("nav's summary {path} does not match this bench's nav")]
    Parse {
        /// File.
        path: PathBuf,
        /// Cause (names the field).
        source: serde_json::Error,
    },
}

/// What nav's CAN controller reported in its error frames (`CAN_RAW_ERR_FILTER`: a Linux CAN
/// driver's bus errors, state changes, bus-off and restarts).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, Eq)]
pub struct CanBusHealth {
    /// Error frames received.
    pub error_frames: u64,
    /// Of which protocol violations and bus errors.
    pub bus_errors: u64,
    /// Times the controller reported error-warning.
    pub warnings: u64,
    /// Times it reported error-passive.
    pub passives: u64,
    /// Times it reported bus-off.
    pub bus_offs: u64,
    /// Times it restarted after bus-off.
    pub restarts: u64,
    /// Its state at the end: `active`, `warning`, `passive` or `bus-off` (empty: never
    /// reported).
    pub state: String,
    /// The worst state it reported.
    pub worst_state: String,
    /// Its transmit error counter, last reported.
    pub tx_errors: u8,
    /// Its receive error counter, last reported.
    pub rx_errors: u8,
    /// The largest transmit error counter reported.
    pub max_tx_errors: u8,
    /// The largest receive error counter reported.
    pub max_rx_errors: u8,
}

impl CanBusHealth {
    /// The name of a state in the summary.
    pub fn name(s: wire::errframe::ErrorState) -> &'static str {
        use wire::errframe::ErrorState as E;
        match s {
            E::Active => "active",
            E::Warning => "warning",
            E::Passive => "passive",
            E::BusOff => "bus-off",
        }
    }

    /// A state's rank, worst last (0: never reported or active).
    pub fn rank(state: &str) -> u8 {
        match state {
            "warning" => 1,
            "passive" => 2,
            "bus-off" => 3,
            _ => 0,
        }
    }
}
