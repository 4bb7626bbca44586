use super::*;

const RESULT: &str = r#"{
  "run_id": 7,
  "vehicle_id": "AB-123",
  "approach_rad": 0.43633232,
  "approach_deg": 25.0,
  "departure_deg": 26.22,
  "breakover_deg": null,
  "warnings": [
    "low-support"
  ],
  "cloud_points": 1110755
}
"#;

fn key(b: u8) -> DeviceKey {
    DeviceKey::from_seed(&[b; SEED_LEN])
}

fn signed(text: &str) -> (Sidecar, PublicKey) {
    let k = key(7);
    (
        sign_bytes(&k, "result.json", Kind::Json, text.as_bytes()),
        k.public(),
    )
}

fn changes(sidecar: &Sidecar, text: &str, key: PublicKey) -> Vec<String> {
    match sidecar.verify(text.as_bytes(), &[key]).unwrap() {
        Verdict::Verified { .. } => Vec::new(),
        Verdict::Changed { changes, .. } => changes.iter().map(ToString::to_string).collect(),
    }
}

#[test]
fn a_signed_file_verifies_after_a_round_trip_through_its_sidecar() {
    let (s, public) = signed(RESULT);
    let read = Sidecar::parse(&s.to_json()).unwrap();
    assert_eq!(read, s);
    assert_eq!(
        read.verify(RESULT.as_bytes(), &[public]).unwrap(),
        Verdict::Verified { key: public }
    );
    assert_eq!(read.manifest.kind, Kind::Json);
    let pointers: Vec<_> = read.manifest.parts.iter().map(|p| &p.locator).collect();
    assert!(
        pointers.iter().any(|p| *p == "/approach_deg"),
        "{pointers:?}"
    );
    assert!(pointers.iter().any(|p| *p == "/warnings/0"), "{pointers:?}");
}

#[test]
fn one_changed_digit_is_named_by_its_pointer() {
    let (s, public) = signed(RESULT);
    let forged = RESULT.replace("\"approach_deg\": 25.0", "\"approach_deg\": 26.0");
    assert_ne!(forged, RESULT);
    assert_eq!(changes(&s, &forged, public), ["changed: /approach_deg"]);
}

#[test]
fn added_removed_and_layout_changes_are_told_apart() {
    let (s, public) = signed(RESULT);
    let added = RESULT.replace(
        "\"run_id\": 7,",
        "\"run_id\": 7,\n  \"checked_by\": \"me\",",
    );
    assert_eq!(changes(&s, &added, public), ["added: /checked_by"]);
    let removed = RESULT.replace("  \"departure_deg\": 26.22,\n", "");
    assert_eq!(changes(&s, &removed, public), ["removed: /departure_deg"]);
    let nulled = RESULT.replace("\"approach_rad\": 0.43633232", "\"approach_rad\": null");
    assert_eq!(changes(&s, &nulled, public), ["changed: /approach_rad"]);
    let compact =
        serde_json::to_string(&serde_json::from_str::<serde_json::Value>(RESULT).unwrap()).unwrap();
    let c = changes(&s, &compact, public);
    assert_eq!(c.len(), 1);
    assert!(c[0].contains("layout only"), "{c:?}");
    let broken = RESULT.replace("\"run_id\": 7,", "\"run_id\": 7");
    let c = changes(&s, &broken, public);
    assert!(c.len() == 1 && c[0].contains("not JSON"), "{c:?}");
}

#[test]
fn text_changes_are_named_by_line() {
    let svg = "<svg>\n<line x1=\"0\"/>\n<text>approach 25.0</text>\n</svg>\n";
    let k = key(3);
    let s = sign_bytes(
        &k,
        "side_view.svg",
        Kind::for_name("side_view.svg"),
        svg.as_bytes(),
    );
    assert_eq!(s.manifest.kind, Kind::Text);
    let c = |t: &str| {
        let Verdict::Changed { changes, .. } = s.verify(t.as_bytes(), &[k.public()]).unwrap()
        else {
            panic!("{t} verified");
        };
        changes.iter().map(ToString::to_string).collect::<Vec<_>>()
    };
    assert_eq!(c(&svg.replace("25.0", "26.0")), ["changed: line 3"]);
    assert_eq!(
        c(&svg.replace("</svg>\n", "<!-- x -->\n</svg>\n")),
        ["added: line 4 (after signed line 3)"]
    );
    assert_eq!(
        c(&svg.replace("<line x1=\"0\"/>\n", "")),
        ["removed: signed line 2"]
    );
}

#[test]
fn binary_changes_are_named_by_offset() {
    let mut bytes = vec![0u8; 3 * BLOCK_LEN + 10];
    let k = key(4);
    let s = sign_bytes(&k, "cloud.ply", Kind::for_name("cloud.ply"), &bytes);
    assert_eq!(s.manifest.kind, Kind::Binary);
    assert_eq!(s.manifest.parts.len(), 4);
    bytes[2 * BLOCK_LEN + 5] = 1;
    let Verdict::Changed { changes, .. } = s.verify(&bytes, &[k.public()]).unwrap() else {
        panic!("verified");
    };
    assert_eq!(
        changes,
        [Change::Bytes {
            offset: 2 * BLOCK_LEN as u64
        }]
    );
}

