//! `passangle verify` on a run directory the onboard recorder signed: a verified record exits 0,
//! one changed digit of `approach_deg` exits 3 naming `/approach_deg`, another robot's key
//! exits 4, a missing or garbage signature exits 5, and no trusted key is an error (1).
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use common::{passangle, temp_root};
use std::path::{Path, PathBuf};

use link::client::Measured;
use link::record_files::ReceivedRecord;
use onboard::signing::{DeviceKey, PublicKey, SEED_LEN};
use protocol::bounded::Text;
use protocol::radio::{MeasurementResult, RecordFile, ResultWarnings};

fn wire() -> MeasurementResult {
    MeasurementResult {
        run_id: 1,
        vehicle_id: Text::truncated("AB-123"),
        approach_rad: 0.436,
        departure_rad: 0.458,
        breakover_rad: 0.349,
        ground_clearance_m: 0.249,
        approach_u_rad: 0.01,
        departure_u_rad: 0.01,
        breakover_u_rad: 0.01,
        ground_clearance_u_m: 0.003,
        absent: [protocol::radio::Absence::Measured; 4],
        wheelbase_m: 2.85,
        track_m: 1.6,
        approach_support: 1631,
        departure_support: 276,
        breakover_support: 566,
        tyre_fit_rms_m: 0.004,
        warnings: ResultWarnings::EMPTY,
        cloud_points: 1_110_755,
        preview_chunks: 3,
        records: protocol::bounded::List::default(),
    }
}

/// A signed run under a fresh root, as the service signs it (a stand-in cloud and side view):
/// (root, run directory, the robot's public key).
fn setup(name: &str) -> (PathBuf, PathBuf, PublicKey) {
    let root = temp_root(name);
    let key = DeviceKey::from_seed(&[0x11; SEED_LEN]);
    let public = key.public();
    let dir = common::signed_run(
        &root,
        key,
        &wire(),
        &vec![7u8; 200_000],
        b"<svg>\n<text>approach 25.0</text>\n</svg>\n",
    );
    (root, dir, public)
}

#[test]
fn verify_accepts_the_robots_records_with_a_key_from_the_user() {
    let (root, dir, public) = setup("verify-ok");
    let hex = public.to_hex();
    let result = dir.join("result.json");
    let result_s = result.to_str().unwrap();

    // The whole run directory, then the one file.
    let (code, text) = passangle(
        &["verify", dir.to_str().unwrap(), "--public-key", &hex],
        Some(&root),
    );
    assert_eq!(code, 0, "{text}");
    for name in [
        "config.toml",
        "meta.json",
        "result.json",
        "cloud.ply",
        "side_view.svg",
    ] {
        assert!(
            text.contains(&format!("OK: {}", dir.join(name).display())),
            "{text}"
        );
    }
    let (code, text) = passangle(&["verify", result_s, "--public-key", &hex], Some(&root));
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains(&format!("signed by {}", public.id())),
        "{text}"
    );

    // The trust list, and the default trust file under $HOME.
    let keys = root.join("robot-keys");
    std::fs::write(&keys, format!("# the lab's robots\n{hex} robot 7\n")).unwrap();
    let (code, text) = passangle(
        &["verify", result_s, "--keys", keys.to_str().unwrap()],
        Some(&root),
    );
    assert_eq!(code, 0, "{text}");
    let (code, text) = passangle(&["verify", result_s], Some(&root));
    assert_eq!(code, 1, "no key given, none in ~/.config: {text}");
    assert!(text.contains("no trusted robot key"), "{text}");
    std::fs::create_dir_all(root.join(".config/passangle")).unwrap();
    std::fs::copy(&keys, root.join(".config/passangle/robot-keys")).unwrap();
    let (code, text) = passangle(&["verify", result_s], Some(&root));
    assert_eq!(code, 0, "{text}");

    // The summary rebuilt from the radio's values has the robot's bytes here (this record has
    // no standards' profiles), so the robot's signature verifies it with `--sig`.
    let saved = save_fetched(&root, &dir);
    let (code, text) = passangle(
        &[
            "verify",
            saved.json.to_str().unwrap(),
            "--sig",
            &format!("{result_s}.sig"),
            "--public-key",
            &hex,
        ],
        Some(&root),
    );
    assert_eq!(code, 0, "{text}");
    std::fs::remove_dir_all(&root).unwrap();
}

/// What `passangle measure`/`fetch` save under `root/handheld` for the signed run in `dir`:
/// the robot's `result.json` and its signature as the radio brings them, byte-exact.
fn save_fetched(root: &Path, dir: &Path) -> link::client::SavedFiles {
    let radio_files = [RecordFile::ResultJson, RecordFile::ResultSig].map(|file| ReceivedRecord {
        file,
        bytes: Ok(std::fs::read(dir.join(file.file_name())).unwrap()),
    });
    link::client::save(
        &root.join("handheld"),
        &Measured {
            result: wire(),
            preview_mm: vec![[0, 0, 0]],
            records: radio_files.to_vec(),
            stop_to_result: None,
            preview_time: None,
        },
    )
    .unwrap()
}

