//! Signed records: a detached Ed25519 signature (`FILE.sig`) over a manifest of a file, so that a
//! lab can check offline, with the robot's public key, that a record is the robot's, and be told
//! *what* was changed when it is not.
//!
//! The manifest holds the file's size and SHA-256 and one digest per located part of it:
//!
//! - [`Kind::Json`]: every leaf value (and every empty object or array), by its JSON pointer
//!   (RFC 6901, e.g. `/approach_deg`); the digest is SHA-256 of the value's compact JSON.
//! - [`Kind::Text`] (SVG, HTML, TOML, CSV): every line, newline included, by its number.
//! - [`Kind::Binary`] (PLY and anything else): every [`BLOCK_LEN`]-byte block, by its offset.
//!
//! The signature covers [`Manifest::signed_bytes`]: a domain-separation prefix, the algorithm,
//! the public key and the manifest, each field length-prefixed, so that no two manifests encode
//! alike. Verification checks the signer's key against the keys the verifier trusts, then the
//! signature, then the file's digest; only when all of the signature holds and the digest does
//! not is the file compared part by part, so a forged sidecar can never make a changed file look
//! unchanged or point at the wrong place.
//!
//! Nothing here does IO or reads a clock: bytes in, results out (`onboard::signing` writes the
//! files, `passangle verify` reads them).

use std::collections::HashMap;
use std::fmt;

use ed25519_dalek::{Signature, Signer, SigningKey, VerifyingKey};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// Version of the sidecar format (the `format` field).
pub const FORMAT: u32 = 1;
/// The only algorithm (the `algorithm` field).
pub const ALGORITHM: &str = "ed25519";
/// Length of a device key's seed (the secret), bytes.
pub const SEED_LEN: usize = 32;
/// What a sidecar's name adds to its file's name.
pub const SIDECAR_SUFFIX: &str = ".sig";
/// The largest sidecar [`Sidecar::parse`] reads, bytes (a 4 GiB binary file's manifest is
/// 6 MiB).
pub const MAX_SIDECAR_BYTES: usize = 8 << 20;
/// The most parts a manifest holds: a JSON or text file with more is signed by blocks.
pub const MAX_PARTS: usize = 100_000;
/// Size of a [`Kind::Binary`] block, bytes.
pub const BLOCK_LEN: usize = 64 * 1024;
/// Prefix of the signed bytes: a signature over anything else never verifies as a record.
const DOMAIN: &[u8] = b"passangle signed record v1\0";

/// A SHA-256 digest.
pub type Digest32 = [u8; 32];

fn sha256(bytes: &[u8]) -> Digest32 {
    Sha256::digest(bytes).into()
}

/// Lower-case hex of `bytes`.
pub fn to_hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut s = String::with_capacity(2 * bytes.len());
    for b in bytes {
        s.push(char::from(DIGITS[usize::from(b >> 4)]));
        s.push(char::from(DIGITS[usize::from(b & 15)]));
    }
    s
}

/// Exactly `N` bytes from `2 * N` hex digits (either case), or `None`.
pub fn from_hex<const N: usize>(hex: &str) -> Option<[u8; N]> {
    let hex = hex.as_bytes();
    if hex.len() != 2 * N {
        return None;
    }
    let digit = |c: u8| char::from(c).to_digit(16).map(|d| d as u8);
    let mut out = [0u8; N];
    for (i, b) in out.iter_mut().enumerate() {
        *b = digit(hex[2 * i])? << 4 | digit(hex[2 * i + 1])?;
    }
    Some(out)
}

/// A robot's public key: what a lab trusts.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct PublicKey([u8; 32]);

impl PublicKey {
    /// From its 32 bytes (not checked to be a curve point: [`Sidecar::verify`] does that).
    pub fn from_bytes(bytes: [u8; 32]) -> Self {
        Self(bytes)
    }

    /// Its 32 bytes.
    pub fn to_bytes(self) -> [u8; 32] {
        self.0
    }

    /// From 64 hex digits (surrounding whitespace ignored).
    pub fn from_hex(hex: &str) -> Option<Self> {
        from_hex(hex.trim()).map(Self)
    }

