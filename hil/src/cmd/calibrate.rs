//! `hil calibrate rotating-imu`: the self-calibration procedure, on the bus or in process.

use crate::*;
use cmd::run::{procedure_folder, report_in_process, run_procedure};

pub(crate) fn calibrate_rotating_imu(a: CalibrateArgs) -> Result<i32> {
    let o = hil::procedures::rotating::CalibrateOptions {
        lat_deg: a.lat,
        heading_deg: a.heading.rem_euclid(360.0),
        tilt_deg: a.tilt,
        level_s: a.level,
        rotate_s: a.rotate,
        rate_dps: a.rate,
        inner_delay_s: a.inner_delay,
        seed: a.seed,
    };
    let mut s = hil::procedures::rotating::scenario(&o);
    s.speed = a.speed;
    s.nav_parameters = a.parameters.as_deref().map(absolute).transpose()?;
    s.check()?;
    let (out, scen) = procedure_folder(
        &s,
        a.bus.out.as_deref(),
        "calibrate-rotating-imu",
        "calibrate.toml",
    )?;
    eprintln!(
        "hil: self-calibration of the rotating IMU at latitude {} deg, heading {} deg: {} s at rest, {} s of rotation at {} deg/s, x{}",
        o.lat_deg, o.heading_deg, o.level_s, o.rotate_s, o.rate_dps, a.speed
    );
    if a.in_process {
        let o = hil::procedures::rotating::run_in_process(&s, |j| {
            hil::status::show(&hil::procedures::rotating::progress_line(j))
        })?;
        hil::status::finish();
        if let Some(p) = &o.parameters {
            let mut p = p.clone();
            p.date = nav::params::now_rfc3339();
            let f = out.join(hil::scenario::navconfig::PARAMETER_FILE);
            std::fs::write(&f, p.to_toml()).with_context(|| format!("writing {}", f.display()))?;
            eprintln!("hil: parameter file {}", f.display());
        }
        report_in_process(
            &out,
            "calibration",
            &o,
            a.bus.json,
            hil::procedures::rotating::card,
        )?;
        return Ok(i32::from(o.result.is_none()));
    }
    run_procedure(scen, out, a.bus, a.live, FreeArgs::default())
}

/// `--fail` of `hil calibrate tetrahedral`: `stuck:G`, `bias-jump:G:DPS` or `noise:G:DPS`
/// (gyro 1-4) at `at_s`.
fn parse_failure(text: &str, at_s: f64) -> Result<emulators::imu::mems::GyroFailure> {
    use emulators::imu::mems::GyroFailure;
    let parts: Vec<&str> = text.split(':').collect();
    let gyro = |p: &str| -> Result<usize> {
        match p.parse::<usize>() {
            Ok(g @ 1..=4) => Ok(g - 1),
            _ => bail!("--fail {text}: the gyro is 1, 2, 3 or 4, not {p:?}"),
        }
    };
    let value = |p: &str| -> Result<f64> {
        p.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v > 0.0)
            .with_context(|| format!("--fail {text}: {p:?} is not a positive rate in deg/s"))
    };
    Ok(match parts.as_slice() {
        ["stuck", g] => GyroFailure::Stuck {
            gyro: gyro(g)?,
            at_s,
        },
        ["bias-jump", g, v] => GyroFailure::BiasJump {
            gyro: gyro(g)?,
            at_s,
            jump_dps: value(v)?,
        },
        ["noise", g, v] => GyroFailure::NoiseBurst {
            gyro: gyro(g)?,
            at_s,
            sigma_dps: value(v)?,
        },
        _ => bail!("--fail {text}: give stuck:G, bias-jump:G:DPS or noise:G:DPS (G 1-4)"),
    })
}

pub(crate) fn calibrate_tetrahedral(a: TetraArgs) -> Result<i32> {
    let mut o = hil::procedures::tetrahedral::TetraOptions {
        lat_deg: a.lat,
        heading_deg: a.heading.rem_euclid(360.0),
        rate_dps: a.rate,
        rest_s: a.rest,
        turn_s: a.turn,
        end_rest_s: a.end_rest,
        noise_dps: a.noise,
        monitor: a.monitor || a.fail.is_some() || a.parameters.is_some(),
        failure: None,
        parameters: a.parameters.as_deref().map(absolute).transpose()?,
        seed: a.seed,
    };
    if let Some(f) = &a.fail {
        // halfway through the monitor's pass: the second, or the only one when the
        // coefficients come from a file
        let pass = hil::procedures::tetrahedral::tetra_scenario(&o)
            .tetra_calibration
            .map_or(0.0, |c| c.profile_s());
        let at = if o.parameters.is_some() { 0.5 } else { 1.5 } * pass;
        o.failure = Some(parse_failure(f, at)?);
    }
    let mut s = hil::procedures::tetrahedral::tetra_scenario(&o);
    s.speed = a.speed;
    s.check()?;
    let (out, scen) = procedure_folder(
        &s,
        a.bus.out.as_deref(),
        "calibrate-tetrahedral",
        "calibrate.toml",
    )?;
    eprintln!(
        "hil: calibration of the redundant MEMS unit on the three-axis table at latitude {} deg: {} s at rest, x y z at {} deg/s for {} s each, {} s at rest{}, x{}",
        o.lat_deg,
        o.rest_s,
        o.rate_dps,
        o.turn_s,
        o.end_rest_s,
        if o.monitor {
            ", then again with the parity monitor"
        } else {
            ""
        },
        a.speed
    );
    if a.in_process {
        let o = hil::procedures::tetrahedral::tetra_in_process(&s, |j| {
            hil::status::show(&hil::procedures::tetrahedral::tetra_progress_line(j))
        })?;
        hil::status::finish();
        if let Some(p) = &o.parameters {
            let mut p = p.clone();
            p.date = nav::params::now_rfc3339();
            let f = out.join(hil::scenario::navconfig::TETRA_PARAMETER_FILE);
            std::fs::write(&f, p.to_toml()).with_context(|| format!("writing {}", f.display()))?;
            eprintln!("hil: parameter file {}", f.display());
        }
        report_in_process(
            &out,
            "tetra_calibration",
            &o,
            a.bus.json,
            hil::procedures::tetrahedral::tetra_card,
        )?;
        return Ok(i32::from(o.result.is_none()));
    }
    run_procedure(scen, out, a.bus, a.live, FreeArgs::default())
}
