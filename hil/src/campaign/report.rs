//! A campaign's merged report: every build's verdict on every case against the baseline, the
//! regressions first; as Markdown, a picture (a colour per verdict), JSON for scripts and JUnit
//! XML for a CI server (a suite per build, a case per campaign case, failing on a regression, a
//! flaky case or a missing result).

use super::against_baseline::{CaseVerdict, CellResult, Verdict, judge};
use super::cells::Cell;
use super::spec::{Campaign, Case};
use crate::junit;
use anyhow::Result;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::Path;

/// The merged campaign.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Merged {
    /// The campaign's name.
    pub campaign: String,
    /// The baseline device.
    pub baseline: String,
    /// Each other device's verdict on each case, device by device, case by case.
    pub verdicts: Vec<CaseVerdict>,
    /// Cells planned, and those with a result.
    pub cells: usize,
    /// See [`Merged::cells`].
    pub cells_done: usize,
}

impl Merged {
    /// The matrix's columns and rows: the devices and the cases, each once, in the verdicts'
    /// order.
    fn axes(&self) -> (Vec<&str>, Vec<&str>) {
        let mut devices: Vec<&str> = Vec::new();
        let mut cases: Vec<&str> = Vec::new();
        for v in &self.verdicts {
            if !devices.contains(&v.device.as_str()) {
                devices.push(&v.device);
            }
            if !cases.contains(&v.case.as_str()) {
                cases.push(&v.case);
            }
        }
        (devices, cases)
    }

    /// The exit status: 1 on a regression or a flaky case, 2 when results are missing (the
    /// campaign is not finished), 0 otherwise.
    pub fn exit_status(&self) -> i32 {
        let any = |v: Verdict| self.verdicts.iter().any(|c| c.verdict == v);
        if any(Verdict::Worse) || any(Verdict::Flaky) {
            1
        } else if any(Verdict::Missing) || self.cells_done < self.cells {
            2
        } else {
            0
        }
    }
}

/// Merge the results of a campaign's cells into verdicts.
pub fn merge(c: &Campaign, cases: &[Case], cells: &[Cell], results: &[CellResult]) -> Merged {
    let of = |device: &str, case: &str| -> Vec<CellResult> {
        results
            .iter()
            .filter(|r| r.device == device && r.case == case)
            .cloned()
            .collect()
    };
    let mut verdicts = Vec::new();
    for d in c.devices.iter().filter(|d| d.name != c.baseline) {
        for k in cases {
            let mut v = judge(&k.id, &of(&c.baseline, &k.id), &of(&d.name, &k.id));
            v.device = d.name.clone();
            verdicts.push(v);
        }
    }
    Merged {
        campaign: c.name.clone(),
        baseline: c.baseline.clone(),
        verdicts,
        cells: cells.len(),
        cells_done: results.len(),
    }
}

fn mark(v: Verdict) -> &'static str {
    match v {
        Verdict::Worse => "WORSE",
        Verdict::Flaky => "FLAKY",
        Verdict::Missing => "missing",
        Verdict::Better => "better",
        Verdict::NotDistinguishable => "~",
        Verdict::Same => "same",
    }
}

