//! In-process navigation runs: the scenario's devices driving nav's pipeline
//! ([`crate::engine::inproc`]), each second scored against the truth trajectory
//! ([`super::scoring`]).

use crate::scenario::Scenario;
use anyhow::{Result, bail};
use emulators::drive::Drive;
use emulators::gps::{GpsErrorParams, ReceiverParams};
use nalgebra::Vector3;
use nav::navigation::filter::FilterConfig;
use nav::navigation::navigator::{NavigationConfig, Navigator};
use nav::procedures::common::Procedure;
use serde::Serialize;

use super::scoring::{errors, nees};

/// One second of a navigation run against truth.
#[derive(Debug, Clone, Copy, Serialize, serde::Deserialize)]
pub struct NavSample {
    /// Simulated time, s.
    pub t_s: f64,
    /// Horizontal position error, m.
    pub position_error_m: f64,
    /// Velocity error (east, north, up), m/s.
    pub velocity_error_mps: [f64; 3],
    /// Heading error, deg.
    pub heading_error_deg: f64,
    /// Normalised estimation error squared of the position (3 dof; none without a filter).
    pub nees_position: Option<f64>,
    /// The same for the velocity.
    pub nees_velocity: Option<f64>,
    /// The filter's horizontal position sigma, `sqrt(sigma_N^2 + sigma_E^2)`, m (the RMS bound
    /// of the horizontal error; none without a filter).
    #[serde(default)]
    pub position_sigma_m: Option<f64>,
    /// The filter's velocity sigma, `sqrt(trace P_v)`, m/s.
    #[serde(default)]
    pub velocity_sigma_mps: Option<f64>,
}

/// Errors of a navigation run.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct NavRun {
    /// The receiver's slow horizontal error at the end: its error averaged over the last 60 s
    /// of fixes, m (none without fixes then). No filter can know it: it is the floor of the
    /// end error.
    #[serde(default)]
    pub end_receiver_wander_m: Option<f64>,
    /// Simulated time navigated, s.
    pub duration_s: f64,
    /// Horizontal position error at the end, m.
    pub end_position_error_m: f64,
    /// Velocity error at the end, m/s.
    pub end_velocity_error_mps: f64,
    /// Horizontal velocity error at the end, m/s.
    pub end_horizontal_velocity_error_mps: f64,
    /// RMS horizontal position error over the run (1 Hz samples), m.
    pub rms_position_error_m: f64,
    /// RMS velocity error over the run, m/s.
    pub rms_velocity_error_mps: f64,
    /// Heading error at the end, deg.
    pub end_heading_error_deg: f64,
    /// Mean NEES per degree of freedom, position and velocity (1 when the filter's covariance
    /// is consistent with its errors; none without a filter).
    pub mean_nees_per_dof: Option<[f64; 2]>,
    /// Horizontal position error at the end of each receiver outage, m.
    pub outage_end_errors_m: Vec<f64>,
    /// Filter counters.
    pub filter: Option<nav::navigation::filter::FilterStats>,
    /// North-finding's result (scenarios that find north first).
    pub north_finding: Option<nav::procedures::north_finding::NorthResult>,
    /// IMU time navigation started, s.
    pub started_at_s: Option<f64>,
    /// How it started (still, or aligned in motion), and the levelling windows it refused
    /// because the vehicle moved.
    #[serde(default)]
    pub start: (Option<nav::navigation::navigator::StartKind>, u64),
    /// nav's integrity monitor over the run.
    pub integrity: nav::navigation::integrity::IntegrityStats,
    /// Fixes nav could not tie to a PPS edge (applied at their arrival instead): none while
    /// the receiver's PPS reaches the IMU.
    #[serde(default)]
    pub untied_fixes: u64,
    /// Fixes the filter's gate refused although their error was within 3 of the receiver's
    /// own sigma on every axis (none may be).
    #[serde(default)]
    pub good_fixes_refused: u64,
    /// The IMU's rate nav read from the PPS edges at the end, and the edges it took.
    #[serde(default)]
    pub imu_clock: (Option<nav::frontend::imu_clock::ClockEstimate>, u64),
    /// The run second by second.
    #[serde(skip)]
    pub series: Vec<NavSample>,
}

