//! `nav`: the production navigation program. A thin shell around [`nav::pipeline`]: it reads
//! its config, opens the CAN interface and the GPS port named there, records, and feeds the
//! pipeline every frame and fix, doing what the pipeline asks (send a command or a solution
//! frame, record, print). On SIGINT/SIGTERM it finishes its recording, prints a summary and
//! exits 0. Wall time serves only the liveness watchdog.

use anyhow::{Context, Result, bail};
use clap::Parser;
use nav::config::NavConfig;
use nav::pipeline::{Output, Pipeline};
use nav::record::writer::{Record, Recorder, wall_ns};
use nav::shell::gps_port::GpsEvent;
use nav::summary::Summary;
use std::os::fd::AsRawFd;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use tokio::signal::unix::{SignalKind, signal};
use tracing::{info, warn};
use wire::RawFrame;

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
    /// Check the config (and the IMU parameter file its `[calibration]` names), say what nav
    /// would use, and exit without opening any device.
    #[arg(long)]
    check: bool,
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
    nav::shell::cli::init_tracing();
    std::process::exit(nav::shell::cli::exit_code("nav", real_main(), |()| 0));
}

fn real_main() -> Result<()> {
    let cli = Cli::parse();
    let cfg = NavConfig::load(&cli.config)?;
    if let Some(c) = &cfg.calibration {
        tracing::info!(
            imu = %c.imu,
            file = %c.parameters.display(),
            "gyro calibration: bias {:?} deg/h, scale factor {:?} ppm",
            cfg.imu.gyro_bias_dph,
            cfg.imu.gyro_scale_factor_ppm
        );
    }
    if cfg.north_finding.enabled {
        match cfg.north_finding.check_plan() {
            (_, Some(why)) => warn!("{why}"),
            (p, None) => info!(
                "north-finding: predicted heading sigma {:.4} deg ({:.0} s dwells at {} positions, latitude {:.4} deg)",
                p.sigma_deg,
                cfg.north_finding.dwell_s,
                cfg.north_finding.positions_deg.len(),
                cfg.north_finding.latitude_deg
            ),
        }
    }
    if cli.check {
        println!(
            "nav: config {} is valid: gyro bias {:?} deg/h, scale factor {:?} ppm{}",
            cli.config.display(),
            cfg.imu.gyro_bias_dph,
            cfg.imu.gyro_scale_factor_ppm,
            cfg.calibration.as_ref().map_or(String::new(), |c| format!(
                " (from {} for unit {})",
                c.parameters.display(),
                c.imu
            ))
        );
        return Ok(());
    }
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the runtime")?;
    let summary = rt.block_on(run(&cfg))?;
    if cli.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print!("{}", summary.text());
    }
    Ok(())
}

/// Open the CAN socket of `c` with its receive buffer; whether it gives each frame's kernel
/// receive time.
fn open_can(c: &nav::config::CanConfig) -> Result<(socketcan::tokio::CanSocket, bool)> {
    let iface = c.interface.as_str();
    let sock = socketcan::tokio::CanSocket::open(iface)
        .map_err(|e| anyhow::anyhow!("CAN interface {iface}: {}", open_error_hint(iface, &e)))?;
    // the kernel's receive time of every frame, for the recording (candump's time stamps)
    // and the order of the receiver's bytes among the frames (nav::shell::arrival)
    let stamped = match socketcan::SocketOptions::set_recv_timestamp(&sock, true) {
        Ok(()) => true,
        Err(e) => {
            warn!(
                interface = iface,
                "no kernel receive times (SO_TIMESTAMPNS: {e}): frames are recorded at read time, and the receiver's bytes go in as they are read"
            );
            false
        }
    };
    // the controller's error frames (bus errors, error-passive, bus-off, restarts): counted,
    // reported, a health bit
    if let Err(e) = wire::set_error_filter(sock.as_raw_fd(), wire::errframe::CAN_ERR_MASK) {
        warn!(
            interface = iface,
            "cannot receive the controller's error frames (CAN_RAW_ERR_FILTER: {e}): bus errors and bus-off go unreported"
        );
    }
    match wire::set_rcvbuf(sock.as_raw_fd(), c.rcvbuf_bytes) {
        Ok(got) if got < c.rcvbuf_bytes => warn!(
            interface = iface,
            "the receive buffer is {got} bytes, not the {} asked for: the system caps it (raise net.core.rmem_max, or give nav CAP_NET_ADMIN)",
            c.rcvbuf_bytes
        ),
        Ok(_) => {}
        Err(e) => warn!(
            interface = iface,
            "cannot enlarge the receive buffer to {} bytes: {e}", c.rcvbuf_bytes
        ),
    }
    Ok((sock, stamped))
}

