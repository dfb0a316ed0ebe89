//! IMU front end: turns IMU_GYRO / IMU_ACCEL / IMU_HK frames into angle and velocity increments.
//!
//! The counters on the wire are free running and wrap at 16 bits, so increments are the
//! wrapping differences of consecutive counters: a lost frame loses no angle, as long as the gap
//! is short enough that no counter could have moved by half its range. Every irregularity is
//! counted and reported with its sample number: gaps, duplicates, backwards jumps, gaps too long
//! to difference safely, unpaired frames, saturation and built-in-test failures.

use serde::{Deserialize, Serialize};
use wire::{ImuAccel, ImuGyro, ImuHk};

/// Calibration bound to the IMU unit (from its calibration file; the config file carries it).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct ImuCalibration {
    /// Gyro pulse weights x, y, z, arcsec per pulse.
    pub gyro_pulse_arcsec: [f64; 3],
    /// Accelerometer pulse weights x, y, z, m/s per pulse.
    pub accel_pulse_mps: [f64; 3],
    /// Gyro range, deg/s (with dither), bounds the pulses per sample.
    pub gyro_range_dps: f64,
    /// Accelerometer range, m/s^2.
    pub accel_range_mps2: f64,
    /// Sample rate, Hz.
    pub rate_hz: f64,
    /// Gyro biases, deg/h, taken off each gyro's rate (from a calibration: the parameter file
    /// of `[calibration]`).
    #[serde(default)]
    pub gyro_bias_dph: [f64; 3],
    /// Gyro scale-factor errors, ppm: rate = (output - bias) / (1 + sf).
    #[serde(default)]
    pub gyro_scale_factor_ppm: [f64; 3],
}

impl Default for ImuCalibration {
    fn default() -> Self {
        Self {
            gyro_pulse_arcsec: [1.0; 3],
            accel_pulse_mps: [1e-4; 3],
            gyro_range_dps: 650.0, // 400 deg/s body rate plus the dither's peak rate
            accel_range_mps2: 10.0 * 9.80665,
            rate_hz: wire::IMU_RATE_HZ,
            gyro_bias_dph: [0.0; 3],
            gyro_scale_factor_ppm: [0.0; 3],
        }
    }
}

impl ImuCalibration {
    /// Longest run of samples across which a 16-bit counter difference is unambiguous for
    /// both gyros and accelerometers at full range.
    pub fn max_safe_span(&self) -> u32 {
        let dt = 1.0 / self.rate_hz;
        let g = self.gyro_range_dps * 3600.0 * dt
            / self
                .gyro_pulse_arcsec
                .iter()
                .cloned()
                .fold(f64::INFINITY, f64::min);
        let a = self.accel_range_mps2 * dt
            / self
                .accel_pulse_mps
                .iter()
                .cloned()
                .fold(f64::INFINITY, f64::min);
        let per_sample = g.max(a).max(1.0);
        ((32767.0 / per_sample).floor() as u32).max(1)
    }
}

/// One IMU sample (or the span of samples since the previous one, after a gap). Recorded as JSON
/// on `/imu/sample`, its flags and PPS offset only when present.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct ImuSample {
    /// Extended (64-bit) sample number; the navigation clock.
    pub sample: u64,
    /// Samples this increment spans: 1, or more after lost frames.
    pub span: u32,
    /// Angle increments x, y, z, rad.
    pub dtheta: [f64; 3],
    /// Velocity increments x, y, z, m/s.
    pub dv: [f64; 3],
    /// PPS edge: time from the edge to the end of this sample, in samples.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pps_offset: Option<f64>,
    /// The accelerometer frame of this sample was lost (its dv arrives with the next one).
    #[serde(skip_serializing_if = "is_false")]
    pub accel_missing: bool,
    /// The span was too long to difference the counters unambiguously: increments unreliable.
    #[serde(skip_serializing_if = "is_false")]
    pub ambiguous: bool,
    /// Built-in test failure reported.
    #[serde(skip_serializing_if = "is_false")]
    pub bit_fail: bool,
    /// A channel saturated.
    #[serde(skip_serializing_if = "is_false")]
    pub saturated: bool,
}

