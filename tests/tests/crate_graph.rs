//! The architecture's rule on crate edges: nav and the emulators share only the wire contract.
//! nav depends on wire and never on emulators; emulators depend on wire and never on nav; only
//! hil and the tests see both. Read from `cargo metadata`.

use serde_json::Value;

#[test]
fn nav_and_the_emulators_share_only_the_wire_contract() {
    let o = std::process::Command::new(env!("CARGO"))
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo metadata runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: Value = serde_json::from_slice(&o.stdout).expect("cargo metadata JSON");
    let deps = |name: &str| -> Vec<String> {
        let p = m["packages"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .unwrap_or_else(|| panic!("no package {name}"));
        p["dependencies"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| d["name"].as_str().unwrap().to_string())
            .collect()
    };
    let forbidden = [
        ("nav", "emulators"),
        ("nav", "hil"),
        ("emulators", "nav"),
        ("emulators", "hil"),
        ("wire", "nav"),
        ("wire", "emulators"),
    ];
    for (from, to) in forbidden {
        assert!(
            !deps(from).iter().any(|d| d == to),
            "forbidden crate edge {from} -> {to} (nav and the emulators share only the wire contract)"
        );
    }
    assert!(deps("nav").iter().any(|d| d == "wire"));
    assert!(deps("emulators").iter().any(|d| d == "wire"));
}

/// Every package the workspace's dev profile names (`[profile.dev.package.NAME]`) is in the lock
/// file: a dependency dropped or renamed upstream leaves its entry naming nothing, silently
/// (cargo only warns), and the build loses the setting the entry was written for.
#[test]
fn the_dev_profile_names_only_packages_the_lock_file_has() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).expect("Cargo.toml");
    let lock = std::fs::read_to_string(root.join("Cargo.lock")).expect("Cargo.lock");
    let locked: std::collections::BTreeSet<&str> = lock
        .lines()
        .filter_map(|l| l.strip_prefix("name = \""))
        .filter_map(|l| l.strip_suffix('"'))
        .collect();
    let named: Vec<&str> = manifest
        .lines()
        .filter_map(|l| l.trim().strip_prefix("[profile.dev.package."))
        .filter_map(|l| l.strip_suffix(']'))
        .map(|n| n.trim_matches('"'))
        .filter(|n| *n != "*")
        .collect();
    assert!(named.len() > 10, "the dev profile's entries: {named:?}");
    let stale: Vec<&&str> = named.iter().filter(|n| !locked.contains(**n)).collect();
    assert!(
        stale.is_empty(),
        "[profile.dev.package.X] names packages Cargo.lock does not have (drop the entries): {stale:?}"
    );
}