async fn run(cfg: &NavConfig) -> Result<Summary> {
    let iface = cfg.can.as_ref().map_or("none", |c| c.interface.as_str());
    let (sock, stamped) = match &cfg.can {
        Some(c) => {
            let (s, stamped) = open_can(c)?;
            (Some(s), stamped)
        }
        None => (None, false),
    };
    let mut gps = cfg.gps.as_ref().map(nav::shell::gps_port::GpsPort::new);
    let export = open_export(cfg)?;
    let recorder = match &cfg.record.mcap {
        Some(p) => Some(Recorder::start(p)?),
        None => None,
    };
    let mut pipeline = Pipeline::new(cfg, recorder.is_some())?;
    let mut sigint = signal(SignalKind::interrupt()).context("installing the SIGINT handler")?;
    let mut sigterm = signal(SignalKind::terminate()).context("installing the SIGTERM handler")?;
    let wait = Duration::from_millis(cfg.watchdog.imu_timeout_ms);
    let mut shell = Shell::new(iface, sock, stamped, recorder.as_ref(), export, wait);
    let mut out = Vec::new();
    let mut batch = Vec::with_capacity(wire::BATCH);
    let mut read_errors = 0u64;
    let start = Instant::now();
    let mut watch = ImuWatch {
        gyro_frames: 0,
        last: Instant::now(),
        timeout_ms: cfg.watchdog.imu_timeout_ms,
    };
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    info!(interface = iface, "receiving");
    match &cfg.gps {
        Some(g) => println!("nav: receiving on {iface} and {}", g.port.display()),
        None => println!("nav: receiving on {iface}"),
    }
    loop {
        tokio::select! {
            // in this order: a signal, then the receiver's port, then more IMU frames
            biased;
            _ = sigint.recv() => { info!("SIGINT: finishing"); break; }
            _ = sigterm.recv() => { info!("SIGTERM: finishing"); break; }
            ev = async {
                match gps.as_mut() {
                    Some(g) => g.next().await,
                    None => std::future::pending().await,
                }
            } => read_errors += on_gps_event(ev, &mut batch, &mut pipeline, &mut shell, &mut out).await?,
            r = async {
                match &shell.sock {
                    Some(s) => s.read_frame_with_timestamps().await,
                    None => std::future::pending().await,
                }
            } => {
                let (f, stamps) = match r {
                    Ok(f) => f,
                    Err(e) => {
                        read_errors += 1;
                        match e.raw_os_error() {
                            Some(libc::ENODEV) | Some(libc::ENXIO) => bail!("CAN interface {iface} disappeared: {e}"),
                            _ => {
                                // the interface went down (a controller restart, a cable
                                // pulled): the socket says so once and receives again once the
                                // interface is back (tests/tests/vcan.rs checks it)
                                warn!(interface = iface, "read error: {e}");
                                tokio::time::sleep(Duration::from_millis(10)).await;
                                continue;
                            }
                        }
                    }
                };
                read_errors += on_frame(f, stamps.socket.and_then(epoch_ns), &mut watch, &mut batch, &mut pipeline, &mut shell, &mut out).await?;
            }
            // the receiver's bytes that waited as long as they may for a later frame
            _ = until(shell.waiting.deadline()) => {
                read_errors += drain_can(&mut batch, &shell);
                let release = nav::shell::arrival::Release::Expired(Instant::now());
                take_in_order(&mut batch, release, &mut pipeline, &mut shell, &mut out).await?;
            }
            _ = tick.tick() => {
                read_errors += watch.check(&mut batch, &mut pipeline, &mut shell, &mut out).await?;
                if let Some(r) = shell.recorder {
                    r.ship_due();
                }
            }
        }
    }
    let ended = Ended {
        gps,
        read_errors,
        start,
    };
    let mut summary = finish(cfg, ended, &mut pipeline, &mut shell, &mut batch, &mut out).await?;
    drop(shell);
    write_summary(cfg, recorder, &mut summary)?;
    Ok(summary)
}

