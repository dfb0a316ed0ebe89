//! A lab's own contract: its mapping file (`wire::mapping`, docs/your-dbc.md) and the DBC it
//! names beside it, read and checked together.

use anyhow::{Context, Result};
use std::path::Path;
use wire::dbc::Contract;
use wire::mapping::{Mapping, MappingFile};

/// Read the mapping at `path` and the DBC it names (relative to it), and check the one against
/// the other; errors name the file and, from the check, the message and signal.
pub fn load(path: &Path) -> Result<(Contract, Mapping)> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the mapping {}", path.display()))?;
    let file: MappingFile =
        toml::from_str(&text).with_context(|| format!("the mapping {}", path.display()))?;
    let dbc_path = path.parent().unwrap_or(Path::new(".")).join(&file.dbc);
    let dbc = std::fs::read_to_string(&dbc_path)
        .with_context(|| format!("cannot read the DBC {}", dbc_path.display()))?;
    let contract =
        Contract::parse(&dbc).with_context(|| format!("the DBC {}", dbc_path.display()))?;
    let m = Mapping::check(file, &contract)
        .with_context(|| format!("the mapping {} against its DBC", path.display()))?;
    Ok((contract, m))
}

/// The IMU of `s` on the lab's contract `c` through its mapping `m`, ready to run: its model at
/// the mapping's rate, riding the table as `tracks` report it (none: as the scenario's own
/// table moves, or still), its samples' writes kept in `sent`.
pub fn imu_run<'a>(
    s: &crate::scenario::Scenario,
    (c, m): (&'a Contract, &'a Mapping),
    tracks: Vec<emulators::reported::SharedTrack>,
    sent: Option<std::sync::Arc<emulators::adapters::freerun::SentSamples>>,
) -> Result<emulators::adapters::fd::MappedImuRun<'a>> {
    let imu_map = m
        .file
        .imu
        .as_ref()
        .context("the mapping has no [imu]: nothing for the IMU to send")?;
    let mut params = s.imu.clone();
    params.rate_hz = imu_map.rate_hz;
    let arcsec = std::f64::consts::PI / 180.0 / 3600.0;
    let mapped = emulators::imu::mapped::MappedImu::new(
        imu_map,
        c,
        params.gyro_pulse_arcsec.map(|x| x * arcsec),
        params.accel_pulse_mps,
    );
    let motion = if tracks.is_empty() {
        s.motion()
    } else {
        s.following(&tracks)
    };
    let table = match (&m.file.turntable, tracks.is_empty()) {
        (Some(_), false) => Some((table_side(c, m)?.0, tracks)),
        _ => None,
    };
    Ok(emulators::adapters::fd::MappedImuRun {
        imu: emulators::imu::ImuEmulator::new(motion, params),
        mapped,
        framer: wire::mapping::Framer::new(c, m),
        rate_hz: imu_map.rate_hz,
        table,
        sent,
    })
}

/// The table's side of the lab's contract `c` through `m`, and the protector of its reports.
pub fn table_side<'a>(
    c: &'a Contract,
    m: &'a Mapping,
) -> Result<(wire::mapping::TableSide<'a>, wire::mapping::Protector<'a>)> {
    if m.file.turntable.is_none() {
        anyhow::bail!("the mapping has no [turntable]: the table cannot speak the lab's contract");
    }
    let side = wire::mapping::TableSide::new(c, m)
        .context("the mapping's [turntable] names a message the DBC lacks")?;
    Ok((side, wire::mapping::Protector::new(m)))
}

/// Seconds of the lab's traffic the bus model runs for its figures.
pub const MEASURE_S: f64 = 10.0;

