//! Fixtures shared by the handheld's integration tests.

use std::path::PathBuf;

/// An empty directory of this test process under the system's temp dir (emptied if it exists).
pub fn temp_root(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("passangle-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
