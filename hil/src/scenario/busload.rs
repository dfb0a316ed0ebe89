//! The traffic a scenario puts on its bus, message by message (its IMU's rate, its turntable's
//! axes and status rate, the redundant unit when it has one, nav's solution), and whether it
//! fits the bus's bit rate: frame lengths from `wire::busload`, stuffing included.

use super::Scenario;
use anyhow::{Result, bail};
use wire::MessageSpec;
use wire::busload::{MessageLoad, load, report_of};

/// Frames per second of each message the scenario's devices and nav send.
pub fn rates(s: &Scenario) -> Vec<(&'static MessageSpec, f64)> {
    let imu = s.imu.rate_hz;
    wire::ALL_MESSAGES
        .iter()
        .map(|spec| {
            let fps = match (spec.sender, spec.name) {
                (_, "IMU_GYRO" | "IMU_ACCEL") => imu,
                // housekeeping every 200th sample at 2 kHz: 10 Hz whatever the rate
                (_, "IMU_HK") => spec.frames_per_second,
                // one frame on each IMU sample's strobe
                ("MEMS", _) => {
                    if s.imu.tetra.is_some() {
                        imu
                    } else {
                        0.0
                    }
                }
                (_, "TT_STATUS") => s
                    .turntable
                    .as_ref()
                    .map_or(0.0, |t| t.status_hz * f64::from(t.axes)),
                // commands and their acks: the contract's event budget, when there is a table
                (_, "TT_CMD" | "TT_ACK") => {
                    if s.turntable.is_some() {
                        spec.frames_per_second
                    } else {
                        0.0
                    }
                }
                // nav's solution at its fixed output rate
                _ => spec.frames_per_second,
            };
            (*spec, fps)
        })
        .collect()
}

/// The scenario's load at its bit rate: per message, and the totals (nominal, worst-case
/// stuffing) as fractions of the bit rate.
pub fn of(s: &Scenario) -> (Vec<MessageLoad>, f64, f64) {
    load(&rates(s), s.bus.bitrate_bps)
}

/// The scenario's load as a printable table.
pub fn report(s: &Scenario) -> String {
    report_of(&of(s), s.bus.bitrate_bps)
}

/// Refuse a scenario whose traffic does not fit its bus with worst-case bit stuffing, with the
/// figures and the message that loads it most.
pub fn fits(s: &Scenario) -> Result<()> {
    let (rows, nominal, worst) = of(s);
    if worst <= 1.0 {
        return Ok(());
    }
    // the first of equals: the message the contract lists first
    let top = rows
        .iter()
        .rev()
        .max_by(|a, b| a.worst_bps.total_cmp(&b.worst_bps))
        .map_or(String::new(), |r| {
            format!(
                "; the most is {} ({:.0} frames/s, {:.0} % of the bus)",
                r.spec.name,
                r.frames_per_second,
                100.0 * r.worst_bps / s.bus.bitrate_bps
            )
        });
    bail!(
        "the scenario's traffic does not fit its bus: {:.1} % of {:.0} kbit/s nominal, {:.1} % with worst-case bit stuffing{top}. Raise bus.bitrate_bps or lower the rates (`hil busload --scenario FILE` shows every message)",
        100.0 * nominal,
        s.bus.bitrate_bps / 1000.0,
        100.0 * worst
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A drill at 1 Mbit/s fits (the IMU is most of it); at 500 and 250 kbit/s it is refused
    /// with the figures; a static run without a table carries no turntable frames.
    #[test]
    fn a_scenario_fits_its_bit_rate_or_is_refused_with_the_figures() {
        let mut s = crate::procedures::northfinding::scenario(30.0, 45.0, 30.0, 1);
        let (rows, nominal, worst) = of(&s);
        assert!(fits(&s).is_ok());
        assert!(nominal < worst && worst < 1.0, "{nominal} {worst}");
        let status = rows.iter().find(|r| r.spec.name == "TT_STATUS").unwrap();
        let tt = s.turntable.as_ref().unwrap();
        assert_eq!(status.frames_per_second, tt.status_hz * f64::from(tt.axes));
        for kbit in [500.0, 250.0] {
            s.bus.bitrate_bps = kbit * 1000.0;
            let e = fits(&s).unwrap_err().to_string();
            assert!(
                e.contains(&format!("of {kbit:.0} kbit/s")) && e.contains("IMU_"),
                "{e}"
            );
        }
        let quiet = Scenario::builtin_static();
        let rows = of(&quiet).0;
        assert!(
            rows.iter()
                .filter(|r| r.spec.name.starts_with("TT_") || r.spec.name == "MEMS_GYRO")
                .all(|r| r.frames_per_second == 0.0)
        );
    }
}
