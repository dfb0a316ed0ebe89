//! The bench's own side of a run: `truth.mcap` beside nav's `nav.mcap`, so that a run can be
//! judged later, and nav's solution overlaid on the truth in a viewer, without re-running it.
//!
//! Channels (JSON with JSON schemas):
//! - `/truth/state` (`hil/schemas/truth-state.json`): the vehicle's position, velocity and
//!   attitude from the scenario's truth models (the drive, or the parked site), 10 Hz;
//! - `/truth/location` (`foxglove.LocationFix`): the same position for a viewer's map, beside
//!   nav's `/nav/location` and the receiver's `/gps/location`;
//! - `/truth/turntable` (`hil/schemas/turntable-truth.json`): the turntable's true angle, rate
//!   and state per axis from its model, 10 Hz, where the run has one;
//! - `/bench/faults` (`foxglove.Log`): each fault the bench injects, when it starts and ends
//!   ([`crate::engine::faultlog`]), beside nav's own `/nav/log`.
//!
//! Times: the publish time is simulated time, the IMU sample counter's time base, as nav's
//! publish times are. The log time is the wall time at which nav logged the same instant: read
//! from nav's recording (its solution messages carry both), interpolated, so that a viewer that
//! plays both files on log time shows them together. Without nav's solutions (a drill, a static
//! run) the log time is the simulated time.

use anyhow::{Context, Result};
use emulators::drive::Drive;
use emulators::truth::Static;
use std::collections::BTreeMap;
use std::path::Path;

/// A run's truth, planned once when the run starts: the vehicle's drive (none when parked),
/// its site, and the faults the bench injects. The live view shows it, the scoring judges nav
/// against it, and [`write`] records it.
#[derive(Debug, Clone)]
pub struct RunTruth {
    /// The drive, when the scenario has one.
    pub drive: Option<Drive>,
    /// The site (where a drive starts, or where the vehicle is parked).
    pub site: Static,
    /// The faults the bench injects, in time order.
    pub faults: Vec<crate::engine::faultlog::FaultEvent>,
}

impl RunTruth {
    /// The truth of scenario `s`, with the bench's own faults: the interface taken down
    /// (`link_downs`), nav killed (`kill_nav_at_s`) and nav stopped a while (`stall_nav`).
    pub fn of(
        s: &crate::scenario::Scenario,
        link_downs: &[[f64; 2]],
        kill_nav_at_s: Option<f64>,
        stall_nav: Option<crate::engine::faultlog::NavStall>,
    ) -> Result<Self> {
        Ok(Self {
            drive: s.drive.as_ref().map(Drive::plan).transpose()?,
            site: s.site,
            faults: crate::engine::faultlog::schedule(s, link_downs, kill_nav_at_s, stall_nav),
        })
    }
}

/// Rate of the truth channels, Hz.
pub const TRUTH_HZ: f64 = 10.0;

/// `/truth/state`'s JSON schema.
pub const STATE_SCHEMA: &str = include_str!("../../schemas/truth-state.json");
/// `/truth/turntable`'s JSON schema.
pub const TURNTABLE_SCHEMA: &str = include_str!("../../schemas/turntable-truth.json");

/// The truth at simulated time `t`: (lat deg, lon deg, h m, velocity ENU m/s, heading, pitch,
/// roll deg).
pub(crate) fn state(
    drive: Option<&Drive>,
    site: &Static,
    t: f64,
) -> (f64, f64, f64, [f64; 3], [f64; 3]) {
    match drive {
        Some(d) => {
            let (lat, lon, h) = d.position(t);
            let v = d.velocity(t);
            // a level route's pitch and roll are zero; a road's its grade, bank and the body's
            // motion on its suspension
            let [hd, p, r] = d.hpr(t);
            (
                lat.to_degrees(),
                lon.to_degrees(),
                h,
                [v.x, v.y, v.z],
                [
                    hd.to_degrees().rem_euclid(360.0),
                    p.to_degrees(),
                    r.to_degrees(),
                ],
            )
        }
        None => (
            site.lat_deg,
            site.lon_deg,
            site.height_m,
            [0.0; 3],
            [site.heading_deg, site.pitch_deg, site.roll_deg],
        ),
    }
}

