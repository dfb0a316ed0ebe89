//! Real receiver captures (gpsd's regression logs in ../shared/testdata/gpsd-nmea): every log
//! decodes without a panic, and the decoded fixes match gpsd's TPV reports (lat/lon to 1e-6 deg,
//! time of day where gpsd has one) for at least 99 % of TPV objects with mode >= 2. Every
//! mismatch is listed with its log. Checked twice: the decoder in process, and the whole path -
//! each log replayed by the GPS emulator onto a pty that the nav binary opens as its serial port.
//! ptys exist on any Linux host, so these run without the VM. Skips with a message when
//! ../shared is absent.

use nav::frontend::gps_receiver::{GpsDecoder, GpsFix};
use std::path::{Path, PathBuf};

fn testdata() -> Option<PathBuf> {
    e2e::gpsd_testdata()
}

/// A TPV with a position.
#[derive(Debug)]
struct Tpv {
    lat: f64,
    lon: f64,
    tod: Option<f64>,
}

fn tpvs(chk: &str) -> Vec<Tpv> {
    chk.lines()
        .filter(|l| l.starts_with('{') && l.contains("\"class\":\"TPV\""))
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["mode"].as_i64().unwrap_or(0) >= 2)
        .filter_map(|v| {
            let (lat, lon) = (v["lat"].as_f64()?, v["lon"].as_f64()?);
            let tod = v["time"].as_str().and_then(|t| {
                // 2007-12-23T19:32:21.000Z
                let hms = t.split('T').nth(1)?.trim_end_matches('Z');
                let mut it = hms.split(':');
                let (h, m, s): (f64, f64, f64) = (
                    it.next()?.parse().ok()?,
                    it.next()?.parse().ok()?,
                    it.next()?.parse().ok()?,
                );
                Some(h * 3600.0 + m * 60.0 + s)
            });
            Some(Tpv { lat, lon, tod })
        })
        .collect()
}

/// Decode a log as nav would receive it: the bytes after the `#` comment lines.
pub fn decode_log(text: &[u8]) -> (Vec<GpsFix>, nav::frontend::gps_receiver::GpsStats) {
    let mut d = GpsDecoder::default();
    let mut fixes = Vec::new();
    let mut body = Vec::new();
    for line in text.split_inclusive(|b| *b == b'\n') {
        if line.first() == Some(&b'#') {
            continue;
        }
        body.extend_from_slice(line);
    }
    for chunk in body.chunks(64) {
        d.push_bytes(chunk, &mut fixes);
    }
    (fixes, d.stats())
}

fn matches(t: &Tpv, f: &GpsFix) -> bool {
    (t.lat - f.lat_deg).abs() <= 1e-6
        && (t.lon - f.lon_deg).abs() <= 1e-6
        && match (t.tod, f.time_of_day_s) {
            (Some(a), Some(b)) => (a - b).abs() < 1e-3 || (a - b).abs() > 86_399.0,
            (Some(_), None) => false,
            _ => true,
        }
}

fn logs() -> Option<Vec<PathBuf>> {
    let Some(dir) = testdata() else {
        eprintln!("SKIPPED: ../shared/testdata/gpsd-nmea is absent");
        return None;
    };
    let mut logs: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "log"))
        .collect();
    logs.sort();
    assert!(logs.len() >= 40, "{} logs", logs.len());
    Some(logs)
}

#[test]
fn gpsd_logs_decode_and_match_tpv() {
    let Some(logs) = logs() else { return };
    compare(&logs, |log| {
        let text = std::fs::read(log).unwrap();
        decode_log(&text)
    });
}

