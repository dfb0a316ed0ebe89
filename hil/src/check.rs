//! One check of a run: what was asked, whether it held, and the measured value against its
//! limit in words. Procedures, the run and the suites all report in it.

use serde::{Deserialize, Serialize};

/// One check of a run.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Check {
    /// Short name.
    pub name: String,
    /// Passed?
    pub pass: bool,
    /// Measured value and limit, in words.
    pub detail: String,
}

/// A process's exit status as people read it: its code, or "none (killed by a signal)".
pub fn exit_words(code: Option<i32>) -> String {
    code.map_or_else(|| "none (killed by a signal)".into(), |c| c.to_string())
}