/// The GPS fix export (a JSON line per decoded fix), when the config asks for one.
fn open_export(cfg: &NavConfig) -> Result<Option<std::io::BufWriter<std::fs::File>>> {
    match cfg.gps.as_ref().and_then(|g| g.fixes_jsonl.as_ref()) {
        Some(p) => Ok(Some(std::io::BufWriter::new(
            std::fs::File::create(p)
                .with_context(|| format!("cannot create the GPS fix export {}", p.display()))?,
        ))),
        None => Ok(None),
    }
}

/// The IMU watchdog: how many gyro frames nav has taken, and when the last came.
struct ImuWatch {
    gyro_frames: u64,
    last: Instant,
    timeout_ms: u64,
}

impl ImuWatch {
    /// Once a tick: the IMU is silent when no gyro frame came within the timeout. The
    /// receiver's bytes read before the silence go in before the watchdog's report (no frame
    /// after them will come to release them: `nav::shell::arrival`). Returns the read errors met.
    async fn check(
        &mut self,
        batch: &mut Vec<Received>,
        pipeline: &mut Pipeline,
        shell: &mut Shell<'_>,
        out: &mut Vec<Output>,
    ) -> Result<u64> {
        let mut read_errors = 0;
        // an IMU frame waiting in the socket means the loop is late (a loaded computer, a
        // process stopped and continued), not that the IMU is silent
        if self.gyro_frames > 0
            && self.last.elapsed() > Duration::from_millis(self.timeout_ms)
            && !shell
                .sock
                .as_ref()
                .is_some_and(|s| imu_frame_waiting(s.as_raw_fd()))
        {
            if !shell.waiting.is_empty() {
                read_errors = take_all(batch, pipeline, shell, out).await?;
            }
            pipeline.set_imu_timeout(true, self.timeout_ms, out);
            shell.act(out).await?;
        }
        Ok(read_errors)
    }
}

/// A CAN frame read: it and every frame already waiting go through the pipeline. Returns the
/// read errors met on the way.
async fn on_frame(
    f: socketcan::CanFrame,
    stamp_ns: Option<u64>,
    watch: &mut ImuWatch,
    batch: &mut Vec<Received>,
    pipeline: &mut Pipeline,
    shell: &mut Shell<'_>,
    out: &mut Vec<Output>,
) -> Result<u64> {
    let mut read_errors = 0;
    // every frame already waiting comes in the same system call (recvmmsg)
    batch.push((wire::from_can_frame(&f), stamp_ns));
    if let Some(s) = &shell.sock
        && let Err(e) = wire::recv_batch_stamped(s.as_raw_fd(), batch, wire::BATCH - 1)
    {
        // the frame already read still goes through; the error is counted
        read_errors += 1;
        warn!(interface = shell.iface, "read error: {e}");
    }
    take_in_order(
        batch,
        nav::shell::arrival::Release::Ordered,
        pipeline,
        shell,
        out,
    )
    .await?;
    if let Some(r) = shell.recorder {
        r.ship_due();
    }
    if pipeline.gyro_frames() > watch.gyro_frames {
        watch.gyro_frames = pipeline.gyro_frames();
        watch.last = Instant::now();
        pipeline.set_imu_timeout(false, watch.timeout_ms, out);
        shell.act(out).await?;
    }
    Ok(read_errors)
}

