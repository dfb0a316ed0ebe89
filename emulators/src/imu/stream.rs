//! The IMU's frames as they go on the bus, the configured faults injected (dropped, duplicated,
//! delayed and foreign frames, the stream stopping), and what went out. Pure, no I/O: the vcan
//! adapter writes what it yields, and the in-process runs take the very same stream.

use crate::imu::ImuEmulator;
use serde::{Deserialize, Serialize};
use wire::RawFrame;

/// Deliberate faults the IMU adapter injects on the bus (for testing the receiver).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct BusFaults {
    /// Sample indices (0-based) whose frames are not sent.
    pub drop_samples: Vec<u64>,
    /// Sample indices whose IMU_GYRO frame is sent twice.
    pub duplicate_samples: Vec<u64>,
    /// Simulated times (s) at which a frame with an id outside the contract is sent.
    pub unknown_id_at_s: Vec<f64>,
    /// Simulated times (s) at which an IMU_GYRO frame with a wrong length is sent.
    pub bad_length_at_s: Vec<f64>,
    /// Periods [start, end] s in which the IMU sends nothing at all (the stream stops).
    pub stop_s: Vec<[f64; 2]>,
    /// Sample indices whose IMU_ACCEL frame is not sent.
    pub drop_accel_samples: Vec<u64>,
    /// Frames held back: [sample index, samples]: that sample's frames go out after those of
    /// the given number of later samples (1: reordered with the next; more: delayed).
    pub delay_samples: Vec<[u64; 2]>,
    /// Floods of foreign frames: [start s, end s, frames per IMU sample] with an id outside
    /// the contract (0x7E6), interleaved with the IMU's.
    pub flood_s: Vec<[f64; 3]>,
}

/// What the adapter sent.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
pub struct TxStats {
    /// Samples produced by the model.
    pub samples: u64,
    /// IMU_GYRO frames written.
    pub gyro_frames: u64,
    /// IMU_ACCEL frames written.
    pub accel_frames: u64,
    /// IMU_HK frames written.
    pub hk_frames: u64,
    /// Frames written in all (including injected ones).
    pub frames: u64,
    /// Samples deliberately dropped.
    pub dropped_samples: u64,
    /// Deliberately injected bad frames (unknown id, wrong length, duplicates, floods).
    pub injected_frames: u64,
    /// Of which: foreign frames of floods.
    #[serde(default)]
    pub flood_frames: u64,
    /// IMU_ACCEL frames deliberately not sent.
    #[serde(default)]
    pub dropped_accel_frames: u64,
    /// Frames that could not be written because the interface was down (and were lost).
    #[serde(default)]
    pub lost_iface_down: u64,
    /// Writes retried after ENOBUFS (transmit queue full).
    pub enobufs_retries: u64,
    /// Largest lag behind the simulated clock, ms of wall time.
    pub max_lag_ms: u64,
    /// Samples whose true input went beyond the sensors' range (clamped): the motion asked
    /// more of the IMU than it can measure.
    #[serde(default)]
    pub over_range_samples: u64,
}

/// The IMU's frames as they go on the bus, with the configured faults injected. Pure (no I/O):
/// the vcan adapter writes what this yields, and in-process replays use the very same stream.
pub struct BusStream {
    imu: ImuEmulator,
    faults: BusFaults,
    unknown: Vec<f64>,
    badlen: Vec<f64>,
    /// Samples' frames held back (`delay_samples`): released after sample index .0.
    held: Vec<(u64, Vec<RawFrame>)>,
    /// Counts of what was yielded (`frames` counts frames handed out).
    pub stats: TxStats,
}

impl BusStream {
    /// The stream of `imu` with `faults`.
    pub fn new(imu: ImuEmulator, faults: &BusFaults) -> Self {
        Self {
            imu,
            unknown: faults.unknown_id_at_s.clone(),
            badlen: faults.bad_length_at_s.clone(),
            held: Vec::new(),
            faults: faults.clone(),
            stats: TxStats::default(),
        }
    }

    /// The emulator.
    pub fn imu(&self) -> &ImuEmulator {
        &self.imu
    }

    /// Simulated time at the end of the next sample, s.
    pub fn next_time(&self) -> f64 {
        self.imu.next_time()
    }

    /// The IMU is stopped at simulated time `t` (a `stop_s` fault: it sends nothing).
    pub fn stopped_at(&self, t: f64) -> bool {
        self.faults.stop_s.iter().any(|p| t >= p[0] && t < p[1])
    }

    /// Append the next sample's frames (as sent, faults included) to `out`.
    pub fn next_frames(&mut self, out: &mut Vec<RawFrame>) {
        let t = self.imu.next_time();
        let s = self.imu.next_sample();
        let st = &mut self.stats;
        st.samples += 1;
        st.over_range_samples += u64::from(s.over_range);
        let stopped = self.faults.stop_s.iter().any(|p| t >= p[0] && t < p[1]);
        if stopped || self.faults.drop_samples.contains(&s.k) {
            st.dropped_samples += 1;
            return;
        }
        let drop_accel = self.faults.drop_accel_samples.contains(&s.k);
        let delay = self
            .faults
            .delay_samples
            .iter()
            .find(|d| d[0] == s.k)
            .map(|d| d[1]);
        let start = out.len();
        for f in &s.frames {
            match f.id {
                0x080 => st.gyro_frames += 1,
                0x081 if drop_accel => {
                    st.dropped_accel_frames += 1;
                    continue;
                }
                0x081 => st.accel_frames += 1,
                _ => st.hk_frames += 1,
            }
            out.push(*f);
        }
        if let Some(n) = delay {
            // held back until the frames of `n` later samples are out
            let frames = out.drain(start..).collect();
            self.held.push((s.k + n, frames));
        }
        if self.held.iter().any(|(after, _)| *after <= s.k) {
            let held = std::mem::take(&mut self.held);
            for (after, frames) in held {
                if after <= s.k {
                    out.extend(frames);
                } else {
                    self.held.push((after, frames));
                }
            }
        }
        for w in &self.faults.flood_s {
            if t >= w[0] && t < w[1] {
                for i in 0..w[2].max(0.0).round() as u32 {
                    out.push(RawFrame {
                        id: 0x7E6,
                        len: 8,
                        data: [0xF1, 0x00, (i & 0xFF) as u8, 0, 0, 0, 0, 0],
                    });
                    st.injected_frames += 1;
                    st.flood_frames += 1;
                }
            }
        }
        if self.faults.duplicate_samples.contains(&s.k) {
            out.push(s.frames[0]);
            st.injected_frames += 1;
        }
        for (times, frame) in [
            (
                &mut self.unknown,
                RawFrame {
                    id: 0x7E5,
                    len: 8,
                    data: *b"UNKNOWN!",
                },
            ),
            (
                &mut self.badlen,
                RawFrame {
                    id: 0x080,
                    len: 5,
                    data: [1, 2, 3, 4, 5, 0, 0, 0],
                },
            ),
        ] {
            if let Some(pos) = times.iter().position(|at| *at <= t) {
                times.swap_remove(pos);
                out.push(frame);
                st.injected_frames += 1;
            }
        }
    }
}
