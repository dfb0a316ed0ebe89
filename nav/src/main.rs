//! `nav`: the production navigation program. It opens the CAN interface named in its config
//! file, decodes the IMU stream, checks it, removes the dither, integrates the attitude with
//! coning compensation, records it all, and on SIGINT/SIGTERM finishes its recording, prints a
//! summary and exits 0.

use anyhow::{Context, Result, bail};
use clap::Parser;
use nav::attitude::{ImuProcessor, ProcessingStats, Update, quaternion_to_rotation_vector};
use nav::config::NavConfig;
use nav::coning::ConingMethod;
use nav::earth;
use nav::fir::FirResponse;
use nav::imu::{Housekeeping, ImuEvent, ImuFrontEnd, ImuSample, ImuStats};
use nav::northfind::{NorthFinder, NorthResult, Phase};
use nav::record::{JsonChannel, Record, Recorder, wall_ns};
use serde::Serialize;
use std::collections::BTreeMap;
use std::os::fd::AsRawFd;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use tokio::signal::unix::{SignalKind, signal};
use tracing::{info, warn};
use wire::{DecodeError, Message, RawFrame};

#[derive(Parser)]
#[command(
    version,
    about = "Navigation computer of the RLG strapdown INS",
    long_about = "Navigation computer of the \
RLG strapdown INS. Opens the devices named in its config file (a CAN interface such as can0 or vcan0), decodes and \
checks the IMU stream, records raw and decoded data to MCAP, and on SIGINT/SIGTERM finishes the recording, prints \
a summary and exits 0."
)]
struct Cli {
    /// Config file (TOML).
    #[arg(short, long)]
    config: PathBuf,
    /// Print the summary as JSON on stdout instead of text.
    #[arg(long)]
    json: bool,
}

/// What `nav` reports at exit (also written to `record.summary`).
#[derive(Debug, Serialize)]
struct Summary {
    interface: String,
    frames_total: u64,
    frames_by_message: BTreeMap<&'static str, u64>,
    unknown_id_frames: u64,
    unknown_ids: Vec<String>,
    bad_length_frames: u64,
    invalid_value_frames: u64,
    non_data_frames: u64,
    read_errors: u64,
    imu: ImuStats,
    max_safe_gap_samples: u32,
    first_sample: Option<u64>,
    last_sample: Option<u64>,
    imu_seconds: f64,
    wall_seconds: f64,
    imu_timeouts: u64,
    /// Mean of the filtered, coning-compensated rate over the run.
    mean_rate_dph: [f64; 3],
    /// Mean of the filtered, sculling-compensated specific force.
    mean_specific_force_mps2: [f64; 3],
    rate_norm_dph: f64,
    specific_force_norm_mps2: f64,
    processing: ProcessingStats,
    attitude: AttitudeSummary,
    north_finding: Option<NorthFindingSummary>,
    gps: Option<GpsSummary>,
    navigation: Option<nav::navigator::NavigatorSummary>,
    housekeeping: Housekeeping,
    /// The navigation solution sent on the bus (NAV_TIME..NAV_HGT at 50 Hz of IMU time).
    solution: SolutionSummary,
    mcap: Option<PathBuf>,
    mcap_messages: u64,
}

/// The solution output on the bus at exit.
#[derive(Debug, Serialize, Default)]
struct SolutionSummary {
    /// Epochs encoded.
    epochs: u64,
    /// Frames written.
    frames_sent: u64,
    /// Frames the socket refused (the bus full); navigation is never held up by its output.
    send_errors: u64,
    /// The last epoch's mode.
    last_mode: Option<String>,
}

/// The GPS receiver at exit.
#[derive(Debug, Serialize)]
struct GpsSummary {
    /// Serial device.
    port: PathBuf,
    /// Stream counters.
    stats: nav::gps::GpsStats,
    /// Port trouble (read errors, the device vanishing), and re-opens.
    port_errors: u64,
    /// Times the port was (re)opened.
    opens: u64,
    /// Fixes handed to navigation.
    fixes: u64,
    /// The last fix.
    last_fix: Option<nav::gps::GpsFix>,
    /// Export file.
    fixes_jsonl: Option<PathBuf>,
}

