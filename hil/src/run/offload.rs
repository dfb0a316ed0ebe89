//! Judging a run's recomputations on another machine: a bench whose devices run on a slow
//! computer (a software-emulated guest, a small box beside the CAN hardware) has the in-process
//! reference run, the replay of nav's recording through its pipeline and the scoring of that
//! recording against truth done by `hil judge-server` on a faster one that shares a folder with
//! it (`HIL_JUDGE_SERVER=FOLDER`: a 9p share of a QEMU guest, NFS).
//!
//! The same code computes either way ([`compute`]): the server runs only for the same build of
//! hil on a CPU with the same floating-point features (where the C library picks another
//! `sin` or `exp` the last bits may differ), otherwise it declines and the run computes here. A
//! result does not depend on where it was computed; wall time decides only whether the server
//! is used (a server that does not take the work within [`PICKUP`], or stops saying it is
//! alive for [`SILENCE`], leaves the work to the run).
//!
//! The exchange, in the shared folder: the run writes `<id>.part/` (its recording's parts and
//! `request.cbor`) and renames it `<id>.req`; the server claims it by renaming it `<id>.taken`
//! and writes `reply.cbor` into it; the run reads the reply and removes the folder. The server
//! writes `server.alive` (its pid and a count) every second while it runs and removes it when
//! stopped. CBOR keeps every `f64` bit for bit (NaN included).

use crate::engine::recording::Playback;
use crate::engine::reference::InProcess;
use crate::engine::scoring::{RecordingScorer, ScoredRecording};
use crate::scenario::Scenario;
use anyhow::{Context, Result, anyhow, bail};
use emulators::drive::Drive;
use nav::config::NavConfig;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, UNIX_EPOCH};

/// The environment variable naming the folder a judge server watches.
pub const ENV: &str = "HIL_JUDGE_SERVER";
/// How long a request may wait unclaimed before the run takes its work back.
pub const PICKUP: Duration = Duration::from_secs(10);
/// How long the server may not update `server.alive` before a run gives up on it.
pub const SILENCE: Duration = Duration::from_secs(30);
/// The file the server keeps alive in its folder.
pub const ALIVE: &str = "server.alive";

/// What judging a run recomputes: the in-process reference run, the replay of nav's recording
/// through its pipeline, and the recording scored against the drive (one reading for both).
pub(crate) struct Recomputed {
    /// The in-process reference run, when asked for.
    pub reference: Option<Result<InProcess>>,
    /// The replay of nav's recording, when asked for.
    pub replayed: Option<Result<Playback>>,
    /// The recording scored against the drive, when there is one.
    pub scored: Option<Result<ScoredRecording>>,
    /// Recomputed by a judge server.
    pub by_server: bool,
}

/// What to recompute for a run.
pub(crate) struct Work<'a> {
    /// The scenario run.
    pub scenario: &'a Scenario,
    /// The config nav ran with.
    pub nav_cfg: &'a NavConfig,
    /// Run the scenario in process for reference.
    pub reference: bool,
    /// Replay nav's recording (`mcap`) through its pipeline.
    pub replay: bool,
    /// Score the recording against this drive (with the replay).
    pub drive: Option<&'a Drive>,
    /// nav's recording (its first part).
    pub mcap: &'a Path,
}

/// Recompute `w` here; `what` names the recording in the replay's summary.
pub(crate) fn compute(w: &Work, what: &str) -> Result<Recomputed> {
    let s = w.scenario;
    let imu = s.imu.oscillator().from_first_sample();
    let (reference, read) = std::thread::scope(|sc| {
        let reference = sc.spawn(|| {
            w.reference.then(|| {
                crate::engine::reference::run_in_process(s).context("in-process reference run")
            })
        });
        let read = w.replay.then(|| {
            let mut scorer = w.drive.map(|d| RecordingScorer::new(d, imu));
            let r = crate::engine::recording::replay_and(w.mcap, what, w.nav_cfg, |m| {
                if let Some(sc) = scorer.as_mut() {
                    sc.message(m);
                }
            });
            (r, scorer)
        });
        let reference = reference
            .join()
            .map_err(|_| anyhow!("the in-process reference run panicked"))?;
        Ok::<_, anyhow::Error>((reference, read))
    })?;
    let (replayed, scored) = match read {
        None => (None, None),
        Some((Ok((playback, cut)), scorer)) => {
            (Some(Ok(playback)), scorer.map(|sc| Ok(sc.finish(cut))))
        }
        // the recording could not be read: both say so
        Some((Err(e), scorer)) => {
            let scored = scorer.map(|_| Err(anyhow!("{e:#}")));
            (Some(Err(e)), scored)
        }
    };
    Ok(Recomputed {
        reference,
        replayed,
        scored,
        by_server: false,
    })
}

