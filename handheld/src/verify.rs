//! `passangle verify FILE|RUN_DIR`: checks a signed record offline against the robot's public key
//! and says what was changed when the check fails (the `signing` crate holds the format).
//!
//! Trust comes from the user, never from the signature file: the sidecar names the key that
//! signed, and the check passes only if that key is one given with `--public-key`, listed in
//! `--keys FILE`, or listed in the default trust file `~/.config/passangle/robot-keys`.
//!
//! Exit codes: 0 every file verified; 1 an error (a file or the trust list unreadable, no trusted
//! key given); 2 usage; 3 a file was changed after the robot signed it; 4 a signature is not by a
//! trusted key or does not hold; 5 a file has no usable signature (missing, too large, not a
//! signature file). With several files, the highest code wins.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;
use onboard::signed::{Check, SIGNED_IN_A_RUN, check_file};
use signing::PublicKey;

/// Every file verified.
pub const OK: u8 = 0;
/// A file was changed after it was signed.
pub const CHANGED: u8 = 3;
/// A signature is not by a trusted key, or does not hold.
pub const UNTRUSTED: u8 = 4;
/// A file has no usable signature.
pub const UNSIGNED: u8 = 5;

/// The largest trust list read, bytes.
const MAX_KEYS_FILE: u64 = 1 << 20;

/// Changes listed per file before the rest are counted.
const MAX_LISTED: usize = 50;

fn default_keys_file() -> Option<PathBuf> {
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".config/passangle/robot-keys"))
}

/// `passangle verify`.
#[derive(Args, Debug)]
pub struct VerifyArgs {
    /// A signed file (its signature is FILE.sig), or a run directory (every signed file in it).
    file: PathBuf,
    /// The signature file, when it is not FILE.sig (e.g. the robot's `result.json.sig` for a
    /// copy of its `result.json` kept under another name). `passangle measure` and `fetch` save
    /// the robot's signed `result.json` with its `.sig` in `run-NNNNNN/`; the `run-NNNNNN.json`
    /// beside it is rebuilt from the radio's values, without the standards' profiles, and is
    /// not the signed file.
    #[arg(long, value_name = "SIG")]
    sig: Option<PathBuf>,
    /// A trusted robot public key (64 hex digits, from `passangle-onboard device-key --public`);
    /// may be repeated.
    #[arg(long = "public-key", value_name = "KEY")]
    public_keys: Vec<String>,
    /// A file of trusted robot public keys: one per line (64 hex digits, then an optional
    /// label), `#` starts a comment. Default, when no key is given:
    /// ~/.config/passangle/robot-keys.
    #[arg(long, value_name = "FILE")]
    keys: Option<PathBuf>,
}

/// Reads a trust list: one key per line, 64 hex digits then an optional label; `#` comments.
pub fn read_keys_file(path: &Path) -> anyhow::Result<Vec<PublicKey>> {
    let mut text = String::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_KEYS_FILE + 1).read_to_string(&mut text))
        .with_context(|| format!("reading the trusted keys {}", path.display()))?;
    anyhow::ensure!(
        text.len() as u64 <= MAX_KEYS_FILE,
        "{}: larger than {MAX_KEYS_FILE} bytes: not a list of keys",
        path.display()
    );
    let mut keys = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        let Some(first) = line.split_whitespace().next() else {
            continue;
        };
        let key = PublicKey::from_hex(first).with_context(|| {
            format!(
                "{} line {}: expected a public key of 64 hex digits (as `passangle-onboard \
                 device-key --public` prints it)",
                path.display(),
                i + 1
            )
        })?;
        keys.push(key);
    }
    anyhow::ensure!(!keys.is_empty(), "{}: no key in it", path.display());
    Ok(keys)
}