/// North-finding at exit.
#[derive(Debug, Serialize)]
struct NorthFindingSummary {
    /// Last phase.
    phase: Phase,
    /// The result, when it finished.
    result: Option<NorthResult>,
    /// Why it gave up, when it did.
    abort: Option<String>,
    /// Turntable commands sent.
    commands_sent: u64,
    /// Turntable frames received (status, acks).
    turntable_frames: u64,
}

/// The integrated attitude at exit.
#[derive(Debug, Serialize)]
struct AttitudeSummary {
    /// The front end's first (baseline) sample.
    baseline_sample: Option<u64>,
    /// Sample the attitude is counted from (once the dither filter has filled).
    origin_sample: Option<i64>,
    /// Sample the attitude is valid at (last input minus the filter delay).
    valid_sample: i64,
    /// Samples between the two.
    span_samples: i64,
    /// Rotation of the body from origin to valid sample (inertial), as a rotation vector, deg.
    rotation_vector_deg: [f64; 3],
    /// Its angle, deg.
    angle_deg: f64,
    /// False when angle was lost (an ambiguous gap): the attitude is then unusable.
    valid: bool,
    /// Filter delay, samples.
    delay_samples: i64,
    /// The dither filter's measured response (none when it is off).
    fir: Option<FirResponse>,
    /// Coning algorithm.
    coning_method: ConingMethod,
    /// Coning coefficients k_1..k_(n-1).
    coning_coefficients: Vec<f64>,
}

#[derive(Default)]
struct Sums {
    samples: u64,
    first: Option<u64>,
    last: Option<u64>,
    phi: [f64; 3],
    dv_c: [f64; 3],
    updates: u64,
}

impl Sums {
    fn add(&mut self, s: &ImuSample) {
        if s.ambiguous {
            return;
        }
        self.samples += u64::from(s.span);
        self.first.get_or_insert(s.sample - u64::from(s.span));
        self.last = Some(s.sample);
    }
}

fn set_rcvbuf(fd: i32, bytes: usize) -> std::io::Result<()> {
    let v = bytes as libc::c_int;
    let len = std::mem::size_of::<libc::c_int>() as libc::socklen_t;
    let p = &v as *const libc::c_int as *const libc::c_void;
    // SAFETY: fd is an open socket, p points to a c_int of the given length.
    let r = unsafe { libc::setsockopt(fd, libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, p, len) };
    if r == 0 {
        return Ok(());
    }
    // SAFETY: as above; without CAP_NET_ADMIN fall back to the capped SO_RCVBUF.
    let r = unsafe { libc::setsockopt(fd, libc::SOL_SOCKET, libc::SO_RCVBUF, p, len) };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Whether this kernel can open CAN sockets at all.
fn kernel_has_can() -> bool {
    // SAFETY: plain socket(2); the descriptor is closed at once.
    let fd = unsafe { libc::socket(libc::AF_CAN, libc::SOCK_RAW, libc::CAN_RAW) };
    if fd >= 0 {
        // SAFETY: fd is ours.
        unsafe { libc::close(fd) };
    }
    fd >= 0
}

fn open_error_hint(iface: &str, e: &std::io::Error) -> String {
    if !kernel_has_can() {
        return "this kernel has no CAN support (modprobe can_raw; on the bench, runs go through vcan-setup)".into();
    }
    match e.raw_os_error() {
        Some(libc::ENODEV) => format!(
            "no such CAN interface {iface} (is it created and up? on the bench: `vcan-setup up {iface}`)"
        ),
        Some(libc::EAFNOSUPPORT) => {
            "this kernel has no CAN support (modprobe can_raw, or run through vcan-setup)".into()
        }
        Some(libc::EPERM) | Some(libc::EACCES) => format!("no permission to open {iface}"),
        _ => e.to_string(),
    }
}

fn main() {
    nav::cli::init_tracing();
    std::process::exit(nav::cli::exit_code("nav", real_main(), |()| 0));
}

fn real_main() -> Result<()> {
    let cli = Cli::parse();
    let cfg = NavConfig::load(&cli.config)?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the runtime")?;
    let summary = rt.block_on(run(&cfg))?;
    if cli.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print_summary(&summary);
    }
    Ok(())
}