#[test]
fn another_key_is_refused_and_so_is_a_forged_manifest() {
    let (s, public) = signed(RESULT);
    let other = key(8).public();
    assert_eq!(
        s.verify(RESULT.as_bytes(), &[other]),
        Err(SignatureError::UntrustedKey {
            key_id: public.id()
        })
    );
    // A forger who changes the file and rewrites the manifest to match cannot re-sign it.
    let forged = RESULT.replace("25.0", "26.0");
    let mut f = s.clone();
    f.manifest = Manifest::of("result.json", Kind::Json, forged.as_bytes());
    assert!(matches!(
        f.verify(forged.as_bytes(), &[public]),
        Err(SignatureError::BadSignature { .. })
    ));
    // Nor can they claim the robot's key for their own signature.
    let mut g = sign_bytes(&key(9), "result.json", Kind::Json, forged.as_bytes());
    g.public_key = public;
    assert!(matches!(
        g.verify(forged.as_bytes(), &[public]),
        Err(SignatureError::BadSignature { .. })
    ));
    let text = String::from_utf8(g.to_json()).unwrap();
    assert!(Sidecar::parse(text.as_bytes()).is_ok());
}

#[test]
fn signatures_are_deterministic_for_a_fixed_key() {
    let a = sign_bytes(&key(1), "result.json", Kind::Json, RESULT.as_bytes());
    let b = sign_bytes(&key(1), "result.json", Kind::Json, RESULT.as_bytes());
    assert_eq!(a.to_json(), b.to_json());
    // Pinned: a change of the manifest's encoding, the domain prefix or the key id shows here.
    assert_eq!(key(1).public().id(), "f864cb89");
    assert_eq!(
        to_hex(&a.signature[..8]),
        "b87da5fbf761e122",
        "signature of the fixed record under seed 0x01..01"
    );
}

#[test]
fn keys_and_signatures_are_rfc_8032_ed25519() {
    // RFC 8032, section 7.1, TEST 1 (the empty message).
    let seed =
        from_hex::<32>("9d61b19deffd5a60ba844af492ec2cc44449c5697b326919703bac031cae7f60").unwrap();
    let k = DeviceKey::from_seed(&seed);
    assert_eq!(
        k.public().to_hex(),
        "d75a980182b10ab7d54bfed3c964073a0ee172f3daa62325af021a68f707511a"
    );
    assert_eq!(
        to_hex(&k.key.sign(b"").to_bytes()),
        "e5564300c360ac729086e2cc806e828a84877f1eb8e5d974d873e065224901555fb8821590a33bacc61e39701cf9b46bd25bf5f0595bbe24655141438e7a100b"
    );
}

#[test]
fn truncated_and_garbage_sidecars_are_errors() {
    let (s, _) = signed(RESULT);
    let json = s.to_json();
    // Every cut short of the closing brace (the last byte is the newline after it).
    for n in 0..json.len() - 1 {
        assert!(Sidecar::parse(&json[..n]).is_err(), "cut at {n}");
    }
    assert!(matches!(
        Sidecar::parse(&vec![b' '; MAX_SIDECAR_BYTES + 1]),
        Err(SidecarError::TooLarge(_))
    ));
    for bad in [&b"\xff\xfe"[..], b"null", b"[]", b"{}", b"{\"format\": 2}"] {
        assert!(Sidecar::parse(bad).is_err());
    }
    let text = String::from_utf8(json).unwrap();
    for (from, to, want) in [
        ("\"format\": 1", "\"format\": 2", SidecarError::Format(2)),
        (
            "\"algorithm\": \"ed25519\"",
            "\"algorithm\": \"rsa\"",
            SidecarError::Algorithm("rsa".into()),
        ),
        ("\"key_id\": \"", "\"key_id\": \"0", SidecarError::KeyId),
    ] {
        assert_eq!(
            Sidecar::parse(text.replacen(from, to, 1).as_bytes()),
            Err(want)
        );
    }
    let short_sig = text.replace("\"signature\": \"", "\"signature\": \"00");
    assert_eq!(
        Sidecar::parse(short_sig.as_bytes()),
        Err(SidecarError::Hex("signature"))
    );
}

#[test]
fn oversized_inputs_fall_back_to_coarser_parts() {
    let many: Vec<u32> = (0..=MAX_PARTS as u32).collect();
    let json = serde_json::to_vec(&many).unwrap();
    let m = Manifest::of("big.json", Kind::Json, &json);
    assert_eq!(m.kind, Kind::Text);
    let lines = "x\n".repeat(MAX_PARTS + 1);
    let m = Manifest::of("big.txt", Kind::Text, lines.as_bytes());
    assert_eq!(m.kind, Kind::Binary);
    assert_eq!(m.parts.len(), lines.len().div_ceil(BLOCK_LEN));
}

#[test]
fn pointers_escape_slashes_and_tildes() {
    let m = Manifest::of(
        "x.json",
        Kind::Json,
        br#"{"a/b": {"~c": 1}, "e": [], "f": {}}"#,
    );
    let p: Vec<_> = m.parts.iter().map(|p| p.locator.as_str()).collect();
    assert_eq!(p.len(), 3);
    assert!(
        p.contains(&"/a~1b/~0c") && p.contains(&"/e") && p.contains(&"/f"),
        "{p:?}"
    );
}

proptest::proptest! {
    #[test]
    fn any_bytes_parse_or_fail_without_panicking(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..600)) {
        let _ = Sidecar::parse(&bytes);
    }

    #[test]
    fn any_single_byte_change_of_a_signed_file_is_caught(i in 0usize..RESULT.len(), b in proptest::num::u8::ANY) {
        let (s, public) = signed(RESULT);
        let mut bytes = RESULT.as_bytes().to_vec();
        proptest::prop_assume!(bytes[i] != b);
        bytes[i] = b;
        let v = s.verify(&bytes, &[public]).unwrap();
        let changed = matches!(v, Verdict::Changed { ref changes, .. } if !changes.is_empty());
        proptest::prop_assert!(changed);
    }
}
