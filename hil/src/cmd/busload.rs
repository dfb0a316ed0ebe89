//! `hil busload`: the bus load of the wire contract, or of a scenario's traffic at its bit rate,
//! and with `--measure` what the bus model measured when the scenario ran in process.

use anyhow::{Context, Result, bail};
use hil::scenario::Scenario;
use std::path::PathBuf;

pub(crate) fn busload(bitrates: &[f64], scenario: Option<PathBuf>, measure: bool) -> Result<i32> {
    if let Some(b) = bitrates.iter().find(|b| **b > 1_000_000.0) {
        bail!("--bitrate {b}: a classic CAN bus runs at 1 Mbit/s at most");
    }
    let scenarios: Vec<Scenario> = match (scenario, measure) {
        (Some(path), _) => {
            // read without the scenario's checks: the table is wanted most when the traffic
            // does not fit
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("cannot read scenario {}", path.display()))?;
            vec![toml::from_str(&text).with_context(|| format!("scenario {}", path.display()))?]
        }
        (None, true) => main_job()?,
        (None, false) => {
            for b in or_default(bitrates, wire::busload::NOMINAL_BITRATE) {
                print!("{}", wire::busload::report(b));
            }
            return Ok(0);
        }
    };
    let mut status = 0;
    for base in scenarios {
        for b in or_default(bitrates, base.bus.bitrate_bps) {
            let mut s = base.clone();
            s.bus.bitrate_bps = b;
            println!("## {} at {:.0} kbit/s\n", s.name, b / 1000.0);
            print!("{}", hil::scenario::busload::report(&s));
            if let Err(e) = hil::scenario::busload::fits(&s) {
                println!("does not fit: {e}\n");
                status = 1;
                continue;
            }
            println!("fits: {} can run at this bit rate\n", s.name);
            if measure {
                println!("{}", measured(&s)?);
            }
        }
    }
    Ok(status)
}

/// `hil busload --mapping FILE`: the lab's contract (the mapping and the DBC it names) on its
/// bus: each mapped message's rate, load and worst-case response time; with `measure`, what the
/// bus model measured of that traffic beside the bounds. Exit status 1 when a message has no
/// bound.
pub(crate) fn mapped(path: &std::path::Path, measure: bool) -> Result<i32> {
    let (contract, m) = hil::scenario::lab_contract::load(path)?;
    let nominal = m.file.bus.bitrate;
    let data = m.file.bus.data_bitrate.unwrap_or(nominal);
    let periodic = m.periodic(&contract);
    let response = wire::busload::response_times(&periodic, nominal, data);
    println!(
        "## {} at {:.0} kbit/s, CAN FD data phase {:.0} kbit/s\n",
        path.display(),
        nominal / 1000.0,
        data / 1000.0
    );
    println!(
        "{:<16} {:>10} {:>5} {:>4} {:>9} {:>9} {:>8} {:>12}",
        "message", "id", "bytes", "FD", "frames/s", "worst %", "jitter", "response ms"
    );
    let mut status = 0;
    for (p, r) in periodic.iter().zip(&response) {
        let t = wire::busload::frame_time_worst_s(p.extended, p.payload, p.fd, nominal, data);
        let id = if p.extended {
            format!("0x{:08X}", p.id)
        } else {
            format!("0x{:03X}", p.id)
        };
        let resp = match r {
            Some(r) => format!("{:.3}", r * 1e3),
            None => {
                status = 1;
                "no bound".into()
            }
        };
        println!(
            "{:<16} {:>10} {:>5} {:>4} {:>9.0} {:>9.2} {:>8.1} {:>12}",
            p.name,
            id,
            p.payload,
            if p.fd { "yes" } else { "no" },
            1.0 / p.period_s,
            100.0 * t / p.period_s,
            p.jitter_s * 1e3,
            resp
        );
    }
    println!(
        "total: {:.1} % of the bus with every frame at its longest\nresponse: the worst-case time from queued to sent (Davis et al. 2007; jitter in ms)",
        100.0 * m.worst_load
    );
    if measure {
        println!(
            "\n{}",
            hil::scenario::lab_contract::measured(&contract, &m)?
        );
    }
    Ok(status)
}

/// The bit rates asked for, else `default`.
fn or_default(bitrates: &[f64], default: f64) -> Vec<f64> {
    if bitrates.is_empty() {
        vec![default]
    } else {
        bitrates.to_vec()
    }
}

/// The main job's two scenarios (`hil demo`): the drill (at a fixed heading and seed, so that
/// the figures repeat) and the GPS-aided drive.
fn main_job() -> Result<Vec<Scenario>> {
    let drill = hil::procedures::northfinding::scenario(30.0, 28.218157, 60.0, 1);
    let drive: Scenario =
        toml::from_str(crate::cmd::demo::DRIVE_GPS).context("built-in drive scenario")?;
    Ok(vec![drill, drive])
}

/// Run `s` in process on its bus model: what the model measured, as a report's section.
fn measured(s: &Scenario) -> Result<String> {
    s.check().with_context(|| format!("scenario {}", s.name))?;
    let mut bench = hil::engine::inproc::InProcessBench::of(s)?;
    while bench.running() {
        bench.step();
    }
    bench.finish();
    let b = bench.bus_stats();
    let (_, nominal, worst) = hil::scenario::busload::of(s);
    Ok(format!(
        "Measured in process on the bus model ({:.1} s simulated): load {:.2} % (predicted {:.2} % unstuffed, {:.2} % with worst-case stuffing).\n\n{}{}",
        b.span_s,
        100.0 * b.load,
        100.0 * nominal,
        100.0 * worst,
        hil::report::bus_figures::markdown(&b),
        against_bounds(&b, s)
    ))
}

/// Each identifier's worst measured time from queued to sent against the analysis' bound with
/// the scenario's rates as periods (`emulators::bus::bounds`).
fn against_bounds(b: &emulators::bus::model::BusStats, s: &Scenario) -> String {
    let bitrate = s.bus.bitrate_bps;
    let (rows, _, _) = hil::scenario::busload::of(s);
    let periodic = wire::busload::periodic_of(&rows);
    let (table, _) = emulators::bus::bounds::against_bounds(b, &periodic, bitrate, bitrate);
    format!("\n{table}")
}