    /// 64 hex digits.
    pub fn to_hex(self) -> String {
        to_hex(&self.0)
    }

    /// The key's public id: the first 4 bytes of SHA-256("passangle device key id" || key), as
    /// eight hex digits (the radio's pairing keys are named the same way, with another prefix,
    /// so a device key id never equals a pairing key's id by construction).
    pub fn id(self) -> String {
        let d = Sha256::new()
            .chain_update(b"passangle device key id")
            .chain_update(self.0)
            .finalize();
        to_hex(&d[..4])
    }
}

impl fmt::Debug for PublicKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "PublicKey({} {})", self.id(), self.to_hex())
    }
}

impl fmt::Display for PublicKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.to_hex())
    }
}

/// The robot's secret signing key (wiped from memory when dropped).
pub struct DeviceKey {
    key: SigningKey,
}

impl DeviceKey {
    /// From a 32-byte seed (RFC 8032's private key).
    pub fn from_seed(seed: &[u8; SEED_LEN]) -> Self {
        Self {
            key: SigningKey::from_bytes(seed),
        }
    }

    /// Its public key.
    pub fn public(&self) -> PublicKey {
        PublicKey(self.key.verifying_key().to_bytes())
    }
}

impl fmt::Debug for DeviceKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "DeviceKey(public {})", self.public().id())
    }
}

/// How a file is cut into located parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    /// Leaf values by JSON pointer.
    Json,
    /// Lines by number.
    Text,
    /// Blocks of [`BLOCK_LEN`] bytes by offset.
    Binary,
}

impl Kind {
    /// The kind for a file name, by its extension: `.json` is JSON; `.svg`, `.html`, `.htm`,
    /// `.xml`, `.toml`, `.csv`, `.txt` and `.md` are text; anything else is binary.
    pub fn for_name(name: &str) -> Self {
        let ext = name
            .rsplit_once('.')
            .map(|(_, e)| e.to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "json" => Self::Json,
            "svg" | "html" | "htm" | "xml" | "toml" | "csv" | "txt" | "md" => Self::Text,
            _ => Self::Binary,
        }
    }

    /// Its name in the sidecar.
    pub fn name(self) -> &'static str {
        match self {
            Self::Json => "json",
            Self::Text => "text",
            Self::Binary => "binary",
        }
    }
}

/// One located part of a file and its digest.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Part {
    /// JSON pointer, line number or byte offset.
    pub locator: String,
    /// SHA-256 of the part.
    pub sha256: Digest32,
}

/// What is signed about a file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Manifest {
    /// The file's name when it was signed (informative: a copy may be renamed).
    pub name: String,
    /// How the parts were cut (a `Json` file that did not parse is signed as `Text`).
    pub kind: Kind,
    /// The file's size, bytes.
    pub size: u64,
    /// SHA-256 of the whole file: what the signature vouches for.
    pub sha256: Digest32,
    /// The parts, in file order.
    pub parts: Vec<Part>,
}

/// Why a file could not be cut as its kind says (the verifier reports it as the change).
#[derive(Clone, Debug, PartialEq, Eq)]
struct Unreadable(String);

fn json_parts(bytes: &[u8]) -> Result<Vec<Part>, Unreadable> {
    fn escape(key: &str) -> String {
        key.replace('~', "~0").replace('/', "~1")
    }
    fn walk(v: &serde_json::Value, pointer: &mut String, out: &mut Vec<Part>) -> bool {
        if out.len() > MAX_PARTS {
            return false;
        }
        let len = pointer.len();
        match v {
            serde_json::Value::Object(m) if !m.is_empty() => m.iter().all(|(k, v)| {
                pointer.push('/');
                pointer.push_str(&escape(k));
                let ok = walk(v, pointer, out);
                pointer.truncate(len);
                ok
            }),
            serde_json::Value::Array(a) if !a.is_empty() => a.iter().enumerate().all(|(i, v)| {
                pointer.push('/');
                pointer.push_str(&i.to_string());
                let ok = walk(v, pointer, out);
                pointer.truncate(len);
                ok
            }),
            leaf => {
                // Serialising a `Value` cannot fail (its keys are strings).
                let compact = serde_json::to_vec(leaf).unwrap_or_default();
                out.push(Part {
                    locator: pointer.clone(),
                    sha256: sha256(&compact),
                });
                true
            }
        }
    }
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|e| Unreadable(format!("not JSON ({e})")))?;
    let mut out = Vec::new();
    if walk(&value, &mut String::new(), &mut out) && out.len() <= MAX_PARTS {
        Ok(out)
    } else {
        Err(Unreadable(format!("more than {MAX_PARTS} JSON values")))
    }
}

