//! A lab's own contract: its mapping file (`wire::mapping`, docs/your-device.md) and the DBC it
//! names beside it, read and checked together.

use anyhow::{Context, Result};
use std::path::Path;
use wire::dbc::Contract;
use wire::mapping::{Mapping, MappingFile};

/// Read the mapping at `path` and the DBC it names (relative to it), and check the one against
/// the other; errors name the file and, from the check, the message and signal.
pub fn load(path: &Path) -> Result<(Contract, Mapping)> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the mapping {}", path.display()))?;
    let file: MappingFile =
        toml::from_str(&text).with_context(|| format!("the mapping {}", path.display()))?;
    let dbc_path = path.parent().unwrap_or(Path::new(".")).join(&file.dbc);
    let dbc = std::fs::read_to_string(&dbc_path)
        .with_context(|| format!("cannot read the DBC {}", dbc_path.display()))?;
    let contract =
        Contract::parse(&dbc).with_context(|| format!("the DBC {}", dbc_path.display()))?;
    let m = Mapping::check(file, &contract)
        .with_context(|| format!("the mapping {} against its DBC", path.display()))?;
    Ok((contract, m))
}
