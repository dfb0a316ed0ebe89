//! What a campaign's cells cost: each cell's wall time as it ran (kept beside its result in
//! `time.json`), by case, and what a campaign of many cells in the same mix would take on a
//! cluster of N nodes. Kept apart from the report: the verdicts do not depend on where or how
//! fast a cell ran, so a cluster's report and the local pool's are the same bytes.

use super::cells::Cell;
use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// How long a cell took, as it ran.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct CellTime {
    /// Wall time of the cell's run, s.
    pub wall_s: f64,
    /// Cells that ran side by side with it (`--jobs`).
    pub jobs: usize,
    /// Whether it ran on real vcan inside the QEMU guest (software emulation).
    pub guest: bool,
}

impl CellTime {
    /// Keep it in the cell's folder `dir`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let p = dir.join("time.json");
        std::fs::write(&p, serde_json::to_string(self)?)
            .with_context(|| format!("writing {}", p.display()))
    }
}

/// The cost of one case's cells.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct CaseCost {
    /// The case.
    pub case: String,
    /// Its cells with a time.
    pub cells: usize,
    /// Their mean wall time, s.
    pub mean_s: f64,
    /// The longest, s.
    pub max_s: f64,
}

/// The campaign's measured cost.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Cost {
    /// Per case, in the plan's order.
    pub cases: Vec<CaseCost>,
    /// Cells with a time.
    pub timed: usize,
    /// Their wall times added, s.
    pub total_s: f64,
    /// The most cells that ran side by side (`--jobs`).
    pub jobs: usize,
    /// Whether any ran in the QEMU guest.
    pub guest: bool,
}

impl Cost {
    /// The cells' times kept in `out` (a cell without `time.json`, run by an older hil or not
    /// yet, is left out).
    pub fn of(cells: &[Cell], out: &Path) -> Self {
        let mut cases: Vec<CaseCost> = Vec::new();
        let (mut timed, mut total_s, mut jobs, mut guest) = (0, 0.0, 1, false);
        for c in cells {
            let Some(t) = std::fs::read(c.folder(out).join("time.json"))
                .ok()
                .and_then(|b| serde_json::from_slice::<CellTime>(&b).ok())
            else {
                continue;
            };
            timed += 1;
            total_s += t.wall_s;
            jobs = jobs.max(t.jobs);
            guest |= t.guest;
            match cases.iter_mut().find(|k| k.case == c.case) {
                Some(k) => {
                    k.mean_s = (k.mean_s * k.cells as f64 + t.wall_s) / (k.cells + 1) as f64;
                    k.cells += 1;
                    k.max_s = k.max_s.max(t.wall_s);
                }
                None => cases.push(CaseCost {
                    case: c.case.clone(),
                    cells: 1,
                    mean_s: t.wall_s,
                    max_s: t.wall_s,
                }),
            }
        }
        Self {
            cases,
            timed,
            total_s,
            jobs,
            guest,
        }
    }

    /// Hours a campaign of `cells` cells in this mix takes on `nodes` nodes like this machine,
    /// each running as many cells side by side as ran here (none without timed cells).
    pub fn hours(&self, cells: usize, nodes: usize) -> Option<f64> {
        (self.timed > 0 && nodes > 0).then(|| {
            let per_cell = self.total_s / self.timed as f64;
            per_cell * cells as f64 / (nodes * self.jobs) as f64 / 3600.0
        })
    }

    /// The cost as Markdown: per case, then 1,000 cells on 1 to 64 nodes.
    pub fn markdown(&self) -> String {
        let mut s = String::from("# What the cells cost\n\n");
        if self.timed == 0 {
            s.push_str("No cell has its time yet (`time.json` beside its result).\n");
            return s;
        }
        s.push_str(&format!(
            "{} cells timed, {:.0} s of wall time in all, up to {} side by side{}.\n\n| case | cells | mean | longest |\n|---|---:|---:|---:|\n",
            self.timed,
            self.total_s,
            self.jobs,
            if self.guest {
                " (on vcan in the QEMU guest: software emulation, several times slower than a kernel with CAN)"
            } else {
                ""
            }
        ));
        for k in &self.cases {
            s.push_str(&format!(
                "| {} | {} | {:.1} s | {:.1} s |\n",
                k.case, k.cells, k.mean_s, k.max_s
            ));
        }
        s.push_str(
            "\nA campaign of 1,000 cells in this mix on nodes like this machine (each running as many cells side by side), the cells' own time only:\n\n| nodes | hours |\n|---:|---:|\n",
        );
        for n in [1, 4, 16, 64] {
            if let Some(h) = self.hours(1000, n) {
                s.push_str(&format!("| {n} | {h:.2} |\n"));
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cost_adds_the_cells_times_and_scales_to_a_cluster() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cell = |n: usize, case: &str| Cell {
            number: n,
            device: "d".into(),
            build: "b".into(),
            case: case.into(),
            seed: n as u64,
            key: format!("k{n}"),
        };
        let cells = [cell(0, "a"), cell(1, "a"), cell(2, "b"), cell(3, "b")];
        for (c, wall_s) in cells.iter().zip([10.0, 20.0, 60.0]) {
            let d = c.folder(dir.path());
            std::fs::create_dir_all(&d).expect("folder");
            CellTime {
                wall_s,
                jobs: 2,
                guest: true,
            }
            .write(&d)
            .expect("written");
        }
        let k = Cost::of(&cells, dir.path());
        assert_eq!((k.timed, k.total_s, k.jobs, k.guest), (3, 90.0, 2, true));
        assert_eq!(k.cases.len(), 2);
        assert_eq!((k.cases[0].mean_s, k.cases[0].max_s), (15.0, 20.0));
        assert_eq!(k.cases[1].cells, 1);
        // 30 s a cell, two at a time: 1,000 cells on 4 nodes, 3,750 s
        let h = k.hours(1000, 4).expect("timed");
        assert!((h - 3750.0 / 3600.0).abs() < 1e-12, "{h}");
        let md = k.markdown();
        assert!(
            md.contains("| a | 2 | 15.0 s | 20.0 s |") && md.contains("| 64 |"),
            "{md}"
        );
        assert_eq!(Cost::of(&cells[3..], dir.path()).hours(1000, 1), None);
    }
}
