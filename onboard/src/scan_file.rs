//! `scan.toml`: what the service gave the angle calculator besides `cloud.ply`.
//!
//! The calculator takes the lidar's path (its optical centre along the trajectory, in the
//! cloud's frame) for its coverage and view checks and for the returns' rays across the path
//! (`angles::AnglesConfig::scan_path_in_cloud`), and the trajectory's stated error along the path
//! for the uncertainty budget. `cloud.ply` carries neither, so the service writes them beside it,
//! signed like it, and the lab report's recomputation (`report`) reads them: with both files the
//! calculator sees what the service saw.
//!
//! ```toml
//! trajectory_x_sigma_per_m = 0.005
//! path_m = [[1.95, -0.13, 0.12], [1.94, -0.13, 0.12]]
//! ```

use std::io::Read as _;
use std::path::Path;

use serde::{Deserialize, Serialize};

/// The file's name in a run directory.
pub const SCAN_FILE: &str = "scan.toml";

/// Largest `scan.toml` read (bytes): about 60 bytes a position, a thousand times a run's few
/// hundred lidar frames.
pub const MAX_SCAN_FILE_BYTES: u64 = 16 << 20;

/// The scan besides its cloud.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanRecord {
    /// Standard uncertainty of the trajectory along the path per metre travelled.
    pub trajectory_x_sigma_per_m: f64,
    /// The lidar's optical centre along the trajectory, cloud frame, metres.
    pub path_m: Vec<[f64; 3]>,
}

impl ScanRecord {
    /// The file's text.
    pub fn to_toml(&self) -> String {
        // Plain numbers of a struct of a float and a list of triples always serialize.
        toml::to_string(self).unwrap_or_default()
    }

    /// Parses the file's text; `Err` names what is wrong.
    pub fn parse(text: &str) -> Result<ScanRecord, String> {
        let record: ScanRecord = toml::from_str(text).map_err(|e| e.to_string())?;
        let sigma = record.trajectory_x_sigma_per_m;
        if !(sigma.is_finite() && (0.0..1.0).contains(&sigma)) {
            return Err(format!(
                "trajectory_x_sigma_per_m {sigma} is not a fraction in 0..1"
            ));
        }
        if let Some(i) = record
            .path_m
            .iter()
            .position(|p| p.iter().any(|v| !v.is_finite()))
        {
            return Err(format!("path_m position {} is not finite", i + 1));
        }
        Ok(record)
    }

    /// Reads `dir`'s `scan.toml`: `Ok(None)` when the run has none (it predates the file, or its
    /// processor gave no path), `Err` naming the file when it is unreadable, too large or wrong.
    pub fn read(dir: &Path) -> Result<Option<ScanRecord>, String> {
        let path = dir.join(SCAN_FILE);
        if !path.exists() {
            return Ok(None);
        }
        Self::read_file(&path).map(Some)
    }

    /// Reads a scan file; `Err` naming it when it is missing, unreadable, too large or wrong.
    pub fn read_file(path: &Path) -> Result<ScanRecord, String> {
        let file = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut text = String::new();
        file.take(MAX_SCAN_FILE_BYTES + 1)
            .read_to_string(&mut text)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        if text.len() as u64 > MAX_SCAN_FILE_BYTES {
            return Err(format!(
                "{}: larger than {MAX_SCAN_FILE_BYTES} bytes",
                path.display()
            ));
        }
        Self::parse(&text).map_err(|e| format!("{}: {e}", path.display()))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn record() -> ScanRecord {
        ScanRecord {
            trajectory_x_sigma_per_m: 0.005,
            // A full-precision value must read back bit for bit.
            path_m: vec![
                [1.947_577_873_945_163_7, -0.133, 0.12],
                [1.5, -0.13, 0.1199],
            ],
        }
    }

    #[test]
    fn a_record_reads_back_exactly() {
        let r = record();
        assert_eq!(ScanRecord::parse(&r.to_toml()).unwrap(), r);
    }

    #[test]
    fn a_wrong_file_is_named_and_refused() {
        for (text, says) in [
            ("trajectory_x_sigma_per_m = 0.005\n", "path_m"),
            (
                "trajectory_x_sigma_per_m = -1.0\npath_m = []\n",
                "not a fraction",
            ),
            (
                "trajectory_x_sigma_per_m = nan\npath_m = []\n",
                "not a fraction",
            ),
            (
                "trajectory_x_sigma_per_m = 0.0\npath_m = [[0.0, 0.0, 0.0], [1.0, inf, 0.0]]\n",
                "position 2 is not finite",
            ),
            (
                "trajectory_x_sigma_per_m = 0.0\npath_m = []\nextra = 1\n",
                "unknown field",
            ),
            (
                "path_m = [[0.0, 0.0]]\ntrajectory_x_sigma_per_m = 0.0\n",
                "invalid length",
            ),
        ] {
            let e = ScanRecord::parse(text).unwrap_err();
            assert!(e.contains(says), "{text:?}: {e}");
        }
    }

    proptest::proptest! {
        /// The fuzz target's check (`fuzz/fuzz_targets/scan_file.rs`) in CI: any text is
        /// refused or parses, and what parses writes back to itself.
        #[test]
        fn any_text_is_refused_or_reads_back(text in "[a-z_ =\\[\\],.0-9\\-\n]{0,120}") {
            if let Ok(record) = ScanRecord::parse(&text) {
                proptest::prop_assert_eq!(ScanRecord::parse(&record.to_toml()), Ok(record));
            }
        }

        /// Any finite record reads back exactly.
        #[test]
        fn any_record_reads_back(
            sigma in 0.0..1.0f64,
            path in proptest::collection::vec(proptest::array::uniform3(-1e3..1e3f64), 0..20),
        ) {
            let record = ScanRecord { trajectory_x_sigma_per_m: sigma, path_m: path };
            proptest::prop_assert_eq!(ScanRecord::parse(&record.to_toml()), Ok(record));
        }
    }

    #[test]
    fn a_run_without_the_file_has_none_and_a_bad_one_names_it() {
        let dir = std::env::temp_dir().join(format!("passangle-scan-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        assert_eq!(ScanRecord::read(&dir).unwrap(), None);
        std::fs::write(dir.join(SCAN_FILE), "path_m = 3\n").unwrap();
        let e = ScanRecord::read(&dir).unwrap_err();
        assert!(e.contains(SCAN_FILE), "{e}");
        std::fs::write(dir.join(SCAN_FILE), record().to_toml()).unwrap();
        assert_eq!(ScanRecord::read(&dir).unwrap(), Some(record()));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
