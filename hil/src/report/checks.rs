//! The checks of a run: nav against truth, against the in-process run of the same scenario,
//! and the bus's and the recording's accounting, each a named pass or fail with its figures.

use crate::check::Check;
use crate::engine::reference::InProcess;
use crate::scenario::Scenario;
use emulators::adapters::transport::TxStats;
use nalgebra::Vector3;
use nav::frontend::imu_clock::ClockEstimate;
use nav::summary::Summary;

/// What the bench's side of a run saw, for [`checks`].
#[derive(Debug, Clone, Copy)]
pub struct BenchSide<'a> {
    /// The IMU's frames.
    pub tx: &'a TxStats,
    /// The lockstep with nav.
    pub lockstep: &'a emulators::adapters::scheduler::LockstepStats,
    /// The bus model.
    pub bus: &'a emulators::bus::model::BusStats,
    /// The turntable's frames, when there is one.
    pub turntable: Option<&'a emulators::adapters::transport::TurntableTxStats>,
    /// The receiver reached nav through gpsd.
    pub gps_via_gpsd: bool,
}

/// Compute the checks of a finished run.
pub fn checks(
    s: &Scenario,
    bench: BenchSide<'_>,
    reference: Option<&InProcess>,
    nav: &Summary,
    nav_exit: Option<i32>,
) -> (Vec<Check>, i64) {
    let BenchSide {
        tx,
        lockstep,
        bus,
        turntable,
        gps_via_gpsd,
    } = bench;
    let mut out = Vec::new();
    // nobody else writes on the bench's bus, and nav drains its socket before it stops
    let tt_frames = turntable.map_or(0, |t| t.acks + t.status_frames);
    let sent = tx.frames + tt_frames;
    let reached = nav.frames_total + nav.non_data_frames + nav.kernel_dropped_frames;
    out.push(Check {
        name: "every frame written reached nav or is in the kernel's drop count".into(),
        pass: sent == reached,
        detail: format!(
            "the emulators wrote {sent} frames ({} IMU stream, {tt_frames} turntable); nav received {} data and {} other frames, and its socket dropped {} (receive buffer full)",
            tx.frames, nav.frames_total, nav.non_data_frames, nav.kernel_dropped_frames
        ),
    });
    out.extend(error_frame_check(bus, nav));
    out.push(Check {
        name: "nav exited cleanly".into(),
        pass: nav_exit == Some(0),
        detail: format!("exit status {}", crate::check::exit_words(nav_exit)),
    });
    out.extend(lockstep_check(lockstep, nav, gps_via_gpsd));
    let rx_gyro = nav.imu.gyro_frames as i64;
    let dup = s.faults.duplicate_samples.len() as i64;
    let lost = tx.gyro_frames as i64 + dup - rx_gyro;
    let missing = nav.imu.missing_samples as i64;
    let sent = tx.gyro_frames.max(1) as f64;
    out.push(Check {
        name: "every lost IMU frame accounted".into(),
        pass: missing == lost + tx.dropped_samples as i64 && lost >= 0,
        detail: format!(
            "sent {} IMU_GYRO, received {rx_gyro}; nav counted {missing} missing samples = {lost} lost on the bus + {} dropped on purpose",
            tx.gyro_frames, tx.dropped_samples
        ),
    });
    out.push(Check {
        name: "bus loss within tolerance".into(),
        pass: (lost.max(0) as f64) / sent <= s.max_bus_loss,
        detail: format!(
            "{lost} of {} frames ({:.4} %), limit {:.4} %",
            tx.gyro_frames,
            100.0 * lost as f64 / sent,
            100.0 * s.max_bus_loss
        ),
    });
    frame_kind_checks(&mut out, s, bus, nav);
    let got = nav.imu.duplicates as usize;
    out.push(Check {
        name: "duplicate frames reported".into(),
        pass: got == s.faults.duplicate_samples.len(),
        detail: format!(
            "nav counted {got}, {} injected",
            s.faults.duplicate_samples.len()
        ),
    });
    // a turntable moves on nav's own commands: there is no in-process run to compare with
    let Some(reference) = reference else {
        return (out, lost);
    };
    reference_checks(&mut out, s, bench, reference, nav, lost);
    (out, lost)
}