async fn run(cfg: &NavConfig) -> Result<Summary> {
    let iface = cfg.can.as_ref().map_or("none", |c| c.interface.as_str());
    let sock = match &cfg.can {
        Some(c) => {
            let sock = socketcan::tokio::CanSocket::open(iface).map_err(|e| {
                anyhow::anyhow!("CAN interface {iface}: {}", open_error_hint(iface, &e))
            })?;
            if let Err(e) = set_rcvbuf(sock.as_raw_fd(), c.rcvbuf_bytes) {
                warn!(
                    interface = iface,
                    "cannot enlarge the receive buffer to {} bytes: {e}", c.rcvbuf_bytes
                );
            }
            Some(sock)
        }
        None => None,
    };
    let gps = match &cfg.gps {
        Some(g) => Some(nav::gpsport::GpsPort::start(g)?),
        None => None,
    };
    let (gps_tx, mut gps_rx) = tokio::sync::mpsc::unbounded_channel::<nav::gps::GpsFix>();
    if let Some(g) = &gps {
        g.forward(gps_tx);
    } else {
        drop(gps_tx);
    }
    let mut gps_fixes = 0u64;
    let mut navigator = cfg
        .navigation
        .enabled
        .then(|| nav::navigator::Navigator::new(cfg.navigation.clone()));
    let mut last_fix: Option<nav::gps::GpsFix> = None;
    let recorder = match &cfg.record.mcap {
        Some(p) => Some(Recorder::start(p)?),
        None => None,
    };
    let mut sigint = signal(SignalKind::interrupt()).context("installing the SIGINT handler")?;
    let mut sigterm = signal(SignalKind::terminate()).context("installing the SIGTERM handler")?;
    let mut fe = ImuFrontEnd::new(cfg.imu);
    let mut proc = ImuProcessor::new(&cfg.processing).context("processing chain")?;
    let fir_response = proc.fir_response();
    let mut finder = if cfg.north_finding.enabled {
        Some(NorthFinder::new(cfg.north_finding.clone()).map_err(anyhow::Error::msg)?)
    } else {
        None
    };
    let mut nf_cmds: Vec<wire::TtCmd> = Vec::new();
    let (mut nf_sent, mut nf_frames) = (0u64, 0u64);
    let mut nf_last_print = f64::NEG_INFINITY;
    let mut nf_last_phase = None;
    let mut nf_reported = false;
    let mut nf_handed = false;
    let out_every = (cfg.imu.rate_hz / 50.0).round().max(1.0) as u64;
    let mut next_out: Option<u64> = None;
    let mut sol_enc = nav::output::SolutionEncoder::default();
    let mut sol = SolutionSummary::default();
    let mut sol_frames: Vec<RawFrame> = Vec::new();
    let mut sums = Sums::default();
    let mut by_msg: BTreeMap<&'static str, u64> = BTreeMap::new();
    let mut unknown: BTreeMap<u32, u64> = BTreeMap::new();
    let (mut bad_len, mut invalid, mut non_data, mut read_errors, mut total) =
        (0u64, 0u64, 0u64, 0u64, 0u64);
    let mut timeouts = 0u64;
    let (mut out, mut ev) = (Vec::new(), Vec::new());
    let mut batch = Vec::with_capacity(wire::BATCH);
    let start = Instant::now();
    let mut last_imu = Instant::now();
    let mut in_timeout = false;
    let timeout = Duration::from_millis(cfg.watchdog.imu_timeout_ms);
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    let sample_ns = 1e9 / cfg.imu.rate_hz;
    info!(interface = iface, "receiving");
    match &cfg.gps {
        Some(g) => println!("nav: receiving on {iface} and {}", g.port.display()),
        None => println!("nav: receiving on {iface}"),
    }
    let event = |rec: &Option<Recorder>, sample: u64, json: String| {
        if let Some(r) = rec {
            r.send(Record::Json {
                channel: JsonChannel::Event,
                t_ns: wall_ns(),
                publish_ns: (sample as f64 * sample_ns) as u64,
                json,
            });
        }
    };
    loop {
        tokio::select! {
            // in this order: a signal, then a waiting GPS fix before more IMU frames (a fix is
            // applied at an IMU time of its own, so it must not wait behind a burst of frames)
            biased;
            _ = sigint.recv() => { info!("SIGINT: finishing"); break; }
            _ = sigterm.recv() => { info!("SIGTERM: finishing"); break; }
            Some(fix) = gps_rx.recv() => {
                gps_fixes += 1;
                if let (Some(r), Ok(json)) = (&recorder, serde_json::to_string(&fix)) {
                    r.send(Record::Json { channel: JsonChannel::Gps, t_ns: wall_ns(), publish_ns: wall_ns(), json });
                }
                if let Some(n) = navigator.as_mut() {
                    n.on_fix(&fix);
                }
                last_fix = Some(fix);
            }
            r = async {
                match &sock {
                    Some(s) => s.read_frame().await,
                    None => std::future::pending().await,
                }
            } => {
                let f = match r {
                    Ok(f) => f,
                    Err(e) => {
                        read_errors += 1;
                        match e.raw_os_error() {
                            Some(libc::ENODEV) | Some(libc::ENXIO) => bail!("CAN interface {iface} disappeared: {e}"),
                            _ => {
                                warn!(interface = iface, "read error: {e}");
                                tokio::time::sleep(Duration::from_millis(10)).await;
                                continue;
                            }
                        }
                    }
                };
                // every frame already waiting comes in the same system call (recvmmsg)
                batch.push(wire::from_can_frame(&f));
                if let Some(s) = &sock {
                    let _ = wire::recv_batch(s.as_raw_fd(), &mut batch, wire::BATCH - 1);
                }
                for conv in batch.drain(..) {
                    total += 1;
                    let raw = match conv {
                        Ok(r) => r,
                        Err(e) => {
                            non_data += 1;
                            if non_data <= 5 {
                                warn!(interface = iface, "ignored: {e}");
                            }
                            event(&recorder, fe.stats().samples, format!("{{\"kind\":\"non_data_frame\",\"detail\":{}}}", serde_json::to_string(&e.to_string())?));
                            continue;
                        }
                    };
                    if let Some(r) = &recorder {
                        r.send(Record::Frame { t_ns: wall_ns(), frame: raw });
                    }
                    match Message::decode(&raw) {
                        Ok(m) => {
                            *by_msg.entry(m.spec().name).or_insert(0) += 1;
                            if matches!(m, Message::ImuGyro(_)) {
                                last_imu = Instant::now();
                            }
                            if let Some(f) = finder.as_mut() {
                                match &m {
                                    Message::TtStatus(st) => { nf_frames += 1; f.on_status(st); }
                                    Message::TtAck(a) => { nf_frames += 1; f.on_ack(a); }
                                    _ => {}
                                }
                            }
                            fe.on_message(&m, &mut out, &mut ev);
                        }
                        Err(e) => report_bad_frame(&e, &raw, iface, &mut unknown, &mut bad_len, &mut invalid, &recorder, fe.stats().samples),
                    }
                    drain(&mut out, &mut ev, &mut sums, &mut proc, &recorder, sample_ns, finder.as_mut(), navigator.as_mut(), cfg.processing.coning_samples);
                    if let (Some(n), Some(r)) = (navigator.as_mut(), finder.as_ref().and_then(|f| f.result())) && !nf_handed {
                        n.set_heading(r.heading_deg);
                        nf_handed = true;
                    }
                    if let Some(f) = finder.as_mut() {
                        let t = proc.valid_sample().saturating_sub(proc.baseline().map_or(0, |b| b as i64)) as f64 / cfg.imu.rate_hz;
                        while let Some(c) = f.poll(t.max(0.0)) {
                            nf_cmds.push(c);
                            if f.finished() { break; }
                        }
                        for c in nf_cmds.drain(..) {
                            if let Some(s) = &sock {
                                send_command(s, iface, c).await?;
                                nf_sent += 1;
                            }
                        }
                        report_north_finding(f, t, &mut nf_last_print, &mut nf_last_phase, &mut nf_reported, &recorder);
                    }
                    // the solution at 50 Hz of IMU time
                    if let (Some(s), Some(last)) = (&sock, sums.last)
                        && last >= *next_out.get_or_insert(last)
                    {
                        next_out = Some(last + out_every);
                        let st = fe.stats();
                        let nf_running = finder.as_ref().is_some_and(|f| !f.finished());
                        let mode = match (&navigator, nf_running) {
                            (_, true) => wire::NavMode::NorthFinding,
                            (Some(n), false) => n.mode(),
                            (None, false) => wire::NavMode::Init,
                        };
                        let sigmas = navigator.as_ref().and_then(|n| n.sigmas());
                        let solution = nav::output::Solution {
                            sample_count: last,
                            mode,
                            health: wire::NavHealth {
                                imu_timeout: in_timeout,
                                imu_gaps: st.gaps > 0,
                                imu_bit: st.bit_fail_samples > 0,
                                gps_stale: cfg.gps.is_some() && navigator.as_ref().is_none_or(|n| n.gps_stale()),
                                turntable: finder.as_ref().is_some_and(|f| f.abort_reason().is_some()),
                                filter: proc.stats().invalid_since.is_some()
                                    || navigator.as_ref().and_then(|n| n.filter()).is_some_and(|k| k.stats().reanchors > 0),
                            },
                            output: navigator.as_ref().and_then(|n| n.state()).map(|x| x.output()),
                            pos_sigma_m: sigmas.map_or(0.0, |x| x.0),
                            heading_sigma_deg: sigmas.map_or(0.0, |x| x.1),
                        };
                        // once a second of IMU time, the solution goes in the recording too
                        if sol_enc.epochs.is_multiple_of(50)
                            && let (Some(r), Some(o), Some(n)) = (&recorder, &solution.output, &navigator)
                        {
                            let j = serde_json::json!({
                                "t_s": n.time(),
                                "mode": format!("{mode:?}"),
                                "output": o,
                                "pos_sigma_m": solution.pos_sigma_m,
                                "heading_sigma_deg": solution.heading_sigma_deg,
                            });
                            r.send(Record::Json {
                                channel: JsonChannel::Solution,
                                t_ns: wall_ns(),
                                publish_ns: (last as f64 * sample_ns) as u64,
                                json: j.to_string(),
                            });
                        }
                        sol_enc.encode(&solution, &mut sol_frames);
                        sol.last_mode = Some(format!("{mode:?}"));
                        for f in sol_frames.drain(..) {
                            match wire::to_can_frame(&f) {
                                Ok(frame) => match s.try_write_frame(frame) {
                                    Ok(()) => sol.frames_sent += 1,
                                    Err(e) => {
                                        sol.send_errors += 1;
                                        if sol.send_errors <= 3 {
                                            warn!(interface = iface, "solution frame 0x{:03X} not sent: {e}", f.id);
                                        }
                                    }
                                },
                                Err(_) => sol.send_errors += 1,
                            }
                        }
                    }
                    if in_timeout && last_imu.elapsed() < timeout {
                        info!(interface = iface, "IMU data back");
                        in_timeout = false;
                    }
                }
            }
            _ = tick.tick() => {
                if !in_timeout && last_imu.elapsed() > timeout && fe.stats().gyro_frames > 0 {
                    timeouts += 1;
                    in_timeout = true;
                    warn!(interface = iface, "no IMU frame for {} ms (last sample {:?})", timeout.as_millis(), sums.last);
                    event(&recorder, sums.last.unwrap_or(0), format!("{{\"kind\":\"imu_timeout\",\"after_ms\":{}}}", timeout.as_millis()));
                }
            }
        }
    }
    fe.flush(&mut out, &mut ev);
    drain(
        &mut out,
        &mut ev,
        &mut sums,
        &mut proc,
        &recorder,
        sample_ns,
        finder.as_mut(),
        navigator.as_mut(),
        cfg.processing.coning_samples,
    );
    let dt = 1.0 / cfg.imu.rate_hz;
    let n = (sums.updates * cfg.processing.coning_samples as u64).max(1) as f64;
    let mean_rate_dph = sums
        .phi
        .map(|x| x / (n * dt) * earth::DEG_PER_HOUR_PER_RAD_S);
    let mean_f = sums.dv_c.map(|x| x / (n * dt));
    let pst = proc.stats();
    let rv = quaternion_to_rotation_vector(&proc.attitude()).map(f64::to_degrees);
    let attitude = AttitudeSummary {
        baseline_sample: proc.baseline(),
        origin_sample: proc.origin(),
        valid_sample: proc.valid_sample(),
        span_samples: proc.valid_sample() - proc.origin().unwrap_or(0),
        rotation_vector_deg: rv,
        angle_deg: proc.attitude().angle().to_degrees(),
        valid: pst.invalid_since.is_none(),
        delay_samples: proc.delay(),
        fir: fir_response,
        coning_method: cfg.processing.coning,
        coning_coefficients: proc.coefficients().k.clone(),
    };
    let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let mut summary = Summary {
        interface: iface.to_string(),
        frames_total: total,
        frames_by_message: by_msg,
        unknown_id_frames: unknown.values().sum(),
        unknown_ids: unknown.keys().map(|id| format!("0x{id:03X}")).collect(),
        bad_length_frames: bad_len,
        invalid_value_frames: invalid,
        non_data_frames: non_data,
        read_errors,
        imu: fe.stats(),
        max_safe_gap_samples: fe.max_span(),
        first_sample: sums.first,
        last_sample: sums.last,
        imu_seconds: sums.samples as f64 * dt,
        wall_seconds: start.elapsed().as_secs_f64(),
        imu_timeouts: timeouts,
        mean_rate_dph,
        mean_specific_force_mps2: mean_f,
        rate_norm_dph: norm(mean_rate_dph),
        specific_force_norm_mps2: norm(mean_f),
        processing: pst,
        attitude,
        navigation: navigator.as_ref().map(|n| n.summary()),
        gps: match gps {
            Some(g) => {
                let (stats, port_errors, opens) = g.finish();
                Some(GpsSummary {
                    port: cfg.gps.as_ref().map(|c| c.port.clone()).unwrap_or_default(),
                    stats,
                    port_errors,
                    opens,
                    fixes: gps_fixes,
                    last_fix,
                    fixes_jsonl: cfg.gps.as_ref().and_then(|c| c.fixes_jsonl.clone()),
                })
            }
            None => None,
        },
        north_finding: finder.map(|f| NorthFindingSummary {
            phase: f.phase(),
            result: f.result().cloned(),
            abort: f.abort_reason().map(str::to_string),
            commands_sent: nf_sent,
            turntable_frames: nf_frames,
        }),
        housekeeping: fe.housekeeping(),
        solution: SolutionSummary {
            epochs: sol_enc.epochs,
            ..sol
        },
        mcap: cfg.record.mcap.clone(),
        mcap_messages: 0,
    };
    if let Some(r) = recorder {
        r.send(Record::Json {
            channel: JsonChannel::Summary,
            t_ns: wall_ns(),
            publish_ns: (sums.last.unwrap_or(0) as f64 * sample_ns) as u64,
            json: serde_json::to_string(&summary)?,
        });
        summary.mcap_messages = r.finish()?;
    }
    if let Some(p) = &cfg.record.summary {
        std::fs::write(p, serde_json::to_string_pretty(&summary)?)
            .with_context(|| format!("writing summary {}", p.display()))?;
    }
    Ok(summary)
}

