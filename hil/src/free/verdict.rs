//! The verdict of a free-running run: the device's figures against the truth (the scenario's,
//! and the table's as it reported itself) and against its budget, the checks, what the bench
//! could not judge.

use crate::check::Check;
use crate::free::clock::{self, DataOffset, Lead};
use crate::free::listener::Observed;
use crate::free::score::{self, DriveScore, Epoch, HeadingScore, Spread};
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

    /// The end of IMU sample `k` (tick `k + 1` of its oscillator), s.
    fn t_of(&self, k: u64) -> f64 {
        self.s.imu.oscillator().tick_time(k + 1)
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

/// The device's timing: its latency (and what of it the host could explain), its samples
/// named ahead, its output period, s.
struct Timing {
    latency: Spread,
    own: Spread,
    unnamed: u64,
    lead: Lead,
    period_s: f64,
}

impl Timing {
    fn of(
        s: &Scenario,
        o: &FreeOptions,
        e: &[Epoch],
        host: &crate::free::probe::HostDelays,
    ) -> Self {
        let (latency, unnamed) = score::stated_latency(e);
        let lat: Vec<(f64, f64)> = e
            .iter()
            .filter_map(|x| x.sample.map(|(_, at)| (x.rx_s, x.rx_s - at)))
            .collect();
        let own = Spread::of(host.unexplained_ms(&lat, o.latency_budget_ms * 1e-3));
        let step = score::rate(e).step_samples;
        let period_s = if step > 0 && step < 1 << 16 {
            f64::from(step) / s.imu.rate_hz
        } else {
            0.02
        };
        Self {
            latency,
            own,
            unnamed,
            lead: clock::lead(e),
            period_s,
        }
    }
}

/// The verdict: the device's figures against truth and its budget, unless the bench fell
/// behind real time.
pub(crate) fn judge(s: &Scenario, o: &FreeOptions, j: Judged, seen: Observed) -> FreeReport {
    let truth = Truth::new(s, &j.tracks);
    let e = &seen.epochs;
    let timing = Timing::of(s, o, e, &j.host);
    let heading = s
        .north_finding
        .as_ref()
        .and_then(|_| score::drill_heading(e, |k| truth.heading_deg(truth.t_of(k))));
    let offset = clock::data_offset(e, |t| truth.heading_deg(t), |k| truth.t_of(k));
    let navigation = match (&truth.plan, is_drill(s), &o.real_gps) {
        (Some(plan), false, None) => {
            score::drive(e, |t, p| Truth::drive_error(plan, t, p), |k| truth.t_of(k))
        }
        _ => None,
    };
    let site_error = heading.as_ref().and_then(|h| {
        let at = e
            .iter()
            .find(|x| x.sample.is_some_and(|(k, _)| k == h.sample))?;
        truth.site_error(at)
    });
    let mut not_judged = Vec::new();
    let mut checks = device_checks(o, &j, &seen, &timing, &mut not_judged);
    let scores = Scores {
        heading: heading.clone(),
        navigation,
        site_error,
        offset: offset.clone(),
        period_s: timing.period_s,
        over_range: j
            .stats
            .iter()
            .filter_map(|st| st.imu.as_ref())
            .map(|i| i.over_range_samples)
            .sum(),
    };
    truth_checks(s, o, &truth, &scores, &mut checks, &mut not_judged);
    let behind = j.stats.iter().find_map(|st| st.behind.clone()).or_else(|| {
        // a device stopped at its limit says so; one late beyond it at its last write (as it
        // stopped) is late all the same
        j.stats
            .iter()
            .find(|st| st.lateness.max_ms > o.max_late_ms)
            .map(|st| {
                format!(
                    "the bench's {} was {:.1} ms late at worst (limit {:.0} ms): the host could not keep real time",
                    st.device, st.lateness.max_ms, o.max_late_ms
                )
            })
    });
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
        contract: o.lab.as_ref().map_or_else(
            || "wire/bench.dbc".to_string(),
            |l| format!("{} (through {})", l.dbc_name, l.path.display()),
        ),
        device: j.device,
        device_exit: j.device_exit,
        ended: j.ended,
        wall_s: j.wall_s,
        bench: j.stats,
        bench_behind: behind,
        real,
        epochs: e.len() as u64,
        latency: timing.latency,
        latency_own: timing.own,
        unnamed_samples: timing.unnamed,
        lead: timing.lead,
        clock: clock::clock_fit(e, 1.0 / s.imu.rate_hz),
        host: j.host.summary,
        stamps: seen.stamps.words().into(),
        reordered: seen.reordered,
        rate: score::rate(e),
        heading,
        navigation,
        data_offset: offset,
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
/// samples named ahead, its frames, its time tags' order. A check the run cannot decide goes
/// to `not_judged`, with why.
fn device_checks(
    o: &FreeOptions,
    j: &Judged,
    seen: &Observed,
    t: &Timing,
    not_judged: &mut Vec<String>,
) -> Vec<Check> {
    let e = &seen.epochs;
    let w = Words::of(o);
    let (backwards, first_back, swapped) = score::backwards(e);
    let mut checks = vec![
        Check {
            name: "the device answered".into(),
            pass: !e.is_empty(),
            detail: match e.first() {
                Some(f) => format!(
                    "first {} {:.2} s after the stream started; {} epochs",
                    w.epoch,
                    f.rx_s,
                    e.len()
                ),
                None => format!("no {} at all ({})", w.epoch, j.ended),
            },
        },
        Check {
            name: "the device ran to the end".into(),
            pass: !j.ended.contains("device under test exited")
                && !j.device_exit.starts_with("ended before"),
            detail: format!("{}; the device {}", j.ended, j.device_exit),
        },
    ];
    checks.extend(latency_check(o, j, t, not_judged));
    checks.extend(lead_check(o, t, e.is_empty()));
    let dbc = o
        .lab
        .as_ref()
        .map_or("wire/bench.dbc", |l| l.dbc_name.as_str());
    checks.push(Check {
        name: "frames within the DBC".into(),
        pass: seen.outside_count() == 0,
        detail: if seen.outside_dbc.is_empty() {
            format!("every frame heard is defined by {dbc}")
        } else {
            seen.outside_dbc
                .iter()
                .map(|(w, n)| format!("{n} x {w}"))
                .collect::<Vec<_>>()
                .join("; ")
        },
    });
    if o.lab.is_some() {
        checks.push(protection_check(seen));
    }
    checks.push(Check {
        name: "time tags never go backwards".into(),
        pass: backwards == 0,
        detail: match first_back {
            Some((a, b)) => format!(
                "{backwards} of {} {}s named a sample before the one before them; the first from sample {a} to {b}",
                e.len(),
                w.epoch
            ),
            None if swapped > 0 => format!(
                "{} {}s in order; {swapped} pair(s) of neighbours heard swapped (not counted)",
                e.len(),
                w.epoch
            ),
            None => format!("{} {}s in order", e.len(), w.epoch),
        },
    });
    checks
}

/// The latency check: none (said in `not_judged`) where no epoch could be judged, or where the
/// host's delays beside the device explain its excess over the budget.
fn latency_check(
    o: &FreeOptions,
    j: &Judged,
    t: &Timing,
    not_judged: &mut Vec<String>,
) -> Option<Check> {
    let (l, own) = (&t.latency, &t.own);
    let w = Words::of(o);
    let name = "latency within the budget";
    let over = format!(
        "IMU sample on the bus to the {} naming it: median {:.1} ms, p99 {:.1} ms, worst {:.1} ms over {} epochs ({} named samples ahead of the stream, {} named none the bench could place); budget p99 {} ms",
        w.epoch,
        l.p50_ms,
        l.p99_ms,
        l.max_ms,
        l.count,
        t.lead.epochs,
        t.unnamed,
        o.latency_budget_ms
    );
    if l.count == 0 {
        if !j.ended.contains(&format!("no {}", w.epoch)) && t.unnamed > 0 {
            not_judged.push(format!(
                "{name}: none of the {} {}s named a sample the bench could place (older than the half counter period it keeps)",
                t.unnamed, w.epoch
            ));
            return None;
        }
        return Some(Check {
            name: name.into(),
            pass: false,
            detail: over,
        });
    }
    let h = &j.host.summary;
    let bench_p99 = j
        .stats
        .iter()
        .map(|st| st.lateness.p99_ms)
        .fold(0.0, f64::max);
    if l.p99_ms > o.latency_budget_ms && own.p99_ms <= o.latency_budget_ms {
        not_judged.push(format!(
            "{name}: {over}; but a thread beside it was held by the host up to {:.1} ms (p99 {:.2} ms), and less what the host held it of each epoch its p99 is {:.1} ms: the host could explain it",
            h.max_ms, h.p99_ms, own.p99_ms
        ));
        return None;
    }
    if l.p99_ms > o.latency_budget_ms && h.p99_ms.max(bench_p99) >= HOST_STRAINED_MS {
        not_judged.push(format!(
            "{name}: {over}; but the host kept neither the bench's own devices (lateness p99 {bench_p99:.1} ms) nor a thread beside the device (p99 {:.1} ms) to within {HOST_STRAINED_MS} ms: a device short of CPU falls behind by more than any one delay, and the host could explain it",
            h.p99_ms
        ));
        return None;
    }
    Some(Check {
        name: name.into(),
        pass: l.p99_ms <= o.latency_budget_ms,
        detail: if l.p99_ms > o.latency_budget_ms {
            format!(
                "{over}; less what the host held it of each (its own share) p99 {:.1} ms",
                own.p99_ms
            )
        } else {
            over
        },
    })
}

/// The bench's own lateness or the probe's (p99) from which the host is short of CPU for a
/// device beside it, ms: five times what an idle emulated guest shows (p99 2-6 ms); a loaded
/// one shows 30-100 ms, and a device that needs most of a CPU then falls seconds behind.
const HOST_STRAINED_MS: f64 = 25.0;

/// NAV_TIMEs that named samples the bench had not sent: within the device's allowance (by
/// default one output period), or a failure with the figures.
fn lead_check(o: &FreeOptions, t: &Timing, silent: bool) -> Option<Check> {
    if silent {
        return None;
    }
    let allow = o.lead_allowance_ms.unwrap_or(t.period_s * 1e3);
    let l = &t.lead;
    Some(Check {
        name: "no sample named ahead of the stream beyond the allowance".into(),
        pass: l.max_ms <= allow,
        detail: match l.first_at_s {
            None => format!(
                "none of {} epochs named a sample before it went on the bus; allowance {allow:.1} ms",
                l.of
            ),
            Some(first) => format!(
                "{} of {} epochs named a sample before it went on the bus (scored as predictions), the first at {first:.2} s, the farthest {:.1} ms ahead at {:.2} s; allowance {allow:.1} ms{}",
                l.epochs,
                l.of,
                l.max_ms,
                l.max_at_s,
                if o.lead_allowance_ms.is_none() {
                    " (one output period)"
                } else {
                    ""
                }
            ),
        },
    })
}

/// The device's solution scored against the truth.
struct Scores {
    heading: Option<HeadingScore>,
    navigation: Option<DriveScore>,
    site_error: Option<(f64, Option<f64>)>,
    offset: Option<DataOffset>,
    /// The device's output period, s.
    period_s: f64,
    /// Samples the bench's IMU clamped at its range: the gyros did not read the truth there.
    over_range: u64,
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
        period_s,
        over_range,
    } = sc;
    let (navigation, site_error) = (*navigation, *site_error);
    let drive = s.drive.is_some() && !is_drill(s);
    if s.north_finding.is_some() {
        checks.push(heading_check(
            heading.as_ref(),
            |k| truth.t_of(k),
            &Words::of(o),
        ));
    }
    if drive && o.real_gps.is_some() {
        not_judged.push("position along the drive: the real receiver's fixes steer it, and the bench has no truth for where that receiver was".into());
    } else if drive {
        checks.push(navigation_check(s, navigation, &Words::of(o)));
    }
    // a device that only finds north owes no position
    match (is_drill(s) && s.drive.is_some(), site_error) {
        (true, Some(err)) => checks.push(site_check(s, err)),
        (true, None) => not_judged.push(format!(
            "the position at the drill's end: the device sent none ({}) with its heading",
            Words::of(o).position
        )),
        _ => {}
    }
    match data_check(offset.as_ref(), *period_s) {
        // the truth then turned faster than the gyros could read: a heading that follows them
        // is not older than its tag
        Ok(_) if *over_range > 0 => not_judged.push(format!(
            "time tags agree with the data: the bench's IMU was driven beyond its range on {over_range} samples (clamped): its gyros did not read the truth the device is judged against"
        )),
        Ok(c) => checks.push(c),
        Err(why) => not_judged.push(format!("time tags agree with the data: {why}")),
    }
    if o.real_gps.is_some() {
        not_judged.push("the real receiver's fixes themselves: the bench's only truth for them is the site's surveyed position".into());
    }
}

/// The device's data against its tags, turn by turn: each turn's offset within one output
/// period; a turn whose offset is uncertain by more than half of it is not judged. Why not, as
/// the error.
fn data_check(offset: Option<&DataOffset>, period_s: f64) -> Result<Check, String> {
    let limit = period_s * 1e3;
    let Some(d) = offset else {
        return Err("it sent no attitude while the table or the vehicle turned (no turn of 10 epochs with 5 turning)".into());
    };
    let (judged, vague): (Vec<&clock::Turn>, Vec<&clock::Turn>) = d
        .turns
        .iter()
        .partition(|t| t.offset_ms.sigma <= 0.5 * limit);
    let Some(worst) = judged
        .iter()
        .max_by(|a, b| a.offset_ms.value.abs().total_cmp(&b.offset_ms.value.abs()))
    else {
        return Err(format!(
            "no turn tells its offset to within half an output period ({:.1} ms): {}",
            0.5 * limit,
            d.turns
                .iter()
                .map(|t| format!("{:.1} s {}", t.t_s, t.offset_ms.words(1, "ms")))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    };
    Ok(Check {
        name: "time tags agree with the data".into(),
        pass: worst.offset_ms.value.abs() <= limit,
        detail: format!(
            "its headings belong to {} before the samples they name over {} turns ({} epochs){}; the farthest {} at {:.1} s; {}limit one output period, {limit:.0} ms",
            d.offset_ms.words(1, "ms"),
            judged.len(),
            d.epochs,
            d.drift_ppm.map_or(String::new(), |x| format!(
                ", drifting {} against them",
                x.words(0, "ppm")
            )),
            worst.offset_ms.words(1, "ms"),
            worst.t_s,
            if vague.is_empty() {
                String::new()
            } else {
                format!("{} turns too uncertain to judge; ", vague.len())
            }
        ),
    })
}

fn heading_check(heading: Option<&HeadingScore>, t_of: impl Fn(u64) -> f64, w: &Words) -> Check {
    Check {
        name: "heading at the drill's end within 3 of the device's sigmas".into(),
        pass: heading.is_some_and(|h| h.in_sigmas().is_some_and(|x| x.abs() <= 3.0)),
        detail: match heading {
            Some(h) => format!(
                "{:.4} deg at sample {} ({:.2} s; epoch {}, Seq {}, mode {}, {}, heard {:.2} s in), truth {:.4}, error {:+.4} deg{}",
                h.heading_deg,
                h.sample,
                t_of(h.sample),
                h.epoch,
                h.seq,
                h.mode,
                if h.after_finding {
                    "the first after north-finding"
                } else {
                    "its last: it never said it was finding north"
                },
                h.rx_s,
                h.truth_deg,
                h.error_deg,
                match (h.sigma_deg, h.in_sigmas()) {
                    (Some(sg), Some(x)) => format!(" = {x:+.2} sigma ({sg:.4} deg)"),
                    _ => format!(", no sigma sent ({})", w.sigma),
                }
            ),
            None => format!(
                "the device sent no heading ({}) with a sample the bench could place after its mode left north-finding",
                w.attitude
            ),
        },
    }
}

fn navigation_check(s: &Scenario, navigation: Option<DriveScore>, w: &Words) -> Check {
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
            None => format!(
                "the device sent no position ({}) while navigating",
                w.position
            ),
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

/// On a lab's contract: every protected frame the device sent had its checksum right and its
/// alive counter one up from the last; the faults by message and kind, the first of each.
fn protection_check(seen: &Observed) -> Check {
    let faults: u64 = seen.protection_faults.values().map(|(n, _)| n).sum();
    Check {
        name: "the device's checksums and alive counters hold".into(),
        pass: faults == 0,
        detail: if faults == 0 {
            format!(
                "{} protected frames from the device, every checksum right, every alive counter one up",
                seen.protected_checked
            )
        } else {
            let each: Vec<String> = seen
                .protection_faults
                .iter()
                .map(|(what, (n, first))| format!("{n} x {what} (the first: {first})"))
                .collect();
            format!(
                "{faults} of {} protected frames: {}",
                seen.protected_checked,
                each.join("; ")
            )
        },
    }
}

/// What the card calls the device's frames: ours, or the lab's messages by its mapping.
pub(crate) struct Words {
    /// The frame that opens an epoch and names its sample.
    pub(crate) epoch: String,
    /// The frame of the heading.
    pub(crate) attitude: String,
    /// The heading's sigma.
    pub(crate) sigma: String,
    /// The frame of the position.
    pub(crate) position: String,
}

impl Words {
    /// The words of the contract `o` runs on.
    pub(crate) fn of(o: &FreeOptions) -> Self {
        let Some(s) = o
            .lab
            .as_ref()
            .and_then(|l| l.mapping.file.solution.as_ref())
        else {
            return Self {
                epoch: "NAV_TIME".into(),
                attitude: "NAV_ATT".into(),
                sigma: "NAV_HGT's HeadingSigma".into(),
                position: "NAV_POS".into(),
            };
        };
        Self {
            epoch: s.message.clone(),
            attitude: s.message.clone(),
            sigma: s.heading_sigma.as_ref().map_or_else(
                || "the mapping has no heading_sigma".into(),
                |h| format!("{}'s {h}", s.message),
            ),
            position: s.position.as_ref().map_or_else(
                || "the mapping has no [solution.position]".into(),
                |p| p.message.clone(),
            ),
        }
    }
}