/// The report as Markdown: the regressions with their figures, then the matrix of builds by
/// cases (each entry linking to the build's first cell of the case).
pub fn markdown(m: &Merged, cells: &[Cell]) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "# Campaign {}: against {}\n", m.campaign, m.baseline);
    let _ = writeln!(o, "{} of {} cells ran.\n", m.cells_done, m.cells);
    let mut bad: Vec<&CaseVerdict> = m
        .verdicts
        .iter()
        .filter(|v| {
            matches!(
                v.verdict,
                Verdict::Worse | Verdict::Flaky | Verdict::Missing
            )
        })
        .collect();
    bad.sort_by_key(|v| v.verdict);
    let _ = writeln!(o, "## Regressions, flaky and missing\n");
    if bad.is_empty() {
        let _ = writeln!(o, "None.\n");
    }
    for v in &bad {
        let _ = writeln!(
            o,
            "- **{}** {} on {}: {}",
            mark(v.verdict),
            v.device,
            v.case,
            v.why
        );
        for f in v
            .figures
            .iter()
            .filter(|f| f.verdict == Verdict::Worse || v.verdict == Verdict::Flaky)
        {
            let _ = writeln!(
                o,
                "  - {}: {:.4} against {:.4} ({}difference {:+.4} ± {})",
                f.name,
                f.build,
                f.baseline,
                if f.paired { "seed by seed, " } else { "" },
                f.difference,
                f.interval.map_or("-".into(), |h| format!("{h:.4}"))
            );
        }
    }
    let (devices, cases) = m.axes();
    let _ = writeln!(o, "\n## Every build on every case\n");
    let _ = writeln!(o, "| case | {} |", devices.join(" | "));
    let _ = writeln!(o, "|---|{}", "---|".repeat(devices.len()));
    for k in &cases {
        let row: Vec<String> = devices
            .iter()
            .map(|d| {
                let v = m.verdicts.iter().find(|v| v.device == *d && v.case == *k);
                let link = cells
                    .iter()
                    .find(|c| c.device == *d && c.case == *k)
                    .map(|c| format!("cells/{}/", c.key));
                match (v, link) {
                    (Some(v), Some(l)) => format!("[{}]({l})", mark(v.verdict)),
                    (Some(v), None) => mark(v.verdict).to_string(),
                    _ => String::new(),
                }
            })
            .collect();
        let _ = writeln!(o, "| {k} | {} |", row.join(" | "));
    }
    o
}

/// The matrix as a picture: a row per case, a column per build, a colour per verdict.
pub fn svg(m: &Merged) -> String {
    let (devices, cases) = m.axes();
    let (left, top, w, h) = (260.0, 40.0, 140.0, 26.0);
    let width = (left + w * devices.len() as f64 + 10.0).max(640.0);
    let height = top + h * cases.len() as f64 + 34.0;
    let mut o = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
    );
    for (j, d) in devices.iter().enumerate() {
        let _ = writeln!(
            o,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>",
            left + w * (j as f64 + 0.5),
            top - 12.0,
            xml(d)
        );
    }
    for (i, k) in cases.iter().enumerate() {
        let y = top + h * i as f64;
        let _ = writeln!(o, "<text x=\"6\" y=\"{}\">{}</text>", y + 17.0, xml(k));
        for (j, d) in devices.iter().enumerate() {
            let Some(v) = m.verdicts.iter().find(|v| v.device == *d && v.case == *k) else {
                continue;
            };
            let fill = match v.verdict {
                Verdict::Worse => "#d73027",
                Verdict::Flaky => "#fc8d59",
                Verdict::Missing => "#bdbdbd",
                Verdict::Better => "#1a9850",
                Verdict::NotDistinguishable => "#e0f3f8",
                Verdict::Same => "#91bfdb",
            };
            let x = left + w * j as f64;
            let _ = writeln!(
                o,
                "<rect x=\"{x}\" y=\"{y}\" width=\"{}\" height=\"{}\" fill=\"{fill}\" stroke=\"white\"><title>{}</title></rect>\n<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>",
                w - 2.0,
                h - 2.0,
                xml(&v.why),
                x + w / 2.0,
                y + 17.0,
                mark(v.verdict)
            );
        }
    }
    let _ = writeln!(
        o,
        "<text x=\"6\" y=\"{}\" fill=\"#555\">red worse, orange flaky, grey missing, green better, pale not distinguishable, blue the same frames</text>",
        height - 10.0
    );
    o.push_str("</svg>\n");
    o
}