/// The build and the CPU a result was computed by: a server computes only for its own.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
struct Program {
    version: String,
    /// The executable's size and modification time (s, ns since 1970): the same file.
    exe_bytes: u64,
    exe_modified: (u64, u32),
    /// The CPU's features the C library's maths chooses its code by.
    cpu: Vec<String>,
}

impl Program {
    fn this() -> Result<Self> {
        let exe = std::env::current_exe().context("this program's path")?;
        let m = std::fs::metadata(&exe).with_context(|| format!("{}", exe.display()))?;
        let t = m
            .modified()
            .ok()
            .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
            .unwrap_or_default();
        Ok(Self {
            version: env!("CARGO_PKG_VERSION").into(),
            exe_bytes: m.len(),
            exe_modified: (t.as_secs(), t.subsec_nanos()),
            cpu: cpu_features(),
        })
    }

    /// Why a server of this program declines work for `theirs`, if it does.
    fn declines(&self, theirs: &Program) -> Option<String> {
        if self.cpu != theirs.cpu {
            Some(format!(
                "the server's CPU has {:?}, the run's {:?}: their maths may differ in the last bits",
                self.cpu, theirs.cpu
            ))
        } else if self != theirs {
            Some(format!(
                "another build of hil (the server's {} bytes, modified {}.{:09}; the run's {} bytes, modified {}.{:09})",
                self.exe_bytes,
                self.exe_modified.0,
                self.exe_modified.1,
                theirs.exe_bytes,
                theirs.exe_modified.0,
                theirs.exe_modified.1
            ))
        } else {
            None
        }
    }
}

fn cpu_features() -> Vec<String> {
    #[allow(unused_mut)]
    let mut f: Vec<&str> = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("fma") {
            f.push("fma");
        }
        if std::is_x86_feature_detected!("avx2") {
            f.push("avx2");
        }
        if std::is_x86_feature_detected!("avx") {
            f.push("avx");
        }
        if std::is_x86_feature_detected!("sse4.1") {
            f.push("sse4.1");
        }
    }
    f.into_iter().map(String::from).collect()
}

/// nav's config `cfg` as a server gets it: the parameter files it names (relative to the
/// run's folder `run`) copied into `folder`
/// and named relative to it, for the server to load ([`NavConfig::load_input_files`]: what a config
/// loaded holds of them is not serialized). Checked here: `cfg` and what the server will
/// rebuild from the copies must be equal but for the files' paths, as must the scenario
/// serialized and read back, or the work stays here.
fn config_beside(cfg: &NavConfig, run: &Path, folder: &Path) -> Result<NavConfig> {
    let mut sent = cfg.clone();
    for (path, name) in sent.input_files_mut() {
        // (relative: to nav's config, in the run's folder beside its recording)
        let from = run.join(&*path);
        std::fs::copy(&from, folder.join(name))
            .with_context(|| format!("copying nav's {}", from.display()))?;
        *path = PathBuf::from(name);
    }
    let mut back: NavConfig = cbor_round_trip(&sent)?;
    back.load_input_files(&folder.join("nav.toml"))
        .map_err(|e| anyhow!("nav's config as the server would read it: {e}"))?;
    let mut original = cfg.clone();
    for ((p, _), (q, _)) in back.input_files_mut().zip(original.input_files_mut()) {
        *p = q.clone();
    }
    if back != original {
        bail!("nav's config does not survive the way to the server (serialized, read back)");
    }
    Ok(sent)
}

