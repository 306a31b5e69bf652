//! Writing a report.

use std::path::Path;

use anyhow::Result;

/// Writes `value` as pretty JSON to `p`.
pub(crate) fn write_json(p: &Path, value: &serde_json::Value) -> Result<()> {
    host_tools::output::file::write_atomic(p, serde_json::to_string_pretty(value)?)
}
