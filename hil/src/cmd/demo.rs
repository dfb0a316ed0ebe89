//! `hil demo`: the main job (a drill, then a GPS-aided drive).

use crate::cmd::args::{BusArgs, FreeArgs, LiveArgs, finish_view};
use crate::cmd::drill::{NorthFindingArgs, drill_north_finding};
use crate::cmd::guest::{absolute, default_out, run_in_guest, same_command};
use crate::cmd::run::run_procedure;
use anyhow::{Context, Result};
use hil::run::sibling_binary;
use hil::scenario::Scenario;
use std::path::{Path, PathBuf};
use vcan_setup::{CanSupport, GUEST_ENV};

/// The built-in GPS-aided drive of the demo.
pub(crate) const DRIVE_GPS: &str = include_str!("../../../scenarios/drive-gps.toml");

pub(crate) fn demo(speed: f64, dwell: f64, out: Option<PathBuf>, live: LiveArgs) -> Result<i32> {
    let out = absolute(&out.unwrap_or_else(|| default_out("demo")))?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let in_guest = std::env::var_os(GUEST_ENV).is_some();
    if !in_guest && !matches!(vcan_setup::can_support(), CanSupport::Available) {
        // one guest boot for both parts
        let (args, shares) = same_command(&[("out", out.to_string_lossy().into_owned())], &[])?;
        let status = run_in_guest(args, &out, shares, vec![sibling_binary("nav")?], None)?;
        return Ok(status);
    }
    let seed = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(1);
    // one live view for both parts, the drive after the drill on its timeline
    // the timeline's length the viewers are told: the drill's, a second, the drive's
    let drill_s = hil::procedures::northfinding::scenario(0.0, 28.218157, dwell, seed).duration_s;
    let drive_s = toml::from_str::<Scenario>(DRIVE_GPS)
        .map(|s| s.duration_s)
        .unwrap_or(0.0);
    let (view, own_view) = live.view(drill_s.ceil() + 1.0 + drive_s)?;
    let live = LiveArgs { view, ..live };
    let parts = demo_parts(speed, dwell, &out, seed, &live);
    if let (Some(v), true) = (live.view, own_view) {
        finish_view(v);
    }
    let (drill, drive) = parts?;
    let verdict = |c: i32| if c == 0 { "PASS" } else { "FAIL" };
    let mut t = hil::table::Table::left(&["part", "result", "report"]);
    t.row([
        "north-finding drill",
        verdict(drill),
        "[drill/report.md](drill/report.md)",
    ])
    .row([
        "GPS-aided drive",
        verdict(drive),
        "[drive/report.md](drive/report.md)",
    ]);
    let summary = format!("# Demo\n\n{}", t.finish());
    std::fs::write(out.join("report.md"), &summary)?;
    let row = |part: &str, code: i32, dir: &str| {
        format!(
            "<tr><td>{part}</td><td class=\"{}\">{}</td><td><a href=\"{dir}/report.html\">{dir}/report.html</a></td></tr>\n",
            if code == 0 { "pass" } else { "fail" },
            verdict(code)
        )
    };
    std::fs::write(
        out.join("report.html"),
        hil::report::page::page(
            "Bench demo",
            &format!(
                "<table>\n<tr><th>part</th><th>result</th><th>report</th></tr>\n{}{}</table>\n",
                row("north-finding drill", drill, "drill"),
                row("GPS-aided drive", drive, "drive")
            ),
        ),
    )?;
    println!("==============================================================================");
    println!(
        " DEMO  north-finding drill: {}   GPS-aided drive: {}",
        verdict(drill),
        verdict(drive)
    );
    println!(
        " report: {}/report.html (open it in a browser; drill/ and drive/ have one each)",
        out.display()
    );
    println!("==============================================================================");
    Ok(if drill == 0 && drive == 0 { 0 } else { 1 })
}

/// The demo's two parts (drill, drive): their exit statuses.
fn demo_parts(
    speed: f64,
    dwell: f64,
    out: &Path,
    seed: u64,
    live: &LiveArgs,
) -> Result<(i32, i32)> {
    eprintln!("hil: demo part 1 of 2: four-position north-finding drill");
    let drill = drill_north_finding(NorthFindingArgs {
        heading: None,
        lat: 28.218157,
        lon: 112.989583,
        dwell: super::drill::Dwell::Seconds(dwell),
        positions: None,
        out_and_back: false,
        speed,
        disturbances: None,
        // what 60 s dwells on the paper's IMU (its drift included) meet at 3 sigma at the
        // paper's latitude: `hil plan north-finding` says 0.156 deg
        tolerance: 0.2,
        seed,
        in_process: false,
        live: live.clone(),
        bus: BusArgs::to(out.join("drill")),
        free: FreeArgs::default(),
    })?;
    eprintln!("hil: demo part 2 of 2: GPS-aided drive (one 1 km lap, NMEA receiver on a pty)");
    let mut s: Scenario = toml::from_str(DRIVE_GPS).context("built-in drive scenario")?;
    s.speed = speed;
    let scen = out.join("drive-gps.toml");
    std::fs::write(&scen, toml::to_string_pretty(&s)?)?;
    let drive_out = out.join("drive");
    let drive = run_procedure(
        scen,
        drive_out.clone(),
        BusArgs::to(drive_out),
        live.clone(),
        FreeArgs::default(),
    )?;
    Ok((drill, drive))
}
