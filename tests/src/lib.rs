//! passangle end-to-end scenarios across crates live in `tests/tests/`; this library holds their
//! shared helpers.

use std::path::PathBuf;

/// A path named for `name` and this test process under the system's temp dir, with nothing at it
/// (for a run root that the code under test creates).
pub fn scratch(name: &str) -> PathBuf {
    let path = std::env::temp_dir().join(format!("passangle-e2e-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&path);
    path
}

/// An empty directory at [`scratch`]`(name)`.
///
/// # Panics
/// If the directory cannot be created.
pub fn temp_root(name: &str) -> PathBuf {
    let dir = scratch(name);
    std::fs::create_dir_all(&dir).expect("a temp dir");
    dir
}
