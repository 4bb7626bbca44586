//! `passangle-onboard run` refuses to start, before it opens a port, when its pairing-key file or
//! its device key is open to others, missing or malformed: the same owner and mode rules as
//! `check-config` (docs/security.md). `device-key` makes and reads the device key.

use std::fmt::Write as _;
use std::os::unix::fs::PermissionsExt as _;
use std::path::PathBuf;
use std::process::Command;

/// A fresh directory with a pairing key and an `onboard.toml` that uses it, with ports that do not
/// exist and, if `device_key` names a file in the directory, that file as `signing.key-file`:
/// (directory, pairing-key file, config file).
fn service_dir(name: &str, device_key: Option<&str>) -> (PathBuf, PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("passangle-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let key_file = dir.join("pairing.key");
    onboard::config::write_key(
        &key_file,
        &protocol::auth::Key([7; protocol::auth::KEY_LEN]),
    )
    .expect("key written");
    let mut text = format!(
        "[recording]\nroot = \"{}\"\n[radio]\nport = \"/dev/null-radio\"\nkey-file = \"{}\"\n[mcu]\nport = \"/dev/null-mcu\"\n[camera]\nsource = \"none\"\n",
        dir.join("runs").display(),
        key_file.display()
    );
    if let Some(device_key) = device_key {
        let _ = write!(
            text,
            "[signing]\nkey-file = \"{}\"\n",
            dir.join(device_key).display()
        );
    }
    let config = dir.join("onboard.toml");
    std::fs::write(&config, text).expect("config written");
    (dir, key_file, config)
}

#[test]
fn a_key_file_readable_by_others_stops_the_service_before_it_starts() {
    let (dir, key_file, config) = service_dir("start", None);
    std::fs::set_permissions(&key_file, std::fs::Permissions::from_mode(0o644)).expect("chmod");
    let (code, _, stderr) = onboard(&["run".as_ref(), "--config".as_ref(), config.as_os_str()]);
    assert_eq!(code, Some(65), "{stderr}");
    assert!(
        stderr.contains("radio.key-file") && stderr.contains("0644"),
        "names the key and its mode: {stderr}"
    );
    // Refused before the ports: the radio port's path is not even looked at.
    assert!(!stderr.contains("null-radio"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

fn onboard(args: &[&std::ffi::OsStr]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_passangle-onboard"))
        .args(args)
        .output()
        .expect("the binary runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_configured_device_key_must_be_valid_before_the_service_starts() {
    let (dir, _, config) = service_dir("devkey-start", Some("device.key"));
    let device = dir.join("device.key");
    let run = ["run".as_ref(), "--config".as_ref(), config.as_os_str()];
    // Missing.
    let (code, _, stderr) = onboard(&run);
    assert_eq!(code, Some(65), "{stderr}");
    assert!(
        stderr.contains("signing.key-file") && stderr.contains("does not exist"),
        "{stderr}"
    );
    // Made by `device-key --generate`: mode 0600, and `--public` prints the same key.
    let (code, made, stderr) = onboard(&[
        "device-key".as_ref(),
        "--generate".as_ref(),
        device.as_os_str(),
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    let mode = std::fs::metadata(&device)
        .expect("written")
        .permissions()
        .mode()
        & 0o777;
    assert_eq!(mode, 0o600);
    let (code, read, stderr) = onboard(&[
        "device-key".as_ref(),
        "--public".as_ref(),
        device.as_os_str(),
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(made, read);
    assert_eq!(
        made.split_whitespace().next().map(str::len),
        Some(64),
        "{made}"
    );
    let (code, _, stderr) = onboard(&[
        "device-key".as_ref(),
        "--generate".as_ref(),
        device.as_os_str(),
    ]);
    assert_eq!(code, Some(73), "never overwritten: {stderr}");
    let (code, again, _) = onboard(&[
        "device-key".as_ref(),
        "--public".as_ref(),
        device.as_os_str(),
    ]);
    assert_eq!((code, again), (Some(0), made));
    // Open to others.
    std::fs::set_permissions(&device, std::fs::Permissions::from_mode(0o644)).expect("chmod");
    let (code, _, stderr) = onboard(&run);
    assert_eq!(code, Some(65), "{stderr}");
    assert!(
        stderr.contains("signing.key-file") && stderr.contains("0644"),
        "{stderr}"
    );
    assert!(!stderr.contains("null-radio"), "{stderr}");
    // Not a key.
    std::fs::set_permissions(&device, std::fs::Permissions::from_mode(0o600)).expect("chmod");
    std::fs::write(&device, "not a key\n").expect("written");
    let (code, _, stderr) = onboard(&run);
    assert_eq!(code, Some(65), "{stderr}");
    assert!(
        stderr.contains("signing.key-file") && stderr.contains("64 hex digits"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
