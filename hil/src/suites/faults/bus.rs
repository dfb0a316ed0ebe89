//! The fault matrix's rows on the CAN bus and nav's process.

use super::*;

/// The stop of nav in `bus-overload`: it makes the overload certain on any host (a fast one
/// keeps nav up with x40: a CI host's nav received all 24,060 frames).
const OVERLOAD_STALL: crate::run::NavStall = crate::run::NavStall {
    at_s: 1.0,
    wall_s: 0.1,
};

/// The CAN interface: the link down and up.
pub(super) fn interface() -> Vec<FaultCase> {
    vec![FaultCase {
        name: "can-interface-down-up",
        base: Base::Imu,
        injected: "the CAN interface taken down at 3 s of simulated time and brought back up at 4 s (the scheduler switches it between two samples: the frames of that second are written to a downed interface)",
        expected: "nav keeps running through it: exactly the outage's samples counted missing, every frame the emulator lost among them, data taken again when it is back; the interface error counted where the kernel reports it (to a read that finds nav's queue empty, or a send while down: a nav busy with a backlog is not told, as under two CPU hogs)",
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
                    // the socket reports the outage once, to a read that waits on an empty
                    // queue or to a send while down, whichever comes first, if either comes:
                    // counted and shown, not asked for
                    && ran_to_end(r);
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
    }]
}

/// The bus's traffic: a flood of foreign frames, an overloaded bus, frames of a bad length.
pub(super) fn traffic() -> Vec<FaultCase> {
    vec![
        FaultCase {
            name: "foreign-frame-flood",
            base: Base::Imu,
            injected: "a foreign node queues 6 frames of the lowest priority (0x7E6) per IMU sample (12,000 frames/s, more than the 1 Mbit/s bus can carry beside the IMU) from 2 s to 4 s",
            expected: "the bus carries what fits after the IMU's frames, the rest overflows the foreign node's queue (counted by the bus model); nav counts every foreign frame that reached it exactly by id; the IMU keeps its priority: no IMU sample lost",
            at_s: 2.0,
            inject: |s, _| s.faults.flood_s = vec![[2.0, 4.0, 6.0]],
            judge: |r, _| {
                let flood = r.tx.flood_frames;
                let on_bus = r
                    .bus
                    .ids
                    .iter()
                    .find(|i| i.id == 0x7E6)
                    .map_or(0, |i| i.frames);
                let overflow = r
                    .bus
                    .nodes
                    .iter()
                    .find(|n| n.name == emulators::bus::model::FOREIGN)
                    .map_or(0, |n| n.overflow);
                let seen = r.nav.unknown_id_frames;
                let pass = survived(r)
                    && on_bus > 0
                    && on_bus + overflow == flood
                    && seen + r.nav.kernel_dropped_frames >= on_bus
                    && seen <= on_bus
                    && r.nav.imu.missing_samples == 0;
                verdict(
                    pass,
                    format!(
                        "queued {flood}: {on_bus} on the bus, {overflow} overflowed the node's queue; nav counted {seen} (ids {:?}), kernel dropped {}, IMU samples missing {}",
                        r.nav.unknown_ids, r.nav.kernel_dropped_frames, r.nav.imu.missing_samples
                    ),
                    None,
                )
            },
        },
        FaultCase {
            name: "bus-overload",
            base: Base::Imu,
            injected: "the emulators run free (no lockstep) at x40, 80,000 IMU samples/s, into a nav whose socket receive buffer is 64 KiB, and nav is stopped (SIGSTOP) for 0.1 s of wall time at 1 s, as a host that deschedules it",
            expected: "nav falls behind and the kernel drops frames: every frame written is either received by nav or in the socket's drop count (SO_RXQ_OVFL), the lost samples counted missing; no crash",
            at_s: 1.0,
            inject: |s, o| {
                s.speed = 40.0;
                s.bus.lockstep = false;
                s.bus.nav_rcvbuf_bytes = 65536;
                o.stall_nav = Some(OVERLOAD_STALL);
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
    ]
}

/// nav's own process killed outright.
pub(super) fn nav_process() -> Vec<FaultCase> {
    vec![FaultCase {
        name: "nav-killed",
        base: Base::Imu,
        injected: "nav killed outright (SIGKILL) at a random time between 2 s and 5 s, at real-time pace",
        expected: "its recording reads back up to the cut (nav's own reader rebuilds the summary from it): at most 1 s of what nav had processed (its last NAV_TIME on the bus) missing from it; what was still in nav's socket is reported",
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
            // the recorder's promise is about what nav took in; how far nav lagged the stream
            // when it died is the machine's load (nav runs at real-time pace here)
            let (reached, unrecorded) = match (k.nav_reached_s, k.unrecorded_s) {
                (Some(n), Some(u)) => (format!("{n:.2} s"), u),
                _ => ("no NAV_TIME seen".into(), f64::INFINITY),
            };
            let pass = k.recorded_frames > 0 && unrecorded <= 1.0 && k.lost_s >= 0.0;
            verdict(
                pass,
                format!(
                    "killed at {:.2} s, nav's last NAV_TIME at {reached}; recording read back: {} frames up to {:.2} s, {:.2} s of what nav had processed lost ({:.2} s in all), {} unreadable records at the cut",
                    k.at_s,
                    k.recorded_frames,
                    k.recorded_until_s,
                    unrecorded,
                    k.lost_s,
                    k.bad_records
                ),
                None,
            )
        },
    }]
}
