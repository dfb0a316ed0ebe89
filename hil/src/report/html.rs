//! One self-contained HTML report per bench run (`report.html`): the result, the checks, the
//! frame accounting, the drill's dwells and SVG plots (navigation error against nav's own
//! sigma bounds, the turntable's angle against what nav commanded), with links to the CSV and
//! JSON files beside it. No scripts and no external resources: any browser opens it offline.

use crate::report::RunReport;
use crate::report::page::{esc, figure, page};
use crate::report::plot::{LogChart, Series};
use std::fmt::Write;
use std::path::Path;

/// A two-column table of (name, value) rows.
fn kv_table(rows: &[(&str, String)]) -> String {
    let mut s = String::from("<table>\n");
    for (k, v) in rows {
        let _ = writeln!(s, "<tr><th>{}</th><td>{}</td></tr>", esc(k), esc(v));
    }
    s + "</table>\n"
}

/// A table of JSON objects (the keys of the first as columns).
fn json_table(rows: &[serde_json::Value]) -> String {
    let Some(first) = rows.first().and_then(|r| r.as_object()) else {
        return String::new();
    };
    let keys: Vec<&String> = first.keys().collect();
    let mut s = String::from("<table>\n<tr>");
    for k in &keys {
        let _ = write!(s, "<th>{}</th>", esc(k));
    }
    s += "</tr>\n";
    for r in rows {
        s += "<tr>";
        for k in &keys {
            let v = match &r[k.as_str()] {
                serde_json::Value::Number(n) => match n.as_f64() {
                    Some(x) if n.is_f64() => format!("{x:.6}"),
                    _ => n.to_string(),
                },
                serde_json::Value::String(t) => t.clone(),
                serde_json::Value::Array(a) => a
                    .iter()
                    .map(|x| x.as_f64().map_or(x.to_string(), |f| format!("{f:.4}")))
                    .collect::<Vec<_>>()
                    .join(", "),
                other => other.to_string(),
            };
            let _ = write!(s, "<td>{}</td>", esc(&v));
        }
        s += "</tr>\n";
    }
    s + "</table>\n"
}

/// (x, y) points of a plot.
pub type Points = Vec<(f64, f64)>;

/// The turntable's axis-0 angle as nav received it (TT_STATUS) and the angles nav commanded
/// (TT_CMD index moves), against IMU time, from nav's recording. Time is the count of IMU
/// gyro frames received before each frame (the bus carries a sample's IMU frames first).
pub fn turntable_series(mcap_path: &Path, rate_hz: f64) -> anyhow::Result<(Points, Points)> {
    use wire::{Message, TtCommand};
    let (mut angle, mut targets): (Points, Points) = (Vec::new(), Vec::new());
    let mut gyro = 0u64;
    crate::engine::recording::each_message(mcap_path, "plotting", |m| {
        if m.channel.topic != "/can/raw" && m.channel.topic != "/can/tx" {
            return;
        }
        let Some(f) = nav::record::raw::frame_of(m) else {
            return;
        };
        let t = gyro as f64 / rate_hz;
        match Message::decode(&f) {
            Ok(Message::ImuGyro(_)) => gyro += 1,
            Ok(Message::TtStatus(st)) if st.axis == 0 => {
                // unwrapped: the axis turns through 360 deg continuously
                let a = near(st.angle_deg, angle.last().map_or(0.0, |p: &(f64, f64)| p.1));
                angle.push((t, a));
            }
            Ok(Message::TtCmd(c)) if c.axis == 0 => {
                // index moves and the return to zero
                let to = match TtCommand::from_raw(i64::from(c.command)) {
                    Some(TtCommand::IndexAbs) => c.arg,
                    Some(TtCommand::Home) => 0.0,
                    _ => return,
                };
                targets.push((t, to));
            }
            _ => {}
        }
    })?;
    // each target on the turn the table reached before the next command (a move of half a
    // turn may go either way), held until then: steps
    let t_end = angle.last().map_or(0.0, |p| p.0);
    let mut cmd = Vec::new();
    for (i, &(t, to)) in targets.iter().enumerate() {
        let until = targets.get(i + 1).map_or(t_end, |n| n.0);
        let reached = angle
            .iter()
            .take_while(|p| p.0 <= until)
            .last()
            .map_or(0.0, |p| p.1);
        let y = near(to, reached);
        cmd.push((t, y));
        cmd.push((until, y));
    }
    Ok((angle, cmd))
}

/// `deg` plus the whole turns that bring it within half a turn of `reference`.
fn near(deg: f64, reference: f64) -> f64 {
    deg + 360.0 * ((reference - deg) / 360.0).round()
}

