//! The fault matrix's turntable rows.

use super::*;

/// The indexing mechanism: a stall, a lock failure, an encoder glitch, acknowledgements lost and late, its heartbeat lost.
pub(super) fn cases() -> Vec<FaultCase> {
    vec![
        FaultCase {
            name: "turntable-stall",
            base: Base::Drill,
            injected: "the indexing motor stalls on the first move after 5 s",
            expected: "north-finding goes on by a static gyrocompass where the table stopped (NAV_TIME mode Gyrocompass, the reason naming the stall), its heading within 3 of its own larger sigmas, turntable health bit set",
            at_s: 5.0,
            inject: |s, _| tt_faults(s, |f| f.stall_from_s = Some(5.0)),
            judge: |r, at| nf_degraded(r, at, "stall"),
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
            injected: "the mechanism's controller sends no status frames from 12 s on (mid-move)",
            expected: "within 1 s north-finding goes on by a static gyrocompass where the table comes to rest, followed there by the IMU's vertical gyro (NAV_TIME mode Gyrocompass, the reason naming the lost heartbeat), its heading within 3 of its own larger sigmas, turntable health bit set",
            at_s: 12.0,
            inject: |s, _| tt_faults(s, |f| f.status_silent_s = vec![[12.0, 1e9]]),
            judge: |r, at| {
                let v = nf_degraded(r, at, "heartbeat");
                let pass = v.pass && v.latency_s.is_some_and(|l| (0.0..=1.0).contains(&l));
                verdict(pass, v.observed, v.latency_s)
            },
        },
    ]
}
