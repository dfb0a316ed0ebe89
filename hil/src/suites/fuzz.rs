//! Hostile input for nav's decoders and the bench's parsers (`hil fuzz`), on the stable
//! toolchain: a seeded mutation fuzzer. Each target starts from a corpus of valid inputs (what
//! the emulators and the shipped files produce) and feeds mutants of them (bit flips, random
//! bytes, insertions, deletions, duplicated and spliced ranges, truncations) to the code under
//! test. A panic is caught, counted and its input written out; an input that takes longer than
//! the hang limit is counted as a hang; memory is bounded by construction of the targets (the
//! NMEA framer cuts lines at its limit) and checked by the framer's own counters.
//!
//! Targets:
//! - `can`: frame sequences through nav's whole pipeline (decode, front end, north-finding,
//!   navigator) - not only the decoder: any frame in any order must be counted, never fatal;
//! - `nmea`: byte streams through nav's framer and NMEA decoder, cut into reads anywhere;
//! - `config`: nav's config file text through its parser and checks;
//! - `scenario`: scenario file text through the bench's parser and checks.

use crate::scenario::Scenario;
use crate::suites::benchmarks::each_sample;
use anyhow::{Context, Result, bail};
use nav::pipeline::Pipeline;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::Serialize;
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use wire::RawFrame;

/// What to fuzz.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Target {
    /// CAN frame sequences through nav's pipeline.
    Can,
    /// NMEA byte streams through nav's framer and decoder.
    Nmea,
    /// nav's config text.
    Config,
    /// Scenario text.
    Scenario,
}

/// The figures of one target's run.
#[derive(Debug, Clone, Serialize)]
pub struct FuzzReport {
    /// Target.
    pub target: Target,
    /// Inputs run.
    pub inputs: u64,
    /// Panics caught (each input written to the output folder).
    pub panics: u64,
    /// Inputs over the hang limit.
    pub hangs: u64,
    /// The slowest input, ms.
    pub slowest_ms: f64,
    /// Inputs accepted (a valid message, fix, config or scenario came out).
    pub accepted: u64,
    /// Wall seconds.
    pub seconds: f64,
    /// Seed.
    pub seed: u64,
    /// Files holding the inputs that panicked or hung.
    pub crashes: Vec<PathBuf>,
}

/// Limit per input beyond which it counts as a hang: CPU time of the fuzzing thread, so that a
/// stall of the host (another job, a paused VM) is not taken for a hang of the code under test.
pub const HANG: Duration = Duration::from_millis(500);

/// CPU time consumed so far by the calling thread.
fn thread_cpu() -> Duration {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec through a valid pointer.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return Duration::ZERO;
    }
    Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
}

/// Run `inputs` inputs against `target` from `seed`; panicking inputs go to `out`.
pub fn run(
    target: Target,
    inputs: u64,
    seed: u64,
    out: &Path,
    mut progress: impl FnMut(u64),
) -> Result<FuzzReport> {
    let corpus = corpus(target)?;
    if corpus.is_empty() {
        bail!("no corpus for {target:?}");
    }
    // panics are expected findings here: keep their messages off the terminal
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut rng = StdRng::seed_from_u64(seed);
    let mut r = FuzzReport {
        target,
        inputs: 0,
        panics: 0,
        hangs: 0,
        slowest_ms: 0.0,
        accepted: 0,
        seconds: 0.0,
        seed,
        crashes: Vec::new(),
    };
    let mut can = CanTarget::new()?;
    let t0 = Instant::now();
    for i in 0..inputs {
        let input = mutate(&corpus, &mut rng);
        let (outcome, dt) = run_one(target, &input, &mut can, &mut rng);
        r.slowest_ms = r.slowest_ms.max(dt.as_secs_f64() * 1e3);
        if dt > HANG {
            r.hangs += 1;
            if r.crashes.len() < 20 {
                std::fs::create_dir_all(out)
                    .with_context(|| format!("creating {}", out.display()))?;
                let f = out.join(format!("hang-{target:?}-{seed}-{i}.bin").to_lowercase());
                std::fs::write(&f, &input).with_context(|| format!("writing {}", f.display()))?;
                r.crashes.push(f);
            }
        }
        match outcome {
            Ok(true) => r.accepted += 1,
            Ok(false) => {}
            Err(_) => {
                r.panics += 1;
                if r.crashes.len() < 20 {
                    std::fs::create_dir_all(out)
                        .with_context(|| format!("creating {}", out.display()))?;
                    let f = out.join(format!("crash-{target:?}-{seed}-{i}.bin").to_lowercase());
                    std::fs::write(&f, &input)
                        .with_context(|| format!("writing {}", f.display()))?;
                    r.crashes.push(f);
                }
                // the pipeline's state after a panic is not to be trusted
                can = CanTarget::new()?;
            }
        }
        r.inputs += 1;
        if i % 100_000 == 0 {
            progress(i);
        }
    }
    r.seconds = t0.elapsed().as_secs_f64();
    std::panic::set_hook(hook);
    Ok(r)
}

