//! A lab's own contract: its mapping file (`wire::mapping`, docs/your-device.md) and the DBC it
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
