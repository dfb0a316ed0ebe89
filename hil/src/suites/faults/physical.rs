//! The fault matrix's rows on the physical layer: faults the bus model injects
//! ([`emulators::bus::model::PhysicalFaults`]), which nav meets as a Linux CAN controller shows them:
//! error frames (`CAN_RAW_ERR_FILTER`), frames that never come, frames of a node it does not
//! know.

use super::*;
use emulators::bus::model::{NodeTiming, PhysicalFaults, TxFault};

/// A node of the bus model's statistics.
fn node<'a>(r: &'a RunReport, name: &str) -> Option<&'a NodeTiming> {
    r.bus.nodes.iter().find(|n| n.name == name)
}

/// What nav's controller reported, in words.
fn can_text(r: &RunReport) -> String {
    let c = &r.nav.can_bus;
    format!(
        "nav's controller: {} error frames ({} bus errors, {} passive, {} bus-off, {} restarts; worst state {}, state at the end {}, largest counters tec {} rec {}); the model raised {}",
        c.error_frames,
        c.bus_errors,
        c.passives,
        c.bus_offs,
        c.restarts,
        if c.worst_state.is_empty() {
            "none"
        } else {
            &c.worst_state
        },
        if c.state.is_empty() { "none" } else { &c.state },
        c.max_tx_errors,
        c.max_rx_errors,
        r.bus.nav_error_frames
    )
}

/// Every error frame the model raised reached nav, and nav ran to the end.
fn reported(r: &RunReport) -> bool {
    survived(r)
        && r.bus.nav_error_frames > 0
        && r.nav.can_bus.error_frames == r.bus.nav_error_frames
        && r.nav
            .last_sample
            .is_some_and(|k| imu_time(r, k) > r.scenario.duration_s - 0.5)
}

/// nav counted exactly the IMU samples the bus lost.
fn losses_counted(r: &RunReport) -> bool {
    r.checks
        .iter()
        .any(|c| c.name == "every lost IMU frame accounted" && c.pass)
}

fn with(s: &mut Scenario, f: impl FnOnce(&mut PhysicalFaults)) {
    f(&mut s.bus.faults);
}

/// Error frames, a stuck bus, a babbling node, controllers going bus-off (the IMU's, nav's
/// own, the turntable's).
pub(super) fn cases() -> Vec<FaultCase> {
    let mut v = disturbances();
    v.extend(bus_off());
    v
}

/// What the bus does to everybody: error frames, a stuck bus, a babbling node.
fn disturbances() -> Vec<FaultCase> {
    vec![
        FaultCase {
            name: "can-error-frames",
            base: Base::Imu,
            injected: "the harness disturbed from 2 s to 3 s: 200 frames corrupted (cut by an error frame, sent again)",
            expected: "nav reads every error frame its controller raises (CAN_RAW_ERR_FILTER), counts them as bus errors, sets the can_bus health bit within 0.1 s; no IMU sample lost (the frames are sent again)",
            at_s: 2.0,
            inject: |s, _| {
                with(s, |f| f.disturbed_s = vec![[2.0, 3.0, 200.0]]);
                // the bus model's log on the simulated clock, error frames included (read back
                // as Vector ASC and BLF by tests/tests/can_logs.rs)
                s.bus.log = true;
            },
            judge: |r, at| {
                let l = bit_latency(r, "can_bus", at);
                let pass = reported(r)
                    && r.bus.corrupted == 200
                    && r.nav.can_bus.bus_errors == 200
                    && r.nav.imu.missing_samples == 0
                    && l.is_some_and(|l| (0.0..=0.1).contains(&l));
                verdict(
                    pass,
                    format!(
                        "{} frames corrupted on the bus; {}; IMU samples missing {}; can_bus bit after {}",
                        r.bus.corrupted,
                        can_text(r),
                        r.nav.imu.missing_samples,
                        lat_text(l)
                    ),
                    l,
                )
            },
        },
        FaultCase {
            name: "can-stuck-dominant",
            base: Base::Imu,
            injected: "the bus stuck dominant from 2 s for 50 ms",
            expected: "nothing gets through: the IMU's controller (sending) goes bus-off and recovers after 128 x 11 recessive bits, nav's goes error-passive and back to active; nav reports both states, counts every sample it missed, sets the can_bus bit",
            at_s: 2.0,
            inject: |s, _| with(s, |f| f.stuck_dominant_s = vec![[2.0, 2.05]]),
            judge: |r, at| {
                let c = &r.nav.can_bus;
                let l = bit_latency(r, "can_bus", at);
                let imu_off = node(r, "IMU").map_or(0, |n| n.bus_offs);
                let missing = r.nav.imu.missing_samples;
                let pass = reported(r)
                    && c.worst_state == "passive"
                    && c.state == "active"
                    && imu_off == 1
                    && (95..=115).contains(&missing)
                    && losses_counted(r)
                    && l.is_some_and(|l| (0.0..=0.1).contains(&l));
                verdict(
                    pass,
                    format!(
                        "stuck {:.1} ms; the IMU's controller went bus-off {imu_off} time(s); {}; IMU samples missing {missing}; can_bus bit after {}",
                        r.bus.stuck_ms,
                        can_text(r),
                        lat_text(l)
                    ),
                    l,
                )
            },
        },
        FaultCase {
            name: "can-babbling-node",
            base: Base::Imu,
            injected: "a node on the harness sends identifier 0x001 back to back from 2 s for 100 ms (it wins every arbitration)",
            expected: "navigation goes on: every babbling frame that reached the bus counted by id as unknown, the IMU samples it crowded out counted missing (the IMU's queue overflowed), the stream taken again after it",
            at_s: 2.0,
            inject: |s, _| with(s, |f| f.babbling_s = vec![[2.0, 2.1, 1.0]]),
            judge: |r, _| {
                let babble = r
                    .bus
                    .ids
                    .iter()
                    .find(|i| i.id == 0x001)
                    .map_or(0, |i| i.frames);
                let overflow = node(r, "IMU").map_or(0, |n| n.overflow);
                let missing = r.nav.imu.missing_samples;
                let pass = survived(r)
                    && babble > 500
                    && r.nav.unknown_id_frames == babble
                    && r.nav.unknown_ids == ["0x001"]
                    && overflow > 0
                    && missing > 100
                    && losses_counted(r)
                    && r.nav
                        .last_sample
                        .is_some_and(|k| imu_time(r, k) > r.scenario.duration_s - 0.5);
                verdict(
                    pass,
                    format!(
                        "{babble} babbling frames on the bus, nav counted {} unknown ({:?}); the IMU's queue lost {overflow} frames; IMU samples missing {missing}",
                        r.nav.unknown_id_frames, r.nav.unknown_ids
                    ),
                    None,
                )
            },
        },
    ]
}