/// One input against `target` under `catch_unwind`: its outcome (accepted, or the panic) and
/// the CPU time it took.
fn run_one(
    target: Target,
    input: &[u8],
    can: &mut CanTarget,
    rng: &mut StdRng,
) -> (std::thread::Result<bool>, Duration) {
    let t = thread_cpu();
    let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| match target {
        Target::Can => can.feed(input),
        Target::Nmea => nmea(input, rng),
        Target::Config => config(input),
        Target::Scenario => scenario(input),
    }));
    (outcome, thread_cpu().saturating_sub(t))
}

/// What one kept input does when run again on its own (`hil fuzz --rerun FILE`).
#[derive(Debug, Clone, Serialize)]
pub struct Rerun {
    /// The input's file.
    pub file: PathBuf,
    /// It panicked; the panic's message.
    pub panic: Option<String>,
    /// CPU time of the run, ms.
    pub cpu_ms: f64,
    /// The input gave a valid message, fix, config or scenario.
    pub accepted: bool,
}

/// Run each kept input once more against `target`, from a fresh state (a `can` finding that
/// depended on earlier frames in the same pipeline may not reproduce this way: the report says
/// so by showing no panic and a short time).
pub fn rerun(target: Target, files: &[PathBuf], seed: u64) -> Result<Vec<Rerun>> {
    let mut rng = StdRng::seed_from_u64(seed);
    let hook = std::panic::take_hook();
    let message = std::sync::Arc::new(std::sync::Mutex::new(None::<String>));
    let m = message.clone();
    std::panic::set_hook(Box::new(move |info| {
        if let Ok(mut g) = m.lock() {
            *g = Some(info.to_string());
        }
    }));
    let mut out = Vec::new();
    for file in files {
        let input = std::fs::read(file).with_context(|| format!("reading {}", file.display()))?;
        let mut can = CanTarget::new()?;
        let (outcome, dt) = run_one(target, &input, &mut can, &mut rng);
        let cpu_ms = dt.as_secs_f64() * 1e3;
        let panic = match outcome {
            Ok(_) => None,
            Err(_) => Some(
                message
                    .lock()
                    .ok()
                    .and_then(|mut g| g.take())
                    .unwrap_or_else(|| "panic".into()),
            ),
        };
        out.push(Rerun {
            file: file.clone(),
            panic,
            cpu_ms,
            accepted: matches!(outcome, Ok(true)),
        });
    }
    std::panic::set_hook(hook);
    Ok(out)
}

