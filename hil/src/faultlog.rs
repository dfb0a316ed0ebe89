//! The faults a run injects, as events on simulated time: what `truth.mcap` records on
//! `/bench/faults` (Foxglove's Log schema), so that a run can be judged later without its
//! scenario at hand and a viewer shows each fault beside nav's own log (`/nav/log`).
//!
//! The bench injects its faults at fixed simulated times (the scenario's fault tables, and the
//! run's link-downs and kill): the schedule is the injection, to the sample.

use crate::scenario::Scenario;
use serde::Serialize;

/// One fault event.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaultEvent {
    /// Simulated time, s.
    pub t_s: f64,
    /// The device it is injected in: `imu`, `bus`, `gps`, `turntable`, `bench`.
    pub device: &'static str,
    /// The fault (its scenario field).
    pub fault: &'static str,
    /// What happens: `starts`, `ends`, `at`, `throughout`.
    pub phase: &'static str,
    /// Its parameters, for people.
    pub detail: String,
}

/// Every fault event of scenario `s` run with `link_downs` ([simulated time, wall ms]) and a
/// SIGKILL of nav at `kill_at_s`, in time order.
pub fn schedule(s: &Scenario, link_downs: &[[f64; 2]], kill_at_s: Option<f64>) -> Vec<FaultEvent> {
    let mut ev = Vec::new();
    let rate = s.imu.rate_hz.max(1e-9);
    let mut at = |t: f64, device, fault, phase, detail: String| {
        ev.push(FaultEvent {
            t_s: t,
            device,
            fault,
            phase,
            detail,
        })
    };
    let window = |at: &mut dyn FnMut(f64, &'static str, &'static str, &'static str, String),
                  device,
                  fault,
                  w: &[f64],
                  extra: String| {
        at(
            w[0],
            device,
            fault,
            "starts",
            format!("{:.3}-{:.3} s{extra}", w[0], w[1]),
        );
        at(w[1], device, fault, "ends", String::new());
    };
    // the IMU and its frames on the bus
    let i = &s.imu;
    if let Some(t) = i.bit_fail_from_s {
        at(
            t,
            "imu",
            "bit_fail_from_s",
            "starts",
            "built-in test fails from here".into(),
        );
    }
    for w in &i.saturated_s {
        window(&mut at, "imu", "saturated_s", w, String::new());
    }
    for w in &i.pps_missing_s {
        window(&mut at, "imu", "pps_missing_s", w, String::new());
    }
    for &t in &i.pps_spurious_at_s {
        at(
            t,
            "imu",
            "pps_spurious_at_s",
            "at",
            "a spurious PPS edge".into(),
        );
    }
    if i.pps_jitter_s > 0.0 {
        at(
            0.0,
            "imu",
            "pps_jitter_s",
            "throughout",
            format!("{} s", i.pps_jitter_s),
        );
    }
    for [k, jump] in &i.counter_jumps {
        at(
            *k as f64 / rate,
            "imu",
            "counter_jumps",
            "at",
            format!("sample {k}: counter +{jump}"),
        );
    }
    let f = &s.faults;
    for (samples, fault, what) in [
        (&f.drop_samples, "drop_samples", "frames not sent"),
        (
            &f.duplicate_samples,
            "duplicate_samples",
            "IMU_GYRO sent twice",
        ),
        (
            &f.drop_accel_samples,
            "drop_accel_samples",
            "IMU_ACCEL not sent",
        ),
    ] {
        for k in samples {
            at(
                *k as f64 / rate,
                "bus",
                fault,
                "at",
                format!("sample {k}: {what}"),
            );
        }
    }
    for &t in &f.unknown_id_at_s {
        at(
            t,
            "bus",
            "unknown_id_at_s",
            "at",
            "a frame outside the contract".into(),
        );
    }
    for &t in &f.bad_length_at_s {
        at(
            t,
            "bus",
            "bad_length_at_s",
            "at",
            "an IMU_GYRO of wrong length".into(),
        );
    }
    for w in &f.stop_s {
        window(
            &mut at,
            "bus",
            "stop_s",
            w,
            ": the IMU sends nothing".into(),
        );
    }
    for [k, n] in &f.delay_samples {
        at(
            *k as f64 / rate,
            "bus",
            "delay_samples",
            "at",
            format!("sample {k} held back {n} samples"),
        );
    }
    for w in &f.flood_s {
        window(
            &mut at,
            "bus",
            "flood_s",
            w,
            format!(", {} foreign frames per sample", w[2]),
        );
    }
    // the receiver
    if let Some(g) = &s.gps {
        for w in &g.outages {
            let kind = if g.outage_void {
                "void fixes"
            } else {
                "silent"
            };
            window(&mut at, "gps", "outages", w, format!(", {kind}"));
        }
        for m in &g.multipath {
            window(
                &mut at,
                "gps",
                "multipath",
                &[m[0], m[0] + m[1]],
                format!(", {} m north", m[2]),
            );
        }
        for w in &g.port_drops {
            window(
                &mut at,
                "gps",
                "port_drops",
                w,
                ": the device is gone".into(),
            );
        }
        for &t in &g.time_backwards_at_s {
            at(
                t,
                "gps",
                "time_backwards_at_s",
                "at",
                "UTC 10 s back".into(),
            );
        }
        for &t in &g.garbage_at_s {
            at(
                t,
                "gps",
                "garbage_at_s",
                "at",
                "line noise and binary bytes".into(),
            );
        }
    }
    // the turntable
    if let Some(tt) = &s.turntable {
        let f = &tt.faults;
        if let Some(t) = f.stall_from_s {
            at(
                t,
                "turntable",
                "stall_from_s",
                "starts",
                "the axis stalls".into(),
            );
        }
        if f.lock_fails {
            at(
                0.0,
                "turntable",
                "lock_fails",
                "throughout",
                "the lock never engages".into(),
            );
        }
        for &t in &f.encoder_glitch_at_s {
            at(
                t,
                "turntable",
                "encoder_glitch_at_s",
                "at",
                "an encoder glitch".into(),
            );
        }
        if !f.lost_command_seqs.is_empty() {
            at(
                0.0,
                "turntable",
                "lost_command_seqs",
                "throughout",
                format!("commands {:?} lost", f.lost_command_seqs),
            );
        }
        if f.command_delay_s > 0.0 {
            at(
                0.0,
                "turntable",
                "command_delay_s",
                "throughout",
                format!("acknowledgements {} s late", f.command_delay_s),
            );
        }
        for w in &f.status_silent_s {
            window(
                &mut at,
                "turntable",
                "status_silent_s",
                w,
                ": no heartbeat".into(),
            );
        }
    }
    // the bench's own actions
    for [t, ms] in link_downs {
        at(
            *t,
            "bench",
            "link_downs",
            "at",
            format!("CAN interface down for {ms} ms"),
        );
    }
    if let Some(t) = kill_at_s {
        at(
            t,
            "bench",
            "kill_nav_at_s",
            "at",
            "nav killed (SIGKILL)".into(),
        );
    }
    ev.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    ev
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scenario's fault tables become events at their times, windows as a start and an end,
    /// sample indices at their sample's time, the bench's own actions included, in time order.
    #[test]
    fn fault_tables_become_timed_events() {
        let mut s = Scenario::builtin_static();
        s.faults.stop_s = vec![[10.0, 10.5]];
        s.faults.drop_samples = vec![4000];
        s.imu.pps_spurious_at_s = vec![3.25];
        let ev = schedule(&s, &[[7.0, 200.0]], Some(12.0));
        let brief: Vec<(f64, &str, &str)> = ev.iter().map(|e| (e.t_s, e.fault, e.phase)).collect();
        let k = 4000.0 / s.imu.rate_hz;
        let mut expected = vec![
            (k, "drop_samples", "at"),
            (3.25, "pps_spurious_at_s", "at"),
            (7.0, "link_downs", "at"),
            (10.0, "stop_s", "starts"),
            (10.5, "stop_s", "ends"),
            (12.0, "kill_nav_at_s", "at"),
        ];
        expected.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(brief, expected);
        assert!(schedule(&Scenario::builtin_static(), &[], None).is_empty());
    }
}
