//! Signed files: writing a file and its detached signature `FILE.sig` ([`signing`], which holds
//! the format and the checks), both written atomically, the file first; and checking a file
//! against its sidecar (`passangle verify`, the lab report).
//!
//! A crash between the two leaves a file whose sidecar is missing or older than it; `passangle
//! verify` then reports it as unsigned or changed, never as verified.

use std::fmt;
use std::io::Read as _;
use std::path::Path;
use std::sync::Arc;

use signing::{DeviceKey, Kind, PublicKey, Sidecar, Verdict};

use crate::recorder::{RecorderError, write_atomic};

/// The robot's device key, if records are signed (`signing.key-file`); cheap to clone and to
/// hand to the threads that write a run's files.
#[derive(Clone, Default)]
pub struct Signer(Option<Arc<DeviceKey>>);

impl Signer {
    /// Signing with `key`.
    pub fn new(key: DeviceKey) -> Self {
        Self(Some(Arc::new(key)))
    }

    /// No signing.
    pub fn none() -> Self {
        Self(None)
    }

    /// The key, if any.
    pub fn key(&self) -> Option<&DeviceKey> {
        self.0.as_deref()
    }
}

impl fmt::Debug for Signer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.key() {
            Some(k) => write!(f, "Signer({})", k.public().id()),
            None => f.write_str("Signer(none)"),
        }
    }
}

/// Two signers are equal when they sign with the same public key (or both do not sign).
impl PartialEq for Signer {
    fn eq(&self, other: &Self) -> bool {
        self.key().map(DeviceKey::public) == other.key().map(DeviceKey::public)
    }
}

/// Writes `bytes` to `path` atomically and, when `signer` has a key, its signature to
/// `path.sig` (cut as the file name's [`Kind`]).
pub fn write_signed(path: &Path, bytes: &[u8], signer: &Signer) -> Result<(), RecorderError> {
    write_atomic(path, bytes)?;
    let Some(key) = signer.key() else {
        return Ok(());
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let sidecar = signing::sign_bytes(key, &name, Kind::for_name(&name), bytes);
    write_atomic(
        &path.with_file_name(signing::sidecar_name(&name)),
        &sidecar.to_json(),
    )
}

/// The whole files a robot with a device key signs in every run directory: in a directory,
/// one of these without its `.sig` is reported as unsigned.
pub const SIGNED_IN_A_RUN: [&str; 8] = [
    "config.toml",
    "meta.json",
    "result.json",
    "cloud.ply",
    "side_view.svg",
    crate::scan_file::SCAN_FILE,
    crate::report::LAB_FILE,
    crate::report::REPORT_FILE,
];

/// Reads a sidecar without reading more than a sidecar may be.
pub fn read_sidecar(path: &Path) -> Result<Sidecar, String> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| {
            f.take(signing::MAX_SIDECAR_BYTES as u64 + 1)
                .read_to_end(&mut bytes)
        })
        .map_err(|e| format!("{}: {e}", path.display()))?;
    Sidecar::parse(&bytes).map_err(|e| format!("{}: {e}", path.display()))
}

/// What a file's signature says about it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Check {
    /// The file is what the key with this id signed.
    Verified {
        /// The signer's key id.
        key_id: String,
    },
    /// A trusted key signed the file, which was changed since.
    Changed {
        /// The signer's key id.
        key_id: String,
        /// The name the file was signed as.
        signed_as: String,
        /// What was changed (JSON pointers and the like).
        changes: Vec<String>,
    },
    /// The signature is not by a trusted key, or does not hold.
    Untrusted(String),
    /// No usable signature (missing, too large, not a signature file).
    Unsigned(String),
}

/// Checks one file against its sidecar.
pub fn check_file(file: &Path, sig: &Path, trusted: &[PublicKey]) -> Result<Check, RecorderError> {
    let sidecar = match read_sidecar(sig) {
        Ok(s) => s,
        Err(e) => return Ok(Check::Unsigned(e)),
    };
    let bytes = std::fs::read(file).map_err(|e| RecorderError::io(file, e))?;
    Ok(match sidecar.verify(&bytes, trusted) {
        Ok(Verdict::Verified { key }) => Check::Verified { key_id: key.id() },
        Ok(Verdict::Changed { key, changes }) => Check::Changed {
            key_id: key.id(),
            signed_as: sidecar.manifest.name.clone(),
            changes: changes.iter().map(ToString::to_string).collect(),
        },
        Err(e) => Check::Untrusted(e.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_signed_file_and_its_sidecar_verify() {
        let dir = std::env::temp_dir().join(format!("passangle-signed-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let key = DeviceKey::from_seed(&[5; signing::SEED_LEN]);
        let public = key.public();
        let path = dir.join("result.json");
        write_signed(&path, b"{\"a\": 1}\n", &Signer::new(key)).unwrap();
        let sidecar = Sidecar::parse(&std::fs::read(dir.join("result.json.sig")).unwrap()).unwrap();
        assert_eq!(sidecar.manifest.name, "result.json");
        assert_eq!(
            sidecar.verify(&std::fs::read(&path).unwrap(), &[public]),
            Ok(Verdict::Verified { key: public })
        );
        write_signed(&dir.join("plain.json"), b"{}", &Signer::none()).unwrap();
        assert!(!dir.join("plain.json.sig").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