/// What the receive loop leaves for the end of the run.
struct Ended {
    gps: Option<nav::shell::gps_port::GpsPort>,
    read_errors: u64,
    start: Instant,
}

/// The end of a run: what is still waiting on the socket and the port goes through the
/// pipeline, which flushes; its summary, with the shell's counts.
async fn finish(
    cfg: &NavConfig,
    ended: Ended,
    pipeline: &mut Pipeline,
    shell: &mut Shell<'_>,
    batch: &mut Vec<Received>,
    out: &mut Vec<Output>,
) -> Result<Summary> {
    let Ended {
        mut gps,
        mut read_errors,
        start,
    } = ended;
    let iface = shell.iface;
    // what reached the socket and the port before the signal is processed, not left unread:
    // every frame on the bus is then either received or in the kernel's drop count
    read_errors += take_all(batch, pipeline, shell, out).await?;
    if let Some(g) = gps.as_mut() {
        while let Some(bytes) = g.try_read() {
            shell.gps_bytes(wall_ns(), bytes, pipeline, out).await?;
        }
    }
    pipeline.flush(out);
    shell.act(out).await?;
    let mut kernel_dropped_frames = 0;
    if let Some(s) = &shell.sock {
        match wire::socket_drops(s.as_raw_fd()) {
            Ok(n) => kernel_dropped_frames = n,
            Err(e) => warn!(
                interface = iface,
                "cannot read the socket's drop counter: {e}"
            ),
        }
    }
    if let Some(w) = shell.export.as_mut() {
        use std::io::Write;
        if let Err(e) = w.flush() {
            warn!("the GPS fix export: {e}");
        }
    }
    let gps = match (gps, &cfg.gps) {
        (Some(g), Some(c)) => {
            let (port_errors, opens) = g.counters();
            Some(nav::summary::GpsPortCounts {
                port: c.port.clone(),
                port_errors,
                opens,
                reads_released_by_wait: shell.waiting.expired(),
                fixes_jsonl: c.fixes_jsonl.clone(),
            })
        }
        _ => None,
    };
    let summary = pipeline.summary_with(nav::summary::ShellCounts {
        interface: iface.to_string(),
        read_errors,
        command_send_errors: shell.command_errors,
        kernel_dropped_frames,
        // SAFETY: getuid(2) cannot fail.
        process_uid: Some(unsafe { libc::getuid() }),
        wall_seconds: start.elapsed().as_secs_f64(),
        frames_sent: shell.frames_sent,
        send_errors: shell.send_errors,
        gps,
        mcap: cfg.record.mcap.clone(),
        parameter_files: std::mem::take(&mut shell.parameters),
    });
    Ok(summary)
}

/// The summary into the recording (whose message count it then takes) and its file.
fn write_summary(cfg: &NavConfig, recorder: Option<Recorder>, summary: &mut Summary) -> Result<()> {
    if let Some(r) = recorder {
        r.send(Record::Json {
            channel: nav::record::writer::JsonChannel::Summary,
            t_ns: wall_ns(),
            publish_ns: (summary.last_sample.unwrap_or(0) as f64 * 1e9 / cfg.imu.rate_hz) as u64,
            json: serde_json::to_string(&summary)?,
        });
        summary.mcap_messages = r.finish()?;
    }
    if let Some(p) = &cfg.record.summary {
        std::fs::write(p, serde_json::to_string_pretty(&summary)?)
            .with_context(|| format!("writing summary {}", p.display()))?;
    }
    Ok(())
}

