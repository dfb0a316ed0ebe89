//! `hil replay`: a recording through nav's pipeline.

use crate::*;

pub(crate) fn replay(recording: &Path, config: Option<&Path>, json: bool) -> Result<i32> {
    let (mcap, cfg) = if recording.is_dir() {
        (recording.join("nav.mcap"), recording.join("nav.toml"))
    } else {
        let beside = recording
            .parent()
            .unwrap_or(Path::new("."))
            .join("nav.toml");
        (recording.to_path_buf(), beside)
    };
    let cfg = config.map_or(cfg, Path::to_path_buf);
    if !cfg.is_file() {
        bail!(
            "no nav config for {} (looked for {}; give one with --config)",
            recording.display(),
            cfg.display()
        );
    }
    let cfg = nav::config::NavConfig::load(&cfg)?;
    let r = if is_candump(&mcap) {
        hil::playback::replay_candump(&mcap, &cfg)?
    } else {
        hil::playback::replay(&mcap, &cfg)?
    };
    if json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", hil::playback::text(&r));
    }
    Ok(i32::from(!r.identical()))
}

/// The file starts like a `candump -l` log: `(` and a time stamp.
fn is_candump(p: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 1];
    std::fs::File::open(p).is_ok_and(|mut f| f.read_exact(&mut head).is_ok() && head[0] == b'(')
}

pub(crate) fn candump(recording: &Path, out: Option<&Path>, iface: &str) -> Result<i32> {
    let mcap = if recording.is_dir() {
        recording.join("nav.mcap")
    } else {
        recording.to_path_buf()
    };
    let n = match out {
        Some(p) => {
            let f =
                std::fs::File::create(p).with_context(|| format!("creating {}", p.display()))?;
            let mut w = std::io::BufWriter::new(f);
            let n = hil::playback::export_candump(&mcap, iface, &mut w)?;
            std::io::Write::flush(&mut w).with_context(|| format!("writing {}", p.display()))?;
            n
        }
        None => hil::playback::export_candump(&mcap, iface, &mut std::io::stdout().lock())?,
    };
    eprintln!("hil candump: {n} frames from {}", mcap.display());
    Ok(0)
}