/// The handheld's byte-exact copy in `run-NNNNNN/` verifies as it is, the file and its
/// directory; one changed digit in it is named.
#[test]
fn verify_accepts_the_handhelds_copy_and_names_a_changed_digit() {
    let (root, dir, public) = setup("verify-fetched");
    let hex = public.to_hex();
    let saved = save_fetched(&root, &dir);
    let fetched = saved.result_json().unwrap().to_path_buf();
    assert_eq!(
        fetched,
        root.join("handheld").join("run-000001").join("result.json")
    );
    assert!(saved.missing.is_empty(), "{:?}", saved.missing);
    let fetched_s = fetched.to_str().unwrap();
    let (code, text) = passangle(&["verify", fetched_s, "--public-key", &hex], Some(&root));
    assert_eq!(code, 0, "{text}");
    let (code, text) = passangle(
        &[
            "verify",
            fetched.parent().unwrap().to_str().unwrap(),
            "--public-key",
            &hex,
        ],
        Some(&root),
    );
    assert_eq!(code, 0, "the fetched run directory: {text}");
    let copy = std::fs::read_to_string(&fetched).unwrap();
    let line = copy
        .lines()
        .find(|l| l.contains("\"approach_deg\""))
        .unwrap();
    let at = line.find(|c: char| c.is_ascii_digit()).unwrap();
    let mut forged = line.to_owned();
    let digit = forged.as_bytes()[at];
    forged.replace_range(at..=at, if digit == b'3' { "4" } else { "3" });
    std::fs::write(&fetched, copy.replacen(line, &forged, 1)).unwrap();
    let (code, text) = passangle(&["verify", fetched_s, "--public-key", &hex], Some(&root));
    assert_eq!(code, 3, "a changed digit in the fetched copy: {text}");
    assert!(text.contains("changed: /approach_deg"), "{text}");
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn verify_catches_a_changed_digit_and_names_it() {
    let (root, dir, public) = setup("verify-changed");
    let hex = public.to_hex();
    let result = dir.join("result.json");
    let result_s = result.to_str().unwrap();

    // One digit of the approach angle.
    let original = std::fs::read_to_string(&result).unwrap();
    let line = original
        .lines()
        .find(|l| l.contains("\"approach_deg\""))
        .unwrap();
    let at = line.find(|c: char| c.is_ascii_digit()).unwrap();
    let mut forged_line = line.to_owned();
    let digit = forged_line.as_bytes()[at];
    forged_line.replace_range(at..=at, if digit == b'3' { "4" } else { "3" });
    std::fs::write(&result, original.replacen(line, &forged_line, 1)).unwrap();
    let (code, text) = passangle(&["verify", result_s, "--public-key", &hex], Some(&root));
    assert_eq!(code, 3, "{text}");
    assert!(text.contains("changed: /approach_deg"), "{text}");
    assert_eq!(
        text.lines().filter(|l| l.contains("changed:")).count(),
        1,
        "only the one value: {text}"
    );
    let (code, text) = passangle(
        &["verify", dir.to_str().unwrap(), "--public-key", &hex],
        Some(&root),
    );
    assert_eq!(code, 3, "{text}");
    assert!(
        text.contains("OK: ") && text.contains("changed: /approach_deg"),
        "{text}"
    );
    std::fs::write(&result, &original).unwrap();

    // Another robot's key.
    let other = DeviceKey::from_seed(&[0x22; SEED_LEN]).public().to_hex();
    let (code, text) = passangle(&["verify", result_s, "--public-key", &other], Some(&root));
    assert_eq!(code, 4, "{text}");
    assert!(text.contains("signature does not match this key"), "{text}");

    // A sidecar whose manifest was edited to match a forged file: the signature no longer holds.
    let sig = dir.join("result.json.sig");
    let sig_text = std::fs::read_to_string(&sig).unwrap();
    let forged_sig =
        sig_text.replacen("\"name\": \"result.json\"", "\"name\": \"result2.json\"", 1);
    assert_ne!(forged_sig, sig_text);
    std::fs::write(&sig, &forged_sig).unwrap();
    let (code, text) = passangle(&["verify", result_s, "--public-key", &hex], Some(&root));
    assert_eq!(code, 4, "{text}");

    // Garbage, cut short, missing.
    for bytes in [&b"\x00\xffnot json"[..], &sig_text.as_bytes()[..100]] {
        std::fs::write(&sig, bytes).unwrap();
        let (code, text) = passangle(&["verify", result_s, "--public-key", &hex], Some(&root));
        assert_eq!(code, 5, "{text}");
        assert!(text.contains("no usable signature"), "{text}");
    }
    std::fs::remove_file(&sig).unwrap();
    let (code, text) = passangle(&["verify", result_s, "--public-key", &hex], Some(&root));
    assert_eq!(code, 5, "{text}");
    let (code, text) = passangle(
        &["verify", dir.to_str().unwrap(), "--public-key", &hex],
        Some(&root),
    );
    assert_eq!(code, 5, "{text}");
    assert!(text.contains("result.json: not signed"), "{text}");
    std::fs::remove_dir_all(&root).unwrap();
}
