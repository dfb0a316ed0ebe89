//! The verdict of a free-running run: the device's figures against the truth (the scenario's,
//! and the table's as it reported itself) and against its budget, the checks, what the bench
//! could not judge.

use crate::check::Check;
use crate::free::observe::Observed;
use crate::free::score::{self, DriveScore, Epoch, HeadingScore};
use crate::free::{FreeOptions, FreeReport, Judged, is_drill};
use crate::scenario::Scenario;
use emulators::drive::Drive;
use emulators::reported::SharedTrack;

/// The truth a device is judged against.
struct Truth<'a> {
    s: &'a Scenario,
    plan: Option<Drive>,
    table: Option<SharedTrack>,
}

impl<'a> Truth<'a> {
    fn new(s: &'a Scenario, tracks: &[SharedTrack]) -> Self {
        Self {
            s,
            plan: s.drive.as_ref().and_then(|d| Drive::plan(d).ok()),
            table: tracks.first().cloned(),
        }
    }

    /// The end of IMU sample `k`, s.
    fn t_of(&self, k: u64) -> f64 {
        (k + 1) as f64 / self.s.imu.rate_hz
    }

    /// The IMU's heading at `t`: the vehicle's less the table's angle (it turns
    /// counter-clockwise), deg.
    fn heading_deg(&self, t: f64) -> f64 {
        let vehicle = match &self.plan {
            Some(p) => p.heading(t).to_degrees(),
            None => self.s.truth_heading_deg(),
        };
        let table = self.table.as_ref().map_or(0.0, |tr| {
            tr.lock()
                .unwrap_or_else(|e| e.into_inner())
                .eval(t)
                .0
                .to_degrees()
        });
        vehicle - table
    }

    /// Along a drive: the device's position error (east, north, m) at `t` and the truth's
    /// horizontal velocity.
    fn drive_error(plan: &Drive, t: f64, p: [f64; 3]) -> ([f64; 2], [f64; 2]) {
        let (lat, lon, h) = plan.position(t);
        let d = emulators::geodesy::enu_offset(
            (lat, lon, h),
            (p[0].to_radians(), p[1].to_radians(), p[2]),
        );
        let v = plan.velocity(t);
        ([d[0], d[1]], [v.x, v.y])
    }

    /// A drill stands at the site: the horizontal distance of the epoch's position from the
    /// site's surveyed position, m, with its PosSigma.
    fn site_error(&self, at: &Epoch) -> Option<(f64, Option<f64>)> {
        let p = at.pos?;
        let site = &self.s.site;
        let d = emulators::geodesy::enu_offset(
            (
                site.lat_deg.to_radians(),
                site.lon_deg.to_radians(),
                site.height_m,
            ),
            (p[0].to_radians(), p[1].to_radians(), site.height_m),
        );
        let sigma = at.hgt.map(|g| g[1]).filter(|x| *x > 0.0 && *x < 655.0);
        Some((d[0].hypot(d[1]), sigma))
    }
}

