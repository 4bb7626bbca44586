//! Hostile files against every reader of untrusted bytes: the pcap reader and UDP unwrapping, the
//! PLY / PCD (incl. LZF `binary_compressed`) / XYZ / E57 / LAS / LAZ cloud readers, the
//! recording's odometry reader and the signed records' sidecars (`FILE.sig`). Each committed file in `tests/hostile/` must give an error, not a panic; then
//! thousands of deterministic mutations of it and of valid seeds must not panic either.
//!
//! Memory is measured, not assumed: a counting global allocator records the peak heap of each
//! parse, and each parse is held to a stated bound:
//! - pcap: one record buffer ([`MAX_RECORD_LEN`]) plus 64 KiB, whatever the file claims;
//! - clouds: 4 x the file (the text readers' lossy UTF-8 copy and line splitting) plus
//!   24 B x `max_points` plus `max_decoded_bytes` plus 64 KiB;
//! - odometry: 128 B per byte of text (one report and one field slice per byte at worst);
//! - sidecars: 8 x the file plus 64 KiB to parse (its strings, twice, and the part list), and
//!   verifying a file against one: 32 x that file plus 64 KiB (its JSON tree and parts).
//!
//! The hostile files are refused before any allocation their headers ask for, so their bound is
//! the file-size term alone. The test keeps to one `#[test]` so no other test thread allocates
//! while a peak is being measured.

// The counting allocator below is the only unsafe code: GlobalAlloc is an unsafe trait. It
// forwards to the system allocator unchanged.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use cloud_io::{
    Cloud, CloudFormat, ParseError, ParseLimits, detect_format, parse_cloud_with, write_e57,
    write_las,
};
use onboard::recorder::parse_odometry_csv;
use onboard::signing::{DeviceKey, Kind, Sidecar, Verdict, sign_bytes};
use vlp16::pcap::{MAX_RECORD_LEN, PcapError, PcapReader, udp_in_frame};

struct Counting;

static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every method forwards to `System` with the caller's arguments; the counters are plain
// atomics that never influence the allocation itself.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded unchanged.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = CURRENT.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged.
        unsafe { System.dealloc(ptr, layout) };
        CURRENT.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: forwarded unchanged.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            let now = if new_size >= layout.size() {
                CURRENT.fetch_add(new_size - layout.size(), Ordering::Relaxed) + new_size
                    - layout.size()
            } else {
                CURRENT.fetch_sub(layout.size() - new_size, Ordering::Relaxed)
                    - (layout.size() - new_size)
            };
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Runs `f`, returning its result (or the panic message) and the peak heap above the start.
fn measured<T>(f: impl FnOnce() -> T) -> (Result<T, String>, usize) {
    let start = CURRENT.load(Ordering::Relaxed);
    PEAK.store(start, Ordering::Relaxed);
    let out = catch_unwind(AssertUnwindSafe(f)).map_err(|e| {
        e.downcast_ref::<String>()
            .cloned()
            .or_else(|| e.downcast_ref::<&str>().map(|s| (*s).to_owned()))
            .unwrap_or_default()
    });
    (out, PEAK.load(Ordering::Relaxed).saturating_sub(start))
}

const SLACK: usize = 64 << 10;

fn pcap_bound() -> usize {
    MAX_RECORD_LEN + SLACK
}

fn cloud_bound(len: usize, limits: &ParseLimits) -> usize {
    4 * len + 24 * limits.max_points + limits.max_decoded_bytes + SLACK
}

fn odometry_bound(len: usize) -> usize {
    128 * len + SLACK
}

/// Reads a whole capture; the first error, if any, and how many records came before it.
fn read_capture(bytes: &[u8]) -> (usize, Result<(), PcapError>, usize) {
    let mut reader = match PcapReader::new(bytes) {
        Ok(r) => r,
        Err(e) => return (0, Err(e), 0),
    };
    let mut records = 0;
    let mut not_udp = 0;
    loop {
        match reader.next_record() {
            Ok(Some(rec)) => {
                records += 1;
                if udp_in_frame(rec.link_type, rec.data).is_err() {
                    not_udp += 1;
                }
            }
            Ok(None) => return (records, Ok(()), not_udp),
            Err(e) => return (records, Err(e), not_udp),
        }
    }
}