/// What the receiver's port gave, through the pipeline (the read errors met on the way).
async fn on_gps_event(
    ev: GpsEvent,
    batch: &mut Vec<Received>,
    pipeline: &mut Pipeline,
    shell: &mut Shell<'_>,
    out: &mut Vec<Output>,
) -> Result<u64> {
    let mut read_errors = 0;
    match ev {
        GpsEvent::Bytes { bytes, t_ns } => {
            // the frames received before the bytes were read go through first, those after
            // them after: the bytes take their place in the order things arrived, once a
            // frame received after them says that none before them is still on its way
            // (nav::shell::arrival)
            shell.waiting.push(t_ns, bytes, Instant::now());
            read_errors = drain_can(batch, shell);
            let release = if shell.stamped {
                nav::shell::arrival::Release::Ordered
            } else {
                nav::shell::arrival::Release::All
            };
            take_in_order(batch, release, pipeline, shell, out).await?;
        }
        GpsEvent::Opened | GpsEvent::Closed(_) if !shell.waiting.is_empty() => {
            // the bytes read before the port opened or closed go in before it
            read_errors = take_all(batch, pipeline, shell, out).await?;
            port_event(ev, pipeline, out);
        }
        _ => port_event(ev, pipeline, out),
    }
    shell.act(out).await?;
    Ok(read_errors)
}

/// Until `deadline`, or for ever without one.
async fn until(deadline: Option<Instant>) {
    match deadline {
        Some(t) => tokio::time::sleep_until(t.into()).await,
        None => std::future::pending().await,
    }
}

/// The receiver's port opened or closed, to the pipeline.
fn port_event(ev: GpsEvent, pipeline: &mut Pipeline, out: &mut Vec<Output>) {
    match ev {
        GpsEvent::Opened => pipeline.on_gps_port(true, "", out),
        GpsEvent::Closed(why) => pipeline.on_gps_port(false, &why, out),
        GpsEvent::Bytes { .. } => {}
    }
}

/// Write `text` to `path` through a temporary file beside it and a rename: whoever reads the
/// file (nav at its next start) sees the old one or the new one whole, never half of one.
fn write_atomically(path: &std::path::Path, text: &str) -> Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".part");
    let tmp = std::path::PathBuf::from(tmp);
    std::fs::write(&tmp, text).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path)
        .with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))
}

/// A received frame (or why it is not a data frame) and its kernel receive time, ns.
type Received = (Result<wire::RawFrame, wire::FrameConvError>, Option<u64>);

/// A time as ns since the epoch.
fn epoch_ns(t: std::time::SystemTime) -> Option<u64> {
    t.duration_since(std::time::UNIX_EPOCH)
        .ok()
        .map(|d| d.as_nanos() as u64)
}

/// Received frames (or why they are not data frames) through the pipeline, each recorded as it
/// came, and what the pipeline asks done.
async fn take_frames(
    batch: &mut Vec<Received>,
    pipeline: &mut Pipeline,
    shell: &mut Shell<'_>,
    out: &mut Vec<Output>,
) -> Result<()> {
    // a frame's kernel receive time where the socket gives it (SO_TIMESTAMPNS), else the time
    // the batch came out of the socket
    let read_ns = wall_ns();
    for (conv, stamp) in batch.drain(..) {
        match conv {
            Ok(raw) => {
                if let Some(r) = shell.recorder {
                    let t_ns = stamp.unwrap_or(read_ns);
                    r.send(Record::Frame { t_ns, frame: raw });
                }
                pipeline.on_frame(&raw, out);
            }
            Err(wire::FrameConvError::Error(e)) => {
                if let Some(r) = shell.recorder {
                    r.send(Record::ErrorFrame {
                        t_ns: stamp.unwrap_or(read_ns),
                        frame: e,
                    });
                }
                pipeline.on_can_error(&e, out);
            }
            Err(e) => pipeline.on_non_data(&e.to_string(), out),
        }
        shell.act(out).await?;
    }
    Ok(())
}

/// Every frame already waiting on the CAN socket, without waiting, after those in `batch`;
/// the read errors met.
fn drain_can(batch: &mut Vec<Received>, shell: &Shell<'_>) -> u64 {
    let Some(fd) = shell.sock.as_ref().map(|s| s.as_raw_fd()) else {
        return 0;
    };
    loop {
        match wire::recv_batch_stamped(fd, batch, wire::BATCH) {
            Ok(0) => return 0,
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return 0,
            Err(e) => {
                warn!(interface = shell.iface, "read error while draining: {e}");
                return 1;
            }
        }
    }
}