/// The lockstep held: no stall, no fix late (lockstep runs only).
fn lockstep_check(
    lockstep: &emulators::adapters::scheduler::LockstepStats,
    nav: &Summary,
    gps_via_gpsd: bool,
) -> Option<Check> {
    if !lockstep.enabled {
        return None;
    }
    // a fix that reached nav after its time was applied when it came: timing leaked in.
    // Through gpsd a fix reaches nav when gpsd passes it on (its wall time): such a run
    // makes no claim to repeat (it has no reference run), so late fixes are counted only
    let late = nav.navigation.as_ref().map_or(0, |n| n.late_fixes);
    let late_fails = late > 0 && !gps_via_gpsd;
    Some(Check {
        name: "reproducible: the emulators stayed in lockstep with nav".into(),
        pass: lockstep.stalls == 0
            && lockstep.receiver_stalls == 0
            && lockstep.starved == 0
            && lockstep.nav_times > 0
            && !late_fails,
        detail: format!(
            "{} NAV_TIME frames followed, {} waits ({} ms; {} for the receiver's device or bytes, {} of them past the limit), {} stalls, {} turntable commands placed, {late} GPS fixes late{}{}; frame-in to NAV_TIME-out {:.1} ms median, {:.1} ms p99",
            lockstep.nav_times,
            lockstep.waits,
            lockstep.wait_ms,
            lockstep.receiver_waits,
            lockstep.receiver_stalls,
            lockstep.stalls,
            lockstep.placed_commands,
            if gps_via_gpsd {
                " (through gpsd: its timing, counted, not failed)"
            } else {
                ""
            },
            starved_text(lockstep.starved),
            lockstep.latency_p50_ms,
            lockstep.latency_p99_ms
        ),
    })
}

/// The words for `starved` watchdog reports no stop of the stream called for (none: nothing).
pub fn starved_text(starved: u64) -> String {
    if starved == 0 {
        return String::new();
    }
    format!(
        "; nav's watchdog fired {starved} time(s) where the stream had not stopped: the bench was starved of CPU for longer than the watchdog (a loaded host), so the run says nothing of the scenario; run it again on a quieter machine"
    )
}

/// nav against the in-process reference run of the same scenario: attitude, the frames sent
/// and the bus model, and the static checks where the truth is a parked vehicle.
fn reference_checks(
    out: &mut Vec<Check>,
    s: &Scenario,
    bench: BenchSide<'_>,
    reference: &InProcess,
    nav: &Summary,
    lost: i64,
) {
    let (bus, lockstep) = (bench.bus, bench.lockstep);
    attitude_checks(out, reference, nav, lost == 0);
    // the same stream in, the same frames out at the same samples: nothing the host's pace
    // decides reaches what nav sends (docs/pace.md)
    if lost == 0 {
        let (a, b) = (&nav.solution.sent_hash, &reference.sent_hash);
        out.push(Check {
            name: "nav sent the in-process run's frames at the same samples".into(),
            pass: a == b && !a.is_empty(),
            detail: format!(
                "hash over every frame sent and its IMU sample: nav {a}, in process {b} ({} frames){}",
                nav.solution.frames_sent,
                match nav.gps.as_ref().map_or(0, |g| g.reads_released_by_wait) {
                    0 => String::new(),
                    n => format!(
                        "; {n} of the receiver's reads went in when their wait ended, no frame after them having come (the IMU stopped, or the host stalled nav's bench as long as nav's watchdog)"
                    ),
                }
            ),
        });
        if lockstep.enabled && lockstep.stalls == 0 && lockstep.starved == 0 {
            // the bus model saw nav's frames placed by its NAV_TIMEs, on vcan as in process
            out.push(Check {
                name: "the bus model on vcan equals the in-process run's".into(),
                pass: *bus == reference.bus,
                detail: format!(
                    "load {:.2} % and {} identifiers' delays on vcan, {:.2} % and {} in process",
                    100.0 * bus.load,
                    bus.ids.len(),
                    100.0 * reference.bus.load,
                    reference.bus.ids.len()
                ),
            });
        }
    }
    if let (Some(w_truth), Some(f_truth)) = (
        reference.expected_rate_dph,
        reference.expected_specific_force_mps2,
    ) {
        static_checks(
            out,
            s,
            reference,
            Vector3::from(w_truth),
            Vector3::from(f_truth),
            nav,
        );
    }
}