/// The HTML report of a run whose files are in `out`.
pub fn run_report(r: &RunReport, out: &Path) -> String {
    let mut b = String::new();
    let verdict = if r.pass {
        "<span class=\"pass\">PASS</span>"
    } else {
        "<span class=\"fail\">FAIL</span>"
    };
    let _ = writeln!(
        b,
        "<p>Result: {verdict}. Scenario <code>{}</code> on <code>{}</code> ({}): {:.1} s simulated in {:.1} s of wall time (x{:.1} reached, x{} asked). nav exited with {}.</p>",
        esc(&r.scenario.name),
        esc(&r.interface),
        esc(&r.backend),
        r.pace_reached * r.wall_seconds,
        r.wall_seconds,
        r.pace_reached,
        r.scenario.speed,
        r.nav_exit
            .map_or("no status (killed)".into(), |c| c.to_string())
    );
    for p in crate::procedures::ALL {
        if let Some(sec) = p.html(&r.scenario, &r.procedures, &r.nav) {
            b += &procedure_section(&sec);
        }
    }
    b += "<h2>Checks</h2>\n<table>\n<tr><th>check</th><th>result</th><th>measured and limit</th></tr>\n";
    for c in &r.checks {
        let _ = writeln!(
            b,
            "<tr><td>{}</td><td class=\"{}\">{}</td><td>{}</td></tr>",
            esc(&c.name),
            if c.pass { "pass" } else { "fail" },
            if c.pass { "PASS" } else { "FAIL" },
            esc(&c.detail)
        );
    }
    b += "</table>\n";
    b += &frames_section(r);
    b += &crate::report::bus_figures::html(&r.bus);
    let plots = turntable_plot(r, out) + &navigation_csv_plots(out);
    if !plots.is_empty() {
        b += "<h2>Plots</h2>\n";
        b += &plots;
    }
    b += &files_section(out);
    page(&format!("Bench run {}", r.scenario.name), &b)
}

/// A procedure's section: its figures, its card, and its detail table.
fn procedure_section(sec: &crate::procedures::Section) -> String {
    let mut b = format!("<h2>{}</h2>\n", esc(sec.title));
    if !sec.figures.is_empty() {
        b += &kv_table(&sec.figures);
    }
    if let Some(t) = &sec.text {
        let _ = writeln!(b, "<pre>{}</pre>", esc(t));
    }
    if let Some((caption, rows)) = &sec.detail {
        let _ = writeln!(b, "<p>{}</p>", esc(caption));
        b += &json_table(rows);
    }
    b
}

/// What went over the bus and the pty, and nav's memory and CPU time.
fn frames_section(r: &RunReport) -> String {
    let mut b = String::new();
    b += "<h2>Frames and sentences</h2>\n";
    let nav = serde_json::to_value(&r.nav).unwrap_or_default();
    let n = |path: &[&str]| {
        let mut v = &nav;
        for p in path {
            v = &v[*p];
        }
        match v {
            serde_json::Value::Null => "--".to_string(),
            x => x.to_string(),
        }
    };
    let mut rows = vec![
        ("IMU frames sent by the emulator", r.tx.frames.to_string()),
        (
            "frames per second of wall time",
            format!("{:.0}", r.frames_per_wall_second),
        ),
        ("IMU frames lost on the bus", r.bus_lost_frames.to_string()),
        (
            "IMU samples dropped on purpose (faults)",
            r.tx.dropped_samples.to_string(),
        ),
        ("frames nav received", n(&["frames_total"])),
        (
            "frames the kernel dropped at nav's socket",
            n(&["kernel_dropped_frames"]),
        ),
        (
            "IMU samples nav counted missing",
            n(&["imu", "missing_samples"]),
        ),
        ("solution frames nav sent", n(&["solution", "frames_sent"])),
        (
            "solution frames the bench saw",
            r.solution.frames.to_string(),
        ),
    ];
    if let Some(g) = &r.nav.gps {
        let s = serde_json::to_value(g.stats).unwrap_or_default();
        rows.push((
            "NMEA sentences with a bad checksum",
            s["bad_checksum"].to_string(),
        ));
        rows.push(("NMEA sentences not understood", s["unparsed"].to_string()));
        rows.push(("GPS fixes nav used", g.fixes.to_string()));
    }
    if let Some(m) = &r.nav_memory {
        rows.push((
            "nav's memory: after warm-up, end, peak (KiB)",
            format!("{}, {}, {}", m.start_kib, m.end_kib, m.peak_kib),
        ));
        if let Some(c) = m.cpu_s {
            rows.push(("nav's CPU time, s", format!("{c:.1}")));
        }
    }
    b += &kv_table(&rows);

    b
}