/// The verdict: the device's figures against truth and its budget, unless the bench fell
/// behind real time.
pub(crate) fn judge(s: &Scenario, o: &FreeOptions, j: Judged, seen: Observed) -> FreeReport {
    let truth = Truth::new(s, &j.tracks);
    let e = &seen.epochs;
    let (latency, unnamed) = score::stated_latency(e);
    let heading = s
        .north_finding
        .as_ref()
        .and_then(|_| score::drill_heading(e, |k| truth.heading_deg(truth.t_of(k))));
    let offset = score::time_tag_offset(e, |t| truth.heading_deg(t), |k| truth.t_of(k));
    let navigation = match (&truth.plan, is_drill(s), &o.real_gps) {
        (Some(plan), false, None) => {
            score::drive(e, |t, p| Truth::drive_error(plan, t, p), |k| truth.t_of(k))
        }
        _ => None,
    };
    let site_error = heading.and_then(|h| {
        let at = e
            .iter()
            .find(|x| x.sample.is_some_and(|(k, _)| k == h.sample))?;
        truth.site_error(at)
    });
    let mut checks = device_checks(o, &j, &seen, (latency, unnamed));
    let mut not_judged = Vec::new();
    let scores = Scores {
        heading,
        navigation,
        site_error,
        offset,
    };
    truth_checks(s, o, &truth, &scores, &mut checks, &mut not_judged);
    let behind = j.stats.iter().find_map(|st| st.behind.clone());
    let pass = behind.is_none() && checks.iter().all(|c| c.pass);
    let mut real = Vec::new();
    if o.real_turntable {
        real.push(format!("turntable on {}", o.iface));
    }
    if let Some(p) = &o.real_gps {
        real.push(format!("receiver on {}", p.display()));
    }
    FreeReport {
        scenario: s.name.clone(),
        interface: o.iface.clone(),
        device: j.device,
        device_exit: j.device_exit,
        ended: j.ended,
        wall_s: j.wall_s,
        bench: j.stats,
        bench_behind: behind,
        real,
        epochs: e.len() as u64,
        latency,
        unnamed_samples: unnamed,
        rate: score::rate(e),
        heading,
        navigation,
        time_tag_offset: offset,
        backwards: score::backwards(e).0,
        outside_dbc: seen.outside_dbc.clone(),
        commands: seen.commands,
        receiver_bytes: seen.receiver_bytes,
        site_error,
        not_judged,
        checks,
        pass,
    }
}

/// What the device did, whatever the truth: it answered, it ran to the end, its latency, its
/// frames, its time tags' order.
fn device_checks(
    o: &FreeOptions,
    j: &Judged,
    seen: &Observed,
    (latency, unnamed): (score::Spread, u64),
) -> Vec<Check> {
    let e = &seen.epochs;
    let (backwards, first_back, swapped) = score::backwards(e);
    vec![
        Check {
            name: "the device answered".into(),
            pass: !e.is_empty(),
            detail: match e.first() {
                Some(f) => format!(
                    "first NAV_TIME {:.2} s after the stream started; {} epochs",
                    f.rx_s,
                    e.len()
                ),
                None => format!("no NAV_TIME at all ({})", j.ended),
            },
        },
        Check {
            name: "the device ran to the end".into(),
            pass: !j.ended.contains("device under test exited")
                && !j.device_exit.starts_with("ended before"),
            detail: format!("{}; the device {}", j.ended, j.device_exit),
        },
        Check {
            name: "latency within the budget".into(),
            pass: latency.count > 0 && latency.p99_ms <= o.latency_budget_ms,
            detail: format!(
                "IMU sample on the bus to the NAV_TIME naming it: median {:.1} ms, p99 {:.1} ms, worst {:.1} ms over {} epochs ({unnamed} named no sample sent); budget p99 {} ms",
                latency.p50_ms, latency.p99_ms, latency.max_ms, latency.count, o.latency_budget_ms
            ),
        },
        Check {
            name: "frames within the DBC".into(),
            pass: seen.outside_count() == 0,
            detail: if seen.outside_dbc.is_empty() {
                "every frame heard is defined by wire/bench.dbc".into()
            } else {
                seen.outside_dbc
                    .iter()
                    .map(|(w, n)| format!("{n} x {w}"))
                    .collect::<Vec<_>>()
                    .join("; ")
            },
        },
        Check {
            name: "time tags never go backwards".into(),
            pass: backwards == 0,
            detail: match first_back {
                Some((a, b)) => format!(
                    "{backwards} of {} NAV_TIMEs named a sample before the one before them; the first from sample {a} to {b}",
                    e.len()
                ),
                None if swapped > 0 => format!(
                    "{} NAV_TIMEs in order; {swapped} pair(s) of neighbours heard swapped, as vcan's per-CPU queues deliver a device's frames when it moves between CPUs (not counted)",
                    e.len()
                ),
                None => format!("{} NAV_TIMEs in order", e.len()),
            },
        },
    ]
}

/// The device's solution scored against the truth.
#[derive(Clone, Copy)]
struct Scores {
    heading: Option<HeadingScore>,
    navigation: Option<DriveScore>,
    site_error: Option<(f64, Option<f64>)>,
    offset: Option<(f64, usize)>,
}