/// nav counted every error frame the bus model raised for its controller (runs with any).
fn error_frame_check(bus: &emulators::bus::model::BusStats, nav: &Summary) -> Option<Check> {
    let c = &nav.can_bus;
    (bus.nav_error_frames > 0 || c.error_frames > 0).then(|| Check {
        name: "every error frame of nav's controller reached nav".into(),
        pass: c.error_frames == bus.nav_error_frames,
        detail: format!(
            "the bus model raised {} error frames for nav's controller; nav counted {} ({} bus errors, {} bus-off, {} restarts, worst state {:?})",
            bus.nav_error_frames,
            c.error_frames,
            c.bus_errors,
            c.bus_offs,
            c.restarts,
            c.worst_state
        ),
    })
}

/// nav counted the frames of identifiers the contract does not know as the bus carried them
/// (injected, a foreign node's flood, a babbling node), and the wrong-length frames injected.
fn frame_kind_checks(
    out: &mut Vec<Check>,
    s: &Scenario,
    bus: &emulators::bus::model::BusStats,
    nav: &Summary,
) {
    let foreign: u64 = bus
        .ids
        .iter()
        .filter(|i| {
            i.extended || u16::try_from(i.id).map_or(true, |id| wire::spec_for_id(id).is_none())
        })
        .map(|i| i.frames)
        .sum();
    for (name, got, want) in [
        (
            "unknown-id frames reported",
            nav.unknown_id_frames,
            foreign as usize,
        ),
        (
            "wrong-length frames reported",
            nav.bad_length_frames,
            s.faults.bad_length_at_s.len(),
        ),
    ] {
        let got = got as usize;
        out.push(Check {
            name: name.into(),
            pass: got == want,
            detail: format!("nav counted {got}, {want} on the bus"),
        });
    }
}

/// The checks of every procedure scenario `s` ran, on its outcome and nav's summary.
pub fn procedure_checks(
    out: &mut Vec<Check>,
    s: &Scenario,
    o: &crate::procedures::Outcomes,
    nav: &Summary,
) {
    for p in crate::procedures::ALL {
        p.checks(s, o, nav, out);
    }
}

/// nav's solution output: every NAV_* frame nav sent reached the bench and decoded, no epoch
/// was skipped, and the last position on the bus is nav's final one.
pub fn solution_checks(
    out: &mut Vec<Check>,
    w: &crate::procedures::observe::SolutionWatch,
    nav: &Summary,
) {
    let sent = nav.solution.frames_sent;
    let epochs = nav.solution.epochs;
    let mut pass = w.frames == sent && w.bad_frames == 0 && w.seq_gaps == 0 && epochs > 0;
    let mut detail = format!(
        "nav sent {sent} frames in {epochs} epochs ({} refused by the socket); the bench received {} frames, {} epochs, {} undecodable, {} sequence gaps, {} out of order; last mode {}",
        nav.solution.send_errors,
        w.frames,
        w.epochs,
        w.bad_frames,
        w.seq_gaps,
        w.reordered,
        w.last_mode.as_deref().unwrap_or("--")
    );
    if let (Some(p), Some(o)) = (
        w.last_position_deg,
        nav.navigation.as_ref().and_then(|n| n.output.as_ref()),
    ) {
        let e = emulators::geodesy::enu_offset(
            (o.lat_deg.to_radians(), o.lon_deg.to_radians(), o.h_m),
            (p[0].to_radians(), p[1].to_radians(), o.h_m),
        );
        let d = e[0].hypot(e[1]);
        // the last 50 Hz epoch is at most 20 ms before nav's final state
        pass &= d < 1.0;
        detail += &format!("; last NAV_POS {d:.3} m from nav's final position (limit 1 m)");
    }
    out.push(Check {
        name: "solution frames on the bus".into(),
        pass,
        detail,
    });
    out.push(Check {
        name: "nav's time tags never go back".into(),
        pass: w.backwards == 0 && nav.solution.backwards == 0,
        detail: match w.first_backwards {
            Some((a, b)) => format!(
                "{} of {} NAV_TIMEs (in nav's Seq order) named a sample before the one before them; the first from sample {a} to {b}",
                w.backwards, w.epochs
            ),
            None if nav.solution.backwards > 0 => format!(
                "nav held back {} solutions that named an earlier sample than one it had sent",
                nav.solution.backwards
            ),
            None => format!(
                "{} NAV_TIMEs, in nav's Seq order, each named a sample at or after the one before{}",
                w.epochs,
                if w.reordered > 0 {
                    format!(" ({} heard out of order on the bus, put back by Seq)", w.reordered)
                } else {
                    String::new()
                }
            ),
        },
    });
}

