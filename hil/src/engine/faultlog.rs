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

/// nav stopped for a while by the bench (the run's `stall_nav`): SIGSTOP, then SIGCONT.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavStall {
    /// Simulated time of the stop, s.
    pub at_s: f64,
    /// How long nav stays stopped, wall s.
    pub wall_s: f64,
}

/// The events of one device as they are gathered.
struct Device<'a> {
    name: &'static str,
    ev: &'a mut Vec<FaultEvent>,
}

impl Device<'_> {
    fn push(&mut self, t_s: f64, fault: &'static str, phase: &'static str, detail: String) {
        self.ev.push(FaultEvent {
            t_s,
            device: self.name,
            fault,
            phase,
            detail,
        });
    }

    /// One event at each of `times`.
    fn at(&mut self, fault: &'static str, times: &[f64], detail: &str) {
        for &t in times {
            self.push(t, fault, "at", detail.into());
        }
    }

    /// A start and an end for each of `windows` ([start, end, ...] s); `extra` follows the span.
    fn windows<const N: usize>(&mut self, fault: &'static str, windows: &[[f64; N]], extra: &str) {
        for w in windows {
            self.push(
                w[0],
                fault,
                "starts",
                format!("{:.3}-{:.3} s{extra}", w[0], w[1]),
            );
            self.push(w[1], fault, "ends", String::new());
        }
    }

    /// A fault on from `t` (to the end of the run).
    fn from(&mut self, fault: &'static str, t: Option<f64>, detail: &str) {
        if let Some(t) = t {
            self.push(t, fault, "starts", detail.into());
        }
    }

    /// A fault on for the whole run, when `on`.
    fn throughout(&mut self, fault: &'static str, on: bool, detail: String) {
        if on {
            self.push(0.0, fault, "throughout", detail);
        }
    }
}

/// Every fault event of scenario `s` run with `link_downs` ([down at, up at], s), a SIGKILL
/// of nav at `kill_at_s` and a stop of nav (`stall`), in time order.
pub fn schedule(
    s: &Scenario,
    link_downs: &[[f64; 2]],
    kill_at_s: Option<f64>,
    stall: Option<NavStall>,
) -> Vec<FaultEvent> {
    let mut ev = Vec::new();
    imu_events(s, &mut ev);
    bus_events(s, &mut ev);
    if let Some(g) = &s.gps {
        gps_events(g, &mut ev);
    }
    if let Some(tt) = &s.turntable {
        turntable_events(tt, &mut ev);
    }
    // the bench's own actions
    let mut bench = Device {
        name: "bench",
        ev: &mut ev,
    };
    for [down, up] in link_downs {
        bench.push(*down, "link_downs", "starts", "CAN interface down".into());
        bench.push(*up, "link_downs", "ends", "CAN interface back up".into());
    }
    bench.at(
        "kill_nav_at_s",
        kill_at_s.as_slice(),
        "nav killed (SIGKILL)",
    );
    if let Some(st) = stall {
        let detail = format!("nav stopped (SIGSTOP) for {} s of wall time", st.wall_s);
        bench.push(st.at_s, "stall_nav", "at", detail);
    }
    ev.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    ev
}

/// The IMU's own faults.
fn imu_events(s: &Scenario, ev: &mut Vec<FaultEvent>) {
    let rate = s.imu.rate_hz.max(1e-9);
    let at_sample = |k: u64| k as f64 / rate;
    let i = &s.imu;
    let mut imu = Device { name: "imu", ev };
    imu.from(
        "bit_fail_from_s",
        i.bit_fail_from_s,
        "built-in test fails from here",
    );
    imu.windows("saturated_s", &i.saturated_s, "");
    imu.windows("pps_missing_s", &i.pps_missing_s, "");
    imu.at(
        "pps_spurious_at_s",
        &i.pps_spurious_at_s,
        "a spurious PPS edge",
    );
    imu.throughout(
        "pps_jitter_s",
        i.pps_jitter_s > 0.0,
        format!("{} s", i.pps_jitter_s),
    );
    for [k, jump] in &i.counter_jumps {
        let detail = format!("sample {k}: counter +{jump}");
        imu.push(at_sample(*k), "counter_jumps", "at", detail);
    }
}

