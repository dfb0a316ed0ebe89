//! Helpers for the end-to-end tests: locating the workspace binaries and reading MCAP files.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A binary of the workspace, from the same target folder as the running test.
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> -> target/<profile>/<name>
    let dir = exe.parent().and_then(Path::parent).expect("target folder");
    let p = dir.join(name);
    assert!(
        p.is_file(),
        "{} is missing: build the workspace binaries first (cargo build --workspace)",
        p.display()
    );
    p
}

/// Messages per topic in an MCAP file, reading until the end or the first error.
pub fn mcap_topic_counts(path: &Path) -> anyhow::Result<BTreeMap<String, u64>> {
    let buf = std::fs::read(path)?;
    let mut counts = BTreeMap::new();
    for m in mcap::MessageStream::new(&buf)? {
        let m = m?;
        *counts.entry(m.channel.topic.clone()).or_insert(0) += 1;
    }
    Ok(counts)
}