/// nav's recording replayed through its pipeline in process sends exactly what nav sent.
pub fn replay_check(r: Result<&crate::engine::recording::Playback, &anyhow::Error>) -> Check {
    let name = "nav's output replays bit for bit from its recording".to_string();
    match r {
        Ok(p) => Check {
            name,
            pass: p.identical() && p.bad_records == 0 && p.recorded_tx > 0,
            detail: format!(
                "{} frames and {} fixes replayed through nav's pipeline in process: {} frames sent, nav sent {}: {}",
                p.frames_in,
                p.fixes_in,
                p.replayed_tx,
                p.recorded_tx,
                p.verdict()
            ),
        },
        Err(e) => Check {
            name,
            pass: false,
            detail: format!("cannot replay: {e:#}"),
        },
    }
}

/// nav's reading of the IMU's rate from the PPS edges against the line an exact latch of the
/// same window's true seconds would give on the emulated oscillator: within three of nav's own
/// sigma and 0.2 ppm.
/// `clock`: nav's rate at the end, from the `edges` it took.
pub fn imu_clock_check(s: &Scenario, clock: Option<&ClockEstimate>, edges: u64) -> Check {
    let name = "nav reads the IMU's rate from the PPS".to_string();
    let osc = s.imu.oscillator();
    let Some(c) = clock else {
        let few = edges < nav::frontend::imu_clock::MIN_EDGES as u64;
        return Check {
            name,
            pass: few,
            detail: if few {
                format!(
                    "not judged: nav took {edges} PPS edges, {} needed",
                    nav::frontend::imu_clock::MIN_EDGES
                )
            } else {
                format!("nav took {edges} PPS edges and gave no rate")
            },
        };
    };
    // the line an exact latch would give: the oscillator's IMU time at each true second of
    // the window, by the bench's own least squares (not nav's fit, whose bug it would share)
    let end = osc.from_first_sample().sim_time(c.end_s);
    let period = osc.nominal_period_s();
    let edges: Vec<(f64, f64)> = (0..=c.span_s.round() as i64)
        .map(|k| (k as f64, osc.ticks_at(end - c.span_s + k as f64) * period))
        .collect();
    let truth = crate::stats::fit_line(&edges).map(|l| (l.slope - 1.0) * 1e6);
    let Some(truth) = truth.filter(|_| edges.len() >= nav::frontend::imu_clock::MIN_EDGES) else {
        return Check {
            name,
            pass: false,
            detail: format!(
                "nav read {:+.2} ppm over {:.0} s: too short a window to judge",
                c.ppm, c.span_s
            ),
        };
    };
    let limit = 3.0 * c.sigma_ppm + 0.2;
    Check {
        name,
        pass: (c.ppm - truth).abs() <= limit,
        detail: format!(
            "{:+.2} ± {:.2} ppm over the {} edges of the {:.0} s to {:.0} s of IMU time; an exact latch on the oscillator: {:+.2} ppm (limit ±{limit:.2} ppm)",
            c.ppm,
            c.sigma_ppm,
            c.edges,
            c.end_s - c.span_s,
            c.end_s,
            truth
        ),
    }
}

/// The largest mean NEES per degree of freedom (position, velocity) over a run that still holds
/// nav's sigmas to its errors: a consistent filter averages 1; a mean of 5 over a run is sigmas
/// about 2.2 times too small on every sample (one 3-dof sample of a consistent filter gets
/// there with probability 0.2 %), the divergence a reader of NAV_* frames must not be left with.
pub const NEES_PER_DOF_LIMIT: f64 = 5.0;