/// Replay one log through a pty into the nav binary; returns nav's exported fixes and counters.
fn through_nav(log: &Path) -> (Vec<GpsFix>, nav::frontend::gps_receiver::GpsStats) {
    use std::io::{BufRead, BufReader};
    use std::process::{Command, Stdio};
    let dir = tempfile::tempdir().unwrap();
    let mut pty = emulators::adapters::pty::GpsPty::open().unwrap();
    let cfg = dir.path().join("nav.toml");
    std::fs::write(
        &cfg,
        format!(
            "[gps]\nport = \"{}\"\nbaud = 4800\nfixes_jsonl = \"fixes.jsonl\"\n[record]\nsummary = \"summary.json\"\n",
            pty.path()
        ),
    )
    .unwrap();
    let mut child = Command::new(e2e::bin("nav"))
        .arg("--config")
        .arg(&cfg)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("nav starts");
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    while out.read_line(&mut line).unwrap() > 0 && !line.starts_with("nav: receiving") {
        line.clear();
    }
    // nav's reader opens the port right after it reports ready
    std::thread::sleep(std::time::Duration::from_millis(300));
    let lines = emulators::adapters::pty::parse_log(&std::fs::read(log).unwrap());
    let stop = std::sync::atomic::AtomicBool::new(false);
    emulators::adapters::pty::replay(&mut pty, &lines, 2000.0, &stop).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(400));
    // SAFETY: kill(2) on our own child
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let st = child.wait().unwrap();
    assert!(st.success(), "{}: nav exit {st}", log.display());
    let fixes = std::fs::read_to_string(dir.path().join("fixes.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let sum: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("summary.json")).unwrap())
            .unwrap();
    let stats = serde_json::from_value(sum["gps"]["stats"].clone()).unwrap();
    (fixes, stats)
}

#[test]
fn gpsd_logs_through_a_pty_into_nav_match_tpv() {
    let Some(logs) = logs() else { return };
    compare(&logs, through_nav);
}

fn compare(
    logs: &[PathBuf],
    decode: impl Fn(&Path) -> (Vec<GpsFix>, nav::frontend::gps_receiver::GpsStats) + Sync,
) {
    let (mut total, mut matched) = (0usize, 0usize);
    let mut mismatches = Vec::new();
    // the logs side by side (each through its own pty and nav, which mostly wait): eight at a
    // time, in their order
    let mut decoded = Vec::with_capacity(logs.len());
    for group in logs.chunks(8) {
        std::thread::scope(|sc| {
            let runs: Vec<_> = group.iter().map(|l| sc.spawn(|| decode(l))).collect();
            decoded.extend(runs.into_iter().map(|r| r.join().expect("a log's decode")));
        });
    }
    for (log, (fixes, st)) in logs.iter().zip(decoded) {
        let chk = std::fs::read_to_string(log.with_extension("log.chk")).unwrap_or_default();
        let tp = tpvs(&chk);
        let mut bad = 0;
        for t in &tp {
            total += 1;
            if fixes.iter().any(|f| matches(t, f)) {
                matched += 1;
            } else {
                bad += 1;
            }
        }
        if bad > 0 {
            mismatches.push(format!(
                "{}: {bad} of {} TPV unmatched (fixes {}, bad checksum {}, unparsed {}, out of range {})",
                log.file_name().unwrap().to_string_lossy(),
                tp.len(),
                fixes.len(),
                st.bad_checksum,
                st.unparsed,
                st.out_of_range
            ));
        }
    }
    let share = matched as f64 / total.max(1) as f64;
    eprintln!(
        "gpsd logs: {} logs, {matched} of {total} TPV (mode >= 2) matched = {:.2} %",
        logs.len(),
        100.0 * share
    );
    for m in &mismatches {
        eprintln!("  {m}");
    }
    assert!(total > 1000, "{total}");
    assert!(share >= 0.99, "only {:.2} % matched", 100.0 * share);
}

/// The receivers' own accuracy (GST) in the captures that have it: nav reads every statement
/// gpsd reports with usable sigmas (latitude and longitude up to
/// [`nav::frontend::gps_receiver::MAX_GST_SIGMA_M`]) with gpsd's values, and sets aside as unusable exactly those
/// whose sigmas are missing or implausible (a receiver without a fix states 305 km).
#[test]
fn gst_statements_read_as_gpsd_reads_them() {
    let Some(dir) = testdata() else {
        eprintln!("skipped: ../shared/testdata/gpsd-nmea is absent");
        return;
    };
    let mut logs = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let path = e.unwrap().path();
        if path.extension().is_none_or(|x| x != "log") {
            continue;
        }
        let text = std::fs::read(&path).unwrap();
        let Ok(chk) = std::fs::read_to_string(path.with_extension("log.chk")) else {
            continue;
        };
        // gpsd's GST reports, each statement once (gpsd repeats a report per cycle)
        let mut gpsd: Vec<[f64; 3]> = Vec::new();
        for l in chk.lines().filter(|l| l.contains("\"class\":\"GST\"")) {
            let Ok(v) = serde_json::from_str::<serde_json::Value>(l) else {
                continue;
            };
            let f = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
            let g = [f("lat"), f("lon"), f("alt")];
            if !gpsd.contains(&g) {
                gpsd.push(g);
            }
        }
        if gpsd.is_empty() {
            continue;
        }
        logs += 1;
        let mut d = GpsDecoder::default();
        let mut fixes = Vec::new();
        let body: Vec<u8> = text
            .split_inclusive(|b| *b == b'\n')
            .filter(|l| l.first() != Some(&b'#'))
            .flatten()
            .copied()
            .collect();
        d.push_bytes(&body, &mut fixes);
        let ours = d.take_accuracies();
        let st = d.stats();
        let usable = |g: &[f64; 3]| {
            g[..2].iter().all(|v| {
                v.is_finite() && *v > 0.0 && *v <= nav::frontend::gps_receiver::MAX_GST_SIGMA_M
            })
        };
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        eprintln!(
            "{name}: gpsd {} distinct GST, nav {} usable, {} unusable",
            gpsd.len(),
            st.accuracy,
            st.accuracy_unusable
        );
        for g in &gpsd {
            let found = ours.iter().any(|a| {
                (a.lat_sigma_m - g[0]).abs() < 1e-3
                    && (a.lon_sigma_m - g[1]).abs() < 1e-3
                    && a.alt_sigma_m.is_none_or(|u| (u - g[2]).abs() < 1e-3)
            });
            assert_eq!(found, usable(g), "{name}: gpsd's GST {g:?}");
        }
        for a in &ours {
            assert!(
                gpsd.iter()
                    .any(|g| (a.lat_sigma_m - g[0]).abs() < 1e-3
                        && (a.lon_sigma_m - g[1]).abs() < 1e-3),
                "{name}: nav read {a:?}, which gpsd did not report"
            );
        }
        if gpsd.iter().all(|g| !usable(g)) {
            assert_eq!(st.accuracy, 0, "{name}");
            assert!(st.accuracy_unusable > 0, "{name}");
        }
    }
    assert!(logs >= 5, "captures with GST: {logs}");
}
