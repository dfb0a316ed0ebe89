//! What a scenario means for nav's configuration, in one place: the config file the bench
//! writes for the nav binary and the in-process runs give the pipeline (navigation, north-finding,
//! the calibrations, the IMU's calibration, the watchdog, the recording), from the scenario alone.

use crate::scenario::Scenario;
use anyhow::{Context, Result};
use emulators::gps::ReceiverParams;
use nav::config::{CanConfig, GpsConfig, NavConfig, RecordConfig, WatchdogConfig};
use nav::frontend::imu_frames::ImuCalibration;
use nav::navigation::filter::FilterConfig;
use nav::navigation::navigator::NavigationConfig;
use nav::procedures::drill_plan::{GyroNoise, PlanConfig};
use nav::procedures::north_finding::NorthFindingConfig;
use std::path::Path;

/// nav's `[navigation]` for a scenario: enabled, the surveyed heading when north-finding does
/// not give one, the receiver's lever arm when the filter's is left at zero.
pub fn navigation_config(s: &Scenario) -> Option<NavigationConfig> {
    let mut n = s.navigation.clone()?;
    n.enabled = true;
    if s.north_finding.is_none() && n.initial_heading_deg.is_none() {
        n.initial_heading_deg = Some(s.truth_heading_deg());
    }
    if let Some(g) = &s.gps {
        n.filter = crate::scenario::navconfig::with_lever_arm(&n.filter, g);
    }
    Some(n)
}

/// nav's `[self_calibration]` for a scenario: enabled, at the site's latitude, the unit named
/// by the IMU's seed, the parameter file written in the run folder.
pub fn self_calibration_config(
    s: &Scenario,
    c: &nav::procedures::self_calibration::SelfCalibrationConfig,
) -> nav::procedures::self_calibration::SelfCalibrationConfig {
    nav::procedures::self_calibration::SelfCalibrationConfig {
        enabled: true,
        latitude_deg: s.site.lat_deg,
        imu: s.unit_id(),
        parameters_out: Some(PARAMETER_FILE.into()),
        ..c.clone()
    }
}

/// nav's `[imu]` for a scenario, with the parameter file it names loaded (as nav loads it).
pub fn imu_calibration(s: &Scenario) -> nav::frontend::imu_frames::ImuCalibration {
    let mut c = crate::scenario::navconfig::calibration(s);
    if let Some(p) = s
        .nav_parameters
        .as_ref()
        .and_then(|p| nav::procedures::unit_parameters::ImuParameters::load(p, &s.unit_id()).ok())
    {
        c.gyro_bias_dph = p.gyro.bias_dph;
        c.gyro_scale_factor_ppm = p.gyro.scale_factor_ppm;
    }
    c
}

/// The parameter file nav's calibration of the redundant unit writes, in the run folder.
pub const TETRA_PARAMETER_FILE: &str = "tetra-parameters.toml";

/// The parameter file nav's self-calibration writes, in the run folder.
pub const PARAMETER_FILE: &str = "gyro-parameters.toml";

/// nav's config for a scenario. `iface`: the CAN interface (none in process); `gps_port`: the
/// receiver's port when the scenario has one (in process a name only: nothing opens it).
pub fn nav_config(s: &Scenario, iface: Option<&str>, gps_port: Option<&Path>) -> NavConfig {
    NavConfig {
        calibration: s
            .nav_parameters
            .as_ref()
            .map(|p| nav::config::CalibrationConfig {
                imu: s.unit_id(),
                parameters: p.clone(),
            }),
        can: iface.map(|i| CanConfig {
            interface: i.into(),
            rcvbuf_bytes: s.bus.nav_rcvbuf_bytes,
        }),
        gps: gps_port.map(|p| GpsConfig {
            port: p.to_path_buf(),
            baud: 9600,
            fixes_jsonl: Some("gps-fixes.jsonl".into()),
            ..GpsConfig::default()
        }),
        navigation: navigation_config(s).unwrap_or_default(),
        imu: imu_calibration(s),
        processing: s.processing,
        north_finding: s
            .north_finding
            .as_ref()
            .map(|nf| crate::scenario::navconfig::nf_config(s, nf))
            .unwrap_or_default(),
        self_calibration: s
            .self_calibration
            .as_ref()
            .map(|c| self_calibration_config(s, c))
            .unwrap_or_default(),
        tetra_calibration: s
            .tetra_calibration
            .as_ref()
            .map(
                |c| nav::procedures::tetra_calibration::TetraCalibrationConfig {
                    enabled: true,
                    latitude_deg: s.site.lat_deg,
                    base_heading_deg: s.site.heading_deg,
                    imu: s.mems_unit_id(),
                    parameters_out: Some(TETRA_PARAMETER_FILE.into()),
                    // what nav's config loader makes of the file it names
                    coefficients: c.parameters.as_ref().and_then(|p| {
                        nav::procedures::unit_parameters::RedundantParameters::load(
                            p,
                            &s.mems_unit_id(),
                        )
                        .ok()
                        .map(|f| f.coefficients())
                    }),
                    ..c.clone()
                },
            )
            .unwrap_or_default(),
        watchdog: WatchdogConfig {
            imu_timeout_ms: IMU_TIMEOUT_MS,
        },
        record: RecordConfig {
            mcap: Some("nav.mcap".into()),
            summary: Some("nav-summary.json".into()),
        },
    }
}