/// Whether nav's sigmas hold its errors over the run (none where nav sent no covariances).
pub fn sigma_check(series: &crate::engine::scoring::SeriesStats) -> Option<Check> {
    let [p, v] = series.mean_nees_per_dof?;
    Some(Check {
        name: "nav's sigmas hold its errors (NEES)".into(),
        pass: p <= NEES_PER_DOF_LIMIT && v <= NEES_PER_DOF_LIMIT,
        detail: format!(
            "mean NEES per degree of freedom over {} s: position {p:.2}, velocity {v:.2} (1 when consistent; limit {NEES_PER_DOF_LIMIT})",
            series.samples
        ),
    })
}

/// Checks of a navigation run: nav navigated, used the receiver's fixes, read the IMU's rate
/// from the PPS, and its end error is within the scenario's tolerance.
pub fn navigation_checks(
    out: &mut Vec<Check>,
    s: &Scenario,
    score: Option<&crate::engine::scoring::NavScore>,
    nav: &Summary,
    gps: Option<&emulators::adapters::pty::GpsTxStats>,
) {
    let n = nav.navigation.as_ref();
    out.push(Check {
        name: "nav navigated".into(),
        pass: n.is_some_and(|n| n.phase == nav::navigation::navigator::NavPhase::Navigating),
        detail: match n {
            Some(n) => format!(
                "phase {:?}, started at {} s of IMU time",
                n.phase,
                n.started_at_s
                    .map_or_else(|| "--".into(), |t| format!("{t:.3}"))
            ),
            None => "navigation was not enabled in nav".into(),
        },
    });
    if let Some(g) = gps {
        let st = nav.gps.as_ref().map(|g| g.stats).unwrap_or_default();
        let (fixes, bad) = (st.fixes, st.bad_checksum + st.unparsed);
        let filter = n.and_then(|n| n.filter);
        let used = filter.map_or(0, |f| f.updates);
        out.push(Check {
            name: "GPS fixes received and used".into(),
            pass: bad == 0 && fixes > 0 && (s.navigation.as_ref().is_some_and(|c| !c.gps_aiding) || used > 0),
            detail: format!(
                "emulator wrote {} fix epochs ({} void, {} silent, {} unread, {} port drops); nav decoded {fixes} fixes, {bad} bad sentences; the filter used {used}, rejected {}",
                g.fixes,
                g.void_epochs,
                g.silent_epochs,
                g.unread_epochs,
                g.port_drops,
                filter.map_or(0, |f| f.rejected)
            ),
        });
    }
    if gps.is_some() {
        out.push(imu_clock_check(
            s,
            n.and_then(|n| n.imu_clock.as_ref()),
            n.map_or(0, |n| n.pps_edges),
        ));
    }
    match score {
        Some(sc) => out.push(Check {
            name: "navigation error within tolerance".into(),
            pass: sc.position_error_m <= s.position_tolerance_m,
            detail: format!(
                "at {:.1} s: horizontal {:.2} m (limit {} m), velocity {:.3} m/s, heading {:+.4} deg",
                sc.t_s,
                sc.position_error_m,
                s.position_tolerance_m,
                sc.velocity_error_mps,
                sc.heading_error_deg
            ),
        }),
        None => out.push(Check {
            name: "navigation error within tolerance".into(),
            pass: false,
            detail: "nav reported no navigation output".into(),
        }),
    }
}

/// nav on the bus against the same stream processed in process.
fn attitude_checks(out: &mut Vec<Check>, reference: &InProcess, nav: &Summary, same_stream: bool) {
    let rv = Vector3::from(nav.attitude.rotation_vector_deg);
    let valid = Some(nav.attitude.valid_sample);
    let r = Vector3::from(reference.rotation_vector_deg);
    let e = Vector3::from(reference.error_deg);
    if same_stream {
        // identical input and identical code: only the floating-point order could differ
        let d = (rv - r).abs().max();
        out.push(Check {
            name: "attitude equals the in-process run".into(),
            pass: d <= 1e-9 && valid == Some(reference.valid_sample),
            detail: format!(
                "nav [{:.9}, {:.9}, {:.9}] deg at {}, in-process [{:.9}, {:.9}, {:.9}] at sample {}; differ by {d:.1e} deg (limit 1e-9)",
                rv.x,
                rv.y,
                rv.z,
                valid.map_or_else(|| "no valid sample".to_string(), |k| format!("sample {k}")),
                r.x,
                r.y,
                r.z,
                reference.valid_sample
            ),
        });
    } else {
        out.push(Check {
            name: "attitude equals the in-process run".into(),
            pass: true,
            detail: "not comparable: frames were lost on the bus, so nav saw a different stream (counted above)".into(),
        });
    }
    out.push(Check {
        name: "attitude error against truth (information)".into(),
        pass: true,
        detail: format!(
            "in-process [{:.3e}, {:.3e}, {:.3e}] deg (body axes) over the run",
            e.x, e.y, e.z
        ),
    });
}

