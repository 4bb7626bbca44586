//! The shipped systemd unit: its `Documentation=` file is in the repository and the README's
//! install step installs it where the unit says; the confinement and resource settings the
//! service relies on are present; `systemd-analyze verify` accepts it where systemd is installed.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("onboard/ has a parent")
        .to_owned()
}

fn unit() -> String {
    std::fs::read_to_string(root().join("systemd/passangle-onboard.service"))
        .expect("systemd/passangle-onboard.service")
}

/// Values of `key=` lines, each line split on whitespace.
fn values(unit: &str, key: &str) -> Vec<String> {
    unit.lines()
        .filter_map(|l| l.strip_prefix(&format!("{key}=")))
        .flat_map(|v| v.split_whitespace().map(str::to_owned))
        .collect()
}

#[test]
fn documentation_files_are_shipped_and_installed() {
    let unit = unit();
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README.md");
    let docs: Vec<String> = values(&unit, "Documentation")
        .into_iter()
        .filter_map(|d| {
            d.strip_prefix("file:///usr/share/doc/passangle/")
                .map(str::to_owned)
        })
        .collect();
    assert!(
        !docs.is_empty(),
        "no Documentation=file:///usr/share/doc/passangle/ entry"
    );
    for name in docs {
        assert!(
            root().join("systemd").join(&name).is_file(),
            "Documentation names {name}, which systemd/ does not ship"
        );
        let install = format!("install -D -m 0644 systemd/{name} /usr/share/doc/passangle/{name}");
        assert!(
            readme.contains(&install),
            "the README's install step lacks `{install}`"
        );
    }
}

#[test]
fn confinement_and_resource_settings_are_present() {
    let unit = unit();
    for (key, value) in [
        ("ProtectProc", "invisible"),
        ("ProcSubset", "pid"),
        ("IPAddressDeny", "any"),
        ("IPAddressAllow", "localhost"),
        ("IPAddressAllow", "192.168.1.0/24"),
        ("DevicePolicy", "closed"),
        ("DeviceAllow", "char-ttyS"),
        ("DeviceAllow", "char-ttyAMA"),
        ("DeviceAllow", "char-ttyUSB"),
        ("DeviceAllow", "char-ttyACM"),
    ] {
        assert!(
            values(&unit, key).iter().any(|v| v == value),
            "{key}={value} missing"
        );
    }
    for key in ["MemoryMax", "MemoryHigh", "TasksMax"] {
        assert_eq!(values(&unit, key).len(), 1, "{key} missing or repeated");
    }
}

#[test]
fn systemd_analyze_verifies_the_unit() {
    let Ok(out) = std::process::Command::new("systemd-analyze")
        .arg("--version")
        .output()
    else {
        eprintln!("SKIPPED: systemd-analyze is not installed");
        return;
    };
    assert!(out.status.success());
    // The binary is not installed here: point ExecStart at /bin/true, check everything else.
    let dir = std::env::temp_dir().join(format!("passangle-unit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("passangle-onboard.service");
    std::fs::write(
        &path,
        unit().replace("/usr/local/bin/passangle-onboard", "/bin/true"),
    )
    .expect("writing the unit copy");
    let out = std::process::Command::new("systemd-analyze")
        .arg("verify")
        .arg(&path)
        .output()
        .expect("running systemd-analyze");
    std::fs::remove_dir_all(&dir).expect("removing the temp dir");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && stderr.trim().is_empty(),
        "systemd-analyze verify: {stderr}"
    );
}
