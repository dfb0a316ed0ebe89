//! Where a device under test puts its solution on a lab's contract: the message that opens an
//! epoch (its time tag, counting IMU samples, and its mode, by the lab's values for our modes),
//! the heading and its sigma, and optionally the position and the velocity in messages of their
//! own. [`SolutionReader`] turns the device's frames into [`SolutionPart`]s for the judge.

use super::{MappingError, check_counter, message, signal};
use crate::NavMode;
use crate::dbc::{Contract, DecodeError, MessageLayout};
use serde::Deserialize;
use std::collections::BTreeMap;

/// The device's solution on a lab's contract.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolutionMapping {
    /// The message that opens an epoch.
    pub message: String,
    /// Its time tag: the IMU sample the solution is of, counted from the unit's sample 0 and
    /// wrapping at the signal's width.
    pub time_tag: String,
    /// Its mode signal (values in `modes`).
    pub mode: String,
    /// The lab's value of each of our modes it has, by our name (`Init`, `Levelling`,
    /// `NorthFinding`, `Navigation`, `GpsAided`, `Coasting`, `Fault`, `Calibrating`,
    /// `Gyrocompass`); a value it does not list reads as `Init`.
    pub modes: BTreeMap<String, i64>,
    /// The heading, deg.
    #[serde(default)]
    pub heading: Option<String>,
    /// Its 1-sigma, deg.
    #[serde(default)]
    pub heading_sigma: Option<String>,
    /// Pitch, deg.
    #[serde(default)]
    pub pitch: Option<String>,
    /// Roll, deg.
    #[serde(default)]
    pub roll: Option<String>,
    /// The position, in a message of its own.
    #[serde(default)]
    pub position: Option<PositionMapping>,
    /// The velocity, in a message of its own.
    #[serde(default)]
    pub velocity: Option<VelocityMapping>,
}

/// The device's position.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PositionMapping {
    /// The message.
    pub message: String,
    /// Latitude, deg.
    pub latitude: String,
    /// Longitude, deg.
    pub longitude: String,
    /// Height, m.
    #[serde(default)]
    pub height: Option<String>,
    /// The horizontal position's 1-sigma, m.
    #[serde(default)]
    pub sigma: Option<String>,
}

/// The device's velocity.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VelocityMapping {
    /// The message.
    pub message: String,
    /// East, m/s.
    pub east: String,
    /// North, m/s.
    pub north: String,
    /// Up, m/s.
    #[serde(default)]
    pub up: Option<String>,
}

/// Check `s` against `contract`.
pub(super) fn check(s: &SolutionMapping, contract: &Contract) -> Result<(), MappingError> {
    let sec = "solution";
    let m = message(contract, sec, &s.message)?;
    check_counter(sec, m, signal(m, sec, &s.time_tag)?)?;
    super::table::codes(
        "solution.modes",
        m,
        signal(m, sec, &s.mode)?,
        &s.modes,
        |n| NavMode::ALL.iter().any(|x| x.name() == n),
    )?;
    for n in [&s.heading, &s.heading_sigma, &s.pitch, &s.roll]
        .into_iter()
        .flatten()
    {
        signal(m, sec, n)?;
    }
    if let Some(p) = &s.position {
        let sec = "solution.position";
        let m = message(contract, sec, &p.message)?;
        for n in [
            Some(&p.latitude),
            Some(&p.longitude),
            p.height.as_ref(),
            p.sigma.as_ref(),
        ]
        .into_iter()
        .flatten()
        {
            signal(m, sec, n)?;
        }
    }
    if let Some(v) = &s.velocity {
        let sec = "solution.velocity";
        let m = message(contract, sec, &v.message)?;
        for n in [Some(&v.east), Some(&v.north), v.up.as_ref()]
            .into_iter()
            .flatten()
        {
            signal(m, sec, n)?;
        }
    }
    Ok(())
}

/// A piece of the device's solution, as a frame carried it.
#[derive(Debug, Clone, PartialEq)]
pub enum SolutionPart {
    /// An epoch opens.
    Epoch {
        /// The time tag as sent (the sample, modulo 2^`tag_bits`).
        tag: u64,
        /// The time tag's width, bits.
        tag_bits: u16,
        /// The mode, by the lab's table.
        mode: NavMode,
        /// Heading, pitch, roll, deg (pitch and roll 0 where the contract lacks them); none
        /// where it has no heading.
        att: Option<[f64; 3]>,
        /// The heading's sigma, deg.
        heading_sigma: Option<f64>,
    },
    /// The position: latitude, longitude, deg; height, m; its sigma, m.
    Position {
        /// Latitude and longitude, deg.
        lat_lon: [f64; 2],
        /// Height, m.
        height: Option<f64>,
        /// Horizontal sigma, m.
        sigma: Option<f64>,
    },
    /// The velocity, east, north, up, m/s (up 0 where the contract lacks it).
    Velocity([f64; 3]),
}

/// The judge's reader of a device's solution frames.
#[derive(Debug, Clone)]
pub struct SolutionReader<'a> {
    sol: &'a SolutionMapping,
}