/// Mean rate and specific force against truth through the sensor error model. Limits: 5 sigma of
/// the white noise averaged over the run, two pulses of quantization and the dither angle left
/// by the filter at both ends of the run.
fn static_checks(
    out: &mut Vec<Check>,
    s: &Scenario,
    reference: &InProcess,
    w_truth: Vector3<f64>,
    f_truth: Vector3<f64>,
    nav: &Summary,
) {
    let t = nav.attitude.span_samples as f64 / s.imu.rate_hz;
    let w = Vector3::from(nav.mean_rate_dph);
    let arw_dph = s.imu.gyro_arw_dpsh * 60.0; // deg/h per sqrt(Hz)
    // one arcsec over the run, in deg/h: arcsec / 3600 deg, per t/3600 h
    let pulse_dph = s.imu.gyro_pulse_arcsec.iter().cloned().fold(0.0, f64::max);
    let dither = s.imu.dither_arcsec.iter().cloned().fold(0.0, f64::max);
    let lim_w = 5.0 * arw_dph / t.sqrt()
        + (2.0 * pulse_dph + 2.0 * dither * reference.dither_residual_gain) / t;
    let err_w = (w - w_truth).abs().max();
    out.push(Check {
        name: "mean gyro rate matches truth + errors".into(),
        pass: err_w <= lim_w,
        detail: format!(
            "measured [{:.4}, {:.4}, {:.4}] deg/h, truth through the error model [{:.4}, {:.4}, {:.4}]; worst axis off by {err_w:.4} deg/h, limit {lim_w:.4}",
            w.x, w.y, w.z, w_truth.x, w_truth.y, w_truth.z
        ),
    });
    let f = Vector3::from(nav.mean_specific_force_mps2);
    let pulse_a = s.imu.accel_pulse_mps.iter().cloned().fold(0.0, f64::max);
    let lim_f = 5.0 * s.imu.accel_vrw_mpss / t.sqrt() + 2.0 * pulse_a / t;
    let err_f = (f - f_truth).abs().max();
    out.push(Check {
        name: "mean specific force matches truth + errors".into(),
        pass: err_f <= lim_f,
        detail: format!(
            "measured [{:.6}, {:.6}, {:.6}] m/s^2, truth through the error model [{:.6}, {:.6}, {:.6}]; worst axis off by {err_f:.2e}, limit {lim_f:.2e}",
            f.x, f.y, f.z, f_truth.x, f_truth.y, f_truth.z
        ),
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::scoring::SeriesStats;

    #[test]
    fn sigmas_that_do_not_hold_the_errors_fail_their_check() {
        let series = |nees: Option<[f64; 2]>| SeriesStats {
            samples: 30,
            rms_position_error_m: 10.0,
            max_position_error_m: 20.0,
            bad_records: 0,
            mean_nees_per_dof: nees,
        };
        assert!(
            sigma_check(&series(None)).is_none(),
            "no covariances: no check"
        );
        let c = sigma_check(&series(Some([0.8, 1.3]))).expect("a check");
        assert!(
            c.pass && c.detail.contains("position 0.80, velocity 1.30"),
            "{}",
            c.detail
        );
        // an overconfident filter (sigmas a tenth of the errors: NEES 100)
        assert!(
            !sigma_check(&series(Some([100.0, 0.9])))
                .expect("a check")
                .pass
        );
        assert!(
            !sigma_check(&series(Some([0.9, 5.1])))
                .expect("a check")
                .pass
        );
    }
}
