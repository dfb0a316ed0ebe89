//! gpsd, the daemon a Linux vehicle shares its receiver through, on the GPS emulator's pty (a
//! real pty: no CAN is needed, so this runs on the host). The emulated receiver drives a lap in
//! the southern hemisphere at 1 Hz; gpsd reads its pty; `gpspipe -w` (gpsd's own client) must
//! report a TPV for the fixes, each at the emulated receiver's position (truth plus the error the
//! emulator added) to NMEA's resolution; and nav's GPS reader with `source = "gpsd"` must decode
//! every fix through gpsd, bit for bit the positions gpsd reported.
//!
//! Ignored by a plain `cargo test`; `./run-tests` installs gpsd and gpsd-clients with apt and
//! runs it.

use emulators::adapters::pty::GpsPty;
use emulators::drive::{Drive, DriveSpec};
use emulators::gps::{GpsErrorParams, GpsReceiver, GpsRun, NmeaWriter, ReceiverParams};
use nav::config::{GpsConfig, GpsSource};
use serde_json::Value;
use std::io::BufRead;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Metres between two positions (deg), locally flat (they are metres apart).
fn metres(a: (f64, f64), b: (f64, f64)) -> f64 {
    let r = 6_371_000.0;
    let dn = (a.0 - b.0).to_radians() * r;
    let de = (a.1 - b.1).to_radians() * r * a.0.to_radians().cos();
    dn.hypot(de)
}

