//! A nav killed outright (SIGKILL, power loss) keeps its recording: the MCAP file, without its
//! summary and footer, still reads up to about the last flush (`FLUSH_EVERY`, 0.5 s).
//!
//! The parent test runs this test binary again as a child that records frames for 2 s of wall
//! time and then kills itself with SIGKILL (no destructor, no flush runs), then reads what the
//! child left on disk.

use nav::record::raw::frame_of;
use nav::record::writer::{FLUSH_EVERY, Record, Recorder, SHIP_AFTER, wall_ns};
use std::time::{Duration, Instant};
use wire::RawFrame;

const CHILD: &str = "NAV_RECORDING_CRASH_CHILD";

#[test]
fn a_killed_recorder_loses_at_most_about_one_flush() {
    if let Some(path) = std::env::var_os(CHILD) {
        // the child: record at about 4,000 frames/s, then die at once
        let r = Recorder::start(std::path::Path::new(&path)).expect("recorder");
        let t0 = Instant::now();
        let mut k = 0u64;
        while t0.elapsed() < Duration::from_secs(2) {
            for _ in 0..40 {
                r.send(Record::Frame {
                    t_ns: wall_ns(),
                    frame: RawFrame {
                        id: 0x080,
                        len: 8,
                        data: k.to_le_bytes(),
                    },
                });
                k += 1;
            }
            // as nav does after each batch of received frames
            r.ship_due();
            std::thread::sleep(Duration::from_millis(10));
        }
        // give the writer time to take what was queued, as a running nav would have
        std::thread::sleep(Duration::from_millis(50));
        std::fs::write(
            format!("{}.killed_at", path.to_string_lossy()),
            wall_ns().to_string(),
        )
        .expect("kill time");
        // SAFETY: raising a signal on this process.
        unsafe { libc::raise(libc::SIGKILL) };
        unreachable!("SIGKILL did not end the process");
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nav.mcap");
    let status = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "a_killed_recorder_loses_at_most_about_one_flush",
            "--nocapture",
        ])
        .env(CHILD, &path)
        .status()
        .unwrap();
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(
        status.signal(),
        Some(libc::SIGKILL),
        "the child must die by SIGKILL"
    );
    let killed_at: u64 = std::fs::read_to_string(dir.path().join("nav.mcap.killed_at"))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let bytes = std::fs::read(&path).unwrap();
    // the recording has no footer: read record by record until the cut
    let (mut n, mut last_t, mut last_k) = (0u64, 0u64, None);
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let Ok(m) = m else { break };
        if m.channel.topic == "/can/raw" {
            let f = frame_of(&m).expect("a recorded frame");
            let k = u64::from_le_bytes(f.data);
            // nothing before the cut is missing or out of order
            assert_eq!(k, last_k.map_or(0, |l: u64| l + 1));
            last_k = Some(k);
            last_t = m.log_time;
            n += 1;
        }
    }
    let lost_s = (killed_at.saturating_sub(last_t)) as f64 * 1e-9;
    eprintln!("{n} frames kept, the last {lost_s:.3} s before the kill lost");
    assert!(n > 4_000, "only {n} frames kept of 2 s at 4,000 frames/s");
    assert!(
        lost_s <= 2.0 * FLUSH_EVERY.as_secs_f64() + SHIP_AFTER.as_secs_f64() + 0.1,
        "{lost_s} s lost before the kill"
    );
}
