//! Throughput of the VLP-16 input path on one core, printed as figures (no timed assertions).
//!
//! ```text
//! cargo run --release -p vlp16 --example bench_vlp16 -- FILE.pcap [SECONDS]
//! ```
//!
//! Two figures, each the best and the median of repeated passes (about SECONDS in total,
//! default 3):
//! - `end_to_end`: open the capture, read pcap records, unwrap Ethernet/IPv4/UDP, decode every
//!   return to x/y/z and cut frames: what velodyne-decoder's `read_pcap` does, and what
//!   `bench/vlp16_vs_peer.sh` compares with it;
//! - `decode_only`: the frame assembler alone on payloads already in memory.
//!
//! Output lines are `name points=N seconds=S points_per_s=P median_points_per_s=M` (S and P of
//! the best pass) so scripts can parse them.

use std::error::Error;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use vlp16::source::{PACKET_BUF_LEN, PacketKind, PacketSource, PcapSource};
use vlp16::{DecoderConfig, FrameAssembler};

fn end_to_end(path: &Path) -> Result<u64, Box<dyn Error>> {
    let mut source = PcapSource::open(path)?;
    let mut assembler = FrameAssembler::new(DecoderConfig::default())?;
    let mut buf = [0u8; PACKET_BUF_LEN];
    let mut points = 0u64;
    while let Some(meta) = source.next_packet(&mut buf)? {
        let payload = &buf[..meta.len];
        match meta.kind {
            PacketKind::Data => {
                let _ = assembler.push_data(payload, meta.recv_host_ns);
            }
            PacketKind::Position => {
                let _ = assembler.push_position(payload);
            }
        }
        while let Some(frame) = assembler.pop_frame() {
            points += frame.points.len() as u64;
        }
    }
    assembler.finish();
    while let Some(frame) = assembler.pop_frame() {
        points += frame.points.len() as u64;
    }
    Ok(points)
}

fn decode_only(payloads: &[(Vec<u8>, u64)]) -> Result<u64, Box<dyn Error>> {
    let mut assembler = FrameAssembler::new(DecoderConfig::default())?;
    let mut points = 0u64;
    for (payload, stamp_ns) in payloads {
        let _ = assembler.push_data(payload, *stamp_ns);
        while let Some(frame) = assembler.pop_frame() {
            points += frame.points.len() as u64;
        }
    }
    assembler.finish();
    while let Some(frame) = assembler.pop_frame() {
        points += frame.points.len() as u64;
    }
    Ok(points)
}

/// Runs `pass` repeatedly for about `budget` (at least 5 times); returns (points per pass,
/// best seconds per pass, median seconds per pass).
fn measure(
    budget: Duration,
    mut pass: impl FnMut() -> Result<u64, Box<dyn Error>>,
) -> Result<(u64, f64, f64), Box<dyn Error>> {
    let points = pass()?; // warm-up: page cache, allocator
    let mut times = Vec::new();
    let started = Instant::now();
    while times.len() < 5 || started.elapsed() < budget {
        let t = Instant::now();
        let n = pass()?;
        times.push(t.elapsed().as_secs_f64());
        if n != points {
            return Err(format!("pass decoded {n} points, the first {points}").into());
        }
    }
    times.sort_by(f64::total_cmp);
    Ok((points, times[0], times[times.len() / 2]))
}

fn report(name: &str, (points, best, median): (u64, f64, f64)) {
    let n = points as f64;
    println!(
        "{name} points={points} seconds={best:.6} points_per_s={:.0} median_points_per_s={:.0}",
        n / best,
        n / median
    );
}

/// Decoder throughput on a VLP-16 capture.
#[derive(clap::Parser)]
struct Args {
    /// The capture (pcap or pcapng).
    pcap: PathBuf,
    /// Measuring time, seconds (split between the two measurements).
    #[arg(default_value_t = 3.0)]
    seconds: f64,
}

fn main() -> Result<(), Box<dyn Error>> {
    let Args {
        pcap: path,
        seconds,
    } = <Args as clap::Parser>::parse();
    let budget = Duration::from_secs_f64(seconds / 2.0);

    report("end_to_end", measure(budget, || end_to_end(&path))?);

    let mut payloads = Vec::new();
    let mut source = PcapSource::open(&path)?;
    let mut buf = [0u8; PACKET_BUF_LEN];
    while let Some(meta) = source.next_packet(&mut buf)? {
        if meta.kind == PacketKind::Data {
            payloads.push((buf[..meta.len].to_vec(), meta.recv_host_ns));
        }
    }
    report("decode_only", measure(budget, || decode_only(&payloads))?);
    Ok(())
}