/// A controller going bus-off: the IMU's, nav's own, the turntable's.
fn bus_off() -> Vec<FaultCase> {
    vec![
        FaultCase {
            name: "can-imu-bus-off",
            base: Base::Imu,
            injected: "the IMU's transmitter faulty from 2 s for 3 ms: its frames fail until its controller goes bus-off; it recovers after 128 x 11 recessive bits",
            expected: "nav counts the 32 bus errors it sees as a receiver, sets the can_bus bit, counts the samples lost while the IMU was off the bus; navigation goes on",
            at_s: 2.0,
            inject: |s, _| {
                with(s, |f| {
                    f.tx_faults = vec![TxFault {
                        node: "IMU".into(),
                        from_s: 2.0,
                        to_s: 2.003,
                    }]
                })
            },
            judge: |r, at| {
                let imu = node(r, "IMU");
                let (offs, failed) = imu.map_or((0, 0), |n| (n.bus_offs, n.failed));
                let l = bit_latency(r, "can_bus", at);
                let missing = r.nav.imu.missing_samples;
                let pass = reported(r)
                    && offs == 1
                    && failed == 32
                    && r.nav.can_bus.bus_errors == 32
                    && missing > 0
                    && losses_counted(r)
                    && l.is_some_and(|l| (0.0..=0.1).contains(&l));
                verdict(
                    pass,
                    format!(
                        "the IMU's controller: {failed} failed transmissions, {offs} bus-off; {}; IMU samples missing {missing}; can_bus bit after {}",
                        can_text(r),
                        lat_text(l)
                    ),
                    l,
                )
            },
        },
        FaultCase {
            name: "can-nav-bus-off",
            base: Base::Imu,
            injected: "nav's own transmitter faulty from 2 s for 100 ms: each frame it sends fails until its controller goes bus-off, restarts after 128 x 11 recessive bits, and fails again while the fault lasts",
            expected: "nav reads its controller's error-passive, bus-off and restart frames, counts them, sets the can_bus bit, counts the IMU samples it could not receive while off the bus; nothing panics; it is error-active at the end",
            at_s: 2.0,
            inject: |s, _| {
                with(s, |f| {
                    f.tx_faults = vec![TxFault {
                        node: "NAV".into(),
                        from_s: 2.0,
                        to_s: 2.1,
                    }]
                })
            },
            judge: |r, at| {
                let c = &r.nav.can_bus;
                let l = bit_latency(r, "can_bus", at);
                let missing = r.nav.imu.missing_samples;
                let pass = reported(r)
                    && c.bus_offs >= 1
                    && c.restarts == c.bus_offs
                    && c.passives >= 1
                    && c.state == "active"
                    && r.bus.unseen_by_nav > 0
                    && missing > 0
                    && losses_counted(r)
                    && l.is_some_and(|l| (0.0..=0.2).contains(&l));
                verdict(
                    pass,
                    format!(
                        "{}; devices' frames nav's controller missed while bus-off {}; IMU samples missing {missing}; can_bus bit after {}",
                        can_text(r),
                        r.bus.unseen_by_nav,
                        lat_text(l)
                    ),
                    l,
                )
            },
        },
        FaultCase {
            name: "can-turntable-bus-off",
            base: Base::Drill,
            injected: "the turntable's transmitter faulty from 12 s for 3 s (a wiring fault): its status frames fail until it goes bus-off, again after each recovery",
            expected: "within 1 s north-finding goes on by a static gyrocompass (NAV_TIME mode Gyrocompass, the reason naming the lost heartbeat), its heading within 3 of its own larger sigmas; the bus errors counted, the turntable and can_bus health bits set",
            at_s: 12.0,
            inject: |s, _| {
                with(s, |f| {
                    f.tx_faults = vec![TxFault {
                        node: "TT".into(),
                        from_s: 12.0,
                        to_s: 15.0,
                    }]
                })
            },
            judge: |r, at| {
                let v = nf_degraded(r, at, "heartbeat");
                let offs = node(r, "TT").map_or(0, |n| n.bus_offs);
                let can = bit_latency(r, "can_bus", at);
                let pass = v.pass
                    && v.latency_s.is_some_and(|l| (0.0..=1.0).contains(&l))
                    && offs >= 1
                    && r.nav.can_bus.bus_errors > 0
                    && can.is_some();
                verdict(
                    pass,
                    format!(
                        "{}; the turntable's controller went bus-off {offs} times; {}; can_bus bit after {}",
                        v.observed,
                        can_text(r),
                        lat_text(can)
                    ),
                    v.latency_s,
                )
            },
        },
    ]
}