fn parse_odometry_bytes(bytes: &[u8]) -> Result<usize, String> {
    let text = std::str::from_utf8(bytes).map_err(|e| e.to_string())?;
    parse_odometry_csv(text).map(|(reports, _)| reports.len())
}

fn hostile_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/hostile")
}

fn hostile(name: &str) -> Vec<u8> {
    let path = hostile_dir().join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A small deterministic generator (xorshift64*), so every run mutates the same way.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// One mutation of `seed`: byte flips, 32-bit words set to extreme values (lengths and counts),
/// a cut, an insertion, or a duplicated span.
fn mutate(seed: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..=rng.below(4) {
        let len = b.len();
        match rng.below(6) {
            0 if len > 0 => {
                let i = rng.below(len);
                b[i] = rng.next() as u8;
            }
            1 if len >= 4 => {
                let i = rng.below(len - 3);
                let word = [
                    0xffff_ffff,
                    0x7fff_ffff,
                    0x8000_0000,
                    0,
                    1,
                    rng.next() as u32,
                ][rng.below(6)];
                b[i..i + 4].copy_from_slice(&word.to_le_bytes());
            }
            2 => b.truncate(rng.below(len + 1)),
            3 => {
                let at = rng.below(len + 1);
                let junk: Vec<u8> = (0..=rng.below(16)).map(|_| rng.next() as u8).collect();
                b.splice(at..at, junk);
            }
            4 if len > 0 => {
                // Digits in text formats: make a count or value enormous or non-finite.
                let at = rng.below(len);
                let word: &[u8] =
                    [&b"99999999999999999999"[..], b"nan", b"-inf", b"1e999"][rng.below(4)];
                b.splice(at..at, word.iter().copied());
            }
            _ if len > 8 => {
                let from = rng.below(len - 8);
                let span = b[from..from + 8].to_vec();
                let at = rng.below(len);
                b.splice(at..at, span);
            }
            _ => {}
        }
    }
    b
}

/// Valid seeds for the mutations: a pcap of UDP records, a binary PLY with a list property, an
/// ascii PLY, the three PCD encodings, an XYZ file and an odometry CSV.
fn valid_cloud_seeds() -> Vec<(&'static str, Vec<u8>, CloudFormat)> {
    let mut ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n\
                    property float y\nproperty float z\nproperty list uchar int idx\n\
                    element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        .to_vec();
    for k in 0..3u8 {
        for v in [1.0f32, 2.0, f32::from(k)] {
            ply.extend(v.to_le_bytes());
        }
        ply.push(1);
        ply.extend(7i32.to_le_bytes());
    }
    ply.push(3);
    for i in 0..3i32 {
        ply.extend(i.to_le_bytes());
    }
    let ascii_ply = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n\
                      property double z\nproperty list uchar int n\nend_header\n1 2 3 2 0 1\n4 5 6 0\n"
        .to_vec();
    let pcd_head = |data: &str, points: usize| {
        format!(
            "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {points}\n\
             HEIGHT 1\nPOINTS {points}\nDATA {data}\n"
        )
        .into_bytes()
    };
    let mut pcd_ascii = pcd_head("ascii", 2);
    pcd_ascii.extend(b"1 2 3\n4 5 6\n");
    let mut pcd_binary = pcd_head("binary", 2);
    for v in [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0] {
        pcd_binary.extend(v.to_le_bytes());
    }
    // binary_compressed: 24 decoded bytes as one literal run of 24 (control byte 23).
    let mut pcd_lzf = pcd_head("binary_compressed", 2);
    let soa: Vec<u8> = [1.0f32, 4.0, 2.0, 5.0, 3.0, 6.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    pcd_lzf.extend(25u32.to_le_bytes());
    pcd_lzf.extend(24u32.to_le_bytes());
    pcd_lzf.push(23);
    pcd_lzf.extend(&soa);
    let cloud = Cloud {
        points_m: (0..40).map(|i| [f64::from(i) * 0.1, 0.5, 0.25]).collect(),
    };
    let mut e57 = Vec::new();
    write_e57(std::io::Cursor::new(&mut e57), &cloud, "seed").expect("writing to a Vec");
    let las = |compressed| {
        write_las(std::io::Cursor::new(Vec::new()), &cloud, 1e-3, compressed)
            .expect("writing to a Vec")
            .into_inner()
    };
    vec![
        ("E57", e57, CloudFormat::E57),
        ("LAS", las(false), CloudFormat::Las),
        ("LAZ", las(true), CloudFormat::Las),
        ("binary PLY", ply, CloudFormat::Ply),
        ("ascii PLY", ascii_ply, CloudFormat::Ply),
        ("ascii PCD", pcd_ascii, CloudFormat::Pcd),
        ("binary PCD", pcd_binary, CloudFormat::Pcd),
        ("compressed PCD", pcd_lzf, CloudFormat::Pcd),
        (
            "XYZ",
            b"x,y,z\n1,2,3\n4;5;6\n# c\n7 8 9\n".to_vec(),
            CloudFormat::Text,
        ),
    ]
}

fn valid_pcap_seed() -> Vec<u8> {
    use std::net::{Ipv4Addr, SocketAddrV4};
    let mut w = vlp16::pcap::PcapWriter::new(Vec::new()).expect("writing to a Vec");
    let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
    let dst = SocketAddrV4::new(Ipv4Addr::BROADCAST, 2368);
    for k in 0..6u8 {
        w.write_udp(u64::from(k) * 1_000_000, src, dst, &[k; 40])
            .expect("writing to a Vec");
    }
    w.into_inner()
}

#[test]
fn hostile_files_are_refused_within_their_memory_bounds() {
    let mut report = Vec::new();
    issue_files(&mut report);
    lzf_bombs(&mut report);
    mutations(&mut report);
    sidecars(&mut report);
    for line in &report {
        eprintln!("{line}");
    }
}

/// The issue's four hostile inputs and their relatives: each an error, within its bound.
fn issue_files(report: &mut Vec<String>) {
    let defaults = ParseLimits::default();

    // The issue's four, and their relatives.
    let bytes = hostile("short-ipv4.pcap");
    let ((records, end, not_udp), peak) = {
        let (r, peak) = measured(|| read_capture(&bytes));
        (r.expect("no panic"), peak)
    };
    assert!(end.is_ok() && records == 1 && not_udp == 1, "{end:?}");
    let rec_frame = &bytes[24 + 16..];
    assert!(udp_in_frame(1, rec_frame).is_err());
    assert!(peak <= pcap_bound(), "short-ipv4.pcap: peak {peak} B");
    report.push(format!("short-ipv4.pcap: frame refused, peak {peak} B"));

    let bytes = hostile("corrupt-record-mid-capture.pcap");
    let (r, peak) = measured(|| read_capture(&bytes));
    let (records, end, _) = r.expect("no panic");
    let err = end.expect_err("a corrupt record is an error");
    assert!(!err.is_truncated_end(), "{err}");
    // Records 0-3 (24 + 4 x (16 + 142) bytes) come first; record 4 starts at byte 656.
    assert_eq!(records, 4);
    assert!(
        err.to_string().contains("record 4 at byte 656 is corrupt"),
        "{err}"
    );
    assert!(peak <= pcap_bound());
    report.push(format!(
        "corrupt-record-mid-capture.pcap: {err}, peak {peak} B"
    ));

    for (name, expected) in [
        (
            "ply-list-bomb.ply",
            "points: 100000000000000 declared, above the limit",
        ),
        (
            "ply-list-bomb-under-limit.ply",
            "truncated data: header declares 7999999 vertices",
        ),
        ("ply-ascii-huge-count.ply", "above the limit"),
        (
            "pcd-lzf-bomb.pcd",
            "points: 20000000 declared, above the limit of 8000000",
        ),
        ("pcd-ascii-huge-count.pcd", "above the limit"),
        ("all-non-finite.xyz", "empty cloud"),
        // A valid E57 whose header declares a 1 TiB XML section (the e57 crate allocates it).
        (
            "e57-xml-length-huge.e57",
            "XML section of 1099511627776 bytes, more than the file's 3072",
        ),
        // Three points whose fields are all declared constant (minimum = maximum): the e57
        // crate's decoder makes points without end from such a scan (4 GB and growing, measured
        // under a 3 GB ulimit).
        ("e57-constant-fields.e57", "every field is a constant"),
        // An extended VLR of 2^50 bytes (the las crate allocates its declared length).
        (
            "las-evlr-length-huge.las",
            "ends beyond the file's 1235 bytes",
        ),
        (
            "las-huge-count.las",
            "points: 1099511627776 declared, above the limit",
        ),
        // A LAZ chunk table declaring 2^32 - 1 chunks: the laz crate reserves 64 GiB for it
        // (its allocation of 68,719,476,720 bytes fails and aborts the process).
        (
            "laz-chunk-table-bomb.laz",
            "declares 4294967295 chunks for 40 points",
        ),
    ] {
        let bytes = hostile(name);
        let format = detect_format(Some(Path::new(name)), &bytes).expect("a cloud extension");
        let (r, peak) = measured(|| parse_cloud_with(&bytes, format, &defaults));
        let err = r
            .unwrap_or_else(|p| panic!("{name} panicked: {p}"))
            .expect_err(name);
        assert!(err.to_string().contains(expected), "{name}: {err}");
        // Refused before anything the header asks for: the file-size term alone.
        assert!(
            peak <= 4 * bytes.len() + SLACK,
            "{name}: peak {peak} B for a {} B file",
            bytes.len()
        );
        report.push(format!("{name} ({} B): {err}, peak {peak} B", bytes.len()));
    }

    laz_decoder_overflow(report);

    for (name, expected) in [
        (
            "odometry-nan.csv",
            "line 14: column 6 (vx_mps) is not finite",
        ),
        (
            "odometry-inf-last-line.csv",
            "line 21: column 11 (w_rl) is not finite",
        ),
    ] {
        let bytes = hostile(name);
        let (r, peak) = measured(|| parse_odometry_bytes(&bytes));
        let err = r.expect("no panic").expect_err(name);
        assert!(err.contains(expected), "{name}: {err}");
        assert!(peak <= odometry_bound(bytes.len()));
        report.push(format!("{name}: {err}, peak {peak} B"));
    }
}

/// Corrupt arithmetic-coded points (found by fuzzing `las_cloud`): the laz crate's decoder
/// asserts its symbol range in debug builds; with those assertions off, as in release (root
/// Cargo.toml), the stream runs dry and the read fails cleanly. The header is valid, so the
/// decoder's buffers are allocated: the general cloud bound applies, not the header one.
fn laz_decoder_overflow(report: &mut Vec<String>) {
    let defaults = ParseLimits::default();
    let name = "laz-decoder-symbol-overflow.laz";
    let bytes = hostile(name);
    let format = detect_format(Some(Path::new(name)), &bytes).expect("a cloud extension");
    let (r, peak) = measured(|| parse_cloud_with(&bytes, format, &defaults));
    let err = r
        .unwrap_or_else(|p| panic!("{name} panicked: {p}"))
        .expect_err(name);
    assert!(
        err.to_string().contains("failed to fill whole buffer"),
        "{name}: {err}"
    );
    let bound = cloud_bound(bytes.len(), &defaults);
    assert!(peak <= bound, "{name}: peak {peak} B above {bound} B");
    report.push(format!("{name} ({} B): {err}, peak {peak} B", bytes.len()));
}

/// The LZF bomb within the limits (it decodes, within the stated bound) and a 47 MB block
/// declaring 4.1 GB (refused before decoding).
fn lzf_bombs(report: &mut Vec<String>) {
    let defaults = ParseLimits::default();
    // The same LZF bytes declared as 5 M points of `float` x, y, z: within the limits, so it
    // decodes (60 MB) into 5 M points; the peak stays under the stated bound, far from the
    // 943 MB this file grew to with unbounded reading.
    let bomb = hostile("pcd-lzf-bomb.pcd");
    let body_at = bomb
        .windows(23)
        .position(|w| w == b"DATA binary_compressed\n")
        .expect("the bomb's DATA line")
        + 23;
    let mut as_float = b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n\
                         WIDTH 5000000\nHEIGHT 1\nPOINTS 5000000\nDATA binary_compressed\n"
        .to_vec();
    as_float.extend(&bomb[body_at..]);
    let (r, peak) = measured(|| parse_cloud_with(&as_float, CloudFormat::Pcd, &defaults));
    let (cloud, _) = r.expect("no panic").expect("a valid, if silly, cloud");
    assert_eq!(cloud.points_m.len(), 5_000_000);
    assert!(
        peak <= cloud_bound(as_float.len(), &defaults),
        "peak {peak} B"
    );
    report.push(format!(
        "pcd-lzf-bomb.pcd as 5 M float points ({} B): decodes, peak {} MB (bound {} MB)",
        as_float.len(),
        peak >> 20,
        cloud_bound(as_float.len(), &defaults) >> 20
    ));
    drop(cloud);

    // A 47 MB compressed block declaring 4.1 GB of decoded bytes (1.03 M points of 4012-byte
    // records): refused by max_decoded_bytes before the block is touched.
    let mut big = b"VERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1000\n\
                    WIDTH 1030000\nHEIGHT 1\nPOINTS 1030000\nDATA binary_compressed\n"
        .to_vec();
    let compressed = 47_000_000usize;
    big.extend((compressed as u32).to_le_bytes());
    big.extend(((1_030_000usize * 4012) as u32).to_le_bytes());
    big.extend([0, 0]);
    big.resize(big.len() + compressed - 2, 0xE0);
    let (r, peak) = measured(|| parse_cloud_with(&big, CloudFormat::Pcd, &defaults));
    let err = r.expect("no panic").expect_err("over the decoded limit");
    assert!(
        matches!(err, ParseError::OverLimit { what, .. } if what.starts_with("decoded bytes")),
        "{err}"
    );
    assert!(peak <= SLACK, "peak {peak} B");
    report.push(format!(
        "47 MB block declaring 4.1 GB: {err}, peak {peak} B"
    ));
    drop(big);
}

/// Mutations of every hostile file and valid seed: never a panic, always within the bound.
fn mutations(report: &mut Vec<String>) {
    let small = ParseLimits {
        max_points: 100_000,
        max_decoded_bytes: 4 << 20,
    };
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let mut cloud_seeds = valid_cloud_seeds();
    for name in [
        "ply-list-bomb.ply",
        "ply-list-bomb-under-limit.ply",
        "ply-ascii-huge-count.ply",
        "pcd-ascii-huge-count.pcd",
        "all-non-finite.xyz",
        "e57-xml-length-huge.e57",
        "e57-constant-fields.e57",
        "las-evlr-length-huge.las",
        "las-huge-count.las",
        "laz-chunk-table-bomb.laz",
    ] {
        let bytes = hostile(name);
        let format = detect_format(Some(Path::new(name)), &bytes).expect("a cloud extension");
        cloud_seeds.push((name, bytes, format));
    }
    let mut cases = 0usize;
    let mut worst = (0usize, 0usize);
    for (name, seed, format) in &cloud_seeds {
        for _ in 0..2_000 {
            let m = mutate(seed, &mut rng);
            let (r, peak) = measured(|| parse_cloud_with(&m, *format, &small));
            if let Err(p) = r {
                panic!("{name} mutation panicked: {p}\n{m:?}");
            }
            let bound = cloud_bound(m.len(), &small);
            assert!(
                peak <= bound,
                "{name} mutation: peak {peak} > {bound}\n{m:?}"
            );
            worst = worst.max((peak, m.len()));
            cases += 1;
        }
    }
    let mut pcap_seeds = vec![valid_pcap_seed()];
    pcap_seeds.push(hostile("short-ipv4.pcap"));
    pcap_seeds.push(hostile("corrupt-record-mid-capture.pcap"));
    for seed in &pcap_seeds {
        for _ in 0..3_000 {
            let m = mutate(seed, &mut rng);
            let (r, peak) = measured(|| read_capture(&m));
            if let Err(p) = r {
                panic!("pcap mutation panicked: {p}\n{m:?}");
            }
            assert!(peak <= pcap_bound(), "pcap mutation: peak {peak}\n{m:?}");
            cases += 1;
        }
    }
    for name in ["odometry-nan.csv", "odometry-inf-last-line.csv"] {
        let seed = hostile(name);
        for _ in 0..2_000 {
            let m = mutate(&seed, &mut rng);
            let (r, peak) = measured(|| parse_odometry_bytes(&m));
            if let Err(p) = r {
                panic!("odometry mutation panicked: {p}\n{m:?}");
            }
            assert!(peak <= odometry_bound(m.len()));
            cases += 1;
        }
    }
    report.push(format!(
        "{cases} mutations: no panic; largest cloud-parse peak {} B (file {} B)",
        worst.0, worst.1
    ));
}

fn sidecar_bound(len: usize) -> usize {
    8 * len + (64 << 10)
}

fn verify_bound(len: usize) -> usize {
    32 * len + (64 << 10)
}

/// Hostile sidecars (`sidecar-*.sig`) are errors or never verify; mutations of a real sidecar
/// and of the record it signs never panic, never verify a changed record, and stay in bounds.
fn sidecars(report: &mut Vec<String>) {
    let record = br#"{
  "run_id": 7,
  "vehicle_id": "AB-123",
  "approach_deg": 25.003555,
  "warnings": [
    "short-run"
  ],
  "cloud_points": 1110755
}
"#;
    let key = DeviceKey::from_seed(&[0x5a; 32]);
    let public = key.public();
    let valid = sign_bytes(&key, "result.json", Kind::Json, record).to_json();
    let mut names: Vec<String> = std::fs::read_dir(hostile_dir())
        .expect("the hostile corpus")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| {
            n.starts_with("sidecar-") && Path::new(n).extension().is_some_and(|e| e == "sig")
        })
        .collect();
    names.sort();
    assert!(names.len() >= 5, "{names:?}");
    for name in &names {
        let bytes = hostile(name);
        let (r, peak) = measured(|| {
            Sidecar::parse(&bytes).map(|s| {
                let own = s.public_key;
                (s.verify(record, &[own]), s.verify(b"{}", &[own]))
            })
        });
        let r = r.unwrap_or_else(|p| panic!("{name} panicked: {p}"));
        if let Ok((a, b)) = &r {
            for v in [a, b] {
                assert!(
                    !matches!(v, Ok(Verdict::Verified { .. })),
                    "{name} verified something: {v:?}"
                );
            }
        }
        assert!(peak <= sidecar_bound(bytes.len()) + verify_bound(record.len()));
        report.push(format!("{name}: {r:?}, peak {peak} B"));
    }
    let mut rng = Rng(0x51de_ca45);
    let mut cases = 0usize;
    for _ in 0..3_000 {
        let m = mutate(&valid, &mut rng);
        let (r, peak) = measured(|| Sidecar::parse(&m).map(|s| s.verify(record, &[public])));
        let r = r.unwrap_or_else(|p| panic!("sidecar mutation panicked: {p}\n{m:?}"));
        assert!(peak <= sidecar_bound(m.len()) + verify_bound(record.len()));
        cases += 1;
        // Only a mutation that left every signed byte alone (whitespace, hex case) verifies.
        if let Ok(Ok(Verdict::Verified { .. })) = r {
            let s = Sidecar::parse(&m).expect("parsed above");
            assert_eq!(s, Sidecar::parse(&valid).expect("valid"));
        }
    }
    let sidecar = Sidecar::parse(&valid).expect("valid");
    for _ in 0..3_000 {
        let m = mutate(record, &mut rng);
        let (r, peak) = measured(|| sidecar.verify(&m, &[public]));
        let r = r.unwrap_or_else(|p| panic!("record mutation panicked: {p}\n{m:?}"));
        assert!(
            peak <= verify_bound(m.len()),
            "record mutation: peak {peak}\n{m:?}"
        );
        if m != record {
            assert!(
                matches!(r, Ok(Verdict::Changed { .. })),
                "a changed record verified: {m:?}"
            );
        }
        cases += 1;
    }
    // A record nested far beyond serde_json's recursion limit: unreadable, not a stack overflow.
    let deep = [b"[".repeat(100_000), b"]".repeat(100_000)].concat();
    let (r, peak) = measured(|| sidecar.verify(&deep, &[public]));
    let r = r.unwrap_or_else(|p| panic!("deep record panicked: {p}"));
    assert!(
        matches!(&r, Ok(Verdict::Changed { changes, .. }) if changes.len() == 1),
        "{r:?}"
    );
    assert!(peak <= verify_bound(deep.len()));
    report.push(format!("{cases} sidecar and record mutations: no panic"));
}