/// Valid inputs to mutate.
fn corpus(target: Target) -> Result<Vec<Vec<u8>>> {
    Ok(match target {
        Target::Can => {
            // a drill's first seconds: IMU frames, turntable status and acknowledgements
            let s = crate::procedures::northfinding::scenario(37.0, 28.2, 10.0, 1);
            let mut corpus = Vec::new();
            each_sample(&s, 400.0 / s.imu.rate_hz, |frames| {
                corpus.push(frames.iter().flat_map(encode).collect());
            });
            corpus
        }
        Target::Nmea => {
            let s = Scenario::load(
                &Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/drive-gps.toml"),
            )?;
            let rx = s.gps.clone().context("drive-gps has a [gps]")?;
            let run = crate::engine::inproc::gps_run(&s, &rx)?.context("drive-gps has a drive")?;
            let mut g = emulators::gps::GpsReceiver::new(run);
            let mut corpus = Vec::new();
            let mut t = 0.0;
            while corpus.len() < 60 {
                t += 0.5;
                while let Some(e) = g.poll(t, s.duration_s) {
                    corpus.push(e.text.into_bytes());
                }
            }
            corpus
        }
        Target::Config => {
            let s = Scenario::load(
                &Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/campus-loop.toml"),
            )?;
            vec![
                crate::scenario::navconfig::nav_config(
                    &s,
                    Some("can0"),
                    Some(Path::new("/dev/ttyS1")),
                )
                .to_toml()
                .into_bytes(),
                crate::scenario::navconfig::nav_config(
                    &Scenario::builtin_static(),
                    Some("vcan0"),
                    None,
                )
                .to_toml()
                .into_bytes(),
            ]
        }
        Target::Scenario => Scenario::shipped_files()?
            .iter()
            .map(|p| std::fs::read(p).with_context(|| format!("reading {}", p.display())))
            .collect::<Result<_>>()?,
    })
}

/// A frame as 11 bytes: id (2, little-endian), length, data.
fn encode(f: &RawFrame) -> [u8; 11] {
    let mut b = [0u8; 11];
    b[..2].copy_from_slice(&f.id.to_le_bytes());
    b[2] = f.len;
    b[3..].copy_from_slice(&f.data);
    b
}

/// One mutant of a corpus entry.
fn mutate(corpus: &[Vec<u8>], rng: &mut StdRng) -> Vec<u8> {
    let mut v = corpus[rng.random_range(0..corpus.len())].clone();
    for _ in 0..rng.random_range(1..=6) {
        let n = v.len();
        match rng.random_range(0..8) {
            0 if n > 0 => {
                let i = rng.random_range(0..n);
                v[i] ^= 1 << rng.random_range(0..8);
            }
            1 if n > 0 => {
                let i = rng.random_range(0..n);
                v[i] = rng.random();
            }
            2 => {
                let i = rng.random_range(0..=n);
                let k = rng.random_range(1..16);
                let bytes: Vec<u8> = (0..k).map(|_| rng.random()).collect();
                v.splice(i..i, bytes);
            }
            3 if n > 0 => {
                let a = rng.random_range(0..n);
                let b = (a + rng.random_range(1..32)).min(n);
                v.drain(a..b);
            }
            4 if n > 0 => {
                let a = rng.random_range(0..n);
                let b = (a + rng.random_range(1..64)).min(n);
                let dup = v[a..b].to_vec();
                let at = rng.random_range(0..=v.len());
                v.splice(at..at, dup);
            }
            5 => {
                let other = &corpus[rng.random_range(0..corpus.len())];
                if !other.is_empty() {
                    let a = rng.random_range(0..other.len());
                    let at = rng.random_range(0..=v.len());
                    v.splice(at..at, other[a..].iter().copied());
                }
            }
            6 if n > 0 => v.truncate(rng.random_range(0..n)),
            _ => {
                // an interesting value: 0, all ones, a sign boundary
                if n > 0 {
                    let i = rng.random_range(0..n);
                    v[i] = [0u8, 0xFF, 0x7F, 0x80, b'$', b'*', b',', b'\n'][rng.random_range(0..8)];
                }
            }
        }
    }
    v
}

/// nav's pipeline, fed frame sequences; started again every so many frames (a long run in
/// one pipeline explores deep states, fresh ones explore start-up).
struct CanTarget {
    pipeline: Pipeline,
    frames: u64,
    out: Vec<nav::pipeline::Output>,
}

