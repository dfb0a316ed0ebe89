//! The fault matrix (`hil faults`): each fault injected into the emulated devices (from a
//! scenario's fault fields, or by the bench taking the CAN interface down), run through vcan and
//! the pty against the unmodified nav binary, and judged against what nav must do: a counter in
//! its summary, a health bit in NAV_TIME, a mode, an abort reason, and by when.
//!
//! Every case is a short scenario of its own (a static IMU, a parked vehicle navigating with its
//! receiver, or a north-finding drill) with one fault; the whole matrix runs in one guest boot.
//! Detection latency is measured on the bus: the first NAV_TIME carrying the health bit (or the
//! mode) after the injection, in IMU time.

use crate::report::RunReport;
use crate::run::{RunOptions, run_here};
use crate::scenario::Scenario;
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The scenario a fault is injected into.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Base {
    /// The IMU alone, static, 6 s.
    Imu,
    /// A parked vehicle navigating with its receiver (surveyed heading), 16 s.
    Gps,
    /// A north-finding drill with 6 s dwells, cut at 45 s.
    Drill,
}

/// One row of the matrix: the fault and what nav must do.
pub struct FaultCase {
    /// Short name (`--only` takes it).
    pub name: &'static str,
    /// The scenario it goes into.
    pub base: Base,
    /// What is injected, in words.
    pub injected: &'static str,
    /// What nav must do, in words.
    pub expected: &'static str,
    /// IMU time of the injection, s.
    pub at_s: f64,
    /// Put the fault into the scenario (and the bench's actions into the options).
    inject: fn(&mut Scenario, &mut RunOptions),
    /// Judge the run.
    judge: fn(&RunReport, f64) -> Verdict,
}

/// What was seen of one case.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Verdict {
    /// Met the expectation.
    pub pass: bool,
    /// What was observed, in words (the counters and bits the judgement used).
    pub observed: String,
    /// Detection latency (IMU time from the injection to the first NAV_TIME showing it), s.
    pub latency_s: Option<f64>,
}

/// One row of the table.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FaultRow {
    /// Fault name.
    pub fault: String,
    /// Scenario base.
    pub base: Base,
    /// What was injected.
    pub injected: String,
    /// What nav must do.
    pub expected: String,
    /// What was seen.
    pub verdict: Verdict,
    /// nav's exit status.
    pub nav_exit: Option<i32>,
    /// Wall seconds of the run.
    pub wall_seconds: f64,
    /// The run's folder.
    pub run_dir: String,
}

/// The matrix's result.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FaultMatrix {
    /// `native` or `vm`.
    pub backend: String,
    /// Rows, in matrix order.
    pub rows: Vec<FaultRow>,
    /// Every row passed.
    pub pass: bool,
}

/// IMU time of NAV_TIME sample count `k` in run `r`, s.
fn imu_time(r: &RunReport, k: u64) -> f64 {
    let first = r.nav.first_sample.unwrap_or(0);
    (k.saturating_sub(first) as f64 + 1.0) / r.scenario.imu.rate_hz
}

/// Latency of health bit `bit` after `at_s`, s.
fn bit_latency(r: &RunReport, bit: &str, at_s: f64) -> Option<f64> {
    r.solution.health_on_at(bit).map(|k| imu_time(r, k) - at_s)
}

/// Latency of mode `mode` after `at_s`, s.
fn mode_latency(r: &RunReport, mode: &str, at_s: f64) -> Option<f64> {
    let first = r.nav.first_sample.unwrap_or(0);
    let from = first + (at_s * r.scenario.imu.rate_hz) as u64;
    r.solution
        .mode_at(mode, from)
        .map(|k| imu_time(r, k) - at_s)
}

fn verdict(pass: bool, observed: String, latency_s: Option<f64>) -> Verdict {
    Verdict {
        pass,
        observed,
        latency_s,
    }
}

/// nav survived: it exited 0 and wrote its summary.
fn survived(r: &RunReport) -> bool {
    r.nav_exit == Some(0)
}

fn lat_text(l: Option<f64>) -> String {
    l.map_or("never".into(), |l| format!("{l:.3} s"))
}

/// The counter jump of `imu-counter-jump`, samples.
const COUNTER_JUMP: u64 = 30_000;