/// Whether `v` reads back as it was written: its encoding and the encoding of what is read back
/// are the same bytes (a comparison of the values would call a scenario with a start a track gives,
/// NaN until planned, changed by the way).
fn survives<T: Serialize + for<'de> Deserialize<'de>>(v: &T) -> Result<bool> {
    let encode = |v: &T| {
        let mut buf = Vec::new();
        ciborium::into_writer(v, &mut buf).map_err(|e| anyhow!("encoding: {e}"))?;
        Ok::<_, anyhow::Error>(buf)
    };
    let sent = encode(v)?;
    let back: T = ciborium::from_reader(sent.as_slice()).map_err(|e| anyhow!("decoding: {e}"))?;
    Ok(encode(&back)? == sent)
}

fn cbor_round_trip<T: Serialize + for<'de> Deserialize<'de>>(v: &T) -> Result<T> {
    let mut buf = Vec::new();
    ciborium::into_writer(v, &mut buf).map_err(|e| anyhow!("encoding: {e}"))?;
    ciborium::from_reader(buf.as_slice()).map_err(|e| anyhow!("decoding: {e}"))
}

#[derive(Serialize, Deserialize)]
struct Request {
    program: Program,
    scenario: Scenario,
    nav_cfg: NavConfig,
    reference: bool,
    replay: bool,
    score: bool,
    /// The recording's file name in the request's folder.
    mcap: String,
    /// The recording's path where the run is (for the replay's summary and errors).
    what: String,
}

#[derive(Serialize, Deserialize)]
enum Reply {
    Declined(String),
    Done(Box<Done>),
}

#[derive(Serialize, Deserialize)]
struct Done {
    reference: Option<Result<InProcess, String>>,
    replayed: Option<Result<Playback, String>>,
    scored: Option<Result<ScoredRecording, String>>,
}

fn to_wire<T>(r: Option<Result<T>>, from: &str, to: &str) -> Option<Result<T, String>> {
    r.map(|r| r.map_err(|e| format!("{e:#}").replace(from, to)))
}

fn from_wire<T>(r: Option<Result<T, String>>) -> Option<Result<T>> {
    r.map(|r| r.map_err(|e| anyhow!(e)))
}

fn write_cbor<T: Serialize>(path: &Path, v: &T) -> Result<()> {
    let mut buf = Vec::new();
    ciborium::into_writer(v, &mut buf).map_err(|e| anyhow!("encoding {}: {e}", path.display()))?;
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, buf).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming {}", tmp.display()))
}

fn read_cbor<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let buf = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    ciborium::from_reader(buf.as_slice()).map_err(|e| anyhow!("decoding {}: {e}", path.display()))
}

fn alive_mark(dir: &Path) -> Option<String> {
    std::fs::read_to_string(dir.join(ALIVE)).ok()
}

/// Have the judge server in `dir` recompute `w`. `None`: no server took it, or it declined
/// (said in the log); the caller computes here.
pub(crate) fn ask(dir: &Path, w: &Work) -> Result<Option<Recomputed>> {
    ask_as(dir, w, Program::this()?)
}