/// The lab's traffic (`m` of `c`) on the bus model for [`MEASURE_S`]: each message's measured
/// worst time from queued to sent beside its bound (`wire::busload::response_times`), the
/// load beside the analysis' worst, and the table's round trip (its command to the report that
/// answers it at the controller's next 1 ms tick) beside the sum of their bounds and the tick;
/// as a report's section.
pub fn measured(c: &Contract, m: &Mapping) -> Result<String> {
    use std::fmt::Write;
    let nominal = m.file.bus.bitrate;
    let data = m.file.bus.data_bitrate.unwrap_or(nominal);
    let periodic = m.periodic(c);
    let bounds = wire::busload::response_times(&periodic, nominal, data);
    let msgs: Vec<emulators::bus::lab::LabMessage> = periodic
        .iter()
        .map(|p| emulators::bus::lab::LabMessage {
            periodic: p.clone(),
            sender: c
                .message(&p.name)
                .map(|l| l.sender.clone())
                .filter(|s| !s.is_empty())
                .unwrap_or_else(|| p.name.clone()),
        })
        .collect();
    let tick_s = 1e-3;
    let table = m.file.turntable.as_ref().and_then(|t| {
        Some(emulators::bus::lab::TableLoop {
            command: periodic.iter().position(|p| p.name == t.command)?,
            report: periodic.iter().position(|p| p.name == t.report)?,
            tick_s,
        })
    });
    let timing = emulators::bus::model::BusTiming {
        bitrate_bps: nominal,
        data_bitrate_bps: Some(data),
        ..Default::default()
    };
    let b = emulators::bus::lab::simulate(&msgs, table, timing, MEASURE_S, 1);
    let mut s = format!(
        "Measured on the bus model ({:.1} s, every message's first frame at 0, each later one within its jitter; every frame at its longest): load {:.2} % (the analysis' worst {:.2} % for the periodic traffic{}).\n\n{}",
        b.span_s,
        100.0 * b.load,
        100.0 * m.worst_load,
        if table.is_some() {
            "; the table's answer to each command is one report more"
        } else {
            ""
        },
        emulators::bus::bounds::against_bounds(&b, &periodic, nominal, data).0
    );
    if let (Some(t), Some(tl)) = (&m.file.turntable, table) {
        let bound = match (bounds[tl.command], bounds[tl.report]) {
            (Some(a), Some(b)) => format!("{:.0} us", (a + tick_s + b) * 1e6),
            _ => "none".into(),
        };
        let r = &b.round_trip;
        let _ = writeln!(
            s,
            "\nThe table's round trip, {} queued to the {} that answers it over: {} commands, median {:.0} us, p99 {:.0} us, worst {:.0} us; bound {bound} (the command's response, the controller's 1 ms tick, the report's response).",
            t.command, t.report, r.commands, r.p50_us, r.p99_us, r.max_us
        );
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    /// The example contract on the bus model: every message within its bound but one the
    /// analysis' assumption does not cover (IMU_STATUS, queued behind its own node's blocks),
    /// and the table's round trip within the sum of its parts' bounds.
    #[test]
    fn the_labs_traffic_on_the_bus_model_against_its_bounds() {
        let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let (c, m) =
            super::load(&here.join("../wire/contracts/lab-imu.toml")).expect("the example");
        let text = super::measured(&c, &m).expect("measured");
        let rows: Vec<&str> = text
            .lines()
            .filter(|l| l.starts_with("| ") && !l.starts_with("| message"))
            .collect();
        assert_eq!(rows.len(), 7, "{text}");
        for r in &rows {
            assert!(
                r.ends_with("| yes |") || (r.starts_with("| IMU_STATUS |") && r.contains("FIFO")),
                "{r}"
            );
        }
        let trip = text
            .lines()
            .find(|l| l.starts_with("The table's round trip"))
            .expect("a round trip");
        let num = |after: &str| -> f64 {
            let rest = &trip[trip.find(after).expect(after) + after.len()..];
            rest.split(|c: char| !c.is_ascii_digit() && c != '.')
                .next()
                .and_then(|x| x.parse().ok())
                .expect("a figure")
        };
        assert_eq!(num("over: "), 100.0, "{trip}");
        assert!(num("worst ") <= num("bound "), "{trip}");
    }
}