/// The turntable's angle against what nav commanded, from nav's recording.
fn turntable_plot(r: &RunReport, out: &Path) -> String {
    let mut plots = String::new();
    if r.scenario.turntable.is_some() {
        match turntable_series(&out.join("nav.mcap"), r.scenario.imu.rate_hz) {
            Ok((angle, cmd)) if !angle.is_empty() => {
                let c = LogChart {
                    title: "Turntable: angle received against the angle nav commanded".into(),
                    x_label: "IMU time, s".into(),
                    y_label: "deg".into(),
                    series: vec![
                        Series {
                            name: "TT_STATUS angle".into(),
                            color: "#1f77b4",
                            points: angle,
                            markers: false,
                        },
                        Series {
                            name: "TT_CMD index / home".into(),
                            color: "#d62728",
                            points: cmd,
                            markers: false,
                        },
                    ],
                };
                plots += &figure(
                    &c.svg_linear(),
                    "From nav's recording: the status frames' axis angle and the index and home commands nav sent.",
                );
            }
            Ok(_) => {}
            Err(e) => {
                let _ = writeln!(
                    plots,
                    "<p>No turntable plot: {}</p>",
                    esc(&format!("{e:#}"))
                );
            }
        }
    }
    plots
}

/// Position, velocity and heading errors second by second against nav's bounds (from
/// navigation.csv), then [`navigation_plots`].
fn navigation_csv_plots(out: &Path) -> String {
    let mut plots = String::new();
    if let Ok(text) = std::fs::read_to_string(out.join("navigation.csv")) {
        let rows: Vec<Vec<f64>> = text
            .lines()
            .skip(1)
            .map(|l| {
                l.split(',')
                    .map(|v| v.parse().unwrap_or(f64::NAN))
                    .collect()
            })
            .collect();
        let col = |i: usize| -> Vec<(f64, f64)> {
            rows.iter()
                .filter(|r| r.len() > i)
                .map(|r| (r[0], r[i]))
                .collect()
        };
        let scaled = |v: Vec<(f64, f64)>, k: f64| v.into_iter().map(|(t, y)| (t, k * y)).collect();
        let chart = |title: &str, y: &str, series: Vec<Series>| {
            LogChart {
                title: title.into(),
                x_label: "IMU time, s".into(),
                y_label: y.into(),
                series,
            }
            .svg_linear()
        };
        let line = |name: &str, color: &'static str, points| Series {
            name: name.into(),
            color,
            points,
            markers: false,
        };
        plots += &figure(
            &chart(
                "Horizontal position error against nav's 3-sigma bound",
                "m",
                vec![
                    line("error", "#1f77b4", col(1)),
                    line("3 sigma (nav's)", "#d62728", scaled(col(4), 3.0)),
                ],
            ),
            "Each second of navigation from nav's recording, scored against the truth; the bound is the horizontal position sigma nav sent with its solution.",
        );
        plots += &figure(
            &chart(
                "Velocity error",
                "m/s",
                vec![line("error", "#1f77b4", col(2))],
            ),
            "The norm of the velocity error.",
        );
        plots += &figure(
            &chart(
                "Heading error against nav's sigma bounds",
                "deg",
                vec![
                    line("error", "#1f77b4", col(3)),
                    line("+3 sigma", "#d62728", scaled(col(5), 3.0)),
                    line("-3 sigma", "#d62728", scaled(col(5), -3.0)),
                ],
            ),
            "Heading error and nav's own heading sigma, three times, either side.",
        );
        plots += &navigation_plots(out, &col);
    }
    plots
}

/// Links to the run's files that exist.
fn files_section(out: &Path) -> String {
    let mut b = String::new();
    b += "<h2>Files</h2>\n<ul>\n";
    for (f, what) in [
        ("report.json", "this report as data"),
        ("report.md", "this report as text"),
        ("navigation.csv", "navigation error second by second"),
        ("nav.mcap", "nav's recording (MCAP)"),
        (
            "truth.mcap",
            "the bench's truth, turntable and injected faults (MCAP)",
        ),
        (
            "bench-can.log",
            "every CAN frame the emulators put on the bus (candump -l)",
        ),
        (
            "gps-sent.log",
            "every byte the GPS emulator wrote to its port",
        ),
        ("nav-summary.json", "nav's own summary"),
        ("scenario.toml", "the scenario as run"),
        ("nav.toml", "nav's configuration"),
    ] {
        if out.join(f).is_file() {
            let _ = writeln!(b, "<li><a href=\"{f}\">{f}</a>: {what}</li>");
        }
    }
    b += "</ul>\n";
    b
}

