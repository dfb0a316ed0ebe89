//! The receiver model: its parameters, and its epochs as the IMU clock passes their PPS edges
//! (pure: no I/O).

use super::{AntennaTruth, GpsError, GpsErrorParams, NmeaWriter, antenna_truth};

/// What the emulated receiver does (the `[gps]` table of a scenario).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ReceiverParams {
    /// Fixes per second (1-10).
    pub rate_hz: f64,
    /// Talker id (`GP`, `GN`, ...).
    pub talker: String,
    /// Position errors.
    pub errors: GpsErrorParams,
    /// Velocity noise (1 sigma), m/s.
    pub velocity_sigma_mps: f64,
    /// Antenna position in the body frame (x right, y forward, z up), m.
    pub lever_arm_m: [f64; 3],
    /// No fix before this time (time to first fix), s.
    pub ttff_s: f64,
    /// Outages (tunnels): [start, end] s; `void` sentences (status V, quality 0) or silence.
    pub outages: Vec<[f64; 2]>,
    /// During outages send void sentences (true) or nothing (false).
    pub outage_void: bool,
    /// Multipath jumps: [time s, duration s, metres] added to the north error.
    pub multipath: Vec<[f64; 3]>,
    /// Periods [start, end] s during which the receiver's device is gone (a USB receiver
    /// resetting): on the bench its pty closes and a new one appears behind the same link.
    pub port_drops: Vec<[f64; 2]>,
    /// Fix times (s) whose sentences carry a UTC time 10 s earlier than the last (a receiver
    /// whose clock steps back).
    pub time_backwards_at_s: Vec<f64>,
    /// Fix times (s) before whose sentences the receiver puts out line noise and a line of
    /// binary bytes (a receiver switching protocols, a noisy cable).
    pub garbage_at_s: Vec<f64>,
    /// Put out GST with each fix: the receiver's own 1-sigma estimate of its latitude,
    /// longitude and altitude errors (many receivers have it off by default: `false`).
    pub gst: bool,
}

impl Default for ReceiverParams {
    fn default() -> Self {
        Self {
            rate_hz: 1.0,
            talker: "GP".into(),
            errors: GpsErrorParams::class_25m(),
            velocity_sigma_mps: 0.3,
            lever_arm_m: [0.0, 0.5, 1.2],
            ttff_s: 0.0,
            outages: Vec::new(),
            outage_void: true,
            multipath: Vec::new(),
            port_drops: Vec::new(),
            time_backwards_at_s: Vec::new(),
            garbage_at_s: Vec::new(),
            gst: true,
        }
    }
}

/// What the receiver decided for one epoch, which the NMEA encoder ([`super::nmea::encode`])
/// writes.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// The UTC time of day it states, s (a step back where the receiver's clock steps back).
    pub time_of_day_s: f64,
    /// It carries a valid fix (not before the first fix, not in a void outage).
    pub valid: bool,
    /// Measured latitude and longitude, deg, and height above the ellipsoid, m.
    pub lat_deg: f64,
    /// Measured longitude, deg.
    pub lon_deg: f64,
    /// Measured height above the ellipsoid, m.
    pub h_m: f64,
    /// Measured velocity east and north, m/s.
    pub vel_en_mps: [f64; 2],
    /// Satellites used (0 without a fix).
    pub satellites: u32,
    /// Horizontal dilution of precision (99.9 without a fix).
    pub hdop: f64,
    /// The geoid's height above the ellipsoid at the antenna, m.
    pub geoid_m: f64,
    /// The position error applied (east, north, up), m: truth, never on the wire.
    pub error_enu: [f64; 3],
    /// The receiver's own 1-sigma of that error (east, north, up), m.
    pub sigma_enu: [f64; 3],
    /// Line noise and a line of binary bytes come before this epoch's sentences.
    pub garbage: bool,
}

/// The receiver's model without its encoding: its errors, outages, time to first fix,
/// multipath, clock steps and line noise decide each epoch.
pub struct ReceiverModel {
    p: ReceiverParams,
    err: GpsError,
    rng: rand::rngs::StdRng,
}