struct Kill(std::process::Child);
impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
#[ignore = "needs gpsd and gpspipe: run ./run-tests"]
fn gpsd_reads_the_emulated_receiver_and_nav_takes_its_fixes_from_gpsd() {
    for tool in ["gpsd", "gpspipe"] {
        let found = Command::new("sh")
            .args(["-c", &format!("command -v {tool}")])
            .output()
            .is_ok_and(|o| o.status.success());
        assert!(
            found,
            "{tool} is not installed: ./run-tests installs it (apt-get install gpsd gpsd-clients)"
        );
    }
    // the receiver: a lap of 400 m squares at 33.9 S, 10 m/s, a few-metre class receiver
    let spec = DriveSpec {
        lat_deg: -33.92,
        lon_deg: 18.42,
        height_m: 20.0,
        waypoints: vec![[0.0, 100.0], [100.0, 100.0], [100.0, 0.0], [0.0, 0.0]],
        speed_mps: 10.0,
        accel_mps2: 2.0,
        turn_rate_dps: 20.0,
        lateral_accel_mps2: 3.0,
        laps: 1,
        start_wait_s: 2.0,
        ..Default::default()
    };
    let drive = Drive::plan(&spec).expect("the lap plans");
    let rx = ReceiverParams {
        errors: GpsErrorParams::class_few_m(),
        ..ReceiverParams::default()
    };
    let run = GpsRun {
        writer: NmeaWriter::new(rx.clone()),
        drive: drive.clone(),
        pps_phase_s: 0.0,
        latency_s: 0.05,
        utc0_s: 12.0 * 3600.0,
        date: (21, 11, 2026),
    };
    let mut receiver = GpsReceiver::new(run);
    let mut pty = GpsPty::open().expect("a pty");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let _gpsd = Kill(
        Command::new("gpsd")
            .args(["-N", "-n", "-b", "-S", &port.to_string(), pty.path()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("gpsd starts"),
    );
    // gpsd listening
    let t0 = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "gpsd never listened on {port}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // gpsd's own client, and nav's reader through gpsd
    let mut pipe = Kill(
        Command::new("gpspipe")
            .args(["-w", &format!("127.0.0.1:{port}")])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("gpspipe starts"),
    );
    let out = pipe.0.stdout.take().expect("gpspipe's stdout");
    let reports = std::thread::spawn(move || {
        std::io::BufReader::new(out)
            .lines()
            .map_while(Result::ok)
            .filter_map(|l| serde_json::from_str::<Value>(&l).ok())
            .collect::<Vec<Value>>()
    });
    let cfg = GpsConfig {
        source: GpsSource::Gpsd,
        gpsd: format!("127.0.0.1:{port}"),
        ..GpsConfig::default()
    };
    // nav's port reader, as nav's loop runs it, on a runtime of its own until told to stop
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let reader = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .expect("a runtime");
            rt.block_on(async move {
                let mut port = nav::shell::gps_port::GpsPort::new(&cfg);
                let mut bytes = Vec::new();
                while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                    let next = tokio::time::timeout(Duration::from_millis(100), port.next());
                    if let Ok(nav::shell::gps_port::GpsEvent::Bytes { bytes: b, .. }) = next.await {
                        bytes.extend(b);
                    }
                }
                let (errors, opens) = port.counters();
                (bytes, port.gpsd_messages(), errors, opens)
            })
        })
    };
    std::thread::sleep(Duration::from_millis(500));

    // 40 epochs of the lap, at five a second
    let mut written = Vec::new();
    let mut gst_written: Vec<(f64, f64, f64, f64)> = Vec::new();
    let mut t = 0.0;
    while written.len() < 40 {
        t += 0.2;
        while let Some(e) = receiver.poll(t, 1e9) {
            if let Some(err) = e.error_enu {
                let truth = emulators::gps::antenna_truth(&drive, e.edge, rx.lever_arm_m);
                // the position the receiver reported: truth plus its error (east, north)
                let (rm, rn) = emulators::geodesy::radii(truth.lat_deg.to_radians());
                let lat = truth.lat_deg + (err[1] / rm).to_degrees();
                let lon =
                    truth.lon_deg + (err[0] / (rn * truth.lat_deg.to_radians().cos())).to_degrees();
                written.push((e.edge, (lat, lon), (truth.lat_deg, truth.lon_deg)));
            }
            // the receiver's own accuracy, as its GST states it: (time of day, lat, lon, alt)
            for l in e.text.lines().filter(|l| l.get(3..6) == Some("GST")) {
                let f: Vec<&str> = l.split('*').next().unwrap_or("").split(',').collect();
                let num = |i: usize| f[i].parse::<f64>().expect("a GST field");
                let hms = f[1];
                let tod = hms[0..2].parse::<f64>().unwrap() * 3600.0
                    + hms[2..4].parse::<f64>().unwrap() * 60.0
                    + hms[4..].parse::<f64>().unwrap();
                gst_written.push((tod, num(6), num(7), num(8)));
            }
            pty.write(e.text.as_bytes())
                .expect("the pty takes the sentences");
        }
        std::thread::sleep(Duration::from_millis(40));
    }
    std::thread::sleep(Duration::from_millis(1500));
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let (bytes, gpsd_json, port_errors, opens) = reader.join().expect("nav's port reader");
    assert!(
        gpsd_json >= 2,
        "gpsd's VERSION and WATCH replies: {gpsd_json}"
    );
    // decoded as nav's pipeline decodes them
    let mut decoder = nav::frontend::gps_receiver::GpsDecoder::default();
    let mut nav_fixes = Vec::new();
    decoder.push_bytes(&bytes, &mut nav_fixes);
    let nav_accuracy = decoder.take_accuracies();
    let stats = decoder.stats();
    drop(pipe);
    let reports = reports.join().expect("gpspipe's reader");

    // gpspipe: a TPV per fix, at the receiver's position
    let tpv: Vec<&Value> = reports
        .iter()
        .filter(|r| r["class"] == "TPV" && r["mode"].as_u64().unwrap_or(0) >= 2)
        .collect();
    eprintln!(
        "gpspipe: {} reports, {} TPV with a fix; nav through gpsd: {:?}, port errors {port_errors}, opens {opens}",
        reports.len(),
        tpv.len(),
        stats
    );
    assert!(tpv.len() >= 35, "{} TPV of 40 fixes", tpv.len());
    let mut matched = 0;
    for r in &tpv {
        // gpsd's first report may come before it has seen a date (GGA has none, RMC does)
        let Some(time) = r["time"].as_str() else {
            continue;
        };
        // 2026-11-21T12:00:07.000Z: the epoch at 7 s
        let hms: Vec<f64> = time[11..time.len() - 1]
            .split(':')
            .map(|x| x.parse().unwrap())
            .collect();
        assert!(time.starts_with("2026-11-21T"), "{time}");
        let edge = hms[0] * 3600.0 + hms[1] * 60.0 + hms[2] - 12.0 * 3600.0;
        let Some((_, reported, truth)) = written.iter().find(|w| (w.0 - edge).abs() < 1e-3) else {
            panic!("a TPV at {time} for no fix written");
        };
        let p = (r["lat"].as_f64().unwrap(), r["lon"].as_f64().unwrap());
        // NMEA carries 1e-4 minutes (0.19 m) or better
        assert!(metres(p, *reported) < 0.3, "{time}: {p:?} vs {reported:?}");
        // and truth within the emulated few-metre class error (1.7 m per axis, 1 sigma)
        assert!(metres(p, *truth) < 12.0, "{time}: {p:?} vs truth {truth:?}");
        matched += 1;
    }
    assert!(matched >= 35);

    // gpsd reads the receiver's GST: a GST report per statement, with its sigmas
    let gst: Vec<&Value> = reports.iter().filter(|r| r["class"] == "GST").collect();
    eprintln!(
        "GST: {} written, {} reported by gpspipe, {} decoded by nav through gpsd",
        gst_written.len(),
        gst.len(),
        nav_accuracy.len()
    );
    assert!(gst_written.len() >= 38, "{} GST written", gst_written.len());
    assert!(gst.len() >= 35, "gpspipe reported {} GST", gst.len());
    for r in &gst {
        let got = (
            r["lat"].as_f64().unwrap_or(f64::NAN),
            r["lon"].as_f64().unwrap_or(f64::NAN),
            r["alt"].as_f64().unwrap_or(f64::NAN),
        );
        assert!(
            gst_written.iter().any(|w| (w.1 - got.0).abs() < 0.006
                && (w.2 - got.1).abs() < 0.006
                && (w.3 - got.2).abs() < 0.006),
            "gpsd's GST {r} is none the receiver wrote"
        );
    }
    // and nav, through gpsd, takes the same statements, each at its fix's time
    assert!(nav_accuracy.len() >= 38, "{nav_accuracy:?}");
    for a in &nav_accuracy {
        let t = a.time_of_day_s.expect("GST carries its time");
        let w = gst_written
            .iter()
            .find(|w| (w.0 - t).abs() < 1e-3)
            .unwrap_or_else(|| panic!("nav's accuracy {a:?} at no GST written"));
        // (the NMEA parser reads single precision)
        let near = |x: f64, y: f64| (x - y).abs() < 1e-5;
        assert!(
            near(a.lat_sigma_m, w.1)
                && near(a.lon_sigma_m, w.2)
                && a.alt_sigma_m.is_some_and(|u| near(u, w.3)),
            "nav read {a:?}, the receiver wrote {w:?}"
        );
    }

    // nav through gpsd: every fix, checksums good, at the positions gpsd reported
    // the bytes handed on (what nav records) are gpsd's NMEA alone: no JSON line among them
    let text = String::from_utf8_lossy(&bytes);
    assert!(
        text.lines().count() >= 38 && text.lines().all(|l| l.starts_with('$')),
        "{text}"
    );
    let gga: Vec<_> = nav_fixes.iter().filter(|f| f.sentence == "GGA").collect();
    assert!(gga.len() >= 38, "nav decoded {} GGA of 40", gga.len());
    // no gpsd JSON reached the NMEA decoder, and no sentence was damaged on the way
    assert_eq!(
        (stats.bad_checksum, stats.garbage_bytes, stats.unparsed),
        (0, 0, 0),
        "{stats:?}"
    );
    for f in &gga {
        let near = written
            .iter()
            .map(|w| metres((f.lat_deg, f.lon_deg), w.1))
            .fold(f64::INFINITY, f64::min);
        assert!(
            near < 0.3,
            "nav's fix {f:?} is {near} m from any the receiver reported"
        );
    }
}