/// Flags are recorded only when set (most samples have none).
fn is_false(b: &bool) -> bool {
    !*b
}

/// Something irregular in the IMU stream.
#[derive(Debug, Clone, Copy, Serialize, PartialEq, Eq)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ImuEvent {
    /// `missing` samples were lost before `sample`.
    Gap {
        /// First sample after the gap.
        sample: u64,
        /// Samples lost.
        missing: u32,
    },
    /// The gap was too long for an unambiguous counter difference.
    AmbiguousGap {
        /// First sample after the gap.
        sample: u64,
        /// Samples lost.
        missing: u32,
    },
    /// A gyro frame repeated the previous sample counter.
    Duplicate {
        /// The repeated sample.
        sample: u64,
    },
    /// A gyro frame came late (its counter a little behind the last one, the frames after it
    /// already taken): dropped. The counters are cumulative, so the gap it left was differenced
    /// across and no angle is lost.
    Late {
        /// Last good sample.
        last: u64,
        /// Samples it was behind.
        behind: u32,
    },
    /// The counter went backwards: the stream was re-synchronised.
    Backwards {
        /// Last good sample.
        last: u64,
        /// Raw 16-bit counter received.
        counter: u16,
    },
    /// An IMU_ACCEL frame did not match the pending IMU_GYRO sample.
    UnpairedAccel {
        /// Pending sample (if any).
        sample: u64,
        /// Low counter bits received.
        low: u8,
    },
    /// A sample's IMU_ACCEL frame never came.
    AccelMissing {
        /// The sample.
        sample: u64,
    },
    /// Built-in test failure began.
    BitFail {
        /// The sample.
        sample: u64,
    },
    /// Saturation.
    Saturated {
        /// The sample.
        sample: u64,
    },
}

/// More late frames in a row than this is not a frame overtaken on the bus but a counter that
/// went back for good (the IMU restarted): the stream is re-synchronised.
pub const LATE_RUN_MAX: u32 = 8;

/// Counters of the IMU stream.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
pub struct ImuStats {
    /// IMU_GYRO frames received.
    pub gyro_frames: u64,
    /// IMU_ACCEL frames received.
    pub accel_frames: u64,
    /// IMU_HK frames received.
    pub hk_frames: u64,
    /// Samples emitted.
    pub samples: u64,
    /// Gaps seen.
    pub gaps: u64,
    /// Samples lost in gaps.
    pub missing_samples: u64,
    /// Gaps too long to difference safely.
    pub ambiguous_gaps: u64,
    /// Duplicate gyro frames.
    pub duplicates: u64,
    /// Backwards jumps (re-synchronisations).
    pub backwards: u64,
    /// Gyro frames that came late (behind frames already taken) and were dropped.
    #[serde(default)]
    pub late_frames: u64,
    /// Samples whose IMU_ACCEL frame was lost.
    pub accel_missing: u64,
    /// IMU_ACCEL frames that matched no pending sample.
    pub accel_unpaired: u64,
    /// Samples with the BIT failure flag.
    pub bit_fail_samples: u64,
    /// Samples with saturation.
    pub saturated_samples: u64,
    /// PPS edges latched.
    pub pps_edges: u64,
}

/// Latest housekeeping.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct Housekeeping {
    /// Gyro block temperature, degC.
    pub temp_gyro_c: f64,
    /// Accelerometer block temperature, degC.
    pub temp_accel_c: f64,
    /// Any BIT failure.
    pub bit_fail: bool,
}