#[allow(clippy::too_many_arguments)]
fn report_bad_frame(
    e: &DecodeError,
    raw: &RawFrame,
    iface: &str,
    unknown: &mut BTreeMap<u32, u64>,
    bad_len: &mut u64,
    invalid: &mut u64,
    recorder: &Option<Recorder>,
    sample: u64,
) {
    let first = match e {
        DecodeError::UnknownId { id } => {
            let c = unknown.entry(*id).or_insert(0);
            *c += 1;
            *c == 1
        }
        DecodeError::WrongLength { .. } => {
            *bad_len += 1;
            *bad_len <= 5
        }
        _ => {
            *invalid += 1;
            *invalid <= 5
        }
    };
    if first {
        warn!(
            interface = iface,
            "bad frame near IMU sample {sample}: {e} (data {:02X?})",
            raw.payload()
        );
    }
    if let Some(r) = recorder {
        let json = serde_json::json!({"kind": "bad_frame", "sample": sample, "id": raw.id, "len": raw.len, "error": e.to_string()});
        r.send(Record::Json {
            channel: JsonChannel::Event,
            t_ns: wall_ns(),
            publish_ns: 0,
            json: json.to_string(),
        });
    }
}

/// Send one turntable command on the bus.
async fn send_command(
    sock: &socketcan::tokio::CanSocket,
    iface: &str,
    c: wire::TtCmd,
) -> Result<()> {
    let raw = Message::TtCmd(c)
        .encode()
        .map_err(|e| anyhow::anyhow!("encoding TT_CMD: {e}"))?;
    let frame = wire::to_can_frame(&raw).map_err(|e| anyhow::anyhow!("TT_CMD frame: {e}"))?;
    sock.write_frame(frame)
        .await
        .with_context(|| format!("CAN interface {iface}: sending TT_CMD"))?;
    Ok(())
}

