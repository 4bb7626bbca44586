//! Fixtures shared by the handheld's integration tests.
// Each test binary includes this module and uses some of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

use onboard::recorder::{RecordedOutcome, ResultRecord, RunRecorder};
use onboard::signed::{Signer, write_signed};
use onboard::signing::DeviceKey;
use protocol::bounded::Text;
use protocol::radio::{MeasurementResult, StartMeasurement, Zone};

/// An empty directory of this test process under the system's temp dir (emptied if it exists).
pub fn temp_root(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("passangle-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs `passangle` with `args` (and `HOME` at `home`, if given): its exit code and its stdout
/// followed by its stderr.
pub fn passangle(args: &[&str], home: Option<&Path>) -> (i32, String) {
    let mut command = Command::new(env!("CARGO_BIN_EXE_passangle"));
    command.args(args);
    if let Some(home) = home {
        command.env("HOME", home);
    }
    let out = command.output().unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.code().unwrap(), text)
}

/// Run 1 of vehicle AB-123, finished and signed with `key` as the service signs it: the
/// recorder's files with `result`, and the processing thread's `cloud.ply` and `side_view.svg`
/// with the given bytes. Returns the run directory under `root`.
pub fn signed_run(
    root: &Path,
    key: DeviceKey,
    result: &MeasurementResult,
    cloud_ply: &[u8],
    side_view_svg: &[u8],
) -> PathBuf {
    let params = StartMeasurement {
        vehicle_id: Text::truncated("AB-123"),
        speed_mps: 0.2,
        distance_m: 7.0,
        zone: Zone::Tyre,
        lab: protocol::radio::LabRef::NONE,
    };
    let signer = Signer::new(key);
    let mut rec = RunRecorder::begin_signed(
        root,
        1,
        &params,
        1_790_000_000_000_000,
        include_str!("../../../onboard/onboard.example.toml"),
        signer.clone(),
    )
    .unwrap();
    rec.save_result(&ResultRecord::from_wire(result));
    let dir = rec.dir().to_path_buf();
    write_signed(&dir.join("cloud.ply"), cloud_ply, &signer).unwrap();
    write_signed(&dir.join("side_view.svg"), side_view_svg, &signer).unwrap();
    assert!(rec.finish(RecordedOutcome::Completed).is_empty());
    dir
}