/// The matrix, in table order.
pub fn matrix() -> Vec<FaultCase> {
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
        FaultCase {
            name: "can-interface-down-up",
            base: Base::Imu,
            injected: "the CAN interface taken down at 3 s of simulated time and brought back up at 4 s (the scheduler switches it between two samples: the frames of that second are written to a downed interface)",
            expected: "nav keeps running through it: the interface error counted (on a read or a send), exactly the outage's samples counted missing, every frame the emulator lost among them, data taken again when it is back",
            at_s: 3.0,
            inject: |s, o| {
                // long enough to see the data come back
                s.duration_s = 10.0;
                o.link_downs = vec![[3.0, 4.0]];
            },
            judge: |r, _| {
                let i = &r.nav.imu;
                let lost = r.tx.lost_iface_down;
                // the samples due in [3 s, 4 s) (one either way: where a sample's time falls
                // on the window's edges)
                let due = r.scenario.imu.rate_hz;
                let pass = survived(r)
                    && (i.missing_samples as f64 - due).abs() <= 1.0
                    && lost >= i.missing_samples
                    // the socket reports the outage once, to a read or to a send, whichever
                    // comes first
                    && r.nav.read_errors + r.nav.solution.send_errors + r.nav.command_send_errors
                        >= 1
                    && r.nav
                        .last_sample
                        .is_some_and(|k| imu_time(r, k) > r.scenario.duration_s - 0.5);
                verdict(
                    pass,
                    format!(
                        "frames lost while down {lost}, samples missing {} (due in the outage {due}), read errors {}, solution send errors {}, last sample at {:.2} s",
                        i.missing_samples,
                        r.nav.read_errors,
                        r.nav.solution.send_errors,
                        r.nav.last_sample.map_or(0.0, |k| imu_time(r, k))
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "foreign-frame-flood",
            base: Base::Imu,
            injected: "6 foreign frames per IMU sample (12,000 frames/s, 3 times the IMU's frame rate) from 2 s to 4 s",
            expected: "every foreign frame counted exactly by id, no IMU sample lost beyond what the kernel counted",
            at_s: 2.0,
            inject: |s, _| s.faults.flood_s = vec![[2.0, 4.0, 6.0]],
            judge: |r, _| {
                let flood = r.tx.flood_frames;
                let seen = r.nav.unknown_id_frames;
                let pass = survived(r)
                    && flood > 0
                    && seen + r.nav.kernel_dropped_frames >= flood
                    && seen <= flood
                    && r.nav.imu.missing_samples as i64 <= r.bus_lost_frames;
                verdict(
                    pass,
                    format!(
                        "sent {flood}, counted {seen} (ids {:?}), kernel dropped {}, IMU samples missing {}",
                        r.nav.unknown_ids, r.nav.kernel_dropped_frames, r.nav.imu.missing_samples
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "bus-overload",
            base: Base::Imu,
            injected: "the emulators run free (no lockstep) at x40, 80,000 IMU samples/s, into a nav whose socket receive buffer is 64 KiB",
            expected: "nav falls behind and the kernel drops frames: every frame written is either received by nav or in the socket's drop count (SO_RXQ_OVFL), the lost samples counted missing; no crash",
            at_s: 0.0,
            inject: |s, _| {
                s.speed = 40.0;
                s.bus.lockstep = false;
                s.bus.nav_rcvbuf_bytes = 65536;
            },
            judge: |r, _| {
                let dropped = r.nav.kernel_dropped_frames;
                let accounted = r
                    .checks
                    .iter()
                    .find(|c| c.name.starts_with("every frame written"));
                let missing = r.nav.imu.missing_samples;
                let pass = survived(r)
                    && dropped > 0
                    && accounted.is_some_and(|c| c.pass)
                    && missing > 0
                    && missing <= dropped;
                verdict(
                    pass,
                    format!(
                        "{}; IMU samples missing {missing}",
                        accounted.map_or("no frame accounting", |c| c.detail.as_str())
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "bad-length-frames",
            base: Base::Imu,
            injected: "IMU_GYRO frames of 5 bytes at 2 s and 3 s",
            expected: "both counted as wrong-length frames, the stream unharmed",
            at_s: 2.0,
            inject: |s, _| s.faults.bad_length_at_s = vec![2.0, 3.0],
            judge: |r, _| {
                let pass = survived(r)
                    && r.nav.bad_length_frames == 2
                    && r.nav.imu.missing_samples as i64 == r.bus_lost_frames / 2;
                verdict(
                    pass,
                    format!(
                        "wrong-length frames {}, samples missing {}",
                        r.nav.bad_length_frames, r.nav.imu.missing_samples
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "nav-killed",
            base: Base::Imu,
            injected: "nav killed outright (SIGKILL) at a random time between 2 s and 5 s, at real-time pace",
            expected: "its recording reads back up to the cut (nav's own reader rebuilds the summary from it), at most 1 s of IMU data lost",
            at_s: 2.0,
            inject: |s, o| {
                s.speed = 1.0;
                let nanos = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.subsec_nanos());
                o.kill_nav_at_s = Some(2.0 + 3.0 * f64::from(nanos % 1000) / 1000.0);
            },
            judge: |r, _| {
                let Some(k) = &r.killed else {
                    return verdict(false, "nav was not killed".into(), None);
                };
                let pass = k.recorded_frames > 0 && k.lost_s <= 1.0 && k.lost_s >= 0.0;
                verdict(
                    pass,
                    format!(
                        "killed at {:.2} s; recording read back: {} frames up to {:.2} s, {:.2} s of data lost, {} unreadable records at the cut",
                        k.at_s, k.recorded_frames, k.recorded_until_s, k.lost_s, k.bad_records
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "gps-void-outage",
            base: Base::Gps,
            injected: "the receiver sends void sentences (no fix) from 7 s to 13 s",
            expected: "the void fixes counted, gps_stale and mode Coasting within 3.5 s (2.5 s without a fix and the fix delay), GpsAided again after",
            at_s: 7.0,
            inject: |s, _| {
                if let Some(g) = s.gps.as_mut() {
                    g.outages = vec![[7.0, 13.0]];
                    g.outage_void = true;
                }
            },
            judge: |r, at| gps_outage(r, at, at + 6.0, true),
        },
        FaultCase {
            name: "gps-silent-outage",
            base: Base::Gps,
            injected: "the receiver falls silent from 7 s to 13 s",
            expected: "gps_stale and mode Coasting within 3.5 s, GpsAided again after",
            at_s: 7.0,
            inject: |s, _| {
                if let Some(g) = s.gps.as_mut() {
                    g.outages = vec![[7.0, 13.0]];
                    g.outage_void = false;
                }
            },
            judge: |r, at| gps_outage(r, at, at + 6.0, false),
        },
        FaultCase {
            name: "gps-position-jump",
            base: Base::Gps,
            injected: "three fixes 2 km north (7-9 s)",
            expected: "the three fixes rejected by the gate, the integrity alarm (filter bit) within 3.5 s, the position unharmed (within 25 m at the end)",
            at_s: 7.0,
            inject: |s, _| {
                if let Some(g) = s.gps.as_mut() {
                    g.multipath = vec![[7.0, 3.0, 2000.0]];
                }
            },
            judge: |r, at| {
                let f = r.nav.navigation.as_ref().and_then(|n| n.filter.as_ref());
                let rejected = f.map_or(0, |f| f.rejected);
                let l = bit_latency(r, "filter", at);
                let end = end_error(r);
                let pass = survived(r)
                    && rejected == 3
                    && l.is_some_and(|l| (0.0..=3.5).contains(&l))
                    && end.is_some_and(|e| e < 25.0);
                verdict(
                    pass,
                    format!(
                        "rejected {rejected}, filter bit after {}, end error {}",
                        lat_text(l),
                        end.map_or("--".into(), |e| format!("{e:.1} m"))
                    ),
                    l,
                )
            },
        },
        FaultCase {
            name: "gps-time-backwards",
            base: Base::Gps,
            injected: "the fix of 7 s carries a UTC time 10 s earlier",
            expected: "counted as time going backwards and not used",
            at_s: 7.0,
            inject: |s, _| {
                if let Some(g) = s.gps.as_mut() {
                    g.time_backwards_at_s = vec![7.0];
                }
            },
            judge: |r, _| {
                let back = r.nav.gps.as_ref().map_or(0, |g| g.stats.time_backwards);
                let pass = survived(r) && back >= 1;
                verdict(pass, format!("time going backwards {back}"), None)
            },
        },
        FaultCase {
            name: "gps-garbage",
            base: Base::Gps,
            injected: "line noise and a line of binary bytes before the fixes of 6 s and 9 s",
            expected: "the garbage bytes and the two binary lines counted, every fix still decoded",
            at_s: 6.0,
            inject: |s, _| {
                if let Some(g) = s.gps.as_mut() {
                    g.garbage_at_s = vec![6.0, 9.0];
                }
            },
            judge: |r, _| {
                let Some(g) = r.nav.gps.as_ref() else {
                    return verdict(false, "no GPS summary".into(), None);
                };
                let st = &g.stats;
                let sent = r.gps.as_ref().map_or(0, |x| x.fixes);
                let pass = survived(r)
                    && st.garbage_bytes >= 2
                    && st.binary_lines == 2
                    && st.fixes + 2 >= 2 * sent;
                verdict(
                    pass,
                    format!(
                        "garbage bytes {}, binary lines {}, fixes decoded {} (GGA and RMC) of {sent} epochs",
                        st.garbage_bytes, st.binary_lines, st.fixes
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "gps-unplugged",
            base: Base::Gps,
            injected: "the receiver's device vanishes from 7 s to 10 s and comes back behind the same link",
            expected: "the hang-up counted, the port re-opened, gps_stale and Coasting within 3.5 s, GpsAided again after",
            at_s: 7.0,
            inject: |s, _| {
                if let Some(g) = s.gps.as_mut() {
                    g.port_drops = vec![[7.0, 10.0]];
                }
            },
            judge: |r, at| {
                let Some(g) = r.nav.gps.as_ref() else {
                    return verdict(false, "no GPS summary".into(), None);
                };
                let l = mode_latency(r, "Coasting", at);
                let back = mode_latency(r, "GpsAided", at + 3.0);
                let pass = survived(r)
                    && g.port_errors >= 1
                    && g.opens >= 2
                    && l.is_some_and(|l| (0.0..=3.5).contains(&l))
                    && back.is_some();
                verdict(
                    pass,
                    format!(
                        "port errors {}, opens {}, Coasting after {}, GpsAided again {}",
                        g.port_errors,
                        g.opens,
                        lat_text(l),
                        if back.is_some() { "yes" } else { "no" }
                    ),
                    l,
                )
            },
        },
        FaultCase {
            name: "pps-missing",
            base: Base::Gps,
            injected: "no PPS edge latched in the IMU data from 7 s to 11 s",
            expected: "the fixes that found no edge applied at their arrival and counted, the solution stays GPS-aided",
            at_s: 7.0,
            inject: |s, _| s.imu.pps_missing_s = vec![[7.0, 11.0]],
            judge: |r, at| {
                let n = r.nav.navigation.as_ref();
                let untied = n.map_or(0, |n| n.untied_fixes);
                let coasted = mode_latency(r, "Coasting", at).is_some_and(|l| l < 6.0);
                let pass = survived(r) && untied >= 2 && !coasted;
                verdict(
                    pass,
                    format!(
                        "fixes without a PPS edge {untied}, PPS edges {}, coasted {}",
                        n.map_or(0, |n| n.pps_edges),
                        if coasted { "yes" } else { "no" }
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "pps-jitter",
            base: Base::Gps,
            injected: "the PPS latch jitters by 0.5 ms (one sigma) and the PPS line glitches twice, at 7.4 s and 11.7 s",
            expected: "every true edge taken despite the jitter, both glitches rejected and counted, no fix left without its edge, the solution stays GPS-aided",
            at_s: 7.4,
            inject: |s, _| {
                s.imu.pps_jitter_s = 0.0005;
                s.imu.pps_spurious_at_s = vec![7.4, 11.7];
            },
            judge: |r, at| {
                let n = r.nav.navigation.as_ref();
                let (edges, rejected, untied) =
                    n.map_or((0, 0, 0), |n| (n.pps_edges, n.pps_rejected, n.untied_fixes));
                let coasted = mode_latency(r, "Coasting", at).is_some();
                let whole = r.scenario.duration_s.floor() as u64;
                let pass = survived(r)
                    && rejected == 2
                    && edges + 1 >= whole
                    && edges <= whole
                    && untied == 0
                    && !coasted;
                verdict(
                    pass,
                    format!(
                        "PPS edges taken {edges} (of {whole} true ones), rejected {rejected}, fixes without an edge {untied}, coasted {}",
                        if coasted { "yes" } else { "no" }
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "turntable-stall",
            base: Base::Drill,
            injected: "the indexing motor stalls on the first move after 5 s",
            expected: "north-finding aborted with a reason naming the stall, turntable health bit set",
            at_s: 5.0,
            inject: |s, _| tt_faults(s, |f| f.stall_from_s = Some(5.0)),
            judge: |r, at| nf_abort(r, at, "stall"),
        },
        FaultCase {
            name: "turntable-lock-failure",
            base: Base::Drill,
            injected: "the lock pin never engages",
            expected: "north-finding aborted with a reason naming the lock, turntable health bit set",
            at_s: 0.0,
            inject: |s, _| tt_faults(s, |f| f.lock_fails = true),
            judge: |r, at| nf_abort(r, at, "lock"),
        },
        FaultCase {
            name: "turntable-encoder-glitch",
            base: Base::Drill,
            injected: "one status frame at 4 s carries a glitched encoder angle and the encoder bit",
            expected: "north-finding aborted with a reason naming the encoder, turntable health bit set",
            at_s: 4.0,
            inject: |s, _| tt_faults(s, |f| f.encoder_glitch_at_s = vec![4.0]),
            judge: |r, at| nf_abort(r, at, "encoder"),
        },
        FaultCase {
            name: "turntable-lost-ack",
            base: Base::Drill,
            injected: "the mechanism never executes or acknowledges command 3",
            expected: "the command sent again and counted; north-finding goes on",
            at_s: 0.0,
            inject: |s, _| {
                // long enough for the command to be sent again and the drill to go on
                s.duration_s = 25.0;
                tt_faults(s, |f| f.lost_command_seqs = vec![3])
            },
            judge: |r, _| {
                let nf = r.nav.north_finding.as_ref();
                let retries = nf.map_or(0, |n| n.command_retries);
                let abort = nf.and_then(|n| n.abort.clone());
                let pass = survived(r) && retries >= 1 && abort.is_none();
                verdict(
                    pass,
                    format!(
                        "retries {retries}, aborted: {}",
                        abort.as_deref().unwrap_or("no")
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "turntable-late-ack",
            base: Base::Drill,
            injected: "every command takes effect and is acknowledged 1.2 s late (past nav's 0.5 s timeout and its first retry, inside its three tries' 1.5 s)",
            expected: "the late acknowledgements counted and the commands sent again; north-finding aborts with a reason naming the missing acknowledgement once its retries are spent",
            at_s: 0.0,
            // not 1.5 s: the first acknowledgement would then come exactly as nav gives up
            // (three tries of 0.5 s), and which comes first was a matter of a millisecond
            inject: |s, _| tt_faults(s, |f| f.command_delay_s = 1.2),
            judge: |r, at| {
                let v = nf_abort(r, at, "acknowledgement");
                let nf = r.nav.north_finding.as_ref();
                let (retries, stale) = nf.map_or((0, 0), |n| (n.command_retries, n.stale_acks));
                verdict(
                    v.pass && retries >= 1 && stale >= 1,
                    format!(
                        "{}; retries {retries}, late acknowledgements {stale}",
                        v.observed
                    ),
                    v.latency_s,
                )
            },
        },
        FaultCase {
            name: "turntable-heartbeat-loss",
            base: Base::Drill,
            injected: "the mechanism's controller sends no status frames from 12 s on",
            expected: "north-finding aborted within 1 s with a reason naming the lost heartbeat, turntable health bit set",
            at_s: 12.0,
            inject: |s, _| tt_faults(s, |f| f.status_silent_s = vec![[12.0, 1e9]]),
            judge: |r, at| {
                let v = nf_abort(r, at, "heartbeat");
                let pass = v.pass && v.latency_s.is_some_and(|l| (0.0..=1.0).contains(&l));
                verdict(pass, v.observed, v.latency_s)
            },
        },
    ]
}

fn tt_faults(s: &mut Scenario, f: impl FnOnce(&mut emulators::turntable::TurntableFaults)) {
    if let Some(t) = s.turntable.as_mut() {
        f(&mut t.faults);
    }
}

/// The end position error of a navigating run (nav's final output against the truth), m.
fn end_error(r: &RunReport) -> Option<f64> {
    let drive = emulators::drive::Drive::plan(r.scenario.drive.as_ref()?).ok()?;
    let t_first = 1.0 / r.scenario.imu.rate_hz;
    crate::engine::navigate::score_summary(&drive, &r.nav, t_first).map(|n| n.position_error_m)
}

/// What nav must do with a frame overtaken on the bus.
const LATE_FRAME: &str = "the late frame counted and dropped, the gap it left counted and differenced across (cumulative counters: no angle lost, attitude valid), imu_gaps health bit within 0.1 s";

/// A frame overtaken on the bus: dropped and counted, the gap differenced across, no
/// re-synchronisation, the attitude valid, `imu_gaps` within 0.1 s.
fn late_frame(r: &RunReport, at: f64) -> Verdict {
    let i = &r.nav.imu;
    let l = bit_latency(r, "imu_gaps", at);
    let pass = survived(r)
        && i.gaps >= 1
        && i.late_frames == 1
        && i.backwards == 0
        && r.nav.attitude.valid
        && l.is_some_and(|l| (0.0..=0.1).contains(&l));
    verdict(
        pass,
        format!(
            "late frames {}, gaps {}, missing {}, re-synchronisations {}, attitude valid {}, imu_gaps after {}",
            i.late_frames,
            i.gaps,
            i.missing_samples,
            i.backwards,
            r.nav.attitude.valid,
            lat_text(l)
        ),
        l,
    )
}

/// A GPS outage from `at` to `end`: Coasting within 3.5 s of its start, GpsAided again after
/// its end.
fn gps_outage(r: &RunReport, at: f64, end: f64, void: bool) -> Verdict {
    let l = mode_latency(r, "Coasting", at);
    let stale = bit_latency(r, "gps_stale", at);
    let back = mode_latency(r, "GpsAided", end);
    let no_fix = r.nav.gps.as_ref().map_or(0, |g| g.stats.no_fix);
    let pass = survived(r)
        && l.is_some_and(|l| (0.0..=3.5).contains(&l))
        && stale.is_some()
        && back.is_some()
        && (!void || no_fix >= 5);
    verdict(
        pass,
        format!(
            "Coasting after {}, gps_stale seen {}, GpsAided again {}, void fixes {no_fix}",
            lat_text(l),
            if stale.is_some() { "yes" } else { "no" },
            if back.is_some() { "yes" } else { "no" }
        ),
        l,
    )
}

/// North-finding aborted with `word` in its reason and the turntable health bit set; latency
/// from `at` to the bit.
fn nf_abort(r: &RunReport, at: f64, word: &str) -> Verdict {
    let abort = r.nav.north_finding.as_ref().and_then(|n| n.abort.clone());
    let l = bit_latency(r, "turntable", at);
    let pass = survived(r)
        && abort
            .as_deref()
            .is_some_and(|a| a.to_lowercase().contains(word))
        && l.is_some();
    verdict(
        pass,
        format!(
            "aborted: {}; turntable bit after {}",
            abort.as_deref().unwrap_or("no"),
            lat_text(l)
        ),
        l,
    )
}

/// The scenario of base `b` for fault `name`.
pub fn base_scenario(b: Base, name: &str) -> Result<Scenario> {
    let mut s = match b {
        Base::Imu => {
            let mut s = Scenario::builtin_static();
            s.duration_s = 6.0;
            s
        }
        Base::Gps => {
            let mut s = Scenario::from_text(include_str!("../../../scenarios/drive-gps.toml"))
                .context("the drive-gps scenario")?;
            s.duration_s = 16.0;
            if let Some(d) = s.drive.as_mut() {
                // parked the whole run: the faults, not the drive, are what is looked at
                d.start_wait_s = 1000.0;
            }
            s
        }
        Base::Drill => {
            let mut s = crate::procedures::northfinding::scenario(30.0, 45.0, 6.0, 7);
            s.duration_s = 45.0;
            s
        }
    };
    s.name = format!("fault-{name}");
    s.speed = 10.0;
    Ok(s)
}

/// Settings of a matrix run.
pub struct FaultOptions {
    /// CAN interface.
    pub iface: String,
    /// Output folder (one sub-folder per case).
    pub out: std::path::PathBuf,
    /// The nav binary.
    pub nav_bin: std::path::PathBuf,
    /// Only these faults (all when empty).
    pub only: Vec<String>,
    /// Speed factor.
    pub speed: f64,
    /// Print a line per case.
    pub progress: bool,
}

/// Run the matrix here (the kernel must have CAN).
pub fn run_matrix(o: &FaultOptions, backend: &str) -> Result<FaultMatrix> {
    let cases: Vec<FaultCase> = matrix()
        .into_iter()
        .filter(|c| o.only.is_empty() || o.only.iter().any(|n| n == c.name))
        .collect();
    if cases.is_empty() {
        bail!(
            "--only names no fault of the matrix ({})",
            matrix()
                .iter()
                .map(|c| c.name)
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    std::fs::create_dir_all(&o.out).with_context(|| format!("creating {}", o.out.display()))?;
    let mut rows = Vec::new();
    for (i, c) in cases.iter().enumerate() {
        let mut s = base_scenario(c.base, c.name)?;
        s.speed = o.speed;
        let dir = o.out.join(c.name);
        let mut opts = RunOptions {
            // the matrix's own table (faults.md) is the report of its runs
            html: false,
            ..RunOptions::new(&o.iface, dir.clone(), o.nav_bin.clone())
        };
        (c.inject)(&mut s, &mut opts);
        s.check()
            .with_context(|| format!("the scenario of fault {}", c.name))?;
        let t0 = std::time::Instant::now();
        let row = match run_here(&s, &opts, backend) {
            Ok(r) => {
                let v = (c.judge)(&r, c.at_s);
                FaultRow {
                    fault: c.name.into(),
                    base: c.base,
                    injected: c.injected.into(),
                    expected: c.expected.into(),
                    verdict: v,
                    nav_exit: r.nav_exit,
                    wall_seconds: r.wall_seconds,
                    run_dir: dir.display().to_string(),
                }
            }
            Err(e) => FaultRow {
                fault: c.name.into(),
                base: c.base,
                injected: c.injected.into(),
                expected: c.expected.into(),
                verdict: verdict(false, format!("the run failed: {e:#}"), None),
                nav_exit: None,
                wall_seconds: t0.elapsed().as_secs_f64(),
                run_dir: dir.display().to_string(),
            },
        };
        if o.progress {
            eprintln!(
                "hil faults: {}/{} {} {} ({:.1} s): {}",
                i + 1,
                cases.len(),
                if row.verdict.pass { "PASS" } else { "FAIL" },
                row.fault,
                t0.elapsed().as_secs_f64(),
                row.verdict.observed
            );
        }
        rows.push(row);
    }
    let m = FaultMatrix {
        backend: backend.into(),
        pass: rows.iter().all(|r| r.verdict.pass),
        rows,
    };
    write(&m, &o.out)?;
    Ok(m)
}

/// Write `faults.json` and `faults.md`.
pub fn write(m: &FaultMatrix, out: &Path) -> Result<()> {
    std::fs::write(out.join("faults.json"), serde_json::to_string_pretty(m)?)
        .context("writing faults.json")?;
    std::fs::write(out.join("faults.md"), markdown(m)).context("writing faults.md")?;
    crate::report::page::folder_page(out, "Fault matrix", &markdown(m))?;
    Ok(())
}

/// The table as Markdown.
pub fn markdown(m: &FaultMatrix) -> String {
    use std::fmt::Write;
    let mut s = format!(
        "# Fault matrix ({})\n\n{} of {} faults handled as expected.\n\n| fault | injected | expected | observed | detection latency | result |\n|---|---|---|---|---|---|\n",
        m.backend,
        m.rows.iter().filter(|r| r.verdict.pass).count(),
        m.rows.len()
    );
    for r in &m.rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} |",
            r.fault,
            r.injected,
            r.expected,
            r.verdict.observed.replace('|', "/"),
            r.verdict
                .latency_s
                .map_or("--".into(), |l| format!("{l:.3} s")),
            if r.verdict.pass { "pass" } else { "**FAIL**" }
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The matrix covers at least 16 faults, each name once, and every case's scenario passes
    /// its checks with the fault in it.
    #[test]
    fn every_case_builds_a_valid_scenario() {
        let m = matrix();
        assert!(m.len() >= 16, "{} faults", m.len());
        let mut names: Vec<&str> = m.iter().map(|c| c.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), m.len(), "a name is used twice");
        for c in &m {
            let mut s = base_scenario(c.base, c.name).unwrap();
            let mut o = RunOptions::new("vcan0", "/tmp".into(), "nav".into());
            (c.inject)(&mut s, &mut o);
            s.check().unwrap_or_else(|e| panic!("{}: {e:#}", c.name));
            assert!(c.at_s < s.duration_s, "{}", c.name);
        }
    }
}
