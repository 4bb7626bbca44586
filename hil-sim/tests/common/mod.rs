//! Fixtures shared by the simulator's integration tests.
// Each test binary includes this module and uses some of it.
#![allow(dead_code)]

use std::path::PathBuf;

use hil_sim::vehicle::Vehicle;

/// The hil-sim crate's directory (its shipped vehicles, scenarios and worlds).
pub fn crate_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The shipped vehicles' directory.
pub fn vehicles_dir() -> PathBuf {
    crate_dir().join("vehicles")
}

/// The shipped vehicle `vehicles/NAME.toml`.
pub fn shipped_vehicle(name: &str) -> Vehicle {
    Vehicle::load(&vehicles_dir().join(format!("{name}.toml"))).expect("shipped vehicle is valid")
}

/// A fresh, empty directory named for `name` and this test process under the system's temp dir.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hil-sim-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}
