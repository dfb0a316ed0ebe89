//! `hil validate turntable`: the validation suite against the mechanism on a bus.

use crate::cmd::args::BusArgs;
use crate::cmd::guest::{absolute, default_out, run_in_guest_with_junit, same_command};
use anyhow::{Context, Result, bail};
use clap::Subcommand;
use std::path::PathBuf;

#[derive(Subcommand)]
pub(crate) enum Validate {
    /// The indexing mechanism: index accuracy and settle time at each detent, lock engagement,
    /// zero return, rate-mode accuracy and stability, rejection of invalid commands, heartbeat
    /// timeout stop, emergency stop. Prints a pass/fail table and writes validation.json.
    Turntable(ValidateArgs),
}

/// Faults the emulated mechanism can be given for validation.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub(crate) enum TtFault {
    /// The motor stalls on the first move.
    Stall,
    /// The lock pin never engages.
    Lock,
    /// The encoder reports glitched angles now and then.
    EncoderGlitch,
    /// The enable command is lost.
    LostCommands,
    /// Every command takes 0.2 s to act and be acknowledged.
    DelayedCommands,
}

#[derive(clap::Args, Clone)]
pub(crate) struct ValidateArgs {
    /// Axis to test.
    #[arg(long, default_value_t = 0)]
    pub(crate) axis: u8,
    /// Test real hardware on --iface: do not start the emulator.
    #[arg(long)]
    pub(crate) real: bool,
    /// Inject a fault into the emulated mechanism (the suite must catch it).
    #[arg(long, value_enum)]
    pub(crate) fault: Option<TtFault>,
    /// Pace of the emulated mechanism: its seconds per wall second at most. The suite runs in
    /// lockstep with the emulator, so the result is the same at any pace and on a loaded host;
    /// the pace only sets how fast an operator sees it (with --real, the mechanism's own time).
    #[arg(long, value_parser = hil::values::speed, default_value_t = 1.0)]
    pub(crate) speed: f64,
    /// Also write the result as JUnit XML to FILE, for a CI server (GitLab, Jenkins, GitHub):
    /// a test case per check, failing with the measured value, the limit and why.
    #[arg(long, value_name = "FILE")]
    pub(crate) junit: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) bus: BusArgs,
}

pub(crate) fn validate_turntable(a: ValidateArgs) -> Result<i32> {
    use emulators::turntable::{Turntable, TurntableParams};
    use hil::suites::validate::SuiteTime;
    if a.speed.is_nan() || a.speed <= 0.0 || a.speed > 100.0 {
        bail!("--speed must be in (0, 100]");
    }
    let out = absolute(
        &a.bus
            .out
            .clone()
            .unwrap_or_else(|| default_out("validate-turntable")),
    )?;
    let here = a.real || a.bus.here();
    if !here {
        let (args, shares) =
            same_command(&[("out", out.to_string_lossy().into_owned())], &["junit"])?;
        let code = run_in_guest_with_junit(
            args,
            &out,
            shares,
            vec![],
            a.bus.json.then_some("validation.json"),
            a.junit.as_deref(),
        )?;
        return Ok(code);
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let emulator = if a.real {
        None
    } else {
        vcan_setup::ensure_vcan(&a.bus.iface)?;
        let faults = injected(a.fault);
        let p = TurntableParams {
            axes: a.axis + 1,
            faults,
            ..TurntableParams::default()
        };
        p.check()?;
        Some(hil::engine::devices::start_turntable(
            &a.bus.iface,
            Turntable::new(p),
        )?)
    };
    let time = match &emulator {
        Some((_, ls)) => SuiteTime::Lockstep {
            ls: ls.clone(),
            pace: a.speed,
        },
        None => SuiteTime::Wall { speed: 1.0 },
    };
    let started = std::time::Instant::now();
    let result = hil::suites::validate::run_suite(&a.bus.iface, a.axis, time, &Default::default());
    if let Some((tt, _)) = emulator {
        tt.join()?;
    }
    let v = result?;
    if let Some(j) = &a.junit {
        let suite = hil::suites::validate::junit(&v, started.elapsed().as_secs_f64());
        hil::junit::write(j, "hil validate turntable", &[suite])?;
    }
    std::fs::write(
        out.join("validation.json"),
        serde_json::to_string_pretty(&v)?,
    )?;
    let md = hil::suites::validate::markdown(&v);
    std::fs::write(out.join("validation.md"), &md)?;
    hil::report::page::folder_page(&out, "Turntable validation", &md)?;
    if a.bus.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print!("{}", hil::suites::validate::table(&v));
        println!(" report: {}", out.join("validation.json").display());
    }
    Ok(if v.pass { 0 } else { 1 })
}

/// The emulated mechanism's faults for `--fault`.
fn injected(f: Option<TtFault>) -> emulators::turntable::TurntableFaults {
    let mut faults = emulators::turntable::TurntableFaults::default();
    match f {
        Some(TtFault::Stall) => faults.stall_from_s = Some(0.0),
        Some(TtFault::Lock) => faults.lock_fails = true,
        Some(TtFault::EncoderGlitch) => {
            faults.encoder_glitch_at_s = (0..400).map(|i| 0.5 + 0.25 * f64::from(i)).collect();
        }
        Some(TtFault::LostCommands) => faults.lost_command_seqs = vec![4],
        Some(TtFault::DelayedCommands) => faults.command_delay_s = 0.2,
        None => {}
    }
    faults
}
