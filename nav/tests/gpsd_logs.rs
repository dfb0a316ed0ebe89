//! Real receiver captures (gpsd's regression logs in ../shared/testdata/gpsd-nmea): every log
//! decodes without a panic, and the decoded fixes match gpsd's TPV reports (lat/lon to 1e-6 deg,
//! time of day where gpsd has one) for at least 99 % of TPV objects with mode >= 2. Every
//! mismatch is listed with its log. Skips with a message when ../shared is absent.

use nav::gps::{GpsDecoder, GpsFix};
use std::path::{Path, PathBuf};

fn testdata() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/testdata/gpsd-nmea");
    p.is_dir().then_some(p)
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
pub fn decode_log(text: &[u8]) -> (Vec<GpsFix>, nav::gps::GpsStats) {
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

#[test]
fn gpsd_logs_decode_and_match_tpv() {
    let Some(dir) = testdata() else {
        eprintln!("SKIPPED: ../shared/testdata/gpsd-nmea is absent");
        return;
    };
    let mut logs: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "log"))
        .collect();
    logs.sort();
    assert!(logs.len() >= 40, "{} logs", logs.len());
    let (mut total, mut matched) = (0usize, 0usize);
    let mut mismatches = Vec::new();
    for log in &logs {
        let text = std::fs::read(log).unwrap();
        let (fixes, st) = decode_log(&text);
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