impl NavRun {
    /// RMS and largest of the errors at the ends of the outages (none without outages).
    pub fn outage_drift(&self) -> Option<(f64, f64)> {
        let e = &self.outage_end_errors_m;
        if e.is_empty() {
            return None;
        }
        let rms = (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt();
        Some((rms, e.iter().copied().fold(0.0, f64::max)))
    }
}

/// Pure inertial navigation of a drive scenario, initialised from truth.
pub fn pure_inertial(s: &Scenario) -> Result<NavRun> {
    // the start position from an error-free receiver, then no aiding
    let exact = ReceiverParams {
        errors: GpsErrorParams {
            gm_sigma_m: 0.0,
            white_sigma_m: 0.0,
            ..GpsErrorParams::default()
        },
        lever_arm_m: [0.0; 3],
        ..ReceiverParams::default()
    };
    navigate(s, None, &exact, 0.0)
}

/// Navigate a drive scenario in process as the bench does: its devices (the receiver with
/// model `rx`: errors, lever arm, outages) driving nav's pipeline. `filter` none: pure inertial
/// after the start. With `[north_finding]` and a turntable the run finds north first (nav
/// commanding the emulated mechanism) and hands its heading over; otherwise nav is given the
/// truth's heading plus `heading_err_deg`. The scenario's `[navigation]` table applies (without
/// one, levelling is fitted into the wait before the vehicle drives off).
pub fn navigate(
    s: &Scenario,
    filter: Option<&FilterConfig>,
    rx: &ReceiverParams,
    heading_err_deg: f64,
) -> Result<NavRun> {
    let Some(spec) = &s.drive else {
        bail!("scenario {} has no [drive]", s.name);
    };
    let drive = Drive::plan(spec)?;
    let (motion, tt) = s.build();
    let finds_north = s.north_finding.is_some() && tt.is_some();
    let gps = crate::engine::inproc::gps_run(s, rx)?;
    let cfg = run_config(s, spec, &drive, filter, rx, heading_err_deg, finds_north);
    let level_s = cfg.navigation.level_s;
    let mut bench = crate::engine::inproc::InProcessBench::new(s, &cfg, motion, tt, gps)?;
    let mut series = Vec::new();
    let mut outage_end = Vec::new();
    let mut next_score = 1.0;
    while bench.running() {
        bench.step();
        let Some(n) = bench.pipeline().navigator() else {
            bail!("navigation is not enabled");
        };
        let t = bench.sim_time(n.time());
        if t >= next_score {
            next_score += 1.0;
            if let Some(x) = score(n, &drive, t) {
                // the last second of an outage: the error fixes will then correct
                if rx.outages.iter().any(|o| t < o[1] && t + 1.0 >= o[1]) {
                    outage_end.push(x.position_error_m);
                }
                series.push(x);
            }
        }
    }
    bench.finish();
    let p = bench.pipeline();
    let Some(navigator) = p.navigator() else {
        bail!("navigation is not enabled");
    };
    let nf_result = north_finding_result(p.finder(), level_s, spec.start_wait_s)?;
    let last_t = bench.sim_time(navigator.time());
    let Some(end) = score(navigator, &drive, last_t) else {
        bail!("navigation never started (no heading or no fix)");
    };
    let rms = |f: &dyn Fn(&NavSample) -> f64| {
        (series.iter().map(|x| f(x).powi(2)).sum::<f64>() / series.len().max(1) as f64).sqrt()
    };
    let norm3 = |v: [f64; 3]| Vector3::from(v).norm();
    let mean_nees = |f: &dyn Fn(&NavSample) -> Option<f64>| {
        let v: Vec<f64> = series.iter().filter_map(f).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64 / 3.0)
    };
    let nees = match (
        mean_nees(&|x| x.nees_position),
        mean_nees(&|x| x.nees_velocity),
    ) {
        (Some(p), Some(v)) => Some([p, v]),
        _ => None,
    };
    let end_receiver_wander_m = receiver_wander(bench.receiver_errors(), last_t);
    Ok(NavRun {
        end_receiver_wander_m,
        duration_s: last_t,
        end_position_error_m: end.position_error_m,
        end_velocity_error_mps: norm3(end.velocity_error_mps),
        end_horizontal_velocity_error_mps: end.velocity_error_mps[0]
            .hypot(end.velocity_error_mps[1]),
        rms_position_error_m: rms(&|x| x.position_error_m),
        rms_velocity_error_mps: rms(&|x| norm3(x.velocity_error_mps)),
        end_heading_error_deg: end.heading_error_deg,
        mean_nees_per_dof: nees,
        outage_end_errors_m: outage_end,
        filter: navigator.filter().map(nav::navigation::filter::Kf::stats),
        north_finding: nf_result,
        started_at_s: navigator.summary().started_at_s,
        start: (navigator.summary().start, navigator.summary().level_waits),
        integrity: navigator.integrity().stats(),
        untied_fixes: navigator.summary().untied_fixes,
        good_fixes_refused: bench.good_fixes_refused(),
        imu_clock: (navigator.summary().imu_clock, navigator.summary().pps_edges),
        series,
    })
}

