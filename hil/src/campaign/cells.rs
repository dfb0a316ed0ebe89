//! A campaign's cells: every device with every case and seed, each keyed by what decides its
//! result (the build, the case, the seed), so that a cell already run by the same build is
//! found again and not run twice, and a cluster's task takes its cell by its number.

use super::spec::{Campaign, Case, Device};
use anyhow::{Context, Result, bail};
use serde::Serialize;
use std::io::Read;
use std::path::{Path, PathBuf};

/// 64-bit FNV-1a over bytes, continued from `h`.
fn fnv1a(mut h: u64, bytes: &[u8]) -> u64 {
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// 64-bit FNV-1a of `bytes`.
pub fn hash_bytes(bytes: &[u8]) -> u64 {
    fnv1a(FNV_OFFSET, bytes)
}

/// What makes a device's results what they are: its program's bytes and its config, hashed
/// (16 hex digits). Two devices of the same binary and config are one build; a rebuilt binary
/// is another.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Build {
    /// The device's name.
    pub device: String,
    /// The hash.
    pub id: String,
}

impl Build {
    /// The build of `d`, its nav binary `nav_default` when it names none (a free-running
    /// device: its command line).
    pub fn of(d: &Device, nav_default: &Path) -> Result<Self> {
        let mut h = FNV_OFFSET;
        if let Some(cmd) = &d.dut {
            h = fnv1a(h, b"dut\0");
            h = fnv1a(h, cmd.as_bytes());
        } else {
            let nav = d.nav.as_deref().unwrap_or(nav_default);
            h = hash_file(h, nav).with_context(|| format!("device {:?}", d.name))?;
            let config = d.config.as_ref().map(|c| c.to_string()).unwrap_or_default();
            h = fnv1a(h, b"\0config\0");
            h = fnv1a(h, config.as_bytes());
        }
        Ok(Self {
            device: d.name.clone(),
            id: format!("{h:016x}"),
        })
    }
}

fn hash_file(mut h: u64, path: &Path) -> Result<u64> {
    let mut f =
        std::fs::File::open(path).with_context(|| format!("its nav binary {}", path.display()))?;
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f
            .read(&mut buf)
            .with_context(|| format!("reading {}", path.display()))?;
        if n == 0 {
            return Ok(h);
        }
        h = fnv1a(h, &buf[..n]);
    }
}

/// One run of a campaign: a device, a case, a seed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Cell {
    /// Its number in the plan (a cluster task's `--cell`).
    pub number: usize,
    /// The device's name.
    pub device: String,
    /// The device's build.
    pub build: String,
    /// The case's id.
    pub case: String,
    /// The seed.
    pub seed: u64,
    /// The key its result is kept under: the build, the case and the seed.
    pub key: String,
}

impl Cell {
    /// The cell's folder under a campaign's output folder.
    pub fn folder(&self, out: &Path) -> PathBuf {
        out.join("cells").join(&self.key)
    }

    /// The cell has a result in `out` (run before, by the same build).
    pub fn done(&self, out: &Path) -> bool {
        self.folder(out).join("result.json").is_file()
    }
}

/// A case's id as a file name: letters, digits, `-` and `_` kept, the rest `_`.
fn slug(id: &str) -> String {
    id.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Every cell of the campaign, device by device in the file's order, then case by case, then
/// seed by seed; `builds` are the devices' builds in the same order.
pub fn cells(c: &Campaign, cases: &[Case], builds: &[Build]) -> Result<Vec<Cell>> {
    if builds.len() != c.devices.len() {
        bail!("{} builds for {} devices", builds.len(), c.devices.len());
    }
    let mut out = Vec::new();
    for b in builds {
        for k in cases {
            for &seed in &k.seeds {
                out.push(Cell {
                    number: out.len(),
                    device: b.device.clone(),
                    build: b.id.clone(),
                    case: k.id.clone(),
                    seed,
                    key: format!("{}-{}-s{seed}", b.id, slug(&k.id)),
                });
            }
        }
    }
    Ok(out)
}

/// The cells still to run: those without a result in `out`.
pub fn pending<'a>(cells: &'a [Cell], out: &Path) -> Vec<&'a Cell> {
    cells.iter().filter(|c| !c.done(out)).collect()
}

/// Part `k` of `n` of the plan (`--shard K/N`, a cluster's array task among N): the cells whose
/// number is `k` modulo `n`, so that every part gets cells of every case and device alike.
pub fn shard(cells: &[Cell], k: usize, n: usize) -> Result<Vec<&Cell>> {
    if n == 0 || k >= n {
        bail!("--shard {k}/{n}: the part is 0 to N-1 of N parts (N at least 1)");
    }
    Ok(cells.iter().filter(|c| c.number % n == k).collect())
}

/// Experiments run nav's library in process (hil's own, with the device's settings): a device
/// that is another nav binary, or a free-running command, cannot run them; refused with the
/// device and the case when the campaign is planned.
pub fn check_in_process(c: &Campaign, cases: &[Case], nav_default: &Path) -> Result<()> {
    let Some(e) = cases
        .iter()
        .find(|k| matches!(k.kind, super::spec::CaseKind::Experiment(_)))
    else {
        return Ok(());
    };
    let ours = hash_file(FNV_OFFSET, nav_default)?;
    for d in &c.devices {
        let other = match (&d.dut, &d.nav) {
            (Some(_), _) => true,
            (None, Some(nav)) => {
                hash_file(FNV_OFFSET, nav).with_context(|| format!("device {:?}", d.name))? != ours
            }
            (None, None) => false,
        };
        if other {
            bail!(
                "case {}: an experiment runs nav's library in process (the nav beside hil, with a device's settings); device {:?} is {}: give it scenario or drill cases instead",
                e.id,
                d.name,
                if d.dut.is_some() {
                    "a free-running command"
                } else {
                    "another nav binary"
                }
            );
        }
    }
    Ok(())
}