/// Every frame the socket has received, then every read of the receiver's port still waiting,
/// through the pipeline now (a port event, nav's watchdog, the end of the run: no later frame
/// will come to release them). Returns the read errors met.
async fn take_all(
    batch: &mut Vec<Received>,
    pipeline: &mut Pipeline,
    shell: &mut Shell<'_>,
    out: &mut Vec<Output>,
) -> Result<u64> {
    let read_errors = drain_can(batch, shell);
    take_in_order(
        batch,
        nav::shell::arrival::Release::All,
        pipeline,
        shell,
        out,
    )
    .await?;
    Ok(read_errors)
}

/// The frames in `batch` and the receiver's bytes that wait, through the pipeline in the
/// order they arrived (`nav::shell::arrival`), with the waiting bytes `release` lets go after them.
async fn take_in_order(
    batch: &mut Vec<Received>,
    release: nav::shell::arrival::Release,
    pipeline: &mut Pipeline,
    shell: &mut Shell<'_>,
    out: &mut Vec<Output>,
) -> Result<()> {
    if shell.waiting.is_empty() {
        return take_frames(batch, pipeline, shell, out).await;
    }
    let steps = shell.waiting.order(batch.iter().map(|r| r.1), release);
    let mut frames = std::mem::take(batch);
    for step in steps {
        match step {
            nav::shell::arrival::Step::Frames(r) => {
                batch.extend(frames.drain(..r.len()));
                take_frames(batch, pipeline, shell, out).await?;
            }
            nav::shell::arrival::Step::Bytes(b) => {
                shell.gps_bytes(b.t_ns, b.bytes, pipeline, out).await?
            }
        }
    }
    // the batch's buffer back for the next read
    frames.clear();
    *batch = frames;
    Ok(())
}

/// The devices the pipeline's outputs go to.
struct Shell<'a> {
    iface: &'a str,
    sock: Option<socketcan::tokio::CanSocket>,
    /// Turntable commands the socket refused (the finder sends them again).
    command_errors: u64,
    recorder: Option<&'a Recorder>,
    /// Solution frames written.
    frames_sent: u64,
    send_errors: u64,
    /// The parameter files as stamped, and where each was written (none: it could not be).
    parameters: Vec<(
        Option<std::path::PathBuf>,
        nav::procedures::unit_parameters::ParameterFile,
    )>,
    /// Where every decoded fix goes as a JSON line, when asked for.
    export: Option<std::io::BufWriter<std::fs::File>>,
    /// The socket gives each frame's kernel receive time.
    stamped: bool,
    /// The receiver's bytes read and waiting for the frames sent before them.
    waiting: nav::shell::arrival::Waiting,
}

impl<'a> Shell<'a> {
    /// The shell of a run on `iface` (its socket, none without CAN; `stamped`: the socket
    /// gives receive times), recording to `recorder`, exporting fixes to `export`; the
    /// receiver's bytes wait at most `wait` for a frame received after them.
    fn new(
        iface: &'a str,
        sock: Option<socketcan::tokio::CanSocket>,
        stamped: bool,
        recorder: Option<&'a Recorder>,
        export: Option<std::io::BufWriter<std::fs::File>>,
        wait: Duration,
    ) -> Self {
        Shell {
            iface,
            sock,
            command_errors: 0,
            recorder,
            frames_sent: 0,
            send_errors: 0,
            parameters: Vec::new(),
            export,
            stamped,
            waiting: nav::shell::arrival::Waiting::new(wait),
        }
    }

    /// The receiver's bytes, read at `t_ns`: recorded, then through the pipeline.
    async fn gps_bytes(
        &mut self,
        t_ns: u64,
        bytes: Vec<u8>,
        pipeline: &mut Pipeline,
        out: &mut Vec<Output>,
    ) -> Result<()> {
        pipeline.on_gps_bytes(&bytes, out);
        if let Some(r) = self.recorder {
            r.send(Record::GpsBytes { t_ns, bytes });
        }
        self.act(out).await
    }

