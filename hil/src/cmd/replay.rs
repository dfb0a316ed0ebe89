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
    let r = hil::playback::replay(&mcap, &cfg)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", hil::playback::text(&r));
    }
    Ok(i32::from(!r.identical()))
}