/// What the device's solution says against the truth: the drill's heading and position, the
/// drive, its time tags; and what the bench cannot judge.
fn truth_checks(
    s: &Scenario,
    o: &FreeOptions,
    truth: &Truth,
    sc: &Scores,
    checks: &mut Vec<Check>,
    not_judged: &mut Vec<String>,
) {
    let Scores {
        heading,
        navigation,
        site_error,
        offset,
    } = *sc;
    let drive = s.drive.is_some() && !is_drill(s);
    if s.north_finding.is_some() {
        checks.push(heading_check(heading, |k| truth.t_of(k)));
    }
    if drive && o.real_gps.is_some() {
        not_judged.push("position along the drive: the real receiver's fixes steer it, and the bench has no truth for where that receiver was".into());
    } else if drive {
        checks.push(navigation_check(s, navigation));
    }
    // a device that only finds north owes no position
    match (is_drill(s) && s.drive.is_some(), site_error) {
        (true, Some(err)) => checks.push(site_check(s, err)),
        (true, None) => not_judged.push(
            "the position at the drill's end: the device sent none (NAV_POS) with its heading"
                .into(),
        ),
        _ => {}
    }
    match offset {
        Some((tau, n)) => checks.push(Check {
            name: "time tags agree with the data".into(),
            pass: tau.abs() <= 1.0 / 50.0,
            detail: format!(
                "its headings line up with the truth {:+.0} ms from the samples they name ({n} epochs while turning); limit one output period, 20 ms",
                tau * 1e3
            ),
        }),
        None => not_judged.push("the device's latency from its data: it sent no attitude while the table or the vehicle turned (fewer than 10 epochs)".into()),
    }
    if o.real_gps.is_some() {
        not_judged.push("the real receiver's fixes themselves: the bench's only truth for them is the site's surveyed position".into());
    }
}

fn heading_check(heading: Option<HeadingScore>, t_of: impl Fn(u64) -> f64) -> Check {
    Check {
        name: "heading at the drill's end within 3 of the device's sigmas".into(),
        pass: heading.is_some_and(|h| h.in_sigmas().is_some_and(|x| x.abs() <= 3.0)),
        detail: match heading {
            Some(h) => format!(
                "{:.4} deg at sample {} ({:.2} s), truth {:.4}, error {:+.4} deg{}",
                h.heading_deg,
                h.sample,
                t_of(h.sample),
                h.truth_deg,
                h.error_deg,
                match (h.sigma_deg, h.in_sigmas()) {
                    (Some(sg), Some(x)) => format!(" = {x:+.2} sigma ({sg:.4} deg)"),
                    _ => ", no sigma sent (NAV_HGT's HeadingSigma)".into(),
                }
            ),
            None => "the device sent no heading (NAV_ATT) after north-finding".into(),
        },
    }
}

fn navigation_check(s: &Scenario, navigation: Option<DriveScore>) -> Check {
    Check {
        name: "navigation error within tolerance".into(),
        pass: navigation.is_some_and(|n| n.last_m <= s.position_tolerance_m),
        detail: match navigation {
            Some(n) => format!(
                "at {:.1} s: horizontal {:.2} m (limit {} m); along the drive RMS {:.2} m, worst {:.2} m, velocity RMS {:.3} m/s over {} epochs; position NEES per dof {}",
                n.last_t_s,
                n.last_m,
                s.position_tolerance_m,
                n.rms_m,
                n.max_m,
                n.vel_rms_mps,
                n.epochs,
                n.nees
                    .map_or("-- (no PosSigma sent)".into(), |x| format!("{x:.2}"))
            ),
            None => "the device sent no position (NAV_POS) while navigating".into(),
        },
    }
}

fn site_check(s: &Scenario, (d, sg): (f64, Option<f64>)) -> Check {
    Check {
        name: "position at the drill's end within 3 of its sigmas of the site".into(),
        pass: d <= sg.map_or(s.position_tolerance_m, |x| 3.0 * x),
        detail: format!(
            "{d:.2} m from the site's surveyed position ({:.6}, {:.6}){}",
            s.site.lat_deg,
            s.site.lon_deg,
            sg.map_or(
                format!(", no PosSigma sent: limit {} m", s.position_tolerance_m),
                |x| format!(", PosSigma {x:.2} m ({:.2} sigma)", d / x)
            )
        ),
    }
}