impl ReceiverModel {
    /// A receiver with these parameters.
    pub fn new(p: ReceiverParams) -> Self {
        use rand::SeedableRng;
        Self {
            err: GpsError::new(p.errors.clone()),
            rng: rand::rngs::StdRng::seed_from_u64(p.errors.seed ^ 0x5eed),
            p,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &ReceiverParams {
        &self.p
    }

    /// The epoch at `t` (s since the start; `utc0_s` is the UTC second of the day at t = 0)
    /// for the antenna at `truth`; none when the receiver is silent (an outage without void
    /// sentences).
    pub fn observe(&mut self, t: f64, utc0_s: f64, truth: &AntennaTruth) -> Option<Observation> {
        use rand_distr::{Distribution, Normal};
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let in_outage = self.p.outages.iter().any(|o| t >= o[0] && t < o[1]);
        if in_outage && !self.p.outage_void {
            return None;
        }
        let valid = t >= self.p.ttff_s && !in_outage;
        let sample = self.err.sample(t);
        let mut e = sample.enu;
        for m in &self.p.multipath {
            if t >= m[0] && t < m[0] + m[1] {
                e[1] += m[2];
            }
        }
        let (rm, rn) = crate::geodesy::radii(truth.lat_deg.to_radians());
        let ve = truth.vel_enu[0] + self.p.velocity_sigma_mps * n.sample(&mut self.rng);
        let vn = truth.vel_enu[1] + self.p.velocity_sigma_mps * n.sample(&mut self.rng);
        let at = |times: &[f64]| times.iter().any(|x| (t - x.floor()).abs() < 0.5);
        let back = if at(&self.p.time_backwards_at_s) {
            10.0
        } else {
            0.0
        };
        // GGA's altitude is above the geoid, with the geoid's separation from the ellipsoid
        // beside it (EGM2008, a coarse grid: the receiver's own model is no finer)
        let geoid_m = egm2008::geoid_height(truth.lat_deg as f32, truth.lon_deg as f32)
            .map_or(0.0, f64::from);
        Some(Observation {
            time_of_day_s: (utc0_s + t - back).rem_euclid(86_400.0),
            valid,
            lat_deg: truth.lat_deg + (e[1] / rm).to_degrees(),
            lon_deg: truth.lon_deg + (e[0] / (rn * truth.lat_deg.to_radians().cos())).to_degrees(),
            h_m: truth.h_m + e[2],
            vel_en_mps: [ve, vn],
            // the satellites used and the HDOP of the error model's geometry
            satellites: if valid { sample.satellites } else { 0 },
            hdop: if valid { sample.hdop } else { 99.9 },
            geoid_m,
            error_enu: e,
            sigma_enu: sample.sigma_enu,
            garbage: at(&self.p.garbage_at_s),
        })
    }
}

/// The GPS receiver on a pty during a bench run, stepped on the IMU stream's clock by the bus
/// scheduler ([`crate::bus`]): the fix of each PPS edge (at `k / rate + pps_phase_s`, the same
/// edges the IMU latches) is written `latency_s` after the IMU has passed the edge, as a receiver
/// outputs its fix shortly after the pulse. During the receiver's `port_drops` the device is
/// gone: the pty is closed and a new one appears at `link` afterwards (as a USB receiver
/// re-enumerating behind a `/dev/serial/by-id` link).
pub struct GpsRun {
    /// The sentence writer (receiver model and its errors).
    pub writer: NmeaWriter,
    /// The drive the antenna rides on.
    pub drive: crate::drive::Drive,
    /// The IMU's PPS phase, s.
    pub pps_phase_s: f64,
    /// Delay from the PPS edge to the sentences, s.
    pub latency_s: f64,
    /// UTC second of day at t = 0, and the date (day, month, year).
    pub utc0_s: f64,
    /// Date.
    pub date: (u32, u32, u32),
}

/// One fix epoch as the receiver puts it out.
#[derive(Debug, Clone, PartialEq)]
pub struct Epoch {
    /// Its PPS edge, s.
    pub edge: f64,
    /// The sentences (empty in a silent outage).
    pub text: String,
    /// It carries a valid fix.
    pub valid: bool,
    /// The receiver's position error in it (east, north, up), m (none without a fix): truth
    /// for the bench's scoring, never on the wire.
    pub error_enu: Option<[f64; 3]>,
    /// The receiver's own 1-sigma of that error (east, north, up), m: what its GST states, or
    /// would state for a receiver that sends none (none without a fix). Truth for the bench's
    /// scoring: a fix whose error is within 3 of these is a good fix, which no filter may
    /// refuse.
    pub sigma_enu: Option<[f64; 3]>,
    /// The receiver's device is gone at this epoch (which of its `port_drops`).
    pub port_drop: Option<usize>,
}

/// The receiver on the IMU stream's clock, without I/O: epochs out as simulated time passes.
/// The bench puts them on a pty ([`crate::adapters::pty::GpsDevice`]); in-process runs decode them directly.
pub struct GpsReceiver {
    run: GpsRun,
    k: u64,
}

impl GpsReceiver {
    /// The receiver of `run`; its first epoch is the PPS edge at one period.
    pub fn new(run: GpsRun) -> Self {
        Self { run, k: 1 }
    }

    fn period(&self) -> f64 {
        1.0 / self.run.writer.params().rate_hz.clamp(1.0, 10.0)
    }

    /// Simulated time at which the next epoch is put out, s.
    pub fn next_write_time(&self) -> f64 {
        self.k as f64 * self.period() + self.run.pps_phase_s + self.run.latency_s
    }

    /// The next epoch due once the IMU stream has reached `t` (the run ends at `duration_s`).
    pub fn poll(&mut self, t: f64, duration_s: f64) -> Option<Epoch> {
        let edge = self.k as f64 * self.period() + self.run.pps_phase_s;
        if edge > duration_s || t < edge + self.run.latency_s {
            return None;
        }
        // the receiver's epoch: whole UTC seconds at its PPS edges, and between them at a
        // rate above 1 Hz
        let epoch_t = self.k as f64 * self.period();
        self.k += 1;
        let p = self.run.writer.params();
        let port_drop = p
            .port_drops
            .iter()
            .position(|d| edge >= d[0] && edge < d[1]);
        let truth = antenna_truth(&self.run.drive, edge, p.lever_arm_m);
        let (text, err) = self
            .run
            .writer
            .fix(epoch_t, self.run.utc0_s, self.run.date, &truth);
        Some(Epoch {
            edge,
            text,
            valid: err.is_some(),
            error_enu: err.map(|e| e.0),
            sigma_enu: err.map(|e| e.1),
            port_drop,
        })
    }
}
