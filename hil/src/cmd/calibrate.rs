//! `hil calibrate rotating-imu`: the self-calibration procedure, on the bus or in process.

use crate::cmd::args::{BusArgs, FreeArgs, LiveArgs};
use crate::cmd::guest::absolute;
use crate::cmd::run::{procedure_folder, report_in_process, run_procedure};
use anyhow::{Context, Result, bail};
use clap::Subcommand;
use std::path::PathBuf;

#[derive(Subcommand)]
pub(crate) enum Calibrate {
    /// Self-calibration of a dual-axis rotating IMU on a static base (paper 004): nav levels
    /// and finds a coarse heading at rest, turns both axes of the mechanism at the set rate,
    /// reversing each after every turn, estimates the gyro biases and scale-factor errors by the
    /// paper's decoupled RLS (and a 14-state Kalman filter beside it), returns the axes to zero,
    /// locks them and writes the IMU parameter file (gyro-parameters.toml in the run folder).
    /// Live progress, then a result card scored against the emulated unit's true errors.
    RotatingImu(CalibrateArgs),
    /// Kalman calibration of a redundant MEMS gyro unit (four gyros in a tetrahedron) on a
    /// three-axis table (paper 001): nav turns the table about x, y and z in turn at the set
    /// rate, checks every held second that the table did what was commanded, and estimates
    /// each gyro's bias, scale factor and two mounting angles with the paper's 16-state filter.
    /// With --monitor (or --fail) the profile runs again with the parity monitor on the
    /// calibrated outputs; --fail injects one gyro's failure over the bus. Live progress, then
    /// a result card scored against the emulated unit's truth.
    Tetrahedral(TetraArgs),
}

#[derive(clap::Args, Clone)]
pub(crate) struct TetraArgs {
    /// Latitude of the table, deg.
    #[arg(long, value_parser = hil::values::latitude_deg, default_value_t = 45.0, allow_negative_numbers = true)]
    pub(crate) lat: f64,
    /// Heading of the table's base, deg.
    #[arg(long, value_parser = hil::values::heading_deg, default_value_t = 0.0, allow_negative_numbers = true)]
    pub(crate) heading: f64,
    /// Rate of each turn, deg/s (the paper: 20).
    #[arg(long, value_parser = hil::values::rate_dps, default_value_t = 20.0)]
    pub(crate) rate: f64,
    /// Rest before the turns, s.
    #[arg(long, value_parser = hil::values::pause_s, default_value_t = 60.0)]
    pub(crate) rest: f64,
    /// Each turn, s (the paper: 75).
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 75.0)]
    pub(crate) turn: f64,
    /// Rest after the turns, s.
    #[arg(long, value_parser = hil::values::pause_s, default_value_t = 75.0)]
    pub(crate) end_rest: f64,
    /// The unit's gyro noise, deg/s per sample (the paper's is 2.8e-7; MEMS: 0.005 to 0.05).
    #[arg(long, value_parser = hil::values::noise_dps, default_value_t = 0.005)]
    pub(crate) noise: f64,
    /// Run the profile again with the parity monitor on the calibrated outputs.
    #[arg(long)]
    pub(crate) monitor: bool,
    /// Fail one gyro (1-4) halfway through the monitor's pass: stuck:G, bias-jump:G:DPS or
    /// noise:G:DPS (implies --monitor).
    #[arg(long)]
    pub(crate) fail: Option<String>,
    /// Start from the unit's parameter file (an earlier run's tetra-parameters.toml): no
    /// calibration, the profile once with the parity monitor.
    #[arg(long)]
    pub(crate) parameters: Option<PathBuf>,
    /// Speed factor (1 = real time).
    #[arg(long, value_parser = hil::values::speed, default_value_t = 20.0)]
    pub(crate) speed: f64,
    /// Seed of the unit and the table.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Run the same procedure in process (no bus, no nav process).
    #[arg(long)]
    pub(crate) in_process: bool,
    #[command(flatten)]
    pub(crate) live: LiveArgs,
    #[command(flatten)]
    pub(crate) bus: BusArgs,
}

#[derive(clap::Args, Clone)]
pub(crate) struct CalibrateArgs {
    /// Latitude of the site, deg.
    #[arg(long, value_parser = hil::values::latitude_deg, default_value_t = 30.0, allow_negative_numbers = true)]
    pub(crate) lat: f64,
    /// True heading of the base, deg.
    #[arg(long, value_parser = hil::values::heading_deg, default_value_t = 30.06, allow_negative_numbers = true)]
    pub(crate) heading: f64,
    /// True pitch and roll of the base, deg.
    #[arg(long, value_parser = hil::values::tilt_deg, default_value_t = 0.06, allow_negative_numbers = true)]
    pub(crate) tilt: f64,
    /// Coarse alignment at rest, s.
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 60.0)]
    pub(crate) level: f64,
    /// Rotation, s (the paper: 900).
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 900.0)]
    pub(crate) rotate: f64,
    /// Rotation rate of both axes, deg/s (the paper: 5).
    #[arg(long, value_parser = hil::values::rate_dps, default_value_t = 5.0)]
    pub(crate) rate: f64,
    /// The inner axis starts this long after the outer one, s (0: in step; the paper does not
    /// say).
    #[arg(long, value_parser = hil::values::pause_s, default_value_t = 18.0)]
    pub(crate) inner_delay: f64,
    /// Speed factor (1 = real time).
    #[arg(long, value_parser = hil::values::speed, default_value_t = 20.0)]
    pub(crate) speed: f64,
    /// Seed of the emulated unit and mechanism.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// An IMU parameter file for nav to load at start (e.g. an earlier run's
    /// gyro-parameters.toml): the procedure then refines it, and its static alignment starts
    /// from calibrated gyros.
    #[arg(long)]
    pub(crate) parameters: Option<PathBuf>,
    /// Run the same procedure in process (no bus, no nav process: the same emulators and nav
    /// code, stepped in the order the bench delivers the frames).
    #[arg(long)]
    pub(crate) in_process: bool,
    #[command(flatten)]
    pub(crate) live: LiveArgs,
    #[command(flatten)]
    pub(crate) bus: BusArgs,
}

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
            p.date = nav::procedures::unit_parameters::now_rfc3339();
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
            p.date = nav::procedures::unit_parameters::now_rfc3339();
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
