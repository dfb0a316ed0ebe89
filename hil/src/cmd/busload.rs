//! `hil busload`: the bus load of the wire contract, or of a scenario's traffic at its bit rate.

use crate::*;

pub(crate) fn busload(bitrate: Option<f64>, scenario: Option<PathBuf>) -> Result<i32> {
    let Some(path) = scenario else {
        print!(
            "{}",
            wire::busload::report(bitrate.unwrap_or(wire::busload::NOMINAL_BITRATE))
        );
        return Ok(0);
    };
    // read without the scenario's checks: the table is wanted most when the traffic does not fit
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read scenario {}", path.display()))?;
    let mut s: Scenario =
        toml::from_str(&text).with_context(|| format!("scenario {}", path.display()))?;
    if let Some(b) = bitrate {
        if b > 1_000_000.0 {
            bail!("--bitrate {b}: a classic CAN bus runs at 1 Mbit/s at most");
        }
        s.bus.bitrate_bps = b;
    }
    print!("{}", hil::scenario::busload::report(&s));
    match hil::scenario::busload::fits(&s) {
        Ok(()) => {
            println!("fits: {} can run at this bit rate", s.name);
            Ok(0)
        }
        Err(e) => {
            println!("does not fit: {e}");
            Ok(1)
        }
    }
}