/// nav's config for an in-process drive: the scenario's, with the filter (none: the INS
/// alone) and, without north-finding, a start heading `heading_err_deg` off the truth.
fn run_config(
    s: &Scenario,
    spec: &emulators::drive::DriveSpec,
    drive: &Drive,
    filter: Option<&FilterConfig>,
    rx: &ReceiverParams,
    heading_err_deg: f64,
    finds_north: bool,
) -> nav::config::NavConfig {
    let mut cfg =
        crate::scenario::navconfig::nav_config(s, None, Some(std::path::Path::new("(in process)")));
    let fix_delay = NavigationConfig::default().fix_delay_s;
    cfg.navigation = NavigationConfig {
        enabled: true,
        initial_heading_deg: (!finds_north)
            .then(|| drive.heading(0.0).to_degrees() + heading_err_deg),
        gps_aiding: filter.is_some(),
        filter: filter
            .map(|f| crate::scenario::navconfig::with_lever_arm(f, rx))
            .unwrap_or_default(),
        ..s.navigation.clone().unwrap_or_else(|| NavigationConfig {
            // the first fix comes at about 1 s and is applied `fix_delay_s` after its edge
            level_s: (spec.start_wait_s - 1.2 - fix_delay).clamp(0.2, 2.0),
            ..NavigationConfig::default()
        })
    };
    cfg
}

/// North-finding's result before the drive: it must have finished, with the levelling, before
/// the vehicle drives off at `start_wait_s`.
fn north_finding_result(
    finder: Option<&nav::procedures::north_finding::NorthFinder>,
    level_s: f64,
    start_wait_s: f64,
) -> Result<Option<nav::procedures::north_finding::NorthResult>> {
    Ok(match finder {
        Some(f) => {
            let Some(r) = f.result() else {
                bail!(
                    "north-finding did not finish: {}",
                    f.abort().unwrap_or("out of time")
                );
            };
            if r.duration_s + level_s >= start_wait_s {
                bail!(
                    "north-finding ended at {:.1} s: with {level_s} s of levelling the vehicle must wait longer than {} s before it drives off",
                    r.duration_s,
                    start_wait_s
                );
            }
            Some(r.clone())
        }
        None => None,
    })
}

/// The receiver's slow error at the end of a drive at `last_t`.
fn receiver_wander(errors: &[crate::engine::inproc::ReceiverFix], last_t: f64) -> Option<f64> {
    // the receiver's slow error at the end: its horizontal error averaged over the last 60 s of
    // fixes (the white noise and short bursts average out, the wander of minutes does not)
    let tail: Vec<[f64; 3]> = errors
        .iter()
        .filter(|f| f.edge > last_t - 60.0)
        .map(|f| f.error_enu)
        .collect();
    (!tail.is_empty()).then(|| {
        let k = tail.len() as f64;
        let e = tail.iter().map(|x| x[0]).sum::<f64>() / k;
        let n = tail.iter().map(|x| x[1]).sum::<f64>() / k;
        e.hypot(n)
    })
}

