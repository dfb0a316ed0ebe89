//! `hil replay`: a recording through nav's pipeline.

use crate::cmd::args::BusArgs;
use crate::cmd::guest::{absolute, default_out, run_in_guest, same_command};
use anyhow::{Context, Result, bail};
use hil::run::sibling_binary;
use hil::scenario::Scenario;
use std::path::{Path, PathBuf};

/// The recording's MCAP file and nav's config for it (loaded).
fn recording_and_config(
    recording: &Path,
    config: Option<&Path>,
) -> Result<(PathBuf, nav::config::NavConfig)> {
    let (mcap, cfg) = if recording.is_dir() {
        (recording.join("nav.mcap"), recording.join("nav.toml"))
    } else {
        let beside = recording
            .parent()
            .unwrap_or(Path::new("."))
            .join("nav.toml");
        (recording.to_path_buf(), beside)
    };
    let cfg = config.map_or(cfg, Path::to_path_buf);
    if !cfg.is_file() {
        bail!(
            "no nav config for {} (looked for {}; give one with --config)",
            recording.display(),
            cfg.display()
        );
    }
    Ok((mcap, nav::config::NavConfig::load(&cfg)?))
}

pub(crate) fn replay(recording: &Path, config: Option<&Path>, json: bool) -> Result<i32> {
    let (mcap, cfg) = recording_and_config(recording, config)?;
    let r = if is_candump(&mcap) {
        hil::engine::recording::replay_candump(&mcap, &cfg)?
    } else {
        hil::engine::recording::replay(&mcap, &cfg)?
    };
    if json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", hil::engine::recording::text(&r));
    }
    Ok(i32::from(!r.identical()))
}

/// `hil replay --live`: in process, on a live view, paced at `speed`, with the viewer's
/// playback controls; the truth from the run's `scenario.toml` when the folder has it.
pub(crate) fn replay_live(
    recording: &Path,
    config: Option<&Path>,
    addr: std::net::SocketAddr,
    wait: usize,
    speed: f64,
) -> Result<i32> {
    let (mcap, cfg) = recording_and_config(recording, config)?;
    if is_candump(&mcap) {
        bail!("--live replays nav's MCAP recordings, not CAN logs");
    }
    let scen = mcap.with_file_name("scenario.toml");
    let scenario = if scen.is_file() {
        Some(Scenario::load(&scen)?)
    } else {
        eprintln!(
            "hil: no scenario.toml beside {}: the live view shows no truth",
            mcap.display()
        );
        None
    };
    let (r, stats) =
        hil::replay::live_view::replay_live(&mcap, &cfg, scenario.as_ref(), addr, wait, speed)?;
    for c in &stats.clients {
        eprintln!(
            "hil: live view: client {}: {} messages sent, {} dropped (fell behind)",
            c.peer, c.sent, c.dropped
        );
    }
    print!("{}", hil::engine::recording::text(&r));
    Ok(i32::from(!r.identical()))
}

/// `hil replay --bus`: the recording's traffic onto vcan and a pty with the nav binary on it,
/// here where the kernel has CAN, else in the QEMU guest.
pub(crate) fn replay_bus(
    recording: &Path,
    config: Option<&Path>,
    speed: f64,
    nav: Option<&Path>,
    bus: &BusArgs,
) -> Result<i32> {
    if !(speed.is_finite() && speed > 0.0) {
        bail!("--speed must be a positive number, not {speed}");
    }
    let (mcap, cfg) = recording_and_config(recording, config)?;
    if is_candump(&mcap) {
        bail!(
            "{} is a CAN log: it has no GPS bytes nor nav's events; replay it onto the bus with can-utils' canplayer, or in process without --bus",
            mcap.display()
        );
    }
    let out = absolute(&match &bus.out {
        Some(o) => o.clone(),
        None => default_out("replay"),
    })?;
    let nav_bin = match nav {
        Some(n) => absolute(n)?,
        None => sibling_binary("nav")?,
    };
    if bus.here() {
        let opts = hil::replay::on_bus::BusReplayOptions {
            iface: bus.iface.clone(),
            out: out.clone(),
            nav_bin,
            speed,
            progress: !bus.json,
        };
        let r = hil::replay::on_bus::replay_on_bus(&mcap, &cfg, &opts)?;
        let json = serde_json::to_string_pretty(&r)?;
        std::fs::write(out.join("replay.json"), &json)
            .with_context(|| format!("writing {}", out.join("replay.json").display()))?;
        if bus.json {
            println!("{json}");
        } else {
            print!("{}", r.text());
        }
        return Ok(i32::from(!r.identical()));
    }
    // no CAN here: the same command in the QEMU guest, the recording's folder shared (and the
    // config's, given or beside the recording)
    let (args, extra) = same_command(
        &[
            ("out", out.to_string_lossy().into_owned()),
            ("nav", nav_bin.to_string_lossy().into_owned()),
        ],
        &[],
    )?;
    run_in_guest(
        args,
        &out,
        extra,
        vec![nav_bin],
        bus.json.then_some("replay.json"),
    )
}