/// The decoder state machine.
#[derive(Debug)]
pub struct ImuFrontEnd {
    cal: ImuCalibration,
    gyro_scale: [f64; 3],
    /// Each gyro's bias per sample, rad (the calibration's).
    gyro_bias: [f64; 3],
    max_span: u32,
    last_counter: Option<u16>,
    last_gyro: [u16; 3],
    last_accel: Option<[u16; 3]>,
    ext: u64,
    pending: Option<ImuSample>,
    was_bit_fail: bool,
    /// The counters were re-baselined after a backwards jump: the angle in between is unknown.
    resynced: bool,
    /// Late frames in a row (a device reset looks like an endless run of them).
    late_run: u32,
    stats: ImuStats,
    hk: Housekeeping,
}

fn diff(now: [u16; 3], before: [u16; 3]) -> [i64; 3] {
    std::array::from_fn(|i| i64::from(now[i].wrapping_sub(before[i]) as i16))
}

impl ImuFrontEnd {
    /// A front end for an IMU with this calibration.
    pub fn new(cal: ImuCalibration) -> Self {
        let arcsec = std::f64::consts::PI / 180.0 / 3600.0;
        Self {
            cal,
            // the scale-factor error folded into the pulse weight: (c w - b) / (1 + sf)
            gyro_scale: std::array::from_fn(|i| {
                cal.gyro_pulse_arcsec[i] * arcsec / (1.0 + cal.gyro_scale_factor_ppm[i] * 1e-6)
            }),
            gyro_bias: std::array::from_fn(|i| {
                cal.gyro_bias_dph[i] * arcsec
                    / cal.rate_hz
                    / (1.0 + cal.gyro_scale_factor_ppm[i] * 1e-6)
            }),
            max_span: cal.max_safe_span(),
            last_counter: None,
            last_gyro: [0; 3],
            last_accel: None,
            ext: 0,
            pending: None,
            was_bit_fail: false,
            resynced: false,
            late_run: 0,
            stats: ImuStats::default(),
            hk: Housekeeping::default(),
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> ImuStats {
        self.stats
    }

    /// Latest housekeeping.
    pub fn housekeeping(&self) -> Housekeeping {
        self.hk
    }

    /// The calibration in use.
    pub fn calibration(&self) -> &ImuCalibration {
        &self.cal
    }

    /// Longest unambiguous span, samples.
    pub fn max_span(&self) -> u32 {
        self.max_span
    }

    fn emit(&mut self, s: ImuSample, out: &mut Vec<ImuSample>, ev: &mut Vec<ImuEvent>) {
        self.stats.samples += 1;
        if s.accel_missing {
            self.stats.accel_missing += 1;
            ev.push(ImuEvent::AccelMissing { sample: s.sample });
        }
        out.push(s);
    }

    /// Feed an IMU_GYRO frame; completed samples go to `out`, irregularities to `ev`.
    pub fn on_gyro(&mut self, g: &ImuGyro, out: &mut Vec<ImuSample>, ev: &mut Vec<ImuEvent>) {
        self.stats.gyro_frames += 1;
        let Some(last) = self.last_counter else {
            // first frame: baseline only
            self.last_counter = Some(g.sample_counter);
            self.last_gyro = g.counts;
            self.ext = u64::from(g.sample_counter);
            return;
        };
        let d = g.sample_counter.wrapping_sub(last);
        if d == 0 {
            self.stats.duplicates += 1;
            ev.push(ImuEvent::Duplicate { sample: self.ext });
            return;
        }
        if d > 32768 {
            let behind = u32::from(last.wrapping_sub(g.sample_counter));
            if behind <= self.max_span && self.late_run < LATE_RUN_MAX {
                // one frame overtaken by later ones (reordered or delayed on the bus)
                self.late_run += 1;
                self.stats.late_frames += 1;
                ev.push(ImuEvent::Late {
                    last: self.ext,
                    behind,
                });
                return;
            }
            self.late_run = 0;
            self.stats.backwards += 1;
            ev.push(ImuEvent::Backwards {
                last: self.ext,
                counter: g.sample_counter,
            });
            self.flush(out, ev);
            self.last_counter = Some(g.sample_counter);
            self.last_gyro = g.counts;
            self.last_accel = None;
            self.resynced = true;
            return;
        }
        self.late_run = 0;
        // the previous sample's accelerometer frame never came
        self.flush(out, ev);
        let span = u32::from(d);
        self.ext += u64::from(d);
        let mut ambiguous = false;
        if span > 1 {
            self.stats.gaps += 1;
            self.stats.missing_samples += u64::from(span - 1);
            if span > self.max_span {
                ambiguous = true;
                self.stats.ambiguous_gaps += 1;
                ev.push(ImuEvent::AmbiguousGap {
                    sample: self.ext,
                    missing: span - 1,
                });
            } else {
                ev.push(ImuEvent::Gap {
                    sample: self.ext,
                    missing: span - 1,
                });
            }
        }
        // after a re-synchronisation the angle since the last good sample is unknown
        ambiguous |= std::mem::take(&mut self.resynced);
        let dc = diff(g.counts, self.last_gyro);
        self.last_counter = Some(g.sample_counter);
        self.last_gyro = g.counts;
        self.pending = Some(ImuSample {
            sample: self.ext,
            span,
            dtheta: std::array::from_fn(|i| {
                dc[i] as f64 * self.gyro_scale[i] - self.gyro_bias[i] * f64::from(span)
            }),
            dv: [0.0; 3],
            pps_offset: None,
            accel_missing: false,
            ambiguous,
            bit_fail: false,
            saturated: false,
        });
    }

    /// Feed an IMU_ACCEL frame.
    pub fn on_accel(&mut self, a: &ImuAccel, out: &mut Vec<ImuSample>, ev: &mut Vec<ImuEvent>) {
        self.stats.accel_frames += 1;
        let Some(mut p) = self.pending.take() else {
            if self.last_counter.is_some() && self.last_accel.is_none() {
                // the baseline accel frame of the first sample
                self.last_accel = Some(a.counts);
            } else {
                self.stats.accel_unpaired += 1;
                ev.push(ImuEvent::UnpairedAccel {
                    sample: self.ext,
                    low: a.sample_counter_low,
                });
            }
            return;
        };
        // pair by the raw counter (the extended sample number keeps counting across a
        // re-synchronisation, the wire counter does not)
        let raw_low = self.last_counter.map_or(0, |c| (c & 0xF) as u8);
        if a.sample_counter_low != raw_low {
            self.stats.accel_unpaired += 1;
            ev.push(ImuEvent::UnpairedAccel {
                sample: p.sample,
                low: a.sample_counter_low,
            });
            self.pending = Some(p);
            return;
        }
        if let Some(last) = self.last_accel {
            let dc = diff(a.counts, last);
            p.dv = std::array::from_fn(|i| dc[i] as f64 * self.cal.accel_pulse_mps[i]);
        }
        self.last_accel = Some(a.counts);
        if let Some(o) = a.pps_offset {
            self.stats.pps_edges += 1;
            p.pps_offset = Some(f64::from(o) / 256.0);
        }
        p.bit_fail = a.bit_fail;
        p.saturated = a.saturated;
        if a.bit_fail {
            self.stats.bit_fail_samples += 1;
            if !self.was_bit_fail {
                ev.push(ImuEvent::BitFail { sample: p.sample });
            }
        }
        self.was_bit_fail = a.bit_fail;
        if a.saturated {
            self.stats.saturated_samples += 1;
            ev.push(ImuEvent::Saturated { sample: p.sample });
        }
        self.emit(p, out, ev);
    }

    /// Feed any decoded message: IMU messages go to their handler, others are ignored.
    /// Returns whether the message belonged to the IMU.
    pub fn on_message(
        &mut self,
        m: &wire::Message,
        out: &mut Vec<ImuSample>,
        ev: &mut Vec<ImuEvent>,
    ) -> bool {
        match m {
            wire::Message::ImuGyro(g) => self.on_gyro(g, out, ev),
            wire::Message::ImuAccel(a) => self.on_accel(a, out, ev),
            wire::Message::ImuHk(h) => self.on_hk(h),
            _ => return false,
        }
        true
    }

    /// Feed an IMU_HK frame.
    pub fn on_hk(&mut self, h: &ImuHk) {
        self.stats.hk_frames += 1;
        self.hk = Housekeeping {
            temp_gyro_c: h.temp_gyro_c,
            temp_accel_c: h.temp_accel_c,
            bit_fail: h.bit.any(),
        };
    }

    /// End of stream: emit a sample still waiting for its accelerometer frame.
    pub fn flush(&mut self, out: &mut Vec<ImuSample>, ev: &mut Vec<ImuEvent>) {
        if let Some(p) = self.pending.take() {
            self.emit(
                ImuSample {
                    accel_missing: true,
                    ..p
                },
                out,
                ev,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gyro(sc: u16, c: [u16; 3]) -> ImuGyro {
        ImuGyro {
            counts: c,
            sample_counter: sc,
        }
    }
    fn accel(sc: u16, c: [u16; 3]) -> ImuAccel {
        ImuAccel {
            counts: c,
            sample_counter_low: (sc & 0xF) as u8,
            pps_offset: None,
            bit_fail: false,
            saturated: false,
        }
    }

    /// Feed a stream where each gyro counter advances by `rate` pulses per sample.
    fn run(
        fe: &mut ImuFrontEnd,
        samples: impl Iterator<Item = u32>,
        rate: i64,
        drop: impl Fn(u32) -> bool,
    ) -> (Vec<ImuSample>, Vec<ImuEvent>) {
        let (mut out, mut ev) = (Vec::new(), Vec::new());
        for k in samples {
            let c = ((i64::from(k) * rate).rem_euclid(65536)) as u16;
            let sc = (k & 0xFFFF) as u16;
            if !drop(k) {
                fe.on_gyro(&gyro(sc, [c, c.wrapping_neg(), 7]), &mut out, &mut ev);
                fe.on_accel(&accel(sc, [c / 2, 0, 0]), &mut out, &mut ev);
            }
        }
        fe.flush(&mut out, &mut ev);
        (out, ev)
    }

    #[test]
    fn counters_wrap_without_losing_angle() {
        let mut fe = ImuFrontEnd::new(ImuCalibration::default());
        // 700 pulses/sample wraps the 16-bit counter every ~94 samples; the sample counter wraps too
        let (out, ev) = run(&mut fe, 65000..66000, 700, |_| false);
        assert!(ev.is_empty(), "{ev:?}");
        assert_eq!(out.len(), 999);
        let total: f64 = out.iter().map(|s| s.dtheta[0]).sum();
        let pulse = std::f64::consts::PI / 180.0 / 3600.0;
        assert!((total - 999.0 * 700.0 * pulse).abs() < 1e-9);
        assert!(
            out.iter()
                .all(|s| s.span == 1 && (s.dtheta[1] + 700.0 * pulse).abs() < 1e-12)
        );
        assert_eq!(out.last().map(|s| s.sample), Some(65999));
    }

    /// A calibration's bias comes off each sample's angle (across a gap too: by its span) and
    /// its scale-factor error off the rest.
    #[test]
    fn the_calibration_takes_off_bias_and_scale_factor() {
        let cal = ImuCalibration {
            gyro_bias_dph: [3600.0, 0.0, 0.0],
            gyro_scale_factor_ppm: [0.0, 1000.0, 0.0],
            ..ImuCalibration::default()
        };
        let mut fe = ImuFrontEnd::new(cal);
        let (out, _) = run(&mut fe, 0..50, 500, |k| k == 20);
        let arcsec = std::f64::consts::PI / 180.0 / 3600.0;
        // 3600 deg/h is 1 deg/s: 1.8 arcsec a sample at 2 kHz
        for s in &out {
            let n = f64::from(s.span);
            assert!(
                (s.dtheta[0] - n * (500.0 - 1.8) * arcsec).abs() < 1e-15,
                "{s:?}"
            );
            assert!(
                (s.dtheta[1] + n * 500.0 * arcsec / 1.001).abs() < 1e-15,
                "{s:?}"
            );
        }
        assert!(out.iter().any(|s| s.span == 2));
    }

    #[test]
    fn a_gap_is_counted_and_loses_no_angle() {
        let mut fe = ImuFrontEnd::new(ImuCalibration::default());
        let (out, ev) = run(&mut fe, 0..100, 500, |k| (40..43).contains(&k));
        assert_eq!(fe.stats().gaps, 1);
        assert_eq!(fe.stats().missing_samples, 3);
        assert_eq!(
            ev,
            vec![ImuEvent::Gap {
                sample: 43,
                missing: 3
            }]
        );
        let total: f64 = out.iter().map(|s| s.dtheta[0]).sum();
        let pulse = std::f64::consts::PI / 180.0 / 3600.0;
        assert!(
            (total - 99.0 * 500.0 * pulse).abs() < 1e-9,
            "angle kept across the gap"
        );
        let after = out.iter().find(|s| s.sample == 43).expect("sample 43");
        assert_eq!(after.span, 4);
        assert!(!after.ambiguous);
    }

    #[test]
    fn a_gap_too_long_to_difference_is_flagged() {
        let cal = ImuCalibration::default();
        let mut fe = ImuFrontEnd::new(cal);
        let n = fe.max_span();
        assert!(n > 10 && n < 100, "max span {n}");
        let (out, ev) = run(&mut fe, 0..(3 * n), 700, |k| (n..2 * n).contains(&k));
        assert_eq!(fe.stats().ambiguous_gaps, 1);
        assert!(matches!(ev[0], ImuEvent::AmbiguousGap { .. }));
        assert!(out.iter().any(|s| s.ambiguous));
    }

    #[test]
    fn duplicates_and_backwards_jumps_are_reported() {
        let mut fe = ImuFrontEnd::new(ImuCalibration::default());
        let (mut out, mut ev) = (Vec::new(), Vec::new());
        fe.on_gyro(&gyro(10, [0; 3]), &mut out, &mut ev);
        fe.on_accel(&accel(10, [0; 3]), &mut out, &mut ev);
        fe.on_gyro(&gyro(11, [5; 3]), &mut out, &mut ev);
        fe.on_accel(&accel(11, [1; 3]), &mut out, &mut ev);
        fe.on_gyro(&gyro(11, [5; 3]), &mut out, &mut ev);
        assert_eq!(fe.stats().duplicates, 1);
        // further back than any frame can be late: the counter went back for good (a restart)
        let back = 11u16.wrapping_sub(fe.max_span() as u16 + 1);
        fe.on_gyro(&gyro(back, [9; 3]), &mut out, &mut ev);
        assert_eq!(fe.stats().backwards, 1);
        assert!(
            matches!(
                ev[..],
                [
                    ImuEvent::Duplicate { sample: 11 },
                    ImuEvent::Backwards { last: 11, counter }
                ] if counter == back
            ),
            "{ev:?}"
        );
        assert_eq!(out.len(), 1);
        // the first sample after the re-synchronisation carries the unknown angle: flagged
        fe.on_gyro(&gyro(back.wrapping_add(1), [10; 3]), &mut out, &mut ev);
        fe.on_accel(&accel(back.wrapping_add(1), [2; 3]), &mut out, &mut ev);
        assert!(out.last().is_some_and(|s| s.ambiguous), "{out:?}");
    }

    /// A frame overtaken on the bus (sample 12 after 13) is dropped and counted; the gap it left
    /// was differenced across (cumulative counters: no angle lost) and nothing is flagged
    /// ambiguous. A counter that stays behind is a restart: re-synchronised after a few frames.
    #[test]
    fn a_late_frame_is_dropped_and_a_counter_that_stays_back_resynchronises() {
        let mut fe = ImuFrontEnd::new(ImuCalibration::default());
        let (mut out, mut ev) = (Vec::new(), Vec::new());
        for k in [10u16, 11, 13, 12, 14] {
            fe.on_gyro(&gyro(k, [k; 3]), &mut out, &mut ev);
            fe.on_accel(&accel(k, [0; 3]), &mut out, &mut ev);
        }
        let st = fe.stats();
        assert_eq!((st.late_frames, st.backwards, st.gaps), (1, 0, 1), "{ev:?}");
        assert!(out.iter().all(|s| !s.ambiguous), "{out:?}");
        // the samples emitted span every sample from 10 to 14, and carry every count
        assert_eq!(out.iter().map(|s| s.span).sum::<u32>(), 4, "{out:?}");
        let pulse = ImuCalibration::default().gyro_pulse_arcsec[0];
        let total: f64 = out.iter().map(|s| s.dtheta[0]).sum::<f64>();
        assert!(
            (total - 4.0 * pulse * std::f64::consts::PI / 648_000.0).abs() < 1e-12,
            "{total}"
        );
        // a restart: the counter goes back 30 and counts on from there
        let from = 14u16.wrapping_sub(30);
        for k in 0..LATE_RUN_MAX as u16 + 2 {
            fe.on_gyro(&gyro(from.wrapping_add(k), [0; 3]), &mut out, &mut ev);
        }
        assert_eq!(fe.stats().backwards, 1, "{ev:?}");
    }

    #[test]
    fn a_lost_accel_frame_defers_its_velocity_to_the_next_sample() {
        let mut fe = ImuFrontEnd::new(ImuCalibration::default());
        let (mut out, mut ev) = (Vec::new(), Vec::new());
        fe.on_gyro(&gyro(0, [0; 3]), &mut out, &mut ev);
        fe.on_accel(&accel(0, [0; 3]), &mut out, &mut ev);
        fe.on_gyro(&gyro(1, [1; 3]), &mut out, &mut ev);
        fe.on_accel(&accel(1, [100; 3]), &mut out, &mut ev);
        fe.on_gyro(&gyro(2, [2; 3]), &mut out, &mut ev); // accel of 2 lost
        fe.on_gyro(&gyro(3, [3; 3]), &mut out, &mut ev);
        fe.on_accel(&accel(3, [300; 3]), &mut out, &mut ev);
        assert_eq!(fe.stats().accel_missing, 1);
        assert_eq!(out.len(), 3);
        assert!(out[1].accel_missing && out[1].dv == [0.0; 3]);
        assert!(
            (out[2].dv[0] - 200.0 * 1e-4).abs() < 1e-12,
            "dv of the lost frame arrives with the next"
        );
        // an accel frame with the wrong low counter bits is refused
        fe.on_gyro(&gyro(4, [4; 3]), &mut out, &mut ev);
        fe.on_accel(&accel(9, [400; 3]), &mut out, &mut ev);
        assert_eq!(fe.stats().accel_unpaired, 1);
    }

    #[test]
    fn bit_failure_saturation_and_pps_are_reported_with_the_sample() {
        let mut fe = ImuFrontEnd::new(ImuCalibration::default());
        let (mut out, mut ev) = (Vec::new(), Vec::new());
        fe.on_gyro(&gyro(0, [0; 3]), &mut out, &mut ev);
        fe.on_accel(&accel(0, [0; 3]), &mut out, &mut ev);
        fe.on_gyro(&gyro(1, [0; 3]), &mut out, &mut ev);
        let a = ImuAccel {
            bit_fail: true,
            saturated: true,
            pps_offset: Some(128),
            ..accel(1, [0; 3])
        };
        fe.on_accel(&a, &mut out, &mut ev);
        assert_eq!(
            ev,
            vec![
                ImuEvent::BitFail { sample: 1 },
                ImuEvent::Saturated { sample: 1 }
            ]
        );
        assert_eq!(out[0].pps_offset, Some(0.5));
        assert_eq!(fe.stats().pps_edges, 1);
    }
}