/// The IMU's frames on the bus: dropped, duplicated, held back, foreign frames.
fn bus_events(s: &Scenario, ev: &mut Vec<FaultEvent>) {
    let rate = s.imu.rate_hz.max(1e-9);
    let at_sample = |k: u64| k as f64 / rate;
    let f = &s.faults;
    let mut bus = Device { name: "bus", ev };
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
            bus.push(at_sample(*k), fault, "at", format!("sample {k}: {what}"));
        }
    }
    bus.at(
        "unknown_id_at_s",
        &f.unknown_id_at_s,
        "a frame outside the contract",
    );
    bus.at(
        "bad_length_at_s",
        &f.bad_length_at_s,
        "an IMU_GYRO of wrong length",
    );
    bus.windows("stop_s", &f.stop_s, ": the IMU sends nothing");
    for [k, n] in &f.delay_samples {
        let detail = format!("sample {k} held back {n} samples");
        bus.push(at_sample(*k), "delay_samples", "at", detail);
    }
    for w in &f.flood_s {
        let extra = format!(", {} foreign frames per sample", w[2]);
        bus.windows("flood_s", &[*w], &extra);
    }
}

/// The receiver's.
fn gps_events(g: &emulators::gps::ReceiverParams, ev: &mut Vec<FaultEvent>) {
    // the receiver
    let mut gps = Device { name: "gps", ev };
    let kind = if g.outage_void {
        ", void fixes"
    } else {
        ", silent"
    };
    gps.windows("outages", &g.outages, kind);
    for m in &g.multipath {
        gps.windows(
            "multipath",
            &[[m[0], m[0] + m[1]]],
            &format!(", {} m north", m[2]),
        );
    }
    gps.windows("port_drops", &g.port_drops, ": the device is gone");
    gps.at(
        "time_backwards_at_s",
        &g.time_backwards_at_s,
        "UTC 10 s back",
    );
    gps.at(
        "garbage_at_s",
        &g.garbage_at_s,
        "line noise and binary bytes",
    );
}

/// The turntable's.
fn turntable_events(tt: &emulators::turntable::TurntableParams, ev: &mut Vec<FaultEvent>) {
    // the turntable
    let f = &tt.faults;
    let mut table = Device {
        name: "turntable",
        ev,
    };
    table.from("stall_from_s", f.stall_from_s, "the axis stalls");
    table.throughout("lock_fails", f.lock_fails, "the lock never engages".into());
    table.at(
        "encoder_glitch_at_s",
        &f.encoder_glitch_at_s,
        "an encoder glitch",
    );
    let lost = format!("commands {:?} lost", f.lost_command_seqs);
    table.throughout("lost_command_seqs", !f.lost_command_seqs.is_empty(), lost);
    let late = format!("acknowledgements {} s late", f.command_delay_s);
    table.throughout("command_delay_s", f.command_delay_s > 0.0, late);
    table.windows("status_silent_s", &f.status_silent_s, ": no heartbeat");
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
        let stall = NavStall {
            at_s: 11.0,
            wall_s: 1.0,
        };
        let ev = schedule(&s, &[[7.0, 7.5]], Some(12.0), Some(stall));
        let brief: Vec<(f64, &str, &str)> = ev.iter().map(|e| (e.t_s, e.fault, e.phase)).collect();
        let k = 4000.0 / s.imu.rate_hz;
        let mut expected = vec![
            (k, "drop_samples", "at"),
            (3.25, "pps_spurious_at_s", "at"),
            (7.0, "link_downs", "starts"),
            (7.5, "link_downs", "ends"),
            (10.0, "stop_s", "starts"),
            (10.5, "stop_s", "ends"),
            (11.0, "stall_nav", "at"),
            (12.0, "kill_nav_at_s", "at"),
        ];
        expected.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(brief, expected);
        assert!(schedule(&Scenario::builtin_static(), &[], None, None).is_empty());
    }
}