fn text_parts(bytes: &[u8]) -> Result<Vec<Part>, Unreadable> {
    let mut out = Vec::new();
    for (i, line) in bytes.split_inclusive(|&b| b == b'\n').enumerate() {
        if i >= MAX_PARTS {
            return Err(Unreadable(format!("more than {MAX_PARTS} lines")));
        }
        out.push(Part {
            locator: (i + 1).to_string(),
            sha256: sha256(line),
        });
    }
    Ok(out)
}

fn binary_parts(bytes: &[u8]) -> Vec<Part> {
    bytes
        .chunks(BLOCK_LEN)
        .enumerate()
        .map(|(i, block)| Part {
            locator: (i * BLOCK_LEN).to_string(),
            sha256: sha256(block),
        })
        .collect()
}

fn parts(kind: Kind, bytes: &[u8]) -> Result<Vec<Part>, Unreadable> {
    match kind {
        Kind::Json => json_parts(bytes),
        Kind::Text => text_parts(bytes),
        Kind::Binary => Ok(binary_parts(bytes)),
    }
}

fn put_field(out: &mut Vec<u8>, field: &[u8]) {
    out.extend_from_slice(&(field.len() as u64).to_le_bytes());
    out.extend_from_slice(field);
}

impl Manifest {
    /// The manifest of `bytes` named `name`, cut as `kind` if it can be (a JSON file that does
    /// not parse, or one with more than [`MAX_PARTS`] values, is cut as text; a text file with
    /// more lines, as blocks).
    pub fn of(name: &str, kind: Kind, bytes: &[u8]) -> Self {
        let mut kind = kind;
        let parts = loop {
            match parts(kind, bytes) {
                Ok(p) => break p,
                Err(_) if kind == Kind::Json => kind = Kind::Text,
                Err(_) => {
                    kind = Kind::Binary;
                    break binary_parts(bytes);
                }
            }
        };
        Self {
            name: name.to_owned(),
            kind,
            size: bytes.len() as u64,
            sha256: sha256(bytes),
            parts,
        }
    }

    /// The bytes the signature covers: `DOMAIN`, then the algorithm, the public key, the name,
    /// the kind, the size, the file's digest and each part (locator and digest), every variable
    /// field preceded by its length as a little-endian u64.
    pub fn signed_bytes(&self, key: PublicKey) -> Vec<u8> {
        let mut out = Vec::with_capacity(DOMAIN.len() + 200 + self.parts.len() * 64);
        out.extend_from_slice(DOMAIN);
        put_field(&mut out, ALGORITHM.as_bytes());
        out.extend_from_slice(&key.0);
        put_field(&mut out, self.name.as_bytes());
        put_field(&mut out, self.kind.name().as_bytes());
        out.extend_from_slice(&self.size.to_le_bytes());
        out.extend_from_slice(&self.sha256);
        out.extend_from_slice(&(self.parts.len() as u64).to_le_bytes());
        for p in &self.parts {
            put_field(&mut out, p.locator.as_bytes());
            out.extend_from_slice(&p.sha256);
        }
        out
    }
}

/// A detached signature: the manifest, the signer's public key and the signature.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Sidecar {
    /// What was signed.
    pub manifest: Manifest,
    /// Who signed.
    pub public_key: PublicKey,
    /// Ed25519 over [`Manifest::signed_bytes`].
    pub signature: [u8; 64],
}

