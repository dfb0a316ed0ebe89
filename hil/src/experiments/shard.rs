//! Experiments in parts. An experiment is a plan of independent runs; part K of N takes the
//! runs whose place in the plan is K modulo N, and the parts, run anywhere (a Slurm job array,
//! a Kubernetes indexed Job), merge into the very report a single run gives. Each part carries
//! its plan, so parts of different plans (other options, another shard count) are refused.

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize, de::DeserializeOwned};
use std::path::{Path, PathBuf};

/// One part of an experiment: its plan and the outcomes of its runs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Part<T> {
    /// Which experiment (`north-finding`, `navigation`).
    pub experiment: String,
    /// The plan every part of the experiment shares.
    pub plan: serde_json::Value,
    /// This part's index (0-based).
    pub shard: usize,
    /// Parts in all.
    pub shards: usize,
    /// Runs in the whole plan.
    pub total: usize,
    /// (place in the plan, outcome) of this part's runs.
    pub outcomes: Vec<(usize, T)>,
}

/// The runs of part `shard` of `shards`, with their places in the plan.
pub fn select<J>(all: Vec<J>, shard: usize, shards: usize) -> Result<Vec<(usize, J)>> {
    if shards == 0 || shard >= shards {
        bail!("part {shard} of {shards}: parts are numbered 0 to N-1");
    }
    Ok(all
        .into_iter()
        .enumerate()
        .filter(|(g, _)| g % shards == shard)
        .collect())
}

/// The outcomes of every run of the plan, in plan order, from all its parts (each once).
pub fn assemble<T: Clone>(parts: &[Part<T>]) -> Result<Vec<T>> {
    let Some(first) = parts.first() else {
        bail!("no parts to merge");
    };
    let mut seen = vec![false; first.shards];
    for p in parts {
        if p.experiment != first.experiment
            || p.plan != first.plan
            || p.shards != first.shards
            || p.total != first.total
        {
            bail!(
                "part {} of {} comes from another plan (another experiment, other options or shard count)",
                p.shard,
                p.shards
            );
        }
        match seen.get_mut(p.shard) {
            Some(s) if !*s => *s = true,
            _ => bail!(
                "part {} of {} given twice or out of range",
                p.shard,
                p.shards
            ),
        }
    }
    let missing: Vec<usize> = (0..first.shards).filter(|&k| !seen[k]).collect();
    if !missing.is_empty() {
        let each: Vec<String> = missing
            .iter()
            .map(|&k| {
                format!(
                    "part {k} of {} (Slurm array task {k}, Kubernetes completion index {k}): runs {} of the plan's {}",
                    first.shards,
                    places(held(k, first.shards, first.total)),
                    first.total
                )
            })
            .collect();
        bail!(
            "{} missing: {}; run {} again with `--shard K/{}` and the same options, then merge all parts",
            if missing.len() == 1 {
                "a part is"
            } else {
                "parts are"
            },
            each.join("; "),
            if missing.len() == 1 { "it" } else { "them" },
            first.shards
        );
    }
    let mut all: Vec<Option<T>> = vec![None; first.total];
    for p in parts {
        for (g, o) in &p.outcomes {
            match all.get_mut(*g) {
                Some(slot) => *slot = Some(o.clone()),
                None => bail!("part {} has run {g} of only {}", p.shard, first.total),
            }
        }
    }
    all.into_iter()
        .enumerate()
        .map(|(g, o)| o.with_context(|| format!("run {g} is in no part")))
        .collect()
}

/// The places in the plan (of `total` runs) that part `shard` of `shards` holds.
pub fn held(shard: usize, shards: usize, total: usize) -> Vec<usize> {
    (0..total).filter(|g| g % shards.max(1) == shard).collect()
}

/// Places in the plan, for people: all of them when few, else the first ones and how many.
fn places(v: Vec<usize>) -> String {
    let text: Vec<String> = v.iter().take(8).map(usize::to_string).collect();
    match v.len() {
        0 => "none".into(),
        n if n <= 8 => text.join(", "),
        n => format!("{}, ... ({n} runs)", text.join(", ")),
    }
}

/// Writes `part` as `part-K-of-N.json` in `dir`; returns the file.
pub fn write<T: Serialize>(part: &Part<T>, dir: &Path) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let f = dir.join(format!("part-{}-of-{}.json", part.shard, part.shards));
    std::fs::write(&f, serde_json::to_string(part)?)
        .with_context(|| format!("writing {}", f.display()))?;
    Ok(f)
}

/// Which experiment the part file `path` belongs to.
pub fn experiment_of(path: &Path) -> Result<String> {
    #[derive(Deserialize)]
    struct Head {
        experiment: String,
    }
    let t = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let h: Head = serde_json::from_str(&t)
        .with_context(|| format!("{} is not a part of an experiment", path.display()))?;
    Ok(h.experiment)
}

/// Reads the part files `paths` of one experiment.
pub fn read<T: DeserializeOwned>(paths: &[PathBuf]) -> Result<Vec<Part<T>>> {
    paths
        .iter()
        .map(|p| {
            let t =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            serde_json::from_str(&t)
                .with_context(|| format!("{} is not a part of this experiment", p.display()))
        })
        .collect()
}

/// `K/N` (0-based part K of N), for the command line.
pub fn parse(s: &str) -> std::result::Result<(usize, usize), String> {
    let (k, n) = s
        .split_once('/')
        .ok_or_else(|| format!("`{s}`: a part is K/N, e.g. 0/4"))?;
    let (k, n): (usize, usize) = (
        k.trim()
            .parse()
            .map_err(|_| format!("`{k}` is not a part number"))?,
        n.trim()
            .parse()
            .map_err(|_| format!("`{n}` is not a part count"))?,
    );
    if n == 0 || k >= n {
        return Err(format!("`{s}`: parts are numbered 0 to N-1"));
    }
    Ok((k, n))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parts(n: usize) -> Vec<Part<u32>> {
        (0..n)
            .map(|k| Part {
                experiment: "x".into(),
                plan: serde_json::json!({"runs": 7}),
                shard: k,
                shards: n,
                total: 7,
                outcomes: select((0..7u32).map(|i| i * 10).collect(), k, n).unwrap(),
            })
            .collect()
    }

    #[test]
    fn parts_assemble_in_plan_order_and_incomplete_or_foreign_sets_are_refused() {
        let want: Vec<u32> = (0..7).map(|i| i * 10).collect();
        assert_eq!(assemble(&parts(1)).unwrap(), want);
        assert_eq!(assemble(&parts(3)).unwrap(), want);
        let p = parts(3);
        // the missing part is named with its runs, as a Slurm array task and a Job's index
        let e = assemble(&p[..2]).unwrap_err().to_string();
        assert!(
            e.contains("part 2 of 3 (Slurm array task 2")
                && e.contains("runs 2, 5 of the plan's 7")
                && e.contains("--shard K/3"),
            "{e}"
        );
        let twice = vec![p[0].clone(), p[0].clone(), p[1].clone()];
        assert!(assemble(&twice).unwrap_err().to_string().contains("twice"));
        let mut other = p.clone();
        other[1].plan = serde_json::json!({"runs": 8});
        assert!(
            assemble(&other)
                .unwrap_err()
                .to_string()
                .contains("another plan")
        );
        assert!(select(vec![1], 2, 2).is_err());
        assert_eq!(parse("1/4"), Ok((1, 4)));
        assert!(parse("4/4").is_err() && parse("x").is_err());
    }
}
