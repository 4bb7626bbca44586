//! Pairing-key files.
//!
//! A key file holds one pairing key per line as 64 hex digits, optionally followed by a label
//! (the rest of the line); blank lines and lines starting with `#` are ignored. The handheld's
//! file (`passangle pair` writes it, mode 0600) holds its one key; the robot's `radio.key-file`
//! holds one line per paired handheld. A key is named by its public id
//! ([`protocol::auth::key_id`], eight hex digits), which `passangle pair` prints and
//! `passangle-onboard keys list` shows. Revoking removes the line; the service reads the file at
//! start, so a revocation takes effect when it restarts.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use protocol::auth::{KEY_LEN, Key, key_id};

/// Why a key file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum KeyFileError {
    /// Reading or writing failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A line is not a key.
    #[error("{path} line {line}: expected {digits} hex digits and an optional label (a key written by `passangle pair`)", digits = 2 * KEY_LEN)]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
    },
    /// The file holds no key.
    #[error("{0}: no pairing key in the file")]
    Empty(PathBuf),
    /// The key is listed already.
    #[error("{path}: key {id:08x} is already paired")]
    Duplicate {
        /// The file.
        path: PathBuf,
        /// Its id.
        id: u32,
    },
    /// No key with this id.
    #[error("{path}: no key with id {id:08x}")]
    NotFound {
        /// The file.
        path: PathBuf,
        /// The id asked for.
        id: u32,
    },
}

/// One paired key.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyEntry {
    /// Its public id.
    pub id: u32,
    /// The key.
    pub key: Key,
    /// The label after the key (may be empty).
    pub label: String,
}

fn parse_hex_key(hex: &str) -> Option<Key> {
    if hex.len() != 2 * KEY_LEN || !hex.is_ascii() {
        return None;
    }
    let mut key = [0u8; KEY_LEN];
    for (i, b) in key.iter_mut().enumerate() {
        *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok()?;
    }
    Some(Key(key))
}

fn hex_of(key: &Key) -> String {
    key.0.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

/// Parses a key file's text (see the module docs).
pub fn parse(path: &Path, text: &str) -> Result<Vec<KeyEntry>, KeyFileError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (hex, label) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
        let key = parse_hex_key(hex).ok_or_else(|| KeyFileError::Parse {
            path: path.to_owned(),
            line: i + 1,
        })?;
        out.push(KeyEntry {
            id: key_id(&key),
            key,
            label: label.trim().to_owned(),
        });
    }
    Ok(out)
}

/// Reads a key file; at least one key.
pub fn read(path: &Path) -> Result<Vec<KeyEntry>, KeyFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| KeyFileError::Io {
        path: path.to_owned(),
        source,
    })?;
    let keys = parse(path, &text)?;
    if keys.is_empty() {
        return Err(KeyFileError::Empty(path.to_owned()));
    }
    Ok(keys)
}

fn write_lines(path: &Path, entries: &[KeyEntry]) -> Result<(), KeyFileError> {
    let io = |source| KeyFileError::Io {
        path: path.to_owned(),
        source,
    };
    let mut text = String::new();
    for e in entries {
        let _ = writeln!(text, "{} {}", hex_of(&e.key), e.label);
    }
    let tmp = path.with_extension("tmp");
    {
        use std::os::unix::fs::OpenOptionsExt as _;
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .mode(0o600)
            .open(&tmp)
            .map_err(io)?;
        f.write_all(text.as_bytes()).map_err(io)?;
        f.sync_all().map_err(io)?;
    }
    std::fs::rename(&tmp, path).map_err(io)
}

/// Adds `key` with `label` to the key file at `path` (created mode 0600 if missing).
pub fn add(path: &Path, key: &Key, label: &str) -> Result<u32, KeyFileError> {
    let mut entries = match std::fs::read_to_string(path) {
        Ok(text) => parse(path, &text)?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(source) => {
            return Err(KeyFileError::Io {
                path: path.to_owned(),
                source,
            });
        }
    };
    let id = key_id(key);
    if entries.iter().any(|e| e.id == id) {
        return Err(KeyFileError::Duplicate {
            path: path.to_owned(),
            id,
        });
    }
    entries.push(KeyEntry {
        id,
        key: key.clone(),
        label: label.replace(['\n', '\r'], " "),
    });
    write_lines(path, &entries)?;
    Ok(id)
}

/// Removes the key with `id` from the key file at `path`.
pub fn revoke(path: &Path, id: u32) -> Result<KeyEntry, KeyFileError> {
    let mut entries = read(path)?;
    let i = entries
        .iter()
        .position(|e| e.id == id)
        .ok_or_else(|| KeyFileError::NotFound {
            path: path.to_owned(),
            id,
        })?;
    let gone = entries.remove(i);
    write_lines(path, &entries)?;
    Ok(gone)
}

/// Writes a new one-key file (the handheld's, `passangle pair`) readable by its owner only (mode
/// 0600); refuses to overwrite.
pub fn write_key(path: &Path, key: &Key) -> Result<(), KeyFileError> {
    write_secret_hex(path, &key.0).map_err(|source| KeyFileError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Writes `secret` as hex and a newline to a new file of mode 0600; refuses to overwrite. The
/// robot's device key file (`onboard::config::write_device_key`) is written the same way.
pub fn write_secret_hex(path: &Path, secret: &[u8]) -> std::io::Result<()> {
    use std::os::unix::fs::OpenOptionsExt as _;
    let hex: String = secret.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    });
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)?;
    f.write_all(format!("{hex}\n").as_bytes())?;
    f.sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn add_list_revoke_round_trip() {
        let dir = std::env::temp_dir().join(format!("passangle-keys-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("paired");
        let a = Key([1; KEY_LEN]);
        let b = Key([2; KEY_LEN]);
        assert_eq!(add(&p, &a, "field tablet").unwrap(), key_id(&a));
        add(&p, &b, "").unwrap();
        assert!(matches!(
            add(&p, &a, "again"),
            Err(KeyFileError::Duplicate { .. })
        ));
        let keys = read(&p).unwrap();
        assert_eq!(keys.len(), 2);
        assert_eq!(keys[0].label, "field tablet");
        assert_eq!(keys[1].key, b);
        {
            use std::os::unix::fs::PermissionsExt as _;
            let mode = std::fs::metadata(&p).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        assert_eq!(revoke(&p, key_id(&a)).unwrap().key, a);
        assert_eq!(read(&p).unwrap().len(), 1);
        assert!(matches!(
            revoke(&p, key_id(&a)),
            Err(KeyFileError::NotFound { .. })
        ));
        // A bare single-key file (the handheld's) reads as one key.
        std::fs::write(dir.join("one"), format!("{}\n", hex_of(&a))).unwrap();
        assert_eq!(read(&dir.join("one")).unwrap()[0].key, a);
        std::fs::write(dir.join("bad"), "# c\nzz\n").unwrap();
        let e = read(&dir.join("bad")).unwrap_err().to_string();
        assert!(e.contains("line 2"), "{e}");
        std::fs::write(dir.join("empty"), "# nothing\n").unwrap();
        assert!(matches!(
            read(&dir.join("empty")),
            Err(KeyFileError::Empty(_))
        ));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
