//! The fault matrix's IMU rows.

use super::*;

/// The IMU's frames on the bus: dropped, duplicated, reordered, delayed, a counter jump.
pub(super) fn frames() -> Vec<FaultCase> {
    vec![
        FaultCase {
            name: "imu-frames-dropped",
            base: Base::Imu,
            injected: "samples 4000-4002 (t = 2 s) not sent",
            expected: "3 missing samples counted exactly (plus any the bus lost), imu_gaps health bit within 0.1 s, attitude stays valid",
            at_s: 2.0,
            inject: |s, _| s.faults.drop_samples = vec![4000, 4001, 4002],
            judge: |r, at| {
                let i = &r.nav.imu;
                let l = bit_latency(r, "imu_gaps", at);
                let pass = survived(r)
                    && i.missing_samples as i64 == 3 + r.bus_lost_frames / 2
                    && l.is_some_and(|l| (0.0..=0.1).contains(&l))
                    && r.nav.attitude.valid;
                verdict(
                    pass,
                    format!(
                        "missing {} (bus lost {} frames), gaps {}, imu_gaps after {}, attitude valid {}",
                        i.missing_samples,
                        r.bus_lost_frames,
                        i.gaps,
                        lat_text(l),
                        r.nav.attitude.valid
                    ),
                    l,
                )
            },
        },
        FaultCase {
            name: "imu-frames-duplicated",
            base: Base::Imu,
            injected: "the gyro frame of sample 4000 sent twice",
            expected: "1 duplicate counted, nothing missing, attitude valid",
            at_s: 2.0,
            inject: |s, _| s.faults.duplicate_samples = vec![4000],
            judge: |r, _| {
                let i = &r.nav.imu;
                let pass = survived(r)
                    && i.duplicates == 1
                    && i.missing_samples as i64 == r.bus_lost_frames / 2
                    && r.nav.attitude.valid;
                verdict(
                    pass,
                    format!(
                        "duplicates {}, missing {}, attitude valid {}",
                        i.duplicates, i.missing_samples, r.nav.attitude.valid
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "imu-frames-reordered",
            base: Base::Imu,
            injected: "the frames of sample 4000 sent after those of 4001",
            expected: LATE_FRAME,
            at_s: 2.0,
            inject: |s, _| s.faults.delay_samples = vec![[4000, 1]],
            judge: late_frame,
        },
        FaultCase {
            name: "imu-frames-delayed",
            base: Base::Imu,
            injected: "the frames of sample 4000 held back 20 samples (10 ms)",
            expected: LATE_FRAME,
            at_s: 2.0,
            inject: |s, _| s.faults.delay_samples = vec![[4000, 20]],
            judge: late_frame,
        },
        FaultCase {
            name: "imu-counter-jump",
            base: Base::Imu,
            injected: "the sample counter jumps 30,000 ahead at sample 4000 (no sample lost)",
            expected: "a gap too long to difference counted, the attitude marked invalid, filter health bit within 0.1 s",
            at_s: 2.0,
            inject: |s, _| s.imu.counter_jumps = vec![[4000, COUNTER_JUMP]],
            judge: |r, at| {
                let i = &r.nav.imu;
                // the NAV_TIME sample count jumps with the counter: IMU time is that less the jump
                let l = bit_latency(r, "filter", at)
                    .map(|l| l - COUNTER_JUMP as f64 / r.scenario.imu.rate_hz);
                let pass = survived(r)
                    && i.ambiguous_gaps >= 1
                    && !r.nav.attitude.valid
                    && l.is_some_and(|l| (0.0..=0.1).contains(&l));
                verdict(
                    pass,
                    format!(
                        "ambiguous gaps {}, attitude valid {}, filter bit after {}",
                        i.ambiguous_gaps,
                        r.nav.attitude.valid,
                        lat_text(l)
                    ),
                    l,
                )
            },
        },
    ]
}

/// The IMU itself: its built-in test failing, saturation, accelerometer frames missing, the stream stopping.
pub(super) fn sensor() -> Vec<FaultCase> {
    vec![
        FaultCase {
            name: "imu-bit-failure",
            base: Base::Imu,
            injected: "the IMU's built-in test reports a failure from 4 s",
            expected: "every failed sample counted and marked suspect, imu_bit health bit within 0.1 s",
            at_s: 4.0,
            inject: |s, _| s.imu.bit_fail_from_s = Some(4.0),
            judge: |r, at| {
                let i = &r.nav.imu;
                let l = bit_latency(r, "imu_bit", at);
                let expect = ((r.scenario.duration_s - at) * r.scenario.imu.rate_hz) as u64;
                let pass = survived(r)
                    && i.bit_fail_samples + 2 >= expect
                    && i.bit_fail_samples <= expect + 2
                    && r.nav.processing.suspect_samples == i.bit_fail_samples
                    && l.is_some_and(|l| (0.0..=0.1).contains(&l));
                verdict(
                    pass,
                    format!(
                        "BIT-failed samples {} (expected {expect}), suspect {}, imu_bit after {}",
                        i.bit_fail_samples,
                        r.nav.processing.suspect_samples,
                        lat_text(l)
                    ),
                    l,
                )
            },
        },
        FaultCase {
            name: "imu-saturation",
            base: Base::Imu,
            injected: "the IMU flags saturation for 0.5 s from 3 s (a shock beyond its range)",
            expected: "the saturated samples counted (1,000) and marked suspect",
            at_s: 3.0,
            inject: |s, _| s.imu.saturated_s = vec![[3.0, 3.5]],
            judge: |r, _| {
                let i = &r.nav.imu;
                let pass = survived(r)
                    && (998..=1002).contains(&i.saturated_samples)
                    && r.nav.processing.suspect_samples >= i.saturated_samples;
                verdict(
                    pass,
                    format!(
                        "saturated samples {}, suspect {}",
                        i.saturated_samples, r.nav.processing.suspect_samples
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "imu-accel-frames-missing",
            base: Base::Imu,
            injected: "the accelerometer frames of samples 4000-4004 not sent",
            expected: "5 samples counted with their accelerometer frame missing, nothing else lost",
            at_s: 2.0,
            inject: |s, _| s.faults.drop_accel_samples = (4000..4005).collect(),
            judge: |r, _| {
                let i = &r.nav.imu;
                let pass = survived(r)
                    && i.accel_missing as i64 >= 5
                    && i.accel_missing as i64 <= 5 + r.bus_lost_frames
                    && i.missing_samples as i64 <= r.bus_lost_frames;
                verdict(
                    pass,
                    format!(
                        "accelerometer frames missing {}, samples missing {}",
                        i.accel_missing, i.missing_samples
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "imu-stream-stops",
            base: Base::Imu,
            injected: "the IMU sends nothing from 1.5 s to 5 s (the stream held until nav's watchdog has reported it: the bench's is 5 s of wall time)",
            expected: "the watchdog reports an IMU timeout (an event, the counter, a NAV_TIME with the imu_timeout bit) and the data's return; the stop's samples counted missing",
            at_s: 1.5,
            inject: |s, _| s.faults.stop_s = vec![[1.5, 5.0]],
            judge: |r, at| {
                let i = &r.nav.imu;
                let l = bit_latency(r, "imu_timeout", at);
                let stop = (3.5 * r.scenario.imu.rate_hz) as i64;
                let pass = survived(r)
                    && r.nav.imu_timeouts >= 1
                    && l.is_some()
                    && (i.missing_samples as i64 - stop).abs() <= 2 + r.bus_lost_frames;
                verdict(
                    pass,
                    format!(
                        "timeouts {}, imu_timeout bit on a NAV_TIME {}, missing {} (the stop: {stop})",
                        r.nav.imu_timeouts,
                        if l.is_some() { "yes" } else { "no" },
                        i.missing_samples
                    ),
                    None,
                )
            },
        },
    ]
}