/// Wall time (ns) of simulated time `t` from `(t, wall ns)` pairs sorted by `t`: interpolated
/// between them, extended with the nearest segment's slope beyond them; `t` itself (in ns)
/// without pairs.
pub fn wall_of(clock: &[(f64, u64)], t: f64) -> u64 {
    let at = |i: usize, j: usize| {
        let ((t0, w0), (t1, w1)) = (clock[i], clock[j]);
        let slope = if t1 > t0 {
            (w1 as f64 - w0 as f64) / (t1 - t0)
        } else {
            1e9
        };
        (w0 as f64 + (t - t0) * slope).max(0.0) as u64
    };
    match clock.len() {
        0 => (t.max(0.0) * 1e9) as u64,
        1 => (clock[0].1 as f64 + (t - clock[0].0) * 1e9).max(0.0) as u64,
        n => {
            let k = clock.partition_point(|c| c.0 <= t);
            let i = k.saturating_sub(1).min(n - 2);
            at(i, i + 1)
        }
    }
}

/// Write `truth.mcap` for a run of `duration_s` into `out`; `clock` maps simulated time to the
/// wall time nav logged it at (see the module's description). Returns the messages written.
pub fn write(
    out: &Path,
    drive: Option<&Drive>,
    site: &Static,
    duration_s: f64,
    clock: &[(f64, u64)],
    turntable: &[emulators::adapters::scheduler::TtTruth],
    faults: &[crate::engine::faultlog::FaultEvent],
) -> Result<u64> {
    let path = out.join("truth.mcap");
    let file =
        std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .profile("")
        .create(std::io::BufWriter::new(file))
        .with_context(|| format!("{}", path.display()))?;
    // a JSON channel with its JSON schema
    let channel = |w: &mut mcap::Writer<_>, schema: &str, text: &[u8], topic: &str| {
        let id = w.add_schema(schema, "jsonschema", text)?;
        w.add_channel(id, topic, "json", &BTreeMap::new())
    };
    let state_ch = channel(
        &mut w,
        "rlg-hil/bench/truth-state",
        STATE_SCHEMA.as_bytes(),
        "/truth/state",
    )?;
    let fix_ch = channel(
        &mut w,
        "foxglove.LocationFix",
        include_bytes!("../../../nav/schemas/foxglove/LocationFix.json"),
        "/truth/location",
    )?;
    let mut n = 0u64;
    // one message at simulated time `t`, logged at the wall time nav logged it
    let put = |w: &mut mcap::Writer<_>, ch: u16, k: usize, t: f64, data: &[u8]| {
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: ch,
                sequence: k as u32,
                log_time: wall_of(clock, t),
                publish_time: (t.max(0.0) * 1e9) as u64,
            },
            data,
        )
    };
    if !turntable.is_empty() {
        let ch = channel(
            &mut w,
            "rlg-hil/bench/turntable-truth",
            TURNTABLE_SCHEMA.as_bytes(),
            "/truth/turntable",
        )?;
        for (k, tt) in turntable.iter().enumerate() {
            let json = serde_json::to_string(tt)?;
            put(&mut w, ch, k, tt.t_s, json.as_bytes())?;
            n += 1;
        }
    }
    if !faults.is_empty() {
        let ch = channel(
            &mut w,
            "foxglove.Log",
            include_bytes!("../../../nav/schemas/foxglove/Log.json"),
            "/bench/faults",
        )?;
        for (k, f) in faults.iter().enumerate() {
            let m = fault_message(f);
            put(&mut w, ch, k, f.t_s, m.to_string().as_bytes())?;
            n += 1;
        }
    }
    let steps = (duration_s.max(0.0) * TRUTH_HZ).floor() as u64;
    for k in 0..=steps {
        let t = k as f64 / TRUTH_HZ;
        let (s, f) = truth_messages(drive, site, t);
        for (ch, m) in [(state_ch, s), (fix_ch, f)] {
            put(&mut w, ch, k as usize, t, m.to_string().as_bytes())?;
            n += 1;
        }
    }
    w.finish().with_context(|| format!("{}", path.display()))?;
    Ok(n)
}

