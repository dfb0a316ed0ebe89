//! `hil bench`: the benchmark suite.

use crate::*;

pub(crate) fn bench(seconds: f64, passes: u32, scenario: Vec<PathBuf>) -> Result<i32> {
    if seconds.is_nan() || seconds <= 0.1 {
        bail!("--seconds must exceed 0.1");
    }
    let files = if scenario.is_empty() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
            .with_context(|| format!("listing {}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        v.sort();
        v
    } else {
        scenario
    };
    println!("emulators (truth + sensor model + encoding), one core, in process:");
    for f in &files {
        let s = Scenario::load(f)?;
        let secs = seconds.min(s.duration_s);
        let r = hil::bench::emulators(&s, secs);
        println!(
            "  {:<24} {:7.1} s simulated: x{:7.1} real time, {:.3e} frames/s",
            r.scenario, r.seconds, r.speed_factor, r.frames_per_second
        );
    }
    let r = hil::bench::frontend(seconds, passes)?;
    println!(
        "nav front end (decode + counters + dither FIR + coning/sculling + attitude), one core, {} build:\n  {} samples ({} frames) per pass, best of {}: {:.3e} samples/s, {:.3e} frames/s",
        r.profile, r.samples, r.frames, r.passes, r.samples_per_second, r.frames_per_second
    );
    if r.profile == "debug" {
        println!(
            "  (debug build: run `cargo run --release -p hil -- bench` for the product's figure)"
        );
    }
    Ok(0)
}