/// The file starts like a `candump -l` log: `(` and a time stamp.
fn is_candump(p: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 1];
    std::fs::File::open(p).is_ok_and(|mut f| f.read_exact(&mut head).is_ok() && head[0] == b'(')
}

/// python-can's writers: the candump log `argv[1]` rewritten as `argv[2]` (ASC or BLF by its
/// extension), every frame with its time stamp; prints the frames written.
const PYTHON_CAN_CONVERT: &str = r#"
import sys
import can
n = 0
with can.Logger(sys.argv[2]) as out:
    for m in can.LogReader(sys.argv[1]):
        # python-can's candump reader takes only bus errors for error frames: a controller's
        # state change, bus-off or restart (CAN_ERR_FLAG without CAN_ERR_BUSERROR) is one too
        if not m.is_error_frame and m.is_extended_id and m.arbitration_id & 0x20000000:
            m = can.Message(
                timestamp=m.timestamp,
                channel=m.channel,
                is_error_frame=True,
                is_extended_id=True,
                arbitration_id=m.arbitration_id & 0x1FFFFFFF,
                data=m.data,
            )
        out.on_message_received(m)
        n += 1
print(n)
"#;

pub(crate) fn candump(recording: &Path, out: Option<&Path>, iface: &str) -> Result<i32> {
    if recording.extension().is_some_and(|e| e == "log") {
        // a candump log (a run's bus.log, on the simulated clock): to Vector's formats
        let Some(out) = out else {
            bail!(
                "hil candump {}: a candump log is already candump; give --out FILE.asc or FILE.blf",
                recording.display()
            );
        };
        return convert_log(recording, out);
    }
    let mcap = if recording.is_dir() {
        recording.join("nav.mcap")
    } else {
        recording.to_path_buf()
    };
    let vector = out.and_then(|p| {
        p.extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .filter(|e| e == "asc" || e == "blf")
    });
    if let (Some(format), Some(out)) = (vector, out) {
        return vector_log(&mcap, out, iface, &format);
    }
    let n = match out {
        Some(p) => {
            let f =
                std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?;
            let mut w = std::io::BufWriter::new(f);
            let n = hil::engine::recording::export_candump(&mcap, iface, &mut w)?;
            std::io::Write::flush(&mut w).with_context(|| format!("writing {}", p.display()))?;
            n
        }
        None => {
            hil::engine::recording::export_candump(&mcap, iface, &mut std::io::stdout().lock())?
        }
    };
    eprintln!("hil candump: {n} frames from {}", mcap.display());
    Ok(0)
}

/// The recording `mcap` as a Vector log (`format`: asc or blf) at `out`, through python-can's
/// writers (a candump log in between).
/// A candump log `log` to `out` (ASC or BLF by its extension), through python-can.
fn convert_log(log: &Path, out: &Path) -> Result<i32> {
    let text =
        std::fs::read_to_string(log).with_context(|| format!("reading {}", log.display()))?;
    let n = text.lines().filter(|l| !l.trim().is_empty()).count() as u64;
    let written = python_can_convert(log, out)?;
    if written != n {
        bail!(
            "hil candump: python-can wrote {written} of the {n} frames of {} into {}",
            log.display(),
            out.display()
        );
    }
    eprintln!(
        "hil candump: {n} frames from {} as {} (python-can)",
        log.display(),
        out.display()
    );
    Ok(0)
}

/// python-can converts the candump log `log` to `out` (its writer by extension); how many
/// frames it wrote.
fn python_can_convert(log: &Path, out: &Path) -> Result<u64> {
    let o = std::process::Command::new("python3")
        .arg("-c")
        .arg(PYTHON_CAN_CONVERT)
        .arg(log)
        .arg(out)
        .output()
        .context("hil candump: running python3 (the ASC and BLF writers are python-can's)")?;
    if !o.status.success() {
        bail!(
            "hil candump: python-can could not write {}: {}; it needs python3 with python-can (pip install python-can)",
            out.display(),
            String::from_utf8_lossy(&o.stderr).trim()
        );
    }
    Ok(String::from_utf8_lossy(&o.stdout)
        .trim()
        .parse::<u64>()
        .unwrap_or(0))
}

fn vector_log(mcap: &Path, out: &Path, iface: &str, format: &str) -> Result<i32> {
    // the candump log in between, beside the output, removed after
    let tmp = out.with_extension(format!("{format}.candump-tmp.log"));
    let n = {
        let f =
            std::fs::File::create(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
        let mut w = std::io::BufWriter::new(f);
        let n = hil::engine::recording::export_candump(mcap, iface, &mut w)?;
        std::io::Write::flush(&mut w).with_context(|| format!("writing {}", tmp.display()))?;
        n
    };
    let written = python_can_convert(&tmp, out);
    let _ = std::fs::remove_file(&tmp);
    let written = written?;
    if written != n {
        bail!(
            "hil candump: python-can wrote {written} of the {n} frames into {}",
            out.display()
        );
    }
    eprintln!(
        "hil candump: {n} frames from {} as {} ({format}, python-can)",
        mcap.display(),
        out.display()
    );
    Ok(0)
}