/// Progress lines on stdout (`nav: north-finding progress {json}` at most once per second of
/// IMU time and at every phase change; `nav: north-finding result {json}` or
/// `nav: north-finding aborted: reason` once), and the same as events in the recording.
fn report_north_finding(
    f: &NorthFinder,
    t: f64,
    last_print: &mut f64,
    last_phase: &mut Option<(Phase, usize)>,
    reported: &mut bool,
    rec: &Option<Recorder>,
) {
    let stage = f.stage();
    // every stage change, and once a second while it runs (not after it has finished)
    if *last_phase != Some(stage) || (t - *last_print >= 1.0 && !f.finished()) {
        *last_print = t;
        *last_phase = Some(stage);
        let p = f.progress();
        if let Ok(j) = serde_json::to_string(&p) {
            println!("nav: north-finding progress {j}");
            if let Some(r) = rec {
                r.send(Record::Json {
                    channel: JsonChannel::Event,
                    t_ns: wall_ns(),
                    publish_ns: (t * 1e9) as u64,
                    json: format!("{{\"kind\":\"north_finding_progress\",\"progress\":{j}}}"),
                });
            }
        }
    }
    if f.finished() && !*reported {
        *reported = true;
        if let Some(r) = f.result() {
            let j = serde_json::to_string(r).unwrap_or_default();
            info!(
                heading_deg = r.heading_deg,
                sigma_deg = r.sigma_deg,
                "north found"
            );
            println!("nav: north-finding result {j}");
        } else {
            let why = f.abort_reason().unwrap_or("unknown");
            warn!("north-finding aborted: {why}");
            println!("nav: north-finding aborted: {why}");
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn drain(
    out: &mut Vec<ImuSample>,
    ev: &mut Vec<ImuEvent>,
    sums: &mut Sums,
    proc: &mut ImuProcessor,
    rec: &Option<Recorder>,
    sample_ns: f64,
    mut finder: Option<&mut NorthFinder>,
    mut navigator: Option<&mut nav::navigator::Navigator>,
    coning_samples: usize,
) {
    let mut updates: Vec<Update> = Vec::new();
    for e in ev.drain(..) {
        match e {
            ImuEvent::Gap { .. } | ImuEvent::AccelMissing { .. } => tracing::debug!("IMU: {e:?}"),
            _ => warn!("IMU: {e:?}"),
        }
        if let (Some(r), Ok(json)) = (rec, serde_json::to_string(&e)) {
            r.send(Record::Json {
                channel: JsonChannel::Event,
                t_ns: wall_ns(),
                publish_ns: 0,
                json,
            });
        }
    }
    for s in out.drain(..) {
        sums.add(&s);
        let invalid_before = proc.stats().invalid_since.is_some();
        proc.push_sample(&s, &mut updates);
        // the PPS edge came `o` samples before the end of this sample (time from the baseline)
        if let (Some(n), Some(o), Some(b)) =
            (navigator.as_deref_mut(), s.pps_offset, proc.baseline())
        {
            n.on_pps(((s.sample - b) as f64 - o) * sample_ns * 1e-9);
        }
        if !invalid_before && let Some(k) = proc.stats().invalid_since {
            warn!("attitude invalid from sample {k}: counter gap too long to difference");
        }
        let base = proc.baseline().map_or(0, |b| b as i64);
        for u in updates.drain(..) {
            let tu = (u.valid_sample - base) as f64 * sample_ns * 1e-9;
            if let Some(f) = finder.as_deref_mut() {
                f.on_update(tu, u.phi, u.dv);
            }
            // navigation takes over once north-finding (when it runs) is finished
            if let Some(n) = navigator.as_deref_mut()
                && finder.as_deref().is_none_or(|f| f.finished())
            {
                n.on_update(tu, u.phi, u.dv, coning_samples as f64 * sample_ns * 1e-9);
            }
            sums.updates += 1;
            for a in 0..3 {
                sums.phi[a] += u.phi[a];
                sums.dv_c[a] += u.dv[a];
            }
            if let Some(r) = rec
                && sums.updates.is_multiple_of(50)
            {
                let rv = quaternion_to_rotation_vector(&proc.attitude()).map(f64::to_degrees);
                r.send(Record::Json {
                    channel: JsonChannel::Attitude,
                    t_ns: wall_ns(),
                    publish_ns: (u.valid_sample.max(0) as f64 * sample_ns) as u64,
                    json: format!(
                        "{{\"valid_sample\":{},\"rotation_vector_deg\":[{:.9},{:.9},{:.9}]}}",
                        u.valid_sample, rv[0], rv[1], rv[2]
                    ),
                });
            }
        }
        if let Some(r) = rec {
            let publish_ns = (s.sample as f64 * sample_ns) as u64;
            r.send(Record::Sample {
                t_ns: wall_ns(),
                publish_ns,
                sample: s,
            });
        }
    }
}

fn print_summary(s: &Summary) {
    println!("nav summary ({})", s.interface);
    println!(
        "  frames received   {} ({:?})",
        s.frames_total, s.frames_by_message
    );
    println!(
        "  IMU samples       {} over {:.3} s of IMU time ({:.1} s wall)",
        s.imu.samples, s.imu_seconds, s.wall_seconds
    );
    println!(
        "  gaps              {} ({} samples lost, {} too long to difference), duplicates {}, backwards {}",
        s.imu.gaps, s.imu.missing_samples, s.imu.ambiguous_gaps, s.imu.duplicates, s.imu.backwards
    );
    println!(
        "  bad frames        unknown id {} {:?}, wrong length {}, invalid {}, non-data {}, read errors {}",
        s.unknown_id_frames,
        s.unknown_ids,
        s.bad_length_frames,
        s.invalid_value_frames,
        s.non_data_frames,
        s.read_errors
    );
    println!(
        "  accel frames      missing {}, unpaired {}; BIT-fail samples {}, saturated {}, PPS edges {}",
        s.imu.accel_missing,
        s.imu.accel_unpaired,
        s.imu.bit_fail_samples,
        s.imu.saturated_samples,
        s.imu.pps_edges
    );
    println!(
        "  mean rate         [{:.3}, {:.3}, {:.3}] deg/h, |w| = {:.3} deg/h",
        s.mean_rate_dph[0], s.mean_rate_dph[1], s.mean_rate_dph[2], s.rate_norm_dph
    );
    println!(
        "  mean spec. force  [{:.5}, {:.5}, {:.5}] m/s^2, |f| = {:.5} m/s^2",
        s.mean_specific_force_mps2[0],
        s.mean_specific_force_mps2[1],
        s.mean_specific_force_mps2[2],
        s.specific_force_norm_mps2
    );
    println!(
        "  attitude          {:.6} deg about [{:.6}, {:.6}, {:.6}] deg over {} samples ({}), filter delay {} samples, coning {} n={}",
        s.attitude.angle_deg,
        s.attitude.rotation_vector_deg[0],
        s.attitude.rotation_vector_deg[1],
        s.attitude.rotation_vector_deg[2],
        s.attitude.span_samples,
        if s.attitude.valid {
            "valid"
        } else {
            "INVALID: angle lost in a gap"
        },
        s.attitude.delay_samples,
        s.attitude.coning_method,
        s.attitude.coning_coefficients.len() + 1
    );
    println!(
        "  integrity         {} samples filled across gaps, {} lost, {} suspect (saturated/BIT) from {:?}",
        s.processing.filled_samples,
        s.processing.lost_samples,
        s.processing.suspect_samples,
        s.processing.first_suspect
    );
    println!("  IMU timeouts      {}", s.imu_timeouts);
    if let Some(n) = &s.navigation {
        match &n.output {
            Some(o) => println!(
                "  navigation        {:?}: lat {:.7} lon {:.7} h {:.1} m, vel [{:.2}, {:.2}, {:.2}] m/s, heading {:.3} deg; filter {:?}",
                n.phase,
                o.lat_deg,
                o.lon_deg,
                o.h_m,
                o.vel_enu_mps[0],
                o.vel_enu_mps[1],
                o.vel_enu_mps[2],
                o.hpr_deg[0],
                n.filter
            ),
            None => println!("  navigation        {:?} (not started)", n.phase),
        }
    }
    if let Some(g) = &s.gps {
        let t = &g.stats;
        println!(
            "  GPS {}  fixes {} ({} no-fix, {} out of range, {} time backwards); sentences {}, bad checksum {}, unparsed {}, garbage bytes {}, binary lines {}, overlong {}; port errors {}, opens {}",
            g.port.display(),
            t.fixes,
            t.no_fix,
            t.out_of_range,
            t.time_backwards,
            t.accepted,
            t.bad_checksum,
            t.unparsed,
            t.garbage_bytes,
            t.binary_lines,
            t.overlong_lines,
            g.port_errors,
            g.opens
        );
    }
    if let Some(p) = &s.mcap {
        println!(
            "  recording         {} ({} messages)",
            p.display(),
            s.mcap_messages
        );
    }
}
