//! Shared helpers for the system tests.
use std::path::PathBuf;

/// `../shared/meshes` beside the checkout (tests read the organ meshes from there).
pub fn shared_meshes_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/meshes")
}