/// The sidecar's name for a file's name: `result.json` -> `result.json.sig`.
pub fn sidecar_name(name: &str) -> String {
    format!("{name}{SIDECAR_SUFFIX}")
}

/// Signs `bytes`, a file named `name` cut as `kind` (use [`Kind::for_name`] when in doubt).
/// Ed25519 signatures are deterministic: the same key and bytes give the same sidecar.
pub fn sign_bytes(key: &DeviceKey, name: &str, kind: Kind, bytes: &[u8]) -> Sidecar {
    let manifest = Manifest::of(name, kind, bytes);
    let public_key = key.public();
    let signature = key.key.sign(&manifest.signed_bytes(public_key)).to_bytes();
    Sidecar {
        manifest,
        public_key,
        signature,
    }
}

/// The sidecar file, as JSON (`deny_unknown_fields`: a field this version does not know is an
/// error, not ignored).
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SidecarFile {
    format: u32,
    algorithm: String,
    key_id: String,
    public_key: String,
    name: String,
    kind: Kind,
    size: u64,
    sha256: String,
    parts: Vec<(String, String)>,
    signature: String,
}

/// Why a sidecar could not be read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SidecarError {
    /// Larger than [`MAX_SIDECAR_BYTES`].
    TooLarge(usize),
    /// Not the sidecar JSON (serde_json's message, with line and column).
    Json(String),
    /// A `format` this version does not read.
    Format(u32),
    /// An `algorithm` other than Ed25519, the only signature scheme a sidecar may name.
    Algorithm(String),
    /// A field that is not the hex it must be.
    Hex(&'static str),
    /// `key_id` is not the id of `public_key`.
    KeyId,
    /// More than [`MAX_PARTS`] parts.
    TooManyParts(usize),
}

impl fmt::Display for SidecarError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooLarge(n) => write!(
                f,
                "{n} bytes: larger than any signature file ({MAX_SIDECAR_BYTES} bytes)"
            ),
            Self::Json(e) => write!(f, "not a passangle signature file: {e}"),
            Self::Format(v) => write!(
                f,
                "signature format {v}: this passangle reads format {FORMAT}"
            ),
            Self::Algorithm(a) => write!(f, "algorithm {a:?}: only {ALGORITHM:?} is used"),
            Self::Hex(field) => write!(f, "`{field}` is not valid hex of the right length"),
            Self::KeyId => f.write_str("`key_id` is not the id of `public_key`"),
            Self::TooManyParts(n) => write!(f, "{n} parts: more than {MAX_PARTS}"),
        }
    }
}

impl std::error::Error for SidecarError {}

impl Sidecar {
    /// The sidecar file's bytes: JSON, one part per line.
    pub fn to_json(&self) -> Vec<u8> {
        use std::fmt::Write as _;
        let q = |s: &str| serde_json::Value::String(s.to_owned()).to_string();
        let m = &self.manifest;
        let mut s = format!(
            "{{\n  \"format\": {FORMAT},\n  \"algorithm\": \"{ALGORITHM}\",\n  \"key_id\": \"{}\",\n  \
             \"public_key\": \"{}\",\n  \"name\": {},\n  \"kind\": \"{}\",\n  \"size\": {},\n  \
             \"sha256\": \"{}\",\n  \"parts\": [",
            self.public_key.id(),
            self.public_key.to_hex(),
            q(&m.name),
            m.kind.name(),
            m.size,
            to_hex(&m.sha256),
        );
        for (i, p) in m.parts.iter().enumerate() {
            let sep = if i == 0 { "" } else { "," };
            let _ = write!(
                s,
                "{sep}\n    [{}, \"{}\"]",
                q(&p.locator),
                to_hex(&p.sha256)
            );
        }
        if !m.parts.is_empty() {
            s.push_str("\n  ");
        }
        let _ = write!(
            s,
            "],\n  \"signature\": \"{}\"\n}}\n",
            to_hex(&self.signature)
        );
        s.into_bytes()
    }