/// nav's IMU watchdog on the bench (wall time, ms). It decides liveness, never a result: where
/// the scenario stops the IMU, and at the stream's end, the scheduler holds the stream until
/// nav's watchdog has reported the stop ([`emulators::step::Step::stop_begins`],
/// `Stepper::end_awaits_watchdog`), so it fires once per stop after the same sample. Anywhere
/// else nothing holds the stream anywhere near this long, on an idle or a loaded host (the
/// longest gap between two batches seen under CPU hogs on host and guest: docs/pace.md). Each
/// run's end waits this long once.
pub const IMU_TIMEOUT_MS: u64 = 2000;

/// The calibration nav is given for this scenario's IMU.
pub fn calibration(s: &Scenario) -> ImuCalibration {
    ImuCalibration {
        gyro_pulse_arcsec: s.imu.gyro_pulse_arcsec,
        accel_pulse_mps: s.imu.accel_pulse_mps,
        rate_hz: s.imu.rate_hz,
        ..ImuCalibration::default()
    }
}

/// The filter as installed: the receiver's lever arm when the filter's is left at zero.
pub fn with_lever_arm(filter: &FilterConfig, rx: &ReceiverParams) -> FilterConfig {
    let mut f = filter.clone();
    if f.lever_arm_m == [0.0; 3] {
        f.lever_arm_m = rx.lever_arm_m;
    }
    f
}

/// The drill's north-finding settings for a scenario (latitude from the site).
pub fn nf_config(s: &Scenario, base: &NorthFindingConfig) -> NorthFindingConfig {
    NorthFindingConfig {
        enabled: true,
        latitude_deg: s.site.lat_deg,
        plan: plan_config(s, base),
        ..base.clone()
    }
}

/// The angle noise at each end of a dwell per arcsec of gyro pulse weight (quantization and the
/// dither residue the end windows leave), arcsec: measured by the Monte Carlo with neither
/// white noise nor drift (docs/north-finding.md, "The plan").
pub const END_ANGLE_PER_PULSE: f64 = 0.085;

/// The scenario's gyros and mechanism in the figures the drill's prediction takes.
pub fn gyro_noise(s: &Scenario) -> GyroNoise {
    let imu = &s.imu;
    let pulse = imu.gyro_pulse_arcsec[0].max(imu.gyro_pulse_arcsec[1]);
    // nav reads the table's angle from its status frames over the dwell: the encoder's noise
    // averaged over a second's frames at least
    let index = s.turntable.as_ref().map_or(0.0, |t| {
        t.encoder_noise_arcsec / t.status_hz.max(1.0).sqrt()
    });
    GyroNoise {
        arw_dpsh: imu.gyro_arw_dpsh,
        drift_dph: imu.gyro_bias_instability_dph,
        drift_tau_s: imu.gyro_bias_tau_s,
        end_angle_arcsec: END_ANGLE_PER_PULSE * pulse,
        index_arcsec: index,
        // the horizontal gyros' bias (drawn at +- this per axis), nav told none
        bias_dph: imu.gyro_bias_dph[0]
            .abs()
            .max(imu.gyro_bias_dph[1].abs())
            .max(1e-3),
    }
}

/// What nav is told to expect of the drill `nf` (`[north_finding.plan]`): the scenario's
/// tolerance, its gyros' figures, and the time between dwells on its mechanism (unlock, the
/// largest step at its rate and acceleration limits, lock) with nav's settling wait.
pub fn plan_config(s: &Scenario, nf: &NorthFindingConfig) -> PlanConfig {
    let tt = s.turntable.clone().unwrap_or_default();
    let step = nf
        .positions_deg
        .windows(2)
        .map(|w| {
            let d = (w[1] - w[0]).rem_euclid(360.0);
            d.min(360.0 - d)
        })
        .fold(0.0, f64::max);
    let (v, a) = (tt.max_rate_dps.max(1e-6), tt.max_accel_dps2.max(1e-6));
    let travel = if step >= v * v / a {
        step / v + v / a
    } else {
        2.0 * (step / a).sqrt()
    };
    PlanConfig {
        tolerance_deg: s.heading_tolerance_deg,
        confidence: nf.plan.confidence,
        // unlock, travel, settle into the lock window, lock, nav's wait, the acknowledgements
        index_time_s: 2.0 * tt.lock_time_s + travel + 0.3 + nf.settle_s,
        gyro: gyro_noise(s),
    }
}

/// Write nav's config for a scenario to `path` (as [`nav_config`]), the parameter files it
/// loads copied beside it (where nav, perhaps another user, can read them) and named there.
pub fn write_nav_config(
    s: &Scenario,
    iface: Option<&str>,
    gps_port: Option<&Path>,
    path: &Path,
) -> Result<NavConfig> {
    let mut cfg = nav_config(s, iface, gps_port);
    copy_inputs_beside(&mut cfg, path.parent().unwrap_or(Path::new(".")))?;
    std::fs::write(path, cfg.to_toml()).with_context(|| format!("writing {}", path.display()))?;
    Ok(cfg)
}

/// The parameter files `cfg` loads, copied into `dir` (beside its config file) and named there.
pub fn copy_inputs_beside(cfg: &mut NavConfig, dir: &Path) -> Result<()> {
    for (p, name) in cfg.input_files_mut() {
        std::fs::copy(&*p, dir.join(name))
            .with_context(|| format!("copying {} for nav", p.display()))?;
        *p = name.into();
    }
    Ok(())
}