/// The cell a cluster's task `K` of the plan runs (`--cell K`).
pub fn cell_at(cells: &[Cell], k: usize) -> Result<&Cell> {
    cells.get(k).with_context(|| {
        format!(
            "cell {k}: the plan has {} cells (0 to {})",
            cells.len(),
            cells.len().saturating_sub(1)
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::campaign::spec::tests::EXAMPLE;

    fn plan(dir: &Path, nav: &Path) -> (Campaign, Vec<Cell>) {
        let file = dir.join("campaign.toml");
        std::fs::write(&file, EXAMPLE).expect("written");
        let c = Campaign::load(&file).expect("loads");
        let builds: Vec<Build> = c
            .devices
            .iter()
            .map(|d| Build::of(d, nav).expect("build"))
            .collect();
        let cells = cells(&c, &c.cases().expect("cases"), &builds).expect("cells");
        (c, cells)
    }

    #[test]
    fn cells_are_keyed_by_build_case_and_seed_and_a_campaign_resumes() {
        let dir = tempfile::tempdir().expect("temp dir");
        let nav = dir.path().join("nav");
        std::fs::write(&nav, b"a build of nav").expect("written");
        let (_, cells) = plan(dir.path(), &nav);
        // 2 devices x (2 fault rows + 2 scenario seeds + 3 drill seeds + 4 + 2 experiment runs)
        assert_eq!(cells.len(), 26);
        assert!(cells.iter().enumerate().all(|(i, c)| c.number == i));
        let keys: std::collections::BTreeSet<&str> = cells.iter().map(|c| c.key.as_str()).collect();
        assert_eq!(keys.len(), cells.len(), "every key its own");
        // the two devices are one binary with another config: two builds
        assert_ne!(cells[0].build, cells[13].build);
        assert_eq!(
            cells[3].key,
            format!("{}-scenario_drive-gps-s2", cells[3].build)
        );
        // the same plan again: the same keys
        let (_, again) = plan(dir.path(), &nav);
        assert_eq!(again, cells);
        // three cells done: the rest pending
        let out = dir.path().join("out");
        for c in &cells[..3] {
            std::fs::create_dir_all(c.folder(&out)).expect("folder");
            std::fs::write(c.folder(&out).join("result.json"), "{}").expect("written");
        }
        let left = pending(&cells, &out);
        assert_eq!(left.len(), 23);
        assert_eq!(left[0].number, 3);
        // nav rebuilt: every key changes, nothing is taken for done
        std::fs::write(&nav, b"another build of nav").expect("written");
        let (_, rebuilt) = plan(dir.path(), &nav);
        assert!(rebuilt.iter().zip(&cells).all(|(a, b)| a.build != b.build));
        assert_eq!(pending(&rebuilt, &out).len(), 26);
        assert_eq!(cell_at(&cells, 25).expect("last").number, 25);
        let e = cell_at(&cells, 26).expect_err("past the end");
        assert!(e.to_string().contains("26 cells"), "{e}");
        // three parts: every cell in exactly one
        let parts: Vec<Vec<usize>> = (0..3)
            .map(|k| {
                shard(&cells, k, 3)
                    .expect("part")
                    .iter()
                    .map(|c| c.number)
                    .collect()
            })
            .collect();
        assert_eq!(parts[1][..3], [1, 4, 7]);
        let mut all: Vec<usize> = parts.concat();
        all.sort_unstable();
        assert_eq!(all, (0..26).collect::<Vec<_>>());
        assert!(shard(&cells, 3, 3).is_err() && shard(&cells, 0, 0).is_err());
    }

    #[test]
    fn an_experiment_is_refused_for_another_nav_binary() {
        let dir = tempfile::tempdir().expect("temp dir");
        let nav = dir.path().join("nav");
        std::fs::write(&nav, b"a build of nav").expect("written");
        let (mut c, _) = plan(dir.path(), &nav);
        let cases = c.cases().expect("cases");
        check_in_process(&c, &cases, &nav).expect("both devices are the nav beside hil");
        // a copy of the same binary is the same
        let copy = dir.path().join("nav-copy");
        std::fs::write(&copy, b"a build of nav").expect("written");
        c.devices[1].nav = Some(copy);
        check_in_process(&c, &cases, &nav).expect("the same bytes");
        let other = dir.path().join("nav-other");
        std::fs::write(&other, b"another build").expect("written");
        c.devices[1].nav = Some(other);
        let e = check_in_process(&c, &cases, &nav).expect_err("another binary");
        assert!(
            format!("{e:#}").contains("case experiment:north-finding")
                && format!("{e:#}").contains("device \"worse\" is another nav binary"),
            "{e:#}"
        );
    }

    #[test]
    fn a_missing_binary_names_its_device() {
        let d = Device {
            name: "nightly".into(),
            nav: Some("/nonexistent/nav".into()),
            config: None,
            dut: None,
        };
        let e = Build::of(&d, Path::new("nav")).expect_err("no binary");
        assert!(format!("{e:#}").contains("device \"nightly\""), "{e:#}");
    }
}