fn xml(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The verdicts as JUnit suites, one per build.
pub fn junit_suites(m: &Merged) -> Vec<junit::Suite> {
    let (devices, _) = m.axes();
    devices
        .iter()
        .map(|d| {
            let cases = m
                .verdicts
                .iter()
                .filter(|v| v.device == *d)
                .map(|v| {
                    let ok = !matches!(
                        v.verdict,
                        Verdict::Worse | Verdict::Flaky | Verdict::Missing
                    );
                    junit::Case::judged(
                        &format!("campaign.{}", m.campaign),
                        &v.case,
                        0.0,
                        ok,
                        format!("{}: {}", mark(v.verdict), v.why),
                        serde_json::to_string_pretty(&v.figures).unwrap_or_default(),
                    )
                })
                .collect();
            junit::Suite::new(&format!("{} against {}", d, m.baseline), 0.0, cases)
        })
        .collect()
}

/// Write report.md, report.svg, report.json and junit.xml into `out`.
pub fn write(out: &Path, m: &Merged, cells: &[Cell]) -> Result<()> {
    use anyhow::Context;
    let put = |name: &str, text: String| -> Result<()> {
        std::fs::write(out.join(name), text)
            .with_context(|| format!("writing {}", out.join(name).display()))
    };
    put("report.md", markdown(m, cells))?;
    put("report.svg", svg(m))?;
    put("report.json", serde_json::to_string_pretty(m)?)?;
    junit::write(
        &out.join("junit.xml"),
        &format!("campaign {}", m.campaign),
        &junit_suites(m),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::campaign::cells::{Build, cells};
    use crate::campaign::spec::tests::EXAMPLE;

    /// The example campaign's results: the `worse` build's scenario errors 30 % larger, its
    /// fault rows the same frames, one drill seed failing, the experiments not run.
    fn merged() -> (Merged, Vec<Cell>) {
        let c: Campaign = toml::from_str(EXAMPLE).expect("parses");
        let cases = c.cases().expect("cases");
        let builds = vec![
            Build {
                device: "release".into(),
                id: "aaaa".into(),
            },
            Build {
                device: "worse".into(),
                id: "bbbb".into(),
            },
        ];
        let cells = cells(&c, &cases, &builds).expect("cells");
        let results: Vec<CellResult> = cells
            .iter()
            .filter(|k| !k.case.starts_with("experiment"))
            .map(|k| {
                let worse = k.device == "worse";
                let x = 3.0 + 0.1 * k.seed as f64;
                CellResult {
                    device: k.device.clone(),
                    case: k.case.clone(),
                    seed: k.seed,
                    pass: Some(!(worse && k.case.starts_with("drill") && k.seed == 8)),
                    figures: [(
                        "rms_position_error_m".to_string(),
                        if worse && k.case.starts_with("scenario") {
                            1.3 * x
                        } else {
                            x
                        },
                    )]
                    .into_iter()
                    .collect(),
                    sent_hash: k.case.starts_with("fault").then(|| format!("h{}", k.seed)),
                }
            })
            .collect();
        (merge(&c, &cases, &cells, &results), cells)
    }

    #[test]
    fn the_merged_report_puts_regressions_first_and_fails_on_them() {
        let (m, cells) = merged();
        let verdict = |case: &str| {
            m.verdicts
                .iter()
                .find(|v| v.case == case)
                .map(|v| v.verdict)
        };
        assert_eq!(verdict("fault:imu-frames-dropped"), Some(Verdict::Same));
        assert_eq!(verdict("scenario:drive-gps"), Some(Verdict::Worse));
        assert_eq!(verdict("drill:north-finding"), Some(Verdict::Flaky));
        assert_eq!(verdict("experiment:north-finding"), Some(Verdict::Missing));
        assert_eq!((m.cells, m.cells_done), (26, 14));
        assert_eq!(m.exit_status(), 1);
        let md = markdown(&m, &cells);
        let regressions = md.find("## Regressions").expect("section");
        let matrix = md.find("## Every build").expect("section");
        let worse = md
            .find("**WORSE** worse on scenario:drive-gps")
            .expect("listed");
        assert!(regressions < worse && worse < matrix, "{md}");
        assert!(
            md.contains("rms_position_error_m: 4.0950 against 3.1500 (seed by seed"),
            "{md}"
        );
        assert!(
            md.contains("[same](cells/bbbb-fault_imu-frames-dropped-s0/)"),
            "{md}"
        );
        let svg = svg(&m);
        assert_eq!(svg.matches("<rect x=").count(), 6, "{svg}");
        assert!(svg.contains("#d73027") && svg.contains("#fc8d59") && svg.contains("#91bfdb"));
        let suites = junit_suites(&m);
        assert_eq!(suites.len(), 1);
        assert_eq!((suites[0].cases.len(), suites[0].failures()), (6, 4));
        let back: Merged =
            serde_json::from_str(&serde_json::to_string(&m).expect("json")).expect("reads back");
        assert_eq!(back, m);
    }
}