/// The navigator's state against truth at simulated time `t`.
fn score(navigator: &Navigator, drive: &Drive, t: f64) -> Option<NavSample> {
    let st = navigator.state()?;
    let (position_error_m, velocity_error_mps, heading_error_deg) = errors(drive, t, &st.output());
    let (lat, lon, h) = drive.position(t);
    let v = drive.velocity(t);
    let (nees_position, nees_velocity, position_sigma_m, velocity_sigma_mps) =
        match navigator.filter() {
            Some(k) => {
                let p = k.covariance();
                let dpos = [st.lat - lat, st.lon - lon, st.h - h];
                let dv = [st.v.x - v.x, st.v.y - v.y, st.v.z - v.z];
                // the filter's position variances are in rad^2: to metres with the truth
                // side's radii
                let (rm, rn) = emulators::geodesy::radii(lat);
                let (mn, me) = (rm + h, (rn + h) * lat.cos());
                let var_h = p[(6, 6)] * mn * mn + p[(7, 7)] * me * me;
                let var_v = p[(3, 3)] + p[(4, 4)] + p[(5, 5)];
                (
                    nees(&dpos, &p.fixed_view::<3, 3>(6, 6).into_owned()),
                    nees(&dv, &p.fixed_view::<3, 3>(3, 3).into_owned()),
                    (var_h >= 0.0).then(|| var_h.sqrt()),
                    (var_v >= 0.0).then(|| var_v.sqrt()),
                )
            }
            None => (None, None, None, None),
        };
    Some(NavSample {
        t_s: t,
        position_error_m,
        velocity_error_mps,
        heading_error_deg,
        nees_position,
        nees_velocity,
        position_sigma_m,
        velocity_sigma_mps,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use emulators::drive::DriveSpec;
    use emulators::imu::ImuParams;

    fn loop_scenario(imu: ImuParams, duration: f64) -> Scenario {
        let mut s = Scenario::builtin_static();
        s.duration_s = duration;
        s.drive = Some(DriveSpec {
            lat_deg: 28.218157,
            lon_deg: 112.989583,
            height_m: 0.0,
            waypoints: vec![[0.0, 300.0], [200.0, 300.0], [200.0, 0.0], [0.0, 0.0]],
            speed_mps: 10.0,
            accel_mps2: 1.5,
            turn_rate_dps: 15.0,
            lateral_accel_mps2: 2.5,
            laps: 1,
            start_wait_s: 2.0,
            ..Default::default()
        });
        s.imu = imu;
        s
    }

    #[test]
    fn an_ideal_imu_navigates_a_loop_to_within_a_metre() {
        let s = loop_scenario(ImuParams::ideal(), 120.0);
        let r = pure_inertial(&s).unwrap();
        eprintln!("{r:?}");
        assert!(r.duration_s > 119.0);
        assert!(r.end_position_error_m < 1.0, "{r:?}");
        assert!(r.end_velocity_error_mps < 0.05, "{r:?}");
        assert!(r.end_heading_error_deg.abs() < 0.01, "{r:?}");
    }

    #[test]
    fn the_filter_holds_a_paper_grade_imu_to_the_gps_class() {
        let mut s = loop_scenario(ImuParams::default(), 400.0);
        if let Some(d) = s.drive.as_mut() {
            d.laps = 3;
        }
        let rx = ReceiverParams::default();
        let pure = navigate(&s, None, &rx, 0.03).unwrap();
        let std_ = navigate(
            &s,
            Some(&FilterConfig {
                kind: nav::navigation::filter::FilterKind::Standard,
                ..FilterConfig::default()
            }),
            &rx,
            0.03,
        )
        .unwrap();
        let fad = navigate(&s, Some(&FilterConfig::default()), &rx, 0.03).unwrap();
        eprintln!("pure {pure:?}\nstandard {std_:?}\nfading {fad:?}");
        assert!(pure.end_position_error_m > 200.0, "{pure:?}");
        assert!(std_.end_position_error_m < 25.0, "{std_:?}");
        assert!(fad.end_position_error_m < 25.0, "{fad:?}");
        assert!(std_.rms_position_error_m < 25.0 && fad.rms_position_error_m < 25.0);
        // position-only updates keep the heading too (the turns make it observable)
        assert!(std_.end_heading_error_deg.abs() < 1.0 && fad.end_heading_error_deg.abs() < 1.0);
        // the sigmas are a promise: with the receiver's wander modelled, the standard filter's
        // errors match its covariance (NEES per dof about 1; one 400 s run scatters, so 0.25-4;
        // without the wander states it was about 20) and its innovations match their covariance
        // (mean NIS about 3 for 3 dof)
        let [p, v] = std_.mean_nees_per_dof.unwrap();
        assert!(
            (0.25..4.0).contains(&p) && (0.25..4.0).contains(&v),
            "NEES {p} / {v}"
        );
        for r in [&std_, &fad] {
            let nis = r.filter.unwrap().mean_nis;
            assert!((1.5..6.0).contains(&nis), "mean NIS {nis}");
        }
    }

    /// A fast, precise receiver below sea level (the Dead Sea road at -430 m, a sub-metre
    /// receiver at 10 Hz stating GST): no filter refuses a good fix (its error within 3 of
    /// the receiver's own sigma), in its first minute or after. The count does see them: a
    /// gate far too tight refuses good fixes and says so.
    #[test]
    fn a_fast_precise_receiver_below_sea_level_has_every_good_fix_taken() {
        let mut s = Scenario::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../scenarios/route-dead-sea-tunnels.toml"
        )))
        .unwrap();
        s.duration_s = 100.0;
        let mut rx = s.gps.clone().unwrap();
        rx.rate_hz = 10.0;
        rx.errors.gm_sigma_m = 0.4;
        rx.errors.gm_tau_s = 60.0;
        rx.errors.white_sigma_m = 0.2;
        use nav::navigation::filter::FilterKind::*;
        for kind in [Standard, Fading, Adaptive] {
            let f = FilterConfig {
                kind,
                ..FilterConfig::default()
            };
            let r = navigate(&s, Some(&f), &rx, 0.0).unwrap();
            let st = r.filter.unwrap();
            eprintln!(
                "{kind:?}: {st:?}, good fixes refused {}",
                r.good_fixes_refused
            );
            assert!(st.updates > 900, "{st:?}");
            assert_eq!(st.rejected_first_minute, 0, "{kind:?}: {st:?}");
            assert_eq!(r.good_fixes_refused, 0, "{kind:?}");
        }
        let tight = FilterConfig {
            kind: Standard,
            gate_nis: 0.5,
            reanchor_after: 0,
            ..FilterConfig::default()
        };
        let r = navigate(&s, Some(&tight), &rx, 0.0).unwrap();
        let st = r.filter.unwrap();
        assert!(st.rejected > 50, "{st:?}");
        assert!(
            r.good_fixes_refused > st.rejected / 2,
            "{} of {} refused fixes were good",
            r.good_fixes_refused,
            st.rejected
        );
    }

    /// The campus loop's sequence, shortened (8 s dwells, one lap).
    fn drill_then_drive() -> Scenario {
        let mut s = Scenario::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../scenarios/campus-loop.toml"
        )))
        .unwrap();
        if let Some(nf) = s.north_finding.as_mut() {
            nf.dwell_s = 8.0;
        }
        let d = s.drive.as_mut().unwrap();
        d.laps = 1;
        d.start_wait_s = 70.0;
        s.duration_s = 70.0 + 240.0;
        s
    }

    /// The drill, then the drive: north-finding's heading within its sigma, the drive's end
    /// within the receiver's class, every fix tied to its edge.
    fn drills_and_drives(s: &Scenario) -> NavRun {
        let rx = s.gps.clone().unwrap();
        let r = navigate(s, Some(&FilterConfig::default()), &rx, 0.0).unwrap();
        eprintln!(
            "{:?} started {:?}, end {:.1} m",
            r.north_finding, r.started_at_s, r.end_position_error_m
        );
        let nf = r.north_finding.as_ref().expect("north-finding ran");
        let err = crate::stats::wrap180(nf.heading_deg - s.truth_heading_deg());
        assert!(
            err.abs() < 4.0 * nf.sigma_deg.max(0.05),
            "{err} vs {}",
            nf.sigma_deg
        );
        let started = r.started_at_s.unwrap();
        assert!(started > nf.duration_s && started < 70.0, "{started}");
        assert!(r.end_position_error_m < 25.0, "{r:?}");
        assert!(r.filter.unwrap().updates > 200);
        // the fixes that came during north-finding were tied to their PPS edges too
        assert_eq!(r.untied_fixes, 0);
        r
    }

    /// nav's north-finder drives the emulated turntable, its heading goes to the navigator,
    /// which levels and navigates with the filter while the vehicle drives off.
    #[test]
    fn north_finding_hands_its_heading_to_the_filter() {
        let s = drill_then_drive();
        drills_and_drives(&s);
        let rx = s.gps.clone().unwrap();
        // too short a wait: the vehicle would drive off during north-finding
        let mut early = s.clone();
        early.drive.as_mut().unwrap().start_wait_s = 20.0;
        let e = navigate(&early, Some(&FilterConfig::default()), &rx, 0.0).unwrap_err();
        assert!(e.to_string().contains("wait longer"), "{e}");
    }

    /// The same drill and drive with the IMU's oscillator 900 ppm fast and wandering by 40 ppm:
    /// judged as any other, and nav reads the rate from the receiver's edges.
    #[test]
    fn an_imu_off_its_nominal_rate_drills_and_drives_as_any_other() {
        let mut s = drill_then_drive();
        s.imu.clock_offset_ppm = 900.0;
        s.imu.clock_wander_ppm = 40.0;
        s.imu.clock_wander_period_s = 1800.0;
        let r = drills_and_drives(&s);
        let (clock, edges) = r.imu_clock;
        let check = crate::report::imu_clock_check(&s, clock.as_ref(), edges);
        eprintln!("{}: {}", check.name, check.detail);
        assert!(check.pass, "{}", check.detail);
        let c = clock.unwrap();
        assert!(c.ppm > 900.0 && c.ppm < 940.0, "{c:?}");
        // a nominal oscillator's line, read as this one, fails the check
        let nominal = Scenario {
            imu: ImuParams::default(),
            ..s.clone()
        };
        assert!(!crate::report::imu_clock_check(&nominal, Some(&c), edges).pass);
        let [p, v] = r.mean_nees_per_dof.unwrap();
        assert!(p < 3.0 && v < 3.0, "NEES {p} / {v}");
    }

    /// Position-only fixes make the horizontal accelerometer biases observable once the
    /// vehicle turns (levelling had folded them into the tilt): after two laps the standard
    /// filter has them to 2 mg of the emulator's (5 mg each, signs random).
    #[test]
    fn the_filter_learns_the_accelerometer_biases_on_the_loop() {
        let mut s = Scenario::load(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../scenarios/campus-loop.toml"
        )))
        .unwrap();
        s.north_finding = None;
        s.turntable = None;
        let d = s.drive.as_mut().unwrap();
        d.start_wait_s = 5.0;
        d.laps = 2;
        s.duration_s = 460.0;
        let rx = s.gps.clone().unwrap();
        let truth = emulators::imu::ImuEmulator::new(s.motion(), s.imu.clone()).accel_bias_mps2();
        let f = FilterConfig {
            kind: nav::navigation::filter::FilterKind::Standard,
            ..FilterConfig::default()
        };
        let r = navigate(&s, Some(&f), &rx, 0.05).unwrap();
        let est = r.filter.unwrap().accel_bias_mps2;
        eprintln!("accel bias: truth {truth:?}, estimated {est:?}");
        for i in 0..2 {
            assert!(
                (est[i] - truth[i]).abs() < 0.002 * 9.81,
                "axis {i}: {est:?} vs {truth:?}"
            );
        }
    }

    /// A hilly city road (grades to 12 %, three stops, slow corners, the body pitching and
    /// rolling on its suspension, a 10 Hz receiver), and the same drive from a handheld
    /// logger's GPX track of it (the road fitted to the track, glitches dropped), navigated in
    /// process with the scenario's filter: within the position tolerance, and the sigmas
    /// honest (mean NEES per degree of freedom of position and velocity in [0.3, 3] over the
    /// drive).
    /// A shipped scenario navigated in process with its own receiver and filter, the start
    /// heading `heading_err_deg` off.
    fn navigate_shipped(file: &str, heading_err_deg: f64) -> NavRun {
        let s = Scenario::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../scenarios")
                .join(file),
        )
        .unwrap();
        let rx = s.gps.clone().unwrap();
        let f = s.navigation.as_ref().map(|n| n.filter.clone());
        navigate(&s, f.as_ref(), &rx, heading_err_deg).unwrap()
    }

    #[test]
    fn a_hilly_stop_and_go_road_is_navigated_with_honest_sigmas() {
        for file in ["route-lisbon-hills.toml", "track-lisbon-handheld.toml"] {
            let r = navigate_shipped(file, 0.05);
            eprintln!(
                "{file}: rms {:.2} m, end {:.2} m, NEES per dof {:?}",
                r.rms_position_error_m, r.end_position_error_m, r.mean_nees_per_dof
            );
            assert!(
                r.rms_position_error_m < 25.0 && r.end_position_error_m < 25.0,
                "{file}: {r:?}"
            );
            let [p, v] = r.mean_nees_per_dof.unwrap();
            assert!(
                (0.3..3.0).contains(&p) && (0.3..3.0).contains(&v),
                "{file}: {p} {v}"
            );
        }
    }

    /// A logger's track that starts while the vehicle drives off (a scenario of one line
    /// under `[drive]`): nav does not level while the vehicle accelerates, aligns in motion
    /// once the receiver's velocity is steady, and navigates within the position tolerance with
    /// honest sigmas; the brisk drive logged from standing levels still and uses its stops.
    #[test]
    fn a_track_that_starts_moving_is_aligned_in_motion_with_honest_sigmas() {
        use nav::navigation::navigator::StartKind;
        for (file, kind) in [
            ("track-porto-moving.toml", StartKind::InMotion),
            ("track-porto-handheld.toml", StartKind::Still),
        ] {
            let r = navigate_shipped(file, 0.0);
            eprintln!(
                "{file}: started {:?} at {:?} s, rms {:.2} m, end {:.2} m, NEES per dof {:?}, ZUPTs {:?}",
                r.start,
                r.started_at_s,
                r.rms_position_error_m,
                r.end_position_error_m,
                r.mean_nees_per_dof,
                r.filter.map(|f| f.zero_velocity_updates)
            );
            assert_eq!(r.start.0, Some(kind), "{file}");
            assert!(
                r.rms_position_error_m < 10.0 && r.end_position_error_m < 10.0,
                "{file}: {r:?}"
            );
            let [p, v] = r.mean_nees_per_dof.unwrap();
            assert!(
                (0.3..3.0).contains(&p) && (0.3..3.0).contains(&v),
                "{file}: {p} {v}"
            );
            if kind == StartKind::Still {
                // three stops of 8-20 s
                assert!(r.filter.unwrap().zero_velocity_updates >= 20, "{file}");
            } else {
                assert!(r.start.1 >= 1, "{file}: no window refused");
            }
        }
    }

    #[test]
    #[ignore = "figures: cargo test -p hil --release -- --ignored --nocapture pure_inertial"]
    fn pure_inertial_with_the_paper_grade_imu() {
        let mut s = loop_scenario(ImuParams::default(), 600.0);
        if let Some(d) = s.drive.as_mut() {
            d.laps = 3;
        }
        let r = pure_inertial(&s).unwrap();
        eprintln!("paper-grade IMU, pure inertial: {r:?}");
    }
}
