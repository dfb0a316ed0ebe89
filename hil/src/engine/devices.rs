//! The one place that puts the bench's emulated devices on a bus and takes them off again: a
//! scenario's devices behind the bus scheduler (IMU, turntable, GPS receiver, in lockstep with
//! nav), or the indexing mechanism alone on its simulated clock for validation.

use crate::scenario::Scenario;
use anyhow::{Context, Result, anyhow};
use emulators::adapters::clock::SimClock;
use emulators::adapters::pty::GpsDevice;
use emulators::adapters::scheduler::{BusOutcome, Devices, Lockstep};
use emulators::adapters::transport::{Progress, TtLockstep, TurntableTxStats};
use emulators::turntable::Turntable;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

/// Devices running on a bus in their own thread.
pub struct Running<T> {
    thread: JoinHandle<Result<T>>,
    ticker: Option<JoinHandle<()>>,
    stop: Arc<AtomicBool>,
    progress: Arc<Progress>,
}

impl<T> Running<T> {
    /// Whether the devices have stopped by themselves (the scenario's end, or an error).
    pub fn is_finished(&self) -> bool {
        self.thread.is_finished()
    }

    /// Simulated time the devices have reached, s.
    pub fn sim_time(&self) -> f64 {
        self.progress.now()
    }

    /// Asks the devices to stop at their next sample.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }

    /// Stops the devices and waits for them: their statistics, or what went wrong.
    pub fn join(self) -> Result<T> {
        self.stop();
        if let Some(t) = self.ticker {
            t.join().map_err(|_| anyhow!("the device clock panicked"))?;
        }
        self.thread
            .join()
            .map_err(|_| anyhow!("the emulator thread panicked"))?
    }
}

/// Starts a scenario's devices on `iface` behind the bus scheduler, at the scenario's speed
/// factor and in lockstep with nav (unless the scenario's `[bus]` says otherwise): the IMU (with the scenario's stream faults), the turntable
/// when the scenario has one, and `gps` (the receiver, and its pty) when given. Every frame put on
/// the bus goes to the `candump -l` log `sent_log` when given. The interface goes down and up
/// again at each of `link_downs` ([down at, up at], simulated s). A live view watches the bus
/// model (`watch`) and may pause the stream (`hold`).
pub fn start_scenario(
    s: &Scenario,
    iface: &str,
    gps: Option<(emulators::gps::GpsRun, GpsDevice)>,
    sent_log: Option<&std::path::Path>,
    link_downs: &[[f64; 2]],
    watch: Option<emulators::adapters::scheduler::Watch>,
    hold: Option<emulators::adapters::scheduler::Hold>,
) -> Result<Running<BusOutcome>> {
    let lockstep = Lockstep::at_rate(s.imu.rate_hz);
    let follow = s.bus.lockstep.then_some(lockstep);
    let (motion, turntable) = s.build();
    let (receiver, gps) = gps.unzip();
    let devices = Devices {
        step: crate::engine::inproc::stepper(s, motion, turntable, receiver, s.duration_s),
        gps,
        sent_log: sent_log
            .map(|p| emulators::adapters::transport::SentLog::create(p, iface))
            .transpose()?,
        // the bus model's own log on the simulated clock, beside the bench's
        bus_log: sent_log
            .filter(|_| s.bus.log)
            .map(|p| {
                emulators::adapters::transport::SentLog::create(&p.with_file_name("bus.log"), iface)
            })
            .transpose()?,
        link: (!link_downs.is_empty()).then(|| {
            let name = iface.to_string();
            let mut windows = link_downs.to_vec();
            windows.sort_by(|a, b| a[0].total_cmp(&b[0]));
            emulators::adapters::scheduler::LinkOutages::new(
                windows,
                Box::new(move |up| vcan_setup::set_link(&name, up).map_err(std::io::Error::other)),
            )
        }),
        watch,
        hold,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let progress = Arc::new(Progress::default());
    let clock = SimClock::start(s.speed);
    let thread = {
        let (iface, stop, progress) = (iface.to_string(), stop.clone(), progress.clone());
        std::thread::Builder::new()
            .name("bus".into())
            .spawn(move || {
                emulators::adapters::scheduler::run(
                    &iface, devices, clock, follow, &stop, &progress,
                )
                .context("emulators")
            })
            .context("starting the emulator thread")?
    };
    Ok(Running {
        thread,
        ticker: None,
        stop,
        progress,
    })
}

/// Starts the indexing mechanism alone on `iface`, in lockstep with the client that commands it
/// (the returned [`TtLockstep`]: the mechanism's time is what the client asks for), until
/// stopped.
pub fn start_turntable(
    iface: &str,
    tt: Turntable,
) -> Result<(Running<TurntableTxStats>, Arc<TtLockstep>)> {
    let stop = Arc::new(AtomicBool::new(false));
    let progress = Arc::new(Progress::default());
    let ls = Arc::new(TtLockstep::default());
    let thread = {
        let (iface, stop, progress, ls) = (
            iface.to_string(),
            stop.clone(),
            progress.clone(),
            ls.clone(),
        );
        std::thread::Builder::new()
            .name("turntable".into())
            .spawn(move || {
                emulators::adapters::transport::run_turntable(&iface, tt, &ls, &progress, &stop)
                    .context("turntable emulator")
            })
            .context("starting the turntable emulator")?
    };
    Ok((
        Running {
            thread,
            ticker: None,
            stop,
            progress,
        },
        ls,
    ))
}