fn ask_as(dir: &Path, w: &Work, program: Program) -> Result<Option<Recomputed>> {
    let Some(mark) = alive_mark(dir) else {
        tracing::info!(
            "no judge server in {} ({ALIVE} missing): judging here",
            dir.display()
        );
        return Ok(None);
    };
    static SEQ: AtomicU64 = AtomicU64::new(0);
    let now = std::time::SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default();
    let id = format!(
        "{}-{}-{}",
        std::process::id(),
        now.as_nanos(),
        SEQ.fetch_add(1, Ordering::Relaxed)
    );
    let part = dir.join(format!("{id}.part"));
    let req = dir.join(format!("{id}.req"));
    let taken = dir.join(format!("{id}.taken"));
    std::fs::create_dir(&part).with_context(|| format!("creating {}", part.display()))?;
    if let Err(e) = submit(&part, w, program).and_then(|()| {
        std::fs::rename(&part, &req).with_context(|| format!("renaming {}", part.display()))
    }) {
        let _ = std::fs::remove_dir_all(&part);
        return Err(e);
    }
    let asked = Instant::now();
    if let Err(why) = await_reply(dir, &req, &taken, mark) {
        // take the request back if it is still there, or clear what the server left
        let back = dir.join(format!("{id}.gone"));
        if std::fs::rename(&req, &back).is_ok() {
            let _ = std::fs::remove_dir_all(&back);
        } else {
            let _ = std::fs::remove_dir_all(&taken);
        }
        tracing::warn!("judge server in {}: {why}; judging here", dir.display());
        return Ok(None);
    }
    let r: Result<Reply> = read_cbor(&taken.join("reply.cbor"));
    let _ = std::fs::remove_dir_all(&taken);
    match r? {
        Reply::Declined(why) => {
            tracing::info!("the judge server declined: {why}; judging here");
            Ok(None)
        }
        Reply::Done(d) => {
            let Done {
                reference,
                replayed,
                scored,
            } = *d;
            tracing::debug!(
                "judged by the server in {} ({:.1} s)",
                dir.display(),
                asked.elapsed().as_secs_f64()
            );
            Ok(Some(Recomputed {
                reference: from_wire(reference),
                replayed: from_wire(replayed),
                scored: from_wire(scored),
                by_server: true,
            }))
        }
    }
}

/// Write the request for `w` into `part`: the recording's parts, nav's config and its files.
fn submit(part: &Path, w: &Work, program: Program) -> Result<()> {
    let mut parts = nav::record::writer::parts(w.mcap);
    if parts.is_empty() && w.mcap.exists() {
        parts.push(w.mcap.to_path_buf());
    }
    for p in &parts {
        let name = p.file_name().context("a recording part without a name")?;
        std::fs::copy(p, part.join(name))
            .with_context(|| format!("copying {} to {}", p.display(), part.display()))?;
    }
    if !survives(w.scenario)? {
        bail!("the scenario does not survive the way to the server (serialized, read back)");
    }
    let r = Request {
        program,
        scenario: w.scenario.clone(),
        nav_cfg: config_beside(w.nav_cfg, w.mcap.parent().unwrap_or(Path::new(".")), part)?,
        reference: w.reference,
        replay: w.replay,
        score: w.drive.is_some(),
        mcap: w
            .mcap
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        what: w.mcap.display().to_string(),
    };
    write_cbor(&part.join("request.cbor"), &r)
}