    /// Do what the pipeline asked, in its order.
    async fn act(&mut self, out: &mut Vec<Output>) -> Result<()> {
        for o in out.drain(..) {
            match o {
                Output::Command(f) => {
                    if let Some(s) = &self.sock {
                        let frame = wire::to_can_frame(&f)
                            .map_err(|e| anyhow::anyhow!("TT_CMD frame: {e}"))?;
                        match s.write_frame(frame).await {
                            Ok(()) => self.record_sent(f),
                            // counted: north-finding sends it again when no acknowledgement
                            // comes
                            Err(e) => {
                                self.command_errors += 1;
                                warn!(interface = self.iface, "TT_CMD not sent: {e}");
                            }
                        }
                    }
                }
                Output::Solution(f) => {
                    let Some(s) = &self.sock else { continue };
                    match wire::to_can_frame(&f).map(|frame| s.try_write_frame(frame)) {
                        Ok(Ok(())) => {
                            self.frames_sent += 1;
                            self.record_sent(f);
                        }
                        Ok(Err(e)) => {
                            self.send_errors += 1;
                            if self.send_errors <= 3 {
                                warn!(
                                    interface = self.iface,
                                    "solution frame 0x{:03X} not sent: {e}", f.id
                                );
                            }
                        }
                        Err(e) => {
                            self.send_errors += 1;
                            warn!(interface = self.iface, "solution frame 0x{:03X}: {e}", f.id);
                        }
                    }
                }
                Output::Json {
                    channel,
                    publish_ns,
                    json,
                } => {
                    if let Some(r) = self.recorder {
                        r.send(Record::Json {
                            channel,
                            t_ns: wall_ns(),
                            publish_ns,
                            json,
                        });
                    }
                }
                Output::Sample { publish_ns, sample } => {
                    if let Some(r) = self.recorder {
                        r.send(Record::Sample {
                            t_ns: wall_ns(),
                            publish_ns,
                            sample,
                        });
                    }
                }
                Output::Line(l) => println!("{l}"),
                Output::Fix(f) => {
                    if let Some(w) = self.export.as_mut()
                        && let Ok(j) = serde_json::to_string(&f)
                    {
                        use std::io::Write;
                        let _ = writeln!(w, "{j}");
                    }
                }
                Output::Parameters { path, file } => {
                    let mut p = *file;
                    p.set_date(nav::procedures::unit_parameters::now_rfc3339());
                    let written = match write_atomically(&path, &p.to_toml()) {
                        Ok(()) => {
                            info!("calibration parameters written to {}", path.display());
                            println!("nav: parameter file {}", path.display());
                            Some(path)
                        }
                        Err(e) => {
                            tracing::error!(
                                "calibration parameters not written to {}: {e:#}",
                                path.display()
                            );
                            None
                        }
                    };
                    self.parameters.push((written, p));
                }
            }
        }
        Ok(())
    }

    fn record_sent(&self, frame: RawFrame) {
        if let Some(r) = self.recorder {
            r.send(Record::Sent {
                t_ns: wall_ns(),
                frame,
            });
        }
    }
}

/// Whether the next frame waiting in CAN socket `fd` is an IMU frame (read without taking it).
fn imu_frame_waiting(fd: std::os::fd::RawFd) -> bool {
    let mut b = [0u8; 16];
    // SAFETY: recv(2) into a buffer of its length; MSG_PEEK leaves the frame in the socket.
    let n = unsafe {
        libc::recv(
            fd,
            b.as_mut_ptr().cast(),
            b.len(),
            libc::MSG_PEEK | libc::MSG_DONTWAIT,
        )
    };
    if n < 4 {
        return false;
    }
    let id = u32::from_ne_bytes([b[0], b[1], b[2], b[3]]) & libc::CAN_SFF_MASK;
    [
        wire::imu_gyro::SPEC.id,
        wire::imu_accel::SPEC.id,
        wire::imu_hk::SPEC.id,
    ]
    .contains(&(id as u16))
}