    /// Reads a sidecar file. Never panics; allocates within a small multiple of the input,
    /// which is at most [`MAX_SIDECAR_BYTES`].
    pub fn parse(bytes: &[u8]) -> Result<Self, SidecarError> {
        if bytes.len() > MAX_SIDECAR_BYTES {
            return Err(SidecarError::TooLarge(bytes.len()));
        }
        let f: SidecarFile =
            serde_json::from_slice(bytes).map_err(|e| SidecarError::Json(e.to_string()))?;
        if f.format != FORMAT {
            return Err(SidecarError::Format(f.format));
        }
        if f.algorithm != ALGORITHM {
            return Err(SidecarError::Algorithm(f.algorithm));
        }
        if f.parts.len() > MAX_PARTS {
            return Err(SidecarError::TooManyParts(f.parts.len()));
        }
        let public_key =
            PublicKey::from_hex(&f.public_key).ok_or(SidecarError::Hex("public_key"))?;
        if public_key.id() != f.key_id.to_ascii_lowercase() {
            return Err(SidecarError::KeyId);
        }
        let parts = f
            .parts
            .into_iter()
            .map(|(locator, hex)| {
                Ok(Part {
                    locator,
                    sha256: from_hex(&hex).ok_or(SidecarError::Hex("parts"))?,
                })
            })
            .collect::<Result<_, SidecarError>>()?;
        Ok(Self {
            manifest: Manifest {
                name: f.name,
                kind: f.kind,
                size: f.size,
                sha256: from_hex(&f.sha256).ok_or(SidecarError::Hex("sha256"))?,
                parts,
            },
            public_key,
            signature: from_hex(&f.signature).ok_or(SidecarError::Hex("signature"))?,
        })
    }

    /// Checks `bytes` against this signature, trusting only the keys in `trusted`.
    pub fn verify(&self, bytes: &[u8], trusted: &[PublicKey]) -> Result<Verdict, SignatureError> {
        let key = self.public_key;
        if !trusted.contains(&key) {
            return Err(SignatureError::UntrustedKey { key_id: key.id() });
        }
        let bad = || SignatureError::BadSignature { key_id: key.id() };
        let verifying = VerifyingKey::from_bytes(&key.0).map_err(|_| bad())?;
        verifying
            .verify_strict(
                &self.manifest.signed_bytes(key),
                &Signature::from_bytes(&self.signature),
            )
            .map_err(|_| bad())?;
        if sha256(bytes) == self.manifest.sha256 && bytes.len() as u64 == self.manifest.size {
            return Ok(Verdict::Verified { key });
        }
        Ok(Verdict::Changed {
            key,
            changes: diff(&self.manifest, bytes),
        })
    }
}

/// Why a signature does not vouch for anything.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SignatureError {
    /// Signed (or claimed to be signed) by a key the verifier does not trust.
    UntrustedKey {
        /// The signer's key id.
        key_id: String,
    },
    /// The signature does not hold: the sidecar was altered or forged.
    BadSignature {
        /// The key id the sidecar names.
        key_id: String,
    },
}

impl fmt::Display for SignatureError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UntrustedKey { key_id } => write!(
                f,
                "signature does not match this key: signed by key {key_id}, which is not a \
                 trusted robot key"
            ),
            Self::BadSignature { key_id } => write!(
                f,
                "signature does not match this key: the signature file names key {key_id} but \
                 its signature does not hold (the .sig file was altered or forged)"
            ),
        }
    }
}

impl std::error::Error for SignatureError {}

/// The outcome of a verification whose signature holds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// The file is exactly what `key` signed.
    Verified {
        /// The signer.
        key: PublicKey,
    },
    /// `key` signed a different file: what differs.
    Changed {
        /// The signer.
        key: PublicKey,
        /// The differences, in file order (never empty).
        changes: Vec<Change>,
    },
}

