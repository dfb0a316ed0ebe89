//! The receiver model: its parameters, and its epochs as the IMU clock passes their PPS edges
//! (pure: no I/O).

use super::{GpsErrorParams, NmeaWriter, antenna_truth};

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
/// The bench puts them on a pty ([`crate::gps::GpsDevice`]); in-process runs decode them directly.
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