impl<'a> SolutionReader<'a> {
    /// The reader of `sol`.
    pub fn new(sol: &'a SolutionMapping) -> Self {
        Self { sol }
    }

    /// A frame of message `m`: the part of the solution it carries, none for a message that
    /// carries none.
    pub fn read(
        &self,
        m: &MessageLayout,
        data: &[u8],
    ) -> Result<Option<SolutionPart>, DecodeError> {
        let s = self.sol;
        let is = |name: &str| m.name == name;
        if !is(&s.message)
            && !s.position.as_ref().is_some_and(|p| is(&p.message))
            && !s.velocity.as_ref().is_some_and(|v| is(&v.message))
        {
            return Ok(None);
        }
        let v = m.decode(data)?;
        let get = |n: &str| v.iter().find(|(x, _)| *x == n).map(|(_, x)| *x);
        let opt = |n: &Option<String>| n.as_deref().and_then(get);
        if is(&s.message) {
            let raw = get(&s.mode).unwrap_or(-1.0) as i64;
            let mode = s
                .modes
                .iter()
                .find(|(_, v)| **v == raw)
                .and_then(|(n, _)| NavMode::ALL.iter().find(|x| x.name() == n).copied())
                .unwrap_or(NavMode::Init);
            return Ok(Some(SolutionPart::Epoch {
                tag: get(&s.time_tag).unwrap_or(0.0) as u64,
                tag_bits: m.signal(&s.time_tag).map_or(16, |x| x.len),
                mode,
                att: opt(&s.heading)
                    .map(|h| [h, opt(&s.pitch).unwrap_or(0.0), opt(&s.roll).unwrap_or(0.0)]),
                heading_sigma: opt(&s.heading_sigma),
            }));
        }
        if let Some(p) = s.position.as_ref().filter(|p| is(&p.message)) {
            return Ok(Some(SolutionPart::Position {
                lat_lon: [
                    get(&p.latitude).unwrap_or(f64::NAN),
                    get(&p.longitude).unwrap_or(f64::NAN),
                ],
                height: opt(&p.height),
                sigma: opt(&p.sigma),
            }));
        }
        Ok(s.velocity.as_ref().map(|x| {
            SolutionPart::Velocity([
                get(&x.east).unwrap_or(f64::NAN),
                get(&x.north).unwrap_or(f64::NAN),
                opt(&x.up).unwrap_or(0.0),
            ])
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mapping::Mapping;

    /// The device's heading frame opens an epoch (its time tag, its mode by the lab's table,
    /// its heading and sigma); its position frame carries the position; another frame none.
    #[test]
    fn the_devices_solution_frames_read_by_the_mapping() {
        let c = Contract::parse(include_str!("../../contracts/lab-imu.dbc")).expect("DBC");
        let m = Mapping::parse(include_str!("../../contracts/lab-imu.toml"), &c).expect("mapping");
        let r = SolutionReader::new(m.file.solution.as_ref().expect("a solution section"));
        let hd = c.message("INS_HEADING").expect("heading message");
        let data = hd
            .encode(&[
                ("Mode", 5.0),
                ("Heading", 251.25),
                ("HeadingSigma", 0.05),
                ("TimeTag", 65_000.0),
            ])
            .expect("encodes");
        match r.read(hd, &data).expect("reads") {
            Some(SolutionPart::Epoch {
                tag,
                tag_bits,
                mode,
                att: Some(att),
                heading_sigma: Some(hs),
            }) => {
                assert_eq!((tag, tag_bits, mode), (65_000, 16, NavMode::Navigation));
                assert!((att[0] - 251.25).abs() < 0.01 && (hs - 0.05).abs() < 1e-4);
            }
            other => panic!("{other:?}"),
        }
        let pos = c.message("INS_POSITION").expect("position message");
        let data = pos
            .encode(&[
                ("Latitude", 48.5),
                ("Longitude", -3.25),
                ("PositionSigma", 2.5),
            ])
            .expect("encodes");
        match r.read(pos, &data).expect("reads") {
            Some(SolutionPart::Position {
                lat_lon,
                sigma: Some(s),
                ..
            }) => assert!((lat_lon[0] - 48.5).abs() < 1e-6 && (s - 2.5).abs() < 1e-9),
            other => panic!("{other:?}"),
        }
        let rep = c.message("TABLE_REPORT").expect("report");
        assert_eq!(r.read(rep, &[0; 8]).expect("reads"), None);
        let e = Mapping::parse(
            &include_str!("../../contracts/lab-imu.toml").replacen("GpsAided = 6", "Aided = 6", 1),
            &c,
        )
        .expect_err("refused")
        .to_string();
        assert!(e.contains("Aided: not a name of ours"), "{e}");
        let e = Mapping::parse(
            &include_str!("../../contracts/lab-imu.toml").replacen(
                "GpsAided = 6",
                "GpsAided = 5",
                1,
            ),
            &c,
        )
        .expect_err("refused")
        .to_string();
        assert!(e.contains("both 5"), "{e}");
    }
}
