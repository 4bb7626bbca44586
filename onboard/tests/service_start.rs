//! `passangle-onboard run` refuses to start, before it opens a port, when its pairing-key file is
//! open to others: the same owner and mode rules as `check-config` (docs/security.md).

use std::os::unix::fs::PermissionsExt as _;
use std::process::Command;

#[test]
fn a_key_file_readable_by_others_stops_the_service_before_it_starts() {
    let dir = std::env::temp_dir().join(format!("passangle-start-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let key_file = dir.join("pairing.key");
    onboard::config::write_key(
        &key_file,
        &protocol::auth::Key([7; protocol::auth::KEY_LEN]),
    )
    .expect("key written");
    std::fs::set_permissions(&key_file, std::fs::Permissions::from_mode(0o644)).expect("chmod");
    let config = dir.join("onboard.toml");
    std::fs::write(
        &config,
        format!(
            "[recording]\nroot = \"{}\"\n[radio]\nport = \"/dev/null-radio\"\nkey-file = \"{}\"\n[mcu]\nport = \"/dev/null-mcu\"\n[camera]\nsource = \"none\"\n",
            dir.join("runs").display(),
            key_file.display()
        ),
    )
    .expect("config written");
    let out = Command::new(env!("CARGO_BIN_EXE_passangle-onboard"))
        .arg("run")
        .arg("--config")
        .arg(&config)
        .output()
        .expect("the binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(65), "{stderr}");
    assert!(
        stderr.contains("radio.key-file") && stderr.contains("0644"),
        "names the key and its mode: {stderr}"
    );
    // Refused before the ports: the radio port's path is not even looked at.
    assert!(!stderr.contains("null-radio"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}
