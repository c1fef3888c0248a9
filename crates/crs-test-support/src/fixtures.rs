//! Paths of the shipped fixtures, independent of the test's working directory.

use std::path::PathBuf;

/// The workspace root (this crate lives in `crates/crs-test-support`).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A file under the shipped `config/` directory, e.g. `config("crs-nominal.toml")`.
pub fn config(name: &str) -> PathBuf {
    workspace_root().join("config").join(name)
}