/// `/truth/state` and `/truth/location` at simulated time `t` (the MCAP file's and the live
/// view's).
pub(crate) fn truth_messages(
    drive: Option<&Drive>,
    site: &Static,
    t: f64,
) -> (serde_json::Value, serde_json::Value) {
    let (lat, lon, h, v, hpr) = state(drive, site, t);
    let publish = (t.max(0.0) * 1e9) as u64;
    let s = serde_json::json!({
        "t_s": t, "lat_deg": lat, "lon_deg": lon, "h_m": h,
        "vel_enu_mps": v, "hpr_deg": hpr,
    });
    let f = serde_json::json!({
        "timestamp": nav::record::foxglove::time(publish),
        "frame_id": "truth",
        "latitude": lat, "longitude": lon, "altitude": h,
        "position_covariance": vec![0.0; 9],
        "position_covariance_type": 0,
        "heading": hpr[0].to_radians(),
        "velocity": {"x": v[0], "y": v[1], "z": v[2]},
    });
    (s, f)
}

/// `/bench/faults`' `foxglove.Log` of an injected fault's start or end.
pub(crate) fn fault_message(f: &crate::engine::faultlog::FaultEvent) -> serde_json::Value {
    let detail = if f.detail.is_empty() {
        String::new()
    } else {
        format!(": {}", f.detail)
    };
    let message = format!("{} {} {}{detail}", f.device, f.fault, f.phase);
    let ns = (f.t_s.max(0.0) * 1e9) as u64;
    nav::record::foxglove::log(ns, nav::record::foxglove::LOG_WARNING, "bench", message)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wall_clock_is_interpolated_and_extended() {
        assert_eq!(wall_of(&[], 1.5), 1_500_000_000);
        // nav logged sim time 1 s at wall 100 s, 3 s at 101 s (a pace of x2)
        let c = [(1.0, 100_000_000_000), (3.0, 101_000_000_000)];
        assert_eq!(wall_of(&c, 2.0), 100_500_000_000);
        assert_eq!(wall_of(&c, 5.0), 102_000_000_000);
        assert_eq!(wall_of(&c, 0.0), 99_500_000_000);
        assert_eq!(wall_of(&c[..1], 2.0), 101_000_000_000);
    }

    #[test]
    fn a_drive_and_a_site_are_recorded_at_ten_hertz() {
        let d = tempfile::tempdir().unwrap();
        let site = Static {
            lat_deg: -45.0,
            lon_deg: 170.0,
            height_m: 5.0,
            heading_deg: 30.0,
            pitch_deg: 0.5,
            roll_deg: -0.2,
        };
        let n = write(d.path(), None, &site, 2.0, &[], &[], &[]).unwrap();
        assert_eq!(n, 2 * 21);
        let buf = std::fs::read(d.path().join("truth.mcap")).unwrap();
        let msgs: Vec<_> = mcap::MessageStream::new(&buf)
            .unwrap()
            .map(|m| m.unwrap())
            .collect();
        assert_eq!(msgs.len(), 42);
        let last: serde_json::Value = serde_json::from_slice(&msgs[40].data).unwrap();
        assert_eq!(msgs[40].channel.topic, "/truth/state");
        assert_eq!(last["hpr_deg"], serde_json::json!([30.0, 0.5, -0.2]));
        assert_eq!(msgs[40].publish_time, 2_000_000_000);
    }
}
