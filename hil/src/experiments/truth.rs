//! The truth's self-check on every drive the bench scores in process: the reference strapdown
//! integration of the truth's own ideal increments (`emulators::road::reference`, written on
//! the truth side and sharing nothing with nav) beside the truth's position, velocity and
//! attitude. A drive whose truth departs from its own increments beyond the stated bound is
//! refused as the bench's fault, naming where, before any navigator is scored against it: a
//! truth that disagrees with itself would be scored as nav's error.

use crate::scenario::Scenario;
use anyhow::{Result, bail};
use emulators::drive::Drive;
use emulators::road::reference::{SelfCheck, self_check};
use serde::Serialize;
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

/// One drive's self-check, by its scenario's name.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TruthRow {
    /// The scenario.
    pub route: String,
    /// Its truth against the reference integration.
    pub check: SelfCheck,
}

/// The self-check of `s`'s drive over the scenario's duration at its IMU's rate (once per
/// process for the same drive: every seed and filter of an experiment drives the same truth).
pub fn check(s: &Scenario) -> Result<SelfCheck> {
    let Some(spec) = &s.drive else {
        bail!("scenario {} has no [drive]", s.name);
    };
    static DONE: OnceLock<Mutex<HashMap<String, SelfCheck>>> = OnceLock::new();
    let key = format!("{spec:?} {} {}", s.duration_s, s.imu.rate_hz);
    let done = DONE.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(c) = done.lock().ok().and_then(|d| d.get(&key).cloned()) {
        return Ok(c);
    }
    let drive = Drive::plan(spec)?;
    let c = self_check(&drive, s.imu.rate_hz, s.duration_s);
    if let Ok(mut d) = done.lock() {
        d.insert(key, c.clone());
    }
    Ok(c)
}

/// Every scenario's self-check (on `threads`), refused with the first whose truth disagrees
/// with itself: which drive, when, where and by how much.
pub fn check_all(scenarios: &[Scenario], threads: usize) -> Result<Vec<TruthRow>> {
    let rows = crate::par::map(
        scenarios,
        threads,
        |s| {
            check(s).map(|check| TruthRow {
                route: s.name.clone(),
                check,
            })
        },
        || Err(anyhow::anyhow!("the truth's self-check panicked")),
    );
    let rows = rows.into_iter().collect::<Result<Vec<_>>>()?;
    if let Some(bad) = rows.iter().find(|r| !r.check.holds()) {
        bail!(
            "{}: {}; refused as the bench's fault (run `hil plan route --scenario FILE` for the drive)",
            bad.route,
            bad.check.summary()
        );
    }
    Ok(rows)
}

/// The rows as a Markdown section.
pub fn markdown(rows: &[TruthRow]) -> String {
    use crate::table::{Align::*, Table};
    let mut t = Table::new(&[
        ("route", Left),
        ("checked s", Right),
        ("horizontal m", Right),
        ("velocity m/s", Right),
        ("attitude rad", Right),
        ("bound m, m/s, rad", Right),
        ("one motion", Left),
    ]);
    for r in rows {
        let c = &r.check;
        t.row([
            r.route.clone(),
            format!("{:.0}", c.checked_s),
            format!("{:.1e}", c.horizontal_m),
            format!("{:.1e}", c.velocity_mps),
            format!("{:.1e}", c.attitude_rad),
            format!(
                "{:e}, {:e}, {:e}",
                c.bound.horizontal_m, c.bound.velocity_mps, c.bound.attitude_rad
            ),
            (if c.holds() { "yes" } else { "NO" }).to_string(),
        ]);
    }
    format!(
        "## The truth's self-check\n\nThe reference strapdown integration of each drive's own ideal increments at the IMU's rate (the vertical channel held) against the truth's position, velocity and attitude, the largest departure over the drive: what the scores above rest on.\n\n{}",
        t.finish()
    )
}