/// Wait for the server's reply in `taken`; why not, when the server did not take the request
/// (`req`) in time or stopped saying it was alive (`mark`: the last word it wrote).
fn await_reply(dir: &Path, req: &Path, taken: &Path, mut mark: String) -> Result<(), String> {
    let asked = Instant::now();
    let mut heard = Instant::now();
    let mut last_check = Instant::now();
    let reply = taken.join("reply.cbor");
    while !reply.is_file() {
        if req.exists() && asked.elapsed() > PICKUP {
            return Err(format!(
                "the work was not taken within {} s",
                PICKUP.as_secs()
            ));
        }
        if last_check.elapsed() > Duration::from_secs(2) {
            last_check = Instant::now();
            match alive_mark(dir) {
                Some(m) if m != mark => {
                    mark = m;
                    heard = Instant::now();
                }
                None => return Err("the server stopped".into()),
                _ => {}
            }
            if heard.elapsed() > SILENCE {
                return Err(format!(
                    "the server has not said it was alive for {} s",
                    SILENCE.as_secs()
                ));
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

/// What a server did.
#[derive(Debug, Default, Clone, Copy)]
pub struct Served {
    /// Requests recomputed.
    pub done: u64,
    /// Requests declined (another build or CPU, or unreadable).
    pub declined: u64,
}

/// Serve the runs that share `dir` until `stop` is set: claim each request, recompute it with
/// `jobs` requests at a time, write the reply. Stopping finishes the work claimed.
pub fn serve(dir: &Path, jobs: usize, stop: &AtomicBool) -> Result<Served> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let me = Program::this()?;
    let (tx, rx) = std::sync::mpsc::channel::<PathBuf>();
    let rx = Arc::new(Mutex::new(rx));
    let served = Mutex::new(Served::default());
    let alive = dir.join(ALIVE);
    let r = std::thread::scope(|sc| {
        for _ in 0..jobs.max(1) {
            let rx = Arc::clone(&rx);
            let (me, served) = (&me, &served);
            sc.spawn(move || {
                loop {
                    let next = rx
                        .lock()
                        .map_err(|_| ())
                        .and_then(|r| r.recv().map_err(|_| ()));
                    let Ok(folder) = next else { break };
                    let declined = serve_one(&folder, me);
                    if let Ok(mut s) = served.lock() {
                        if declined {
                            s.declined += 1;
                        } else {
                            s.done += 1;
                        }
                    }
                }
            });
        }
        // the workers end when the claims end, however they end
        let r = claim(dir, &alive, stop, &tx);
        drop(tx);
        r
    });
    let _ = std::fs::remove_file(&alive);
    r?;
    Ok(served.into_inner().unwrap_or_default())
}

/// Until `stop`: say the server is alive (`alive`, every second) and claim each request in
/// `dir`, handing it to the workers (`tx`).
fn claim(
    dir: &Path,
    alive: &Path,
    stop: &AtomicBool,
    tx: &std::sync::mpsc::Sender<PathBuf>,
) -> Result<()> {
    let mut count = 0u64;
    let mut beat = Instant::now() - Duration::from_secs(2);
    while !stop.load(Ordering::Relaxed) {
        if beat.elapsed() >= Duration::from_secs(1) {
            beat = Instant::now();
            count += 1;
            let tmp = dir.join(format!("{ALIVE}.tmp"));
            std::fs::write(&tmp, format!("{} {count}\n", std::process::id()))
                .and_then(|_| std::fs::rename(&tmp, alive))
                .with_context(|| format!("writing {}", alive.display()))?;
        }
        let entries = std::fs::read_dir(dir).with_context(|| format!("{}", dir.display()))?;
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let Some(id) = name.strip_suffix(".req") else {
                continue;
            };
            let taken = dir.join(format!("{id}.taken"));
            // the run may have taken it back meanwhile
            if std::fs::rename(e.path(), &taken).is_ok() {
                let _ = tx.send(taken);
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

/// Recompute the request in `folder` and write its reply; whether it was declined.
fn serve_one(folder: &Path, me: &Program) -> bool {
    let started = Instant::now();
    let (reply, name) = match read_cbor::<Request>(&folder.join("request.cbor")) {
        Err(e) => (Reply::Declined(format!("{e:#}")), String::new()),
        Ok(req) => match me.declines(&req.program) {
            Some(why) => (Reply::Declined(why), req.scenario.name.clone()),
            None => {
                // a panic declines the work (the run then judges itself) and ends nothing else
                let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    recompute(folder, &req)
                }));
                let r = r.unwrap_or_else(|_| Reply::Declined("the recomputation panicked".into()));
                (r, req.scenario.name.clone())
            }
        },
    };
    let declined = matches!(reply, Reply::Declined(_));
    match &reply {
        Reply::Declined(why) => tracing::warn!("{}: declined: {why}", folder.display()),
        Reply::Done(_) => tracing::debug!(
            "{}: {name} judged in {:.1} s",
            folder.display(),
            started.elapsed().as_secs_f64()
        ),
    }
    if let Err(e) = write_cbor(&folder.join("reply.cbor"), &reply) {
        tracing::warn!("{e:#}");
    }
    declined
}

fn recompute(folder: &Path, req: &Request) -> Reply {
    let drive = match (req.score, &req.scenario.drive) {
        (true, Some(d)) => match Drive::plan(d) {
            Ok(d) => Some(d),
            Err(e) => return Reply::Declined(format!("the scenario's drive: {e:#}")),
        },
        _ => None,
    };
    let mut nav_cfg = req.nav_cfg.clone();
    if let Err(e) = nav_cfg.load_input_files(&folder.join("nav.toml")) {
        return Reply::Declined(format!("nav's config: {e}"));
    }
    let mcap = folder.join(&req.mcap);
    let w = Work {
        scenario: &req.scenario,
        nav_cfg: &nav_cfg,
        reference: req.reference,
        replay: req.replay,
        drive: drive.as_ref(),
        mcap: &mcap,
    };
    // errors name the run's folder, not this one
    let here = folder.display().to_string();
    let there = Path::new(&req.what)
        .parent()
        .map(|p| p.display().to_string())
        .unwrap_or_default();
    match compute(&w, &req.what) {
        Ok(r) => Reply::Done(Box::new(Done {
            reference: to_wire(r.reference, &here, &there),
            replayed: to_wire(r.replayed, &here, &there),
            scored: to_wire(r.scored, &here, &there),
        })),
        Err(e) => Reply::Declined(format!("{e:#}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nav::record::writer::{Record, Recorder};

    /// A few seconds of the GPS drive, its frames recorded as nav records what it receives:
    /// (scenario, nav's config, the recording's folder).
    fn a_short_drive() -> (Scenario, NavConfig, tempfile::TempDir) {
        let mut s = Scenario::from_text(include_str!("../../../scenarios/drive-gps.toml"))
            .expect("drive-gps.toml");
        s.duration_s = 3.0;
        let dir = tempfile::tempdir().expect("tempdir");
        let cfg = crate::scenario::navconfig::nav_config(&s, None, Some(Path::new("(test)")));
        let mut bench = crate::engine::inproc::InProcessBench::of(&s).expect("bench");
        let rec = Recorder::start(&dir.path().join("nav.mcap")).expect("recorder");
        let mut t_ns = 1_795_435_864_000_000_000u64;
        while bench.running() {
            bench.step();
            for f in bench.last_frames() {
                t_ns += 1000;
                rec.send(Record::Frame { t_ns, frame: *f });
            }
        }
        rec.finish().expect("recording");
        (s, cfg, dir)
    }

    fn wire_bytes(r: Result<Recomputed>) -> Vec<u8> {
        let r = r.expect("recomputed");
        let reply = Reply::Done(Box::new(Done {
            reference: to_wire(r.reference, "", ""),
            replayed: to_wire(r.replayed, "", ""),
            scored: to_wire(r.scored, "", ""),
        }));
        let mut buf = Vec::new();
        ciborium::into_writer(&reply, &mut buf).expect("cbor");
        buf
    }

    /// A drive from a track (its start and speed not given: NaN until the track is planned)
    /// goes to the server as any other scenario: it was judged in the guest instead.
    #[test]
    fn a_scenario_driving_a_track_survives_the_way_to_the_server() {
        let p =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/track-lisbon-handheld.toml");
        let s = Scenario::load(&p).expect("the track's scenario");
        assert!(s.drive.as_ref().is_some_and(|d| d.lat_deg.is_nan()));
        assert!(survives(&s).expect("encoded"));
    }

    #[test]
    fn a_judge_server_recomputes_a_run_bit_for_bit_as_the_run_does_and_declines_another_build() {
        let (s, cfg, run) = a_short_drive();
        let drive = Drive::plan(s.drive.as_ref().expect("a drive")).expect("plan");
        let mcap = run.path().join("nav.mcap");
        let w = Work {
            scenario: &s,
            nav_cfg: &cfg,
            reference: true,
            replay: true,
            drive: Some(&drive),
            mcap: &mcap,
        };
        let here = compute(&w, &mcap.display().to_string());
        let served = tempfile::tempdir().expect("tempdir");
        // no server: nothing is sent, the run judges itself
        assert!(ask(served.path(), &w).expect("ask").is_none());
        let stop = AtomicBool::new(false);
        let (there, other, stats) = std::thread::scope(|sc| {
            let server = sc.spawn(|| serve(served.path(), 2, &stop));
            while !served.path().join(ALIVE).exists() {
                std::thread::sleep(Duration::from_millis(10));
            }
            let there = ask(served.path(), &w);
            let mut another = Program::this().expect("program");
            another.exe_bytes += 1;
            let other = ask_as(served.path(), &w, another);
            // (stopped before any assertion: the scope waits for the server)
            stop.store(true, Ordering::Relaxed);
            let stats = server.join().expect("server").expect("served");
            (there, other, stats)
        });
        let there = there
            .expect("ask")
            .map(Ok)
            .expect("the server judged the run");
        let other = other.expect("ask");
        let replayed = there.as_ref().ok().and_then(|r| r.replayed.as_ref());
        let p = replayed.expect("a replay").as_ref().expect("replayed");
        assert!(p.frames_in > 1000, "{} frames replayed", p.frames_in);
        assert_eq!(p.summary.interface, format!("replay of {}", mcap.display()));
        assert!(
            there
                .as_ref()
                .ok()
                .and_then(|r| r.scored.as_ref())
                .is_some()
        );
        assert_eq!(wire_bytes(there), wire_bytes(here));
        assert!(other.is_none(), "another build's work is declined");
        assert_eq!((stats.done, stats.declined), (1, 1));
        // the server cleared its mark, and the runs their folders
        let left: Vec<_> = std::fs::read_dir(served.path()).expect("dir").collect();
        assert!(left.is_empty(), "{left:?}");
    }

    /// What a loaded config holds of its parameter files is not serialized (the redundant
    /// unit's coefficients): the server loads them from copies and gets the run's config.
    #[test]
    fn the_parameter_files_nav_ran_with_go_to_the_server_and_load_there_as_here() {
        let g = nav::procedures::unit_parameters::RedundantGyro {
            bias_dps: 0.05,
            scale_factor: 2e-3,
            sigma_j_deg: 0.1,
            sigma_k_deg: -0.1,
        };
        let p = nav::procedures::unit_parameters::RedundantParameters {
            format: nav::procedures::unit_parameters::REDUNDANT_FORMAT.into(),
            imu: "MEMS-1".into(),
            procedure: "test".into(),
            date: "2026-11-24T01:00:00Z".into(),
            gyro: vec![g; 4],
        };
        let run = tempfile::tempdir().expect("tempdir");
        std::fs::write(run.path().join("tetra.toml"), p.to_toml()).expect("write");
        let path = run.path().join("nav.toml");
        std::fs::write(
            &path,
            "[can]\ninterface = \"can0\"\n[tetra_calibration]\nenabled = true\nimu = \"MEMS-1\"\nparameters = \"tetra.toml\"\n",
        )
        .expect("write");
        let mut cfg = NavConfig::load(&path).expect("config");
        assert!(cfg.tetra_calibration.coefficients.is_some());
        // as a run has it: the file copied beside nav's config and named relative to it
        crate::scenario::navconfig::copy_inputs_beside(&mut cfg, run.path()).expect("copy");
        let folder = tempfile::tempdir().expect("tempdir");
        let sent = config_beside(&cfg, run.path(), folder.path()).expect("sent");
        // as the server reads it: the coefficients from the copy, the same but for the path
        let mut there: NavConfig = cbor_round_trip(&sent).expect("cbor");
        assert!(there.tetra_calibration.coefficients.is_none());
        there
            .load_input_files(&folder.path().join("nav.toml"))
            .expect("load");
        assert_eq!(
            there.tetra_calibration.coefficients,
            cfg.tetra_calibration.coefficients
        );
        assert_eq!(
            there.tetra_calibration.parameters,
            Some(folder.path().join("nav-tetra-parameters.toml"))
        );
        there.tetra_calibration.parameters = cfg.tetra_calibration.parameters.clone();
        assert_eq!(there, cfg);
    }

    #[test]
    fn a_server_declines_another_cpus_maths_before_another_build() {
        let me = Program::this().expect("program");
        assert_eq!(me.declines(&me.clone()), None);
        let mut other = me.clone();
        other.cpu = vec!["sse4.1".into()];
        other.exe_bytes += 1;
        assert!(me.declines(&other).expect("declined").contains("CPU"));
        other.cpu = me.cpu.clone();
        assert!(
            me.declines(&other)
                .expect("declined")
                .contains("another build")
        );
    }
}
