//! Throughput of the VLP-16 input path on one core, printed as figures (no timed assertions).
//!
//! ```text
//! cargo run --release -p onboard --example bench_vlp16 -- FILE.pcap [SECONDS]
//! ```
//!
//! Two figures, each the best of repeated passes lasting about SECONDS (default 3) in total:
//! - `end_to_end`: open the capture, read pcap records, unwrap Ethernet/IPv4/UDP, decode every
//!   return to x/y/z and cut frames: what velodyne-decoder's `read_pcap` does, and what
//!   `bench/vlp16_vs_peer.sh` compares with it;
//! - `decode_only`: the frame assembler alone on payloads already in memory.
//!
//! Output lines are `name points=N seconds=S points_per_s=P` so scripts can parse them.

use std::error::Error;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use onboard::vlp16::source::{PACKET_BUF_LEN, PacketKind, PacketSource, PcapSource};
use onboard::vlp16::{DecoderConfig, FrameAssembler};

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

/// Runs `pass` repeatedly for about `budget`; returns (points per pass, best seconds per pass).
fn measure(
    budget: Duration,
    mut pass: impl FnMut() -> Result<u64, Box<dyn Error>>,
) -> Result<(u64, f64), Box<dyn Error>> {
    let points = pass()?; // warm-up: page cache, allocator
    let mut best = f64::INFINITY;
    let started = Instant::now();
    let mut runs = 0;
    while runs < 3 || started.elapsed() < budget {
        let t = Instant::now();
        let n = pass()?;
        best = best.min(t.elapsed().as_secs_f64());
        if n != points {
            return Err(format!("pass decoded {n} points, the first {points}").into());
        }
        runs += 1;
    }
    Ok((points, best))
}

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(
        args.next()
            .ok_or("usage: bench_vlp16 FILE.pcap [SECONDS]")?,
    );
    let seconds: f64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(3.0);
    let budget = Duration::from_secs_f64(seconds / 2.0);

    let (points, secs) = measure(budget, || end_to_end(&path))?;
    println!(
        "end_to_end points={points} seconds={secs:.6} points_per_s={:.0}",
        points as f64 / secs
    );

    let mut payloads = Vec::new();
    let mut source = PcapSource::open(&path)?;
    let mut buf = [0u8; PACKET_BUF_LEN];
    while let Some(meta) = source.next_packet(&mut buf)? {
        if meta.kind == PacketKind::Data {
            payloads.push((buf[..meta.len].to_vec(), meta.recv_host_ns));
        }
    }
    let (points, secs) = measure(budget, || decode_only(&payloads))?;
    println!(
        "decode_only points={points} seconds={secs:.6} points_per_s={:.0}",
        points as f64 / secs
    );
    Ok(())
}