/// The keys given with `--public-key` (64 hex digits each) and in `--keys FILE`.
pub fn given_keys(public_keys: &[String], keys: Option<&Path>) -> anyhow::Result<Vec<PublicKey>> {
    let mut trusted = public_keys
        .iter()
        .map(|k| {
            PublicKey::from_hex(k).with_context(|| {
                format!("--public-key {k:?}: expected 64 hex digits (a robot's public key)")
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    if let Some(file) = keys {
        trusted.extend(read_keys_file(file)?);
    }
    Ok(trusted)
}

fn trusted_keys(args: &VerifyArgs) -> anyhow::Result<Vec<PublicKey>> {
    let mut keys = given_keys(&args.public_keys, args.keys.as_deref())?;
    if keys.is_empty() {
        match default_keys_file().filter(|f| f.exists()) {
            Some(file) => keys.extend(read_keys_file(&file)?),
            None => anyhow::bail!(
                "no trusted robot key: give --public-key KEY or --keys FILE (or list the robot's \
                 key in ~/.config/passangle/robot-keys); the key in the signature file is not \
                 trusted on its own"
            ),
        }
    }
    Ok(keys)
}

/// The exit code of `passangle verify` for a check's outcome.
pub fn code(check: &Check) -> u8 {
    match check {
        Check::Verified { .. } => OK,
        Check::Changed { .. } => CHANGED,
        Check::Untrusted(_) => UNTRUSTED,
        Check::Unsigned(_) => UNSIGNED,
    }
}

/// Verifies one file against its sidecar; prints the outcome; returns the exit code.
fn verify_file(
    file: &Path,
    sig: &Path,
    trusted: &[PublicKey],
    out: &mut dyn Write,
) -> anyhow::Result<u8> {
    let shown = file.display();
    let check = check_file(file, sig, trusted)?;
    match &check {
        Check::Verified { key_id } => writeln!(out, "OK: {shown} signed by {key_id}")?,
        Check::Changed {
            key_id,
            signed_as,
            changes,
        } => {
            writeln!(
                out,
                "FAILED: {shown} was changed after {key_id} signed it (as {signed_as}):"
            )?;
            for c in changes.iter().take(MAX_LISTED) {
                writeln!(out, "  {c}")?;
            }
            if changes.len() > MAX_LISTED {
                writeln!(out, "  and {} more", changes.len() - MAX_LISTED)?;
            }
        }
        Check::Untrusted(e) => writeln!(out, "FAILED: {shown}: {e}")?,
        Check::Unsigned(e) => writeln!(out, "FAILED: {shown}: no usable signature: {e}")?,
    }
    Ok(code(&check))
}

/// `passangle verify`.
pub fn run(args: &VerifyArgs, out: &mut dyn Write) -> anyhow::Result<ExitCode> {
    let trusted = trusted_keys(args)?;
    if !args.file.is_dir() {
        let sig = args.sig.clone().unwrap_or_else(|| {
            let mut s = args.file.clone().into_os_string();
            s.push(signing::SIDECAR_SUFFIX);
            PathBuf::from(s)
        });
        return Ok(ExitCode::from(verify_file(
            &args.file, &sig, &trusted, out,
        )?));
    }
    anyhow::ensure!(
        args.sig.is_none(),
        "--sig names the signature of one file, not of a directory"
    );
    let dir = &args.file;
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .collect();
    names.sort();
    let mut worst = OK;
    let mut seen = 0;
    for name in &names {
        let Some(file) = name.strip_suffix(signing::SIDECAR_SUFFIX) else {
            continue;
        };
        seen += 1;
        let code = verify_file(&dir.join(file), &dir.join(name), &trusted, out)?;
        worst = worst.max(code);
    }
    for name in SIGNED_IN_A_RUN {
        if names.iter().any(|n| n == name) && !names.contains(&signing::sidecar_name(name)) {
            writeln!(
                out,
                "FAILED: {}: not signed (no {})",
                dir.join(name).display(),
                signing::sidecar_name(name)
            )?;
            worst = worst.max(UNSIGNED);
        }
    }
    if seen == 0 && worst == OK {
        writeln!(out, "FAILED: {}: no signed file in it", dir.display())?;
        worst = UNSIGNED;
    }
    Ok(ExitCode::from(worst))
}
