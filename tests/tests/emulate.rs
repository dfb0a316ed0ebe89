//! `hil emulate gps` on this machine (a pty needs no vcan): the receiver of a scenario
//! free-running on the host's clock behind a link, read as a serial port is read. Its epochs
//! come at the receiver's rate whether or not anybody reads, every sentence with a valid
//! checksum, and on its end it reports what it wrote and its own lateness.

use e2e::bin;
use std::io::{BufRead, BufReader};
use std::process::Command;
use std::time::{Duration, Instant};

/// An NMEA sentence's checksum holds.
fn checksum_ok(line: &str) -> bool {
    let Some(body) = line.strip_prefix('$') else {
        return false;
    };
    let Some((data, sum)) = body.split_once('*') else {
        return false;
    };
    let x = data.bytes().fold(0u8, |a, b| a ^ b);
    u8::from_str_radix(sum.trim(), 16) == Ok(x)
}

#[test]
fn the_receiver_runs_free_on_a_pty_behind_its_link() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("gps");
    let report = dir.path().join("gps.json");
    let scenario =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/drive-gps.toml");
    let mut child = Command::new(bin("hil"))
        .args(["emulate", "gps", "--duration", "5.5"])
        .arg("--scenario")
        .arg(&scenario)
        .arg("--link")
        .arg(&link)
        .arg("--report")
        .arg(&report)
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("hil emulate gps starts");
    let t0 = Instant::now();
    while !link.exists() {
        assert!(t0.elapsed() < Duration::from_secs(30), "no link {link:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
    let port = std::fs::File::open(&link).expect("the receiver's port opens");
    let mut lines = Vec::new();
    for l in BufReader::new(port).lines() {
        match l {
            Ok(l) => lines.push(l.trim().to_string()),
            // the receiver has gone (its pty closed)
            Err(_) => break,
        }
    }
    let status = child.wait().unwrap();
    assert!(status.success(), "{status}");
    assert!(
        !link.exists(),
        "the link is removed when the receiver stops"
    );
    let rmc = lines.iter().filter(|l| l.contains("RMC,")).count();
    assert!(rmc >= 3, "{lines:?}");
    let bad: Vec<_> = lines
        .iter()
        .filter(|l| !l.is_empty() && !checksum_ok(l))
        .collect();
    assert!(bad.is_empty(), "{bad:?}");
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    eprintln!("{r}");
    assert_eq!(r["device"], "gps");
    let epochs = r["gps"]["epochs"].as_u64().unwrap();
    assert!((4..=6).contains(&epochs), "{r}");
    assert_eq!(r["lateness"]["count"].as_u64(), Some(epochs));
    assert!(r["behind"].is_null(), "{r}");
}
