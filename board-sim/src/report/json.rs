//! Writing a report.

use std::path::Path;

use anyhow::{Context, Result};

/// Writes `value` as pretty JSON to `p`.
pub(crate) fn write_json(p: &Path, value: &serde_json::Value) -> Result<()> {
    std::fs::write(p, serde_json::to_string_pretty(value)?)
        .with_context(|| format!("writing {}", p.display()))
}
