//! `nav/nav.example.toml`, the config file's reference, is a config nav accepts: `nav --check`
//! reads it, checks every key and exits 0.

#[test]
fn the_example_config_passes_nav_check() {
    let example = concat!(env!("CARGO_MANIFEST_DIR"), "/nav.example.toml");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_nav"))
        .args(["--check", "--config", example])
        .output()
        .expect("nav runs");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}{}",
        text,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("is valid"), "{text}");
}
