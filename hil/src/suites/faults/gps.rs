//! The fault matrix's GPS receiver rows.

use super::*;

/// The receiver's sentences: outages void and silent, a position jump, time going backwards, garbage.
pub(super) fn stream() -> Vec<FaultCase> {
    vec![
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
    ]
}

/// The receiver's device and its PPS: unplugged, PPS missing, PPS jitter.
pub(super) fn device() -> Vec<FaultCase> {
    vec![
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
    ]
}
