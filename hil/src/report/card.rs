//! A run's report for people: the result card printed at its end and the Markdown report.

use super::{NavMemory, RunReport};
use crate::table::Table;

/// The result card printed at the end of a run.
pub fn card(r: &RunReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let line = "=".repeat(78);
    let _ = writeln!(s, "{line}");
    let _ = writeln!(
        s,
        " RUN {}  on {} ({})  {:.1} s simulated in {:.1} s wall: x{:.1} reached, x{} asked{}",
        r.scenario.name,
        r.interface,
        r.backend,
        r.pace_reached * r.wall_seconds,
        r.wall_seconds,
        r.pace_reached,
        r.scenario.speed,
        if r.pace_reached < 0.9 * r.scenario.speed {
            " (fell behind; the result does not depend on it)"
        } else {
            ""
        }
    );
    let _ = writeln!(
        s,
        " IMU frames sent {} ({:.0} frames/s wall), lost on the bus {}, dropped on purpose {}",
        r.tx.frames, r.frames_per_wall_second, r.bus_lost_frames, r.tx.dropped_samples
    );
    if let Some(m) = &r.nav_memory {
        let _ = writeln!(s, " {}", memory_line(m));
    }
    let _ = writeln!(s, "{line}");
    for p in crate::procedures::ALL {
        if let Some(c) = p.card(&r.scenario, &r.procedures) {
            for l in c.lines() {
                let _ = writeln!(s, " {l}");
            }
            let _ = writeln!(s, "{line}");
        }
    }
    for c in &r.checks {
        let _ = writeln!(
            s,
            " [{}] {:<42} {}",
            if c.pass { "PASS" } else { "FAIL" },
            c.name,
            c.detail
        );
    }
    let _ = writeln!(s, "{line}");
    let _ = writeln!(s, " RESULT: {}", if r.pass { "PASS" } else { "FAIL" });
    s
}

/// nav's memory in one line.
fn memory_line(m: &NavMemory) -> String {
    format!(
        "nav's memory (resident): {} KiB after {:.0} s, {} KiB at the end, peak {} KiB{}",
        m.start_kib,
        m.warm_s,
        m.end_kib,
        m.peak_kib,
        m.growth_kib_per_hour.map_or(String::new(), |g| format!(
            ", trend {g:+.0} KiB per simulated hour"
        ))
    ) + &m
        .cpu_s
        .map_or(String::new(), |c| format!("; CPU time {c:.1} s"))
}

/// Markdown version of the report.
pub fn markdown(r: &RunReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "# Run report: {}\n", r.scenario.name);
    let _ = writeln!(
        s,
        "- interface: `{}` ({})\n- simulated: {} s at x{}\n- wall: {:.1} s, {:.0} frames/s\n- result: **{}**\n",
        r.interface,
        r.backend,
        r.scenario.duration_s,
        r.scenario.speed,
        r.wall_seconds,
        r.frames_per_wall_second,
        if r.pass { "PASS" } else { "FAIL" }
    );
    for p in crate::procedures::ALL {
        if let Some(m) = p.markdown(&r.scenario, &r.procedures) {
            s += &m;
        }
    }
    if let Some(n) = &r.navigation {
        let mut t = Table::left(&[
            "at",
            "horizontal position error",
            "velocity error",
            "heading error",
        ]);
        t.row([
            format!("{:.1} s", n.t_s),
            format!("{:.2} m", n.position_error_m),
            format!("{:.3} m/s", n.velocity_error_mps),
            format!("{:+.4} deg", n.heading_error_deg),
        ]);
        let _ = writeln!(
            s,
            "## Navigation (nav's output against truth)\n\n{}",
            t.finish()
        );
        if let Some(x) = &r.navigation_series {
            let _ = writeln!(
                s,
                "Over the run ({} s scored from nav's recording): RMS {:.2} m, largest {:.2} m. Plot: `navigation-error.svg`, data: `navigation.csv`.\n",
                x.samples, x.rms_position_error_m, x.max_position_error_m
            );
        }
    }
    if let Some(m) = &r.nav_memory {
        let _ = writeln!(s, "{}\n", memory_line(m));
    }
    s += &super::bus_figures::markdown(&r.bus);
    let mut t = Table::left(&["check", "result", "detail"]);
    for c in &r.checks {
        t.row([
            c.name.as_str(),
            if c.pass { "PASS" } else { "FAIL" },
            &c.detail,
        ]);
    }
    s += &t.finish();
    let _ = writeln!(
        s,
        "\nFiles: `report.json` (everything), `nav-summary.json`, `nav.mcap` (raw frames, decoded samples, events), `nav.toml`, `scenario.toml`."
    );
    s
}