/// One difference between the signed file and the file at hand.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Change {
    /// A JSON value differs.
    Value(String),
    /// A JSON value is present that was not signed.
    Added(String),
    /// A signed JSON value is missing.
    Removed(String),
    /// Lines `signed` (1-based, inclusive; empty when lines were only added) were signed; lines
    /// `now` stand in their place.
    Lines {
        /// First and last signed line of the changed stretch (`first > last`: none).
        signed: (usize, usize),
        /// First and last line now in their place (`first > last`: none).
        now: (usize, usize),
    },
    /// Bytes from `offset` on differ (the first differing block, size aside).
    Bytes {
        /// Offset of the first block that differs.
        offset: u64,
    },
    /// The values are the same; only the layout changed (whitespace, key order, number
    /// spelling).
    Layout,
    /// The file can no longer be read as its kind (e.g. a JSON record that no longer parses).
    Unreadable(String),
}

fn range(r: (usize, usize)) -> String {
    match r {
        (a, b) if a > b => "none".to_owned(),
        (a, b) if a == b => format!("line {a}"),
        (a, b) => format!("lines {a}-{b}"),
    }
}

impl fmt::Display for Change {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Value(p) => write!(f, "changed: {p}"),
            Self::Added(p) => write!(f, "added: {p}"),
            Self::Removed(p) => write!(f, "removed: {p}"),
            Self::Lines { signed, now } if signed.0 > signed.1 => {
                write!(
                    f,
                    "added: {} (after signed line {})",
                    range(*now),
                    signed.0 - 1
                )
            }
            Self::Lines { signed, now } if now.0 > now.1 => {
                write!(f, "removed: signed {}", range(*signed))
            }
            Self::Lines { signed, now } if signed == now => write!(f, "changed: {}", range(*now)),
            Self::Lines { signed, now } => {
                write!(f, "changed: {} (signed as {})", range(*now), range(*signed))
            }
            Self::Bytes { offset } => write!(f, "changed: bytes from offset {offset}"),
            Self::Layout => f.write_str(
                "changed: layout only (whitespace, key order or number spelling); every value \
                 is as signed",
            ),
            Self::Unreadable(why) => write!(f, "changed: the file is {why}"),
        }
    }
}

/// What differs between the signed manifest and `bytes` (whose digest differs from it).
fn diff(signed: &Manifest, bytes: &[u8]) -> Vec<Change> {
    let now = match parts(signed.kind, bytes) {
        Ok(p) => p,
        Err(Unreadable(why)) => return vec![Change::Unreadable(why)],
    };
    let mut changes = match signed.kind {
        Kind::Json => {
            let was: HashMap<&str, &Digest32> = signed
                .parts
                .iter()
                .map(|p| (p.locator.as_str(), &p.sha256))
                .collect();
            let is: HashMap<&str, &Digest32> = now
                .iter()
                .map(|p| (p.locator.as_str(), &p.sha256))
                .collect();
            let mut out: Vec<Change> = signed
                .parts
                .iter()
                .filter_map(|p| match is.get(p.locator.as_str()) {
                    None => Some(Change::Removed(p.locator.clone())),
                    Some(d) if **d != p.sha256 => Some(Change::Value(p.locator.clone())),
                    Some(_) => None,
                })
                .collect();
            out.extend(
                now.iter()
                    .filter(|p| !was.contains_key(p.locator.as_str()))
                    .map(|p| Change::Added(p.locator.clone())),
            );
            out
        }
        Kind::Text | Kind::Binary => {
            let (a, b) = (&signed.parts, &now);
            let prefix = a
                .iter()
                .zip(b)
                .take_while(|(x, y)| x.sha256 == y.sha256)
                .count();
            let suffix = a[prefix..]
                .iter()
                .rev()
                .zip(b[prefix..].iter().rev())
                .take_while(|(x, y)| x.sha256 == y.sha256)
                .count();
            if prefix == a.len() && prefix == b.len() {
                Vec::new()
            } else if signed.kind == Kind::Text {
                vec![Change::Lines {
                    signed: (prefix + 1, a.len() - suffix),
                    now: (prefix + 1, b.len() - suffix),
                }]
            } else {
                vec![Change::Bytes {
                    offset: (prefix * BLOCK_LEN) as u64,
                }]
            }
        }
    };
    if changes.is_empty() {
        changes.push(Change::Layout);
    }
    changes
}

#[cfg(test)]
mod tests;