/// The plots a navigation engineer looks at first, from `navigation.csv` (column `i` by
/// `col`) and `fixes.csv`: the track with the receiver's fixes, the velocity error per axis and
/// the tilt errors against nav's own 3-sigma bounds, and NEES over time against its chi-square
/// bounds.
fn navigation_plots(out: &Path, col: &dyn Fn(usize) -> Vec<(f64, f64)>) -> String {
    let mut plots = String::new();
    let pair = |a: usize, b: usize| -> Vec<(f64, f64)> {
        finite(
            col(a)
                .into_iter()
                .zip(col(b))
                .map(|((_, x), (_, y))| (x, y))
                .collect(),
        )
    };
    // the track: truth, nav, and the receiver's fixes (an outage is where they stop)
    let nav_track = pair(6, 7);
    if !nav_track.is_empty() {
        let text = std::fs::read_to_string(out.join("fixes.csv")).unwrap_or_default();
        let fixes = |fate: &str| -> Vec<(f64, f64)> {
            text.lines()
                .skip(1)
                .filter_map(|l| {
                    let v: Vec<&str> = l.split(',').collect();
                    (v.len() == 4 && v[3] == fate)
                        .then(|| Some((v[1].parse().ok()?, v[2].parse().ok()?)))
                        .flatten()
                })
                .collect()
        };
        plots += &figure(
            &chart(
                "Track: truth, nav and the receiver's fixes",
                "east of the start, m",
                "north of the start, m",
                vec![
                    line("receiver's fixes", "#2ca02c", fixes("valid"), true),
                    line("rejected by the filter", "#d62728", fixes("rejected"), true),
                    line("truth", "#000000", pair(8, 9), false),
                    line("nav", "#1f77b4", nav_track, false),
                ],
            ),
            "The horizontal track once a second of navigation; the receiver's valid fixes as nav took them (where they stop, the receiver was silent or void: an outage) and those the filter's gate refused.",
        );
    }
    for (name, e, sig) in [("east", 10, 13), ("north", 11, 14), ("up", 12, 15)] {
        let err = finite(col(e));
        if err.is_empty() {
            continue;
        }
        plots += &figure(
            &chart(
                &format!("Velocity error {name} against nav's 3-sigma bounds"),
                "IMU time, s",
                "m/s",
                vec![
                    line("error", "#1f77b4", err, false),
                    line("+3 sigma", "#d62728", scaled(col(sig), 3.0), false),
                    line("-3 sigma", "#d62728", scaled(col(sig), -3.0), false),
                ],
            ),
            &format!(
                "The {name} velocity error and nav's own {name} velocity sigma (its filter's covariance, recorded once a second), three times, either side."
            ),
        );
    }
    let (pitch, roll) = (finite(col(16)), finite(col(17)));
    if !pitch.is_empty() {
        plots += &figure(
            &chart(
                "Pitch and roll errors against nav's 3-sigma tilt bounds",
                "IMU time, s",
                "deg",
                vec![
                    line("pitch error", "#1f77b4", pitch, false),
                    line("roll error", "#ff7f0e", roll, false),
                    line("+3 sigma", "#d62728", scaled(col(18), 3.0), false),
                    line("-3 sigma", "#d62728", scaled(col(18), -3.0), false),
                ],
            ),
            "A drive is level: the truth's pitch and roll are 0. The bound is nav's tilt sigma (the mean of its east and north ones), three times, either side.",
        );
    }
    plots += &nees_plot(finite(col(19)), finite(col(20)));
    plots
}

/// Each second's NEES of position and velocity against the chi-square bounds.
fn nees_plot(np: Vec<(f64, f64)>, nv: Vec<(f64, f64)>) -> String {
    if np.is_empty() {
        return String::new();
    }
    let span = (np.first().map(|p| p.0), np.last().map(|p| p.0));
    let at = |k: f64| -> Vec<(f64, f64)> {
        match span {
            (Some(a), Some(b)) => vec![(a, k), (b, k)],
            _ => Vec::new(),
        }
    };
    figure(
        &chart(
            "NEES over time against its chi-square bounds",
            "IMU time, s",
            "NEES (3 degrees of freedom)",
            vec![
                line("position", "#1f77b4", np, false),
                line("velocity", "#ff7f0e", nv, false),
                line("95 % bounds (0.22, 9.35)", "#d62728", at(CHI2_3_LOW), false),
                line("", "#d62728", at(CHI2_3_HIGH), false),
            ],
        ),
        "Each second's error against nav's own covariance: a filter whose sigmas are right stays between the bounds 95 % of the time, and averages 3.",
    )
}