impl CanTarget {
    fn new() -> Result<Self> {
        let s = crate::procedures::northfinding::scenario(37.0, 28.2, 10.0, 1);
        let mut cfg = crate::scenario::navconfig::nav_config(&s, None, None);
        cfg.navigation.enabled = true;
        cfg.navigation.initial_heading_deg = Some(37.0);
        Ok(Self {
            pipeline: Pipeline::new(&cfg, false).context("nav's pipeline")?,
            frames: 0,
            out: Vec::new(),
        })
    }

    fn feed(&mut self, bytes: &[u8]) -> bool {
        if self.frames > 200_000
            && let Ok(fresh) = Self::new()
        {
            *self = fresh;
        }
        let mut any = false;
        for c in bytes.chunks(11) {
            let mut data = [0u8; 8];
            let n = c.len().saturating_sub(3).min(8);
            if c.len() > 3 {
                data[..n].copy_from_slice(&c[3..3 + n]);
            }
            let f = RawFrame {
                id: u16::from_le_bytes([c[0], *c.get(1).unwrap_or(&0)]) & 0x7FF,
                // a classic frame: the socket layer never hands over more than 8 bytes
                len: c.get(2).map_or(0, |l| l % 9),
                data,
            };
            any |= wire::Message::decode(&f).is_ok();
            self.pipeline.on_frame(&f, &mut self.out);
            self.out.clear();
            self.frames += 1;
        }
        any
    }
}

fn nmea(bytes: &[u8], rng: &mut StdRng) -> bool {
    let mut d = nav::frontend::gps_receiver::GpsDecoder::default();
    let mut fixes = Vec::new();
    // cut into reads anywhere, as a serial port delivers them
    let mut at = 0;
    while at < bytes.len() {
        let k = rng.random_range(1..=bytes.len() - at);
        d.push_bytes(&bytes[at..at + k], &mut fixes);
        at += k;
    }
    !fixes.is_empty()
}

fn config(bytes: &[u8]) -> bool {
    let text = String::from_utf8_lossy(bytes);
    nav::config::NavConfig::from_text(&text, Path::new("/fuzz/nav.toml")).is_ok()
}

fn scenario(bytes: &[u8]) -> bool {
    let text = String::from_utf8_lossy(bytes);
    match Scenario::from_text(&text) {
        // an accepted scenario must also build its devices and plan its drive without panicking
        Ok(s) => {
            let _ = s.build();
            if let Some(d) = &s.drive {
                let _ = emulators::drive::Drive::plan(d);
            }
            true
        }
        Err(_) => false,
    }
}

/// The figures as a Markdown table.
pub fn markdown(rs: &[FuzzReport]) -> String {
    let mut t = crate::table::Table::figures(&[
        "target",
        "inputs",
        "accepted",
        "panics",
        "hangs (> 500 ms CPU)",
        "slowest ms",
        "seconds",
        "inputs/s",
        "seed",
    ]);
    for r in rs {
        t.row([
            format!("{:?}", r.target),
            r.inputs.to_string(),
            r.accepted.to_string(),
            r.panics.to_string(),
            r.hangs.to_string(),
            format!("{:.2}", r.slowest_ms),
            format!("{:.1}", r.seconds),
            format!("{:.0}", r.inputs as f64 / r.seconds.max(1e-9)),
            r.seed.to_string(),
        ]);
    }
    t.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A short run of every target: no panic, no hang, and the mutants are not all rejected
    /// (the corpus is valid and the mutations keep some of it).
    #[test]
    fn a_short_run_of_every_target_finds_no_panic() {
        let dir = tempfile::tempdir().unwrap();
        for (t, n) in [
            (Target::Can, 3_000),
            (Target::Nmea, 20_000),
            (Target::Config, 2_000),
            (Target::Scenario, 1_000),
        ] {
            let r = run(t, n, 1, dir.path(), |_| {}).unwrap();
            assert_eq!(r.inputs, n);
            assert_eq!(r.panics, 0, "{t:?}: crashes in {:?}", r.crashes);
            assert_eq!(r.hangs, 0, "{t:?}: slowest {} ms", r.slowest_ms);
            assert!(r.accepted > 0, "{t:?}: every mutant refused");
        }
    }
}