/// The points whose both coordinates are finite.
fn finite(v: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    v.into_iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect()
}

/// A series of a chart.
fn line(name: &str, color: &'static str, points: Vec<(f64, f64)>, markers: bool) -> Series {
    Series {
        name: name.into(),
        color,
        points,
        markers,
    }
}

/// The points with their values times `k`.
fn scaled(v: Vec<(f64, f64)>, k: f64) -> Vec<(f64, f64)> {
    finite(v.into_iter().map(|(t, y)| (t, k * y)).collect())
}

/// A chart on linear axes.
fn chart(title: &str, x: &str, y: &str, series: Vec<Series>) -> String {
    LogChart {
        title: title.into(),
        x_label: x.into(),
        y_label: y.into(),
        series,
    }
    .svg_linear()
}

/// The two-sided 95 % bounds of a chi-square variable with 3 degrees of freedom.
const CHI2_3_LOW: f64 = 0.216;
const CHI2_3_HIGH: f64 = 9.348;

#[cfg(test)]
mod tests {
    use super::*;

    /// A recording (written by nav's own recorder) of an index to 90 deg, then to 270, then
    /// home through 360: the angle is unwrapped and the commands are steps on the same turn.
    #[test]
    fn the_turntable_plot_follows_the_recording() {
        use nav::record::writer::{Record, Recorder};
        use wire::{ImuGyro, Message, TtCmd, TtCommand, TtState, TtStatus};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nav.mcap");
        let r = Recorder::start(&path).unwrap();
        let frame = |m: Message| m.encode().unwrap();
        let cmd = |c: TtCommand, arg: f64| {
            frame(Message::TtCmd(TtCmd {
                seq: 1,
                command: c as u8,
                axis: 0,
                arg,
            }))
        };
        let angles = [0.0, 45.0, 90.0, 180.0, 270.0, 330.0, 359.9, 0.1];
        for (k, a) in angles.iter().enumerate() {
            for _ in 0..100 {
                r.send(Record::Frame {
                    t_ns: 0,
                    frame: frame(Message::ImuGyro(ImuGyro {
                        counts: [0; 3],
                        sample_counter: k as u16,
                    })),
                });
            }
            let sent = match k {
                0 => Some(cmd(TtCommand::IndexAbs, 90.0)),
                3 => Some(cmd(TtCommand::IndexAbs, 270.0)),
                5 => Some(cmd(TtCommand::Home, 0.0)),
                _ => None,
            };
            if let Some(f) = sent {
                r.send(Record::Sent { t_ns: 0, frame: f });
            }
            r.send(Record::Frame {
                t_ns: 0,
                frame: frame(Message::TtStatus(TtStatus {
                    angle_deg: *a,
                    rate_dps: 0.0,
                    state: TtState::Idle,
                    axis: 0,
                    faults: Default::default(),
                    ack_seq: 0,
                    counter: k as u8,
                })),
            });
        }
        r.finish().unwrap();
        let (angle, cmd) = turntable_series(&path, 100.0).unwrap();
        let a: Vec<f64> = angle.iter().map(|p| (p.1 * 10.0).round() / 10.0).collect();
        assert_eq!(a, [0.0, 45.0, 90.0, 180.0, 270.0, 330.0, 359.9, 360.1]);
        assert_eq!(angle[1].0, 2.0, "time from the gyro frames before it");
        let c: Vec<f64> = cmd.iter().map(|p| p.1).collect();
        assert_eq!(c, [90.0, 90.0, 270.0, 270.0, 360.0, 360.0], "{cmd:?}");
    }

    #[test]
    fn text_is_escaped_and_tables_follow_the_first_row() {
        assert_eq!(esc("<a & \"b\">"), "&lt;a &amp; &quot;b&quot;&gt;");
        let t = json_table(&[
            serde_json::json!({"angle": 90.0, "n": 3}),
            serde_json::json!({"angle": 180.5, "n": 4}),
        ]);
        assert!(t.contains("<th>angle</th><th>n</th>"), "{t}");
        assert!(t.contains("<td>180.500000</td><td>4</td>"), "{t}");
        let p = page("a < b", "<p>x</p>");
        assert!(p.starts_with("<!DOCTYPE html>") && p.contains("<title>a &lt; b</title>"));
        assert!((near(359.9, 0.0) + 0.1).abs() < 1e-9);
        assert!((near(1.0, 358.0) - 361.0).abs() < 1e-9);
        assert!((near(90.0, 80.0) - 90.0).abs() < 1e-9);
    }
}
