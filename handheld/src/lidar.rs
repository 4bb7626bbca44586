//! `passangle lidar FILE.pcap`: what is in a VLP-16 capture.
//!
//! Prints a summary (packets, frames, points per frame, rpm, return mode, product, malformed
//! counts), or with `--frame N --csv` one frame's points as `x,y,z,intensity,ring,time_us`
//! (metres in the VLP-16 manual's sensor frame, microseconds since the frame's first firing).
//! `--json` prints the summary (or the frame's summary) as JSON. Angles are degrees here, at the
//! user boundary; the library works in radians.
//!
//! `--calibrate` estimates each laser's range offset from a capture taken with the sensor
//! standing still where it sees walls (`vlp16::calibration`), prints them per laser with their
//! standard errors and the line for the onboard config (`[processing]
//! lidar-range-offsets-m`), and exits non-zero when the capture cannot calibrate. The capture is
//! decoded without offsets, so the result replaces any offsets configured before.

use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, bail};
use serde_json::json;
use vlp16::source::{PACKET_BUF_LEN, PacketKind, PacketSource, PcapSource, Ports};
use vlp16::{DecodeStats, DecoderConfig, Frame, FrameAssembler};

/// Arguments of `passangle lidar`.
// Independent command-line switches, each a bool by nature.
#[allow(clippy::struct_excessive_bools)]
#[derive(Debug, clap::Args)]
pub struct LidarArgs {
    /// Capture file (pcap or pcapng; Ethernet, Linux cooked or raw IP).
    pub file: PathBuf,
    /// Report only frame N (counted from 0, including the partial first frame).
    #[arg(long, value_name = "N")]
    pub frame: Option<u64>,
    /// With --frame: dump the frame's points as CSV `x,y,z,intensity,ring,time_us`.
    #[arg(long, requires = "frame")]
    pub csv: bool,
    /// Machine-readable JSON output.
    #[arg(long, conflicts_with = "csv")]
    pub json: bool,
    /// Estimate the lasers' range offsets from this capture (the sensor standing still where it
    /// sees walls; see docs/operator/run.md, "Calibrating the lidar's range").
    #[arg(long, conflicts_with = "frame")]
    pub calibrate: bool,
    /// Do not add the lasers' vertical offsets (manual Table 9-1) to z.
    #[arg(long)]
    pub no_vertical_offset: bool,
    /// Drop returns closer than this, metres.
    #[arg(long, default_value_t = 0.1, value_name = "M")]
    pub min_range: f32,
    /// Drop returns farther than this, metres.
    #[arg(long, default_value_t = 131.0, value_name = "M")]
    pub max_range: f32,
    /// Cut frames where the azimuth passes this angle, degrees in [0, 360).
    #[arg(long, default_value_t = 0.0, value_name = "DEG")]
    pub cut_angle: f32,
    /// UDP port of data packets.
    #[arg(long, default_value_t = 2368)]
    pub data_port: u16,
    /// UDP port of position packets.
    #[arg(long, default_value_t = 8308)]
    pub position_port: u16,
}

impl LidarArgs {
    fn decoder_config(&self) -> anyhow::Result<DecoderConfig> {
        let config = DecoderConfig {
            min_range_m: self.min_range,
            max_range_m: self.max_range,
            vertical_offset: !self.no_vertical_offset,
            cut_azimuth_rad: self.cut_angle.to_radians(),
            ..DecoderConfig::default()
        };
        config
            .check()
            .context("--min-range/--max-range/--cut-angle")?;
        Ok(config)
    }
}

/// Most points pooled for a calibration (about 100 MB; a 2 s capture has 0.6 million).
const MAX_CALIBRATION_POINTS: usize = 3_000_000;

/// `--calibrate`: pool the capture's points (up to [`MAX_CALIBRATION_POINTS`]), estimate the
/// range offsets, print them.
fn calibrate(
    args: &LidarArgs,
    source: &mut PcapSource,
    assembler: &mut FrameAssembler,
    out: &mut impl Write,
) -> anyhow::Result<()> {
    let (points, frames, capped) = pooled_points(source, assembler)?;
    let config = *assembler.config();
    let cal = vlp16::calibration::estimate_range_offsets(&points, &config)
        .with_context(|| format!("{}: range calibration", args.file.display()))?;
    // Rounded to 0.1 mm: the standard errors are tenths of a millimetre at best.
    let offsets: Vec<f64> = cal
        .offsets_m
        .iter()
        .map(|o| (o * 1e4).round() / 1e4)
        .collect();
    if args.json {
        let lasers: Vec<_> = (0..16)
            .map(|l| {
                json!({
                    "laser": l,
                    "elevation_deg": vlp16::decoder::ELEVATION_DEG[l],
                    "offset_m": offsets[l],
                    "standard_error_m": cal.standard_error_m[l],
                    "returns_on_planes": cal.returns[l],
                })
            })
            .collect();
        let planes: Vec<_> = cal
            .planes
            .iter()
            .map(|p| {
                json!({"normal": p.normal, "distance_m": p.distance_m, "returns": p.returns,
                       "residual_sigma_m": p.residual_sigma_m})
            })
            .collect();
        let doc = json!({
            "file": args.file.display().to_string(),
            "frames": frames,
            "points": points.len(),
            "capped": capped,
            "lasers": lasers,
            "planes": planes,
            "residual_sigma_m": cal.residual_sigma_m,
            "uncalibrated": cal.uncalibrated(),
            "config_line": config_line(&offsets),
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&doc)?)?;
        return Ok(());
    }
    let mut text = format!(
        "{}: {frames} frames, {} points{}\n",
        args.file.display(),
        points.len(),
        if capped {
            " (stopped at the point cap)"
        } else {
            ""
        }
    );
    text.push_str(&calibration_text(&cal, &offsets)?);
    out.write_all(text.as_bytes())?;
    Ok(())
}

/// The complete frames' points of a capture, up to [`MAX_CALIBRATION_POINTS`]: the points, the
/// frames and whether the cap stopped the reading.
fn pooled_points(
    source: &mut PcapSource,
    assembler: &mut FrameAssembler,
) -> anyhow::Result<(Vec<vlp16::Point>, usize, bool)> {
    let mut buf = [0u8; PACKET_BUF_LEN];
    let mut points = Vec::new();
    let mut frames = 0usize;
    loop {
        let more = feed(source, assembler, &mut buf)?;
        while let Some(frame) = assembler.pop_frame() {
            if !frame.is_complete() {
                continue;
            }
            if points.len() + frame.points.len() > MAX_CALIBRATION_POINTS {
                return Ok((points, frames, true));
            }
            frames += 1;
            points.extend(frame.points);
        }
        if !more {
            return Ok((points, frames, false));
        }
    }
}

/// The calibration as text: the planes, each laser's offset, what was not calibrated, and the
/// config line.
fn calibration_text(
    cal: &vlp16::calibration::RangeCalibration,
    offsets: &[f64],
) -> anyhow::Result<String> {
    let mut text = String::new();
    writeln!(
        text,
        "planes: {} (residual sigma {:.1} mm)",
        cal.planes.len(),
        1e3 * cal.residual_sigma_m
    )?;
    for p in &cal.planes {
        writeln!(
            text,
            "  {:5.2} m away, normal ({:+.2}, {:+.2}, {:+.2}), {} returns, sigma {:.1} mm",
            p.distance_m,
            p.normal[0],
            p.normal[1],
            p.normal[2],
            p.returns,
            1e3 * p.residual_sigma_m
        )?;
    }
    writeln!(text, "laser  elevation  offset mm  std. error mm  returns")?;
    for (l, offset) in offsets.iter().enumerate() {
        let se = cal.standard_error_m[l].map_or_else(
            || "not calibrated".to_owned(),
            |s| format!("{:.1}", 1e3 * s),
        );
        writeln!(
            text,
            "{l:>5}  {:>9.0}  {:>9.1}  {se:>13}  {:>7}",
            vlp16::decoder::ELEVATION_DEG[l],
            1e3 * offset,
            cal.returns[l]
        )?;
    }
    let missing = cal.uncalibrated();
    if !missing.is_empty() {
        writeln!(
            text,
            "not calibrated (too few returns on walls; offset 0 kept): lasers {missing:?}. \
             Lasers that look down see only the floor from the robot's height: calibrate the \
             sensor raised (on a tripod) to reach them."
        )?;
    }
    writeln!(
        text,
        "The standard errors count the range noise only; a wall's unevenness adds to them."
    )?;
    writeln!(
        text,
        "For the onboard config:\n[processing]\n{}",
        config_line(offsets)
    )?;
    Ok(text)
}

/// The onboard config's line for the offsets.
fn config_line(offsets: &[f64]) -> String {
    let list: Vec<String> = offsets.iter().map(|o| format!("{o:.4}")).collect();
    format!("lidar-range-offsets-m = [{}]", list.join(", "))
}

/// Per-frame figures kept for the summary (not the points).
#[derive(Debug, Clone, Copy)]
struct FrameFigures {
    points: usize,
    complete: bool,
    rpm: Option<f64>,
}

/// Everything the summary reports.
#[derive(Debug)]
struct Summary {
    stats: DecodeStats,
    frames: Vec<FrameFigures>,
    skips: vlp16::source::PcapSkips,
    truncated: Option<String>,
    last_position: Option<(u32, &'static str, String)>,
}

/// Runs the command, writing to `out`. A closed pipe (`passangle lidar ... | head`) ends the
/// output quietly.
pub fn run(args: &LidarArgs, out: &mut impl Write) -> anyhow::Result<()> {
    match run_inner(args, out) {
        Err(err)
            if err
                .downcast_ref::<std::io::Error>()
                .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe) =>
        {
            Ok(())
        }
        other => other,
    }
}

fn run_inner(args: &LidarArgs, out: &mut impl Write) -> anyhow::Result<()> {
    let config = args.decoder_config()?;
    let ports = Ports {
        data: args.data_port,
        position: args.position_port,
    };
    let mut source = PcapSource::open_with_ports(&args.file, ports)?;
    let mut assembler = FrameAssembler::new(config)?;
    if args.calibrate {
        return calibrate(args, &mut source, &mut assembler, out);
    }
    if let Some(index) = args.frame {
        let frame = find_frame(&mut source, &mut assembler, index)?.with_context(|| {
            format!(
                "{} has only {} frames (counted from 0); no frame {index}",
                args.file.display(),
                assembler.stats().frames
            )
        })?;
        return if args.csv {
            write_csv(&frame, out)
        } else {
            write_frame_summary(&frame, args.json, out)
        };
    }
    let summary = summarize(&mut source, &mut assembler)?;
    if args.json {
        let json = serde_json::to_string_pretty(&summary_json(args, &summary))?;
        writeln!(out, "{json}")?;
    } else {
        out.write_all(summary_text(args, &summary).as_bytes())?;
    }
    // A summary of nothing is a failure: the capture holds no VLP-16 frame (wrong ports, not a
    // lidar capture, or every packet malformed).
    if summary.frames.is_empty() {
        bail!(
            "{}: no VLP-16 frame ({} data packets, {} records skipped)",
            args.file.display(),
            summary.stats.data_packets,
            summary.skips.not_udp + summary.skips.other_port + summary.skips.oversized
        );
    }
    Ok(())
}

/// Feeds one packet; malformed packets are counted by the assembler and skipped.
fn feed(
    source: &mut PcapSource,
    assembler: &mut FrameAssembler,
    buf: &mut [u8; PACKET_BUF_LEN],
) -> anyhow::Result<bool> {
    let Some(meta) = source.next_packet(buf)? else {
        assembler.finish();
        return Ok(false);
    };
    let payload = &buf[..meta.len];
    match meta.kind {
        PacketKind::Data => {
            let _ = assembler.push_data(payload, meta.recv_host_ns);
        }
        PacketKind::Position => {
            let _ = assembler.push_position(payload);
        }
    }
    Ok(true)
}

fn find_frame(
    source: &mut PcapSource,
    assembler: &mut FrameAssembler,
    index: u64,
) -> anyhow::Result<Option<Frame>> {
    let mut buf = [0u8; PACKET_BUF_LEN];
    loop {
        let more = feed(source, assembler, &mut buf)?;
        while let Some(frame) = assembler.pop_frame() {
            if frame.index == index {
                return Ok(Some(frame));
            }
        }
        if !more {
            return Ok(None);
        }
    }
}

fn summarize(source: &mut PcapSource, assembler: &mut FrameAssembler) -> anyhow::Result<Summary> {
    let mut buf = [0u8; PACKET_BUF_LEN];
    let mut frames = Vec::new();
    loop {
        let more = feed(source, assembler, &mut buf)?;
        while let Some(frame) = assembler.pop_frame() {
            frames.push(FrameFigures {
                points: frame.points.len(),
                complete: frame.is_complete(),
                rpm: frame.rpm(),
            });
        }
        if !more {
            break;
        }
    }
    let last_position = assembler.last_position().map(|p| {
        (
            p.timestamp_us,
            p.pps.name(),
            p.nmea_sentence().unwrap_or("(not ASCII)").to_owned(),
        )
    });
    Ok(Summary {
        stats: assembler.stats().clone(),
        frames,
        skips: source.skips(),
        truncated: source.truncated().map(str::to_owned),
        last_position,
    })
}

/// Min, mean and max of points over complete frames (all frames when none is complete).
fn points_per_frame(frames: &[FrameFigures]) -> Option<(usize, f64, usize)> {
    let complete: Vec<usize> = frames
        .iter()
        .filter(|f| f.complete)
        .map(|f| f.points)
        .collect();
    let counts = if complete.is_empty() {
        frames.iter().map(|f| f.points).collect()
    } else {
        complete
    };
    let min = *counts.iter().min()?;
    let max = *counts.iter().max()?;
    let mean = counts.iter().sum::<usize>() as f64 / counts.len() as f64;
    Some((min, mean, max))
}

fn mean_rpm(frames: &[FrameFigures]) -> Option<f64> {
    let rpms: Vec<f64> = frames
        .iter()
        .filter(|f| f.complete)
        .filter_map(|f| f.rpm)
        .collect();
    let rpms = if rpms.is_empty() {
        frames.iter().filter_map(|f| f.rpm).collect()
    } else {
        rpms
    };
    (!rpms.is_empty()).then(|| rpms.iter().sum::<f64>() / rpms.len() as f64)
}

const RETURN_MODES: [&str; 3] = ["strongest", "last", "dual"];
const PRODUCTS: [&str; 2] = ["VLP-16 (0x22)", "VLP-16, firmware < 3.0.29.0 (0x21)"];

fn count_map(pairs: Vec<(String, u64)>) -> serde_json::Map<String, serde_json::Value> {
    pairs
        .into_iter()
        .map(|(name, n)| (name, json!(n)))
        .collect()
}

fn named_counts(names: &[&str], counts: &[u64]) -> Vec<(String, u64)> {
    names
        .iter()
        .zip(counts)
        .filter(|(_, n)| **n > 0)
        .map(|(s, n)| ((*s).to_owned(), *n))
        .collect()
}

fn summary_text(args: &LidarArgs, s: &Summary) -> String {
    let st = &s.stats;
    let mut t = String::new();
    let complete = s.frames.iter().filter(|f| f.complete).count();
    let _ = writeln!(t, "file:               {}", args.file.display());
    let _ = writeln!(t, "data packets:       {}", st.data_packets);
    let _ = writeln!(t, "position packets:   {}", st.position_packets);
    let _ = writeln!(
        t,
        "frames:             {} ({complete} complete, cut at {} deg)",
        s.frames.len(),
        args.cut_angle
    );
    let _ = writeln!(t, "points:             {}", st.points);
    if let Some((min, mean, max)) = points_per_frame(&s.frames) {
        let _ = writeln!(
            t,
            "points per frame:   min {min}, mean {mean:.0}, max {max}"
        );
    }
    match mean_rpm(&s.frames) {
        Some(rpm) => {
            let _ = writeln!(t, "rotation:           {rpm:.1} rpm ({:.2} Hz)", rpm / 60.0);
        }
        None => {
            let _ = writeln!(t, "rotation:           unknown (no frame spans time)");
        }
    }
    let list = |pairs: Vec<(String, u64)>| {
        if pairs.is_empty() {
            "none".to_owned()
        } else {
            pairs
                .iter()
                .map(|(n, c)| format!("{n} x{c}"))
                .collect::<Vec<_>>()
                .join(", ")
        }
    };
    let _ = writeln!(
        t,
        "return mode:        {}",
        list(named_counts(&RETURN_MODES, &st.return_modes))
    );
    let _ = writeln!(
        t,
        "product:            {}",
        list(named_counts(&PRODUCTS, &st.products))
    );
    let _ = writeln!(
        t,
        "dropped returns:    {} zero-distance, {} outside [{}, {}] m, {} dual duplicates",
        st.zero_returns, st.out_of_range, args.min_range, args.max_range, st.dual_duplicates
    );
    let malformed: Vec<(String, u64)> = st
        .malformed_data
        .iter()
        .map(|(r, n)| ((*r).to_owned(), *n))
        .collect();
    let _ = writeln!(t, "malformed data:     {}", list(malformed));
    let _ = writeln!(t, "malformed position: {}", st.malformed_position);
    let _ = writeln!(
        t,
        "skipped records:    {} not IPv4/UDP, {} other ports, {} oversized",
        s.skips.not_udp, s.skips.other_port, s.skips.oversized
    );
    if let Some((ts, pps, nmea)) = &s.last_position {
        let nmea = if nmea.is_empty() { "(none)" } else { nmea };
        let _ = writeln!(
            t,
            "last position:      t = {ts} us past the hour, PPS {pps}, NMEA {nmea}"
        );
    }
    if let Some(reason) = &s.truncated {
        let _ = writeln!(t, "capture ends early: {reason}");
    }
    t
}

fn summary_json(args: &LidarArgs, s: &Summary) -> serde_json::Value {
    let st = &s.stats;
    let ppf = points_per_frame(&s.frames);
    json!({
        "file": args.file.display().to_string(),
        "data_packets": st.data_packets,
        "position_packets": st.position_packets,
        "frames": s.frames.len(),
        "complete_frames": s.frames.iter().filter(|f| f.complete).count(),
        "cut_angle_deg": args.cut_angle,
        "points": st.points,
        "points_per_frame": ppf.map(|(min, mean, max)| json!({"min": min, "mean": mean, "max": max})),
        "points_by_frame": s.frames.iter().map(|f| f.points).collect::<Vec<_>>(),
        "rpm": mean_rpm(&s.frames),
        "return_modes": count_map(named_counts(&RETURN_MODES, &st.return_modes)),
        "products": count_map(named_counts(&PRODUCTS, &st.products)),
        "zero_returns": st.zero_returns,
        "out_of_range": st.out_of_range,
        "dual_duplicates": st.dual_duplicates,
        "malformed_data": st.malformed_data.iter().map(|(r, n)| ((*r).to_owned(), json!(n))).collect::<serde_json::Map<_, _>>(),
        "malformed_position": st.malformed_position,
        "skipped_not_udp": s.skips.not_udp,
        "skipped_other_port": s.skips.other_port,
        "skipped_oversized": s.skips.oversized,
        "last_position": s.last_position.as_ref().map(|(ts, pps, nmea)| json!({"timestamp_us": ts, "pps": pps, "nmea": nmea})),
        "truncated": s.truncated,
        "vertical_offset": !args.no_vertical_offset,
    })
}

fn write_frame_summary(frame: &Frame, as_json: bool, out: &mut impl Write) -> anyhow::Result<()> {
    let value = json!({
        "index": frame.index,
        "points": frame.points.len(),
        "packets": frame.packets,
        "start_sensor_us": frame.start_sensor_us,
        "start_host_ns": frame.start_host_ns,
        "starts_at_cut": frame.starts_at_cut,
        "ends_at_cut": frame.ends_at_cut,
        "rpm": frame.rpm(),
        "sweep_deg": frame.sweep_raw / 100.0,
    });
    if as_json {
        writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
    } else {
        let rpm = frame
            .rpm()
            .map_or_else(|| "unknown".to_owned(), |r| format!("{r:.1}"));
        writeln!(
            out,
            "frame {}: {} points from {} packets, starts {:.0} us past the hour (sensor clock), \
             sweeps {:.1} deg at {rpm} rpm, {}",
            frame.index,
            frame.points.len(),
            frame.packets,
            frame.start_sensor_us,
            frame.sweep_raw / 100.0,
            if frame.is_complete() {
                "complete"
            } else {
                "partial"
            }
        )?;
    }
    Ok(())
}

fn write_csv(frame: &Frame, out: &mut impl Write) -> anyhow::Result<()> {
    writeln!(out, "x,y,z,intensity,ring,time_us")?;
    for p in &frame.points {
        writeln!(
            out,
            "{:.4},{:.4},{:.4},{},{},{:.3}",
            p.x_m, p.y_m, p.z_m, p.intensity, p.ring, p.time_us
        )?;
    }
    if frame.points.is_empty() {
        bail!("frame {} has no points", frame.index);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::net::{Ipv4Addr, SocketAddrV4};

    use vlp16::pcap::PcapWriter;
    use vlp16::{BlockRepr, ChannelRepr, DataPacketRepr, Product, ReturnMode};

    use super::*;

    /// A synthetic capture: `packets` single-return packets at 600 rpm (0.2 deg per cycle),
    /// every channel at 5 m, laser id as reflectivity, starting at azimuth `start_raw`.
    fn synthetic_capture(packets: u32, start_raw: u32) -> tempfile_path::TempPath {
        let path = tempfile_path::TempPath::new("lidar-cli");
        let file = std::fs::File::create(&path.0).unwrap();
        let mut w = PcapWriter::new(std::io::BufWriter::new(file)).unwrap();
        let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
        let dst = SocketAddrV4::new(Ipv4Addr::BROADCAST, 2368);
        for k in 0..packets {
            let mut blocks = [BlockRepr::default(); 12];
            for (b, block) in blocks.iter_mut().enumerate() {
                block.azimuth_raw = ((start_raw + (k * 12 + b as u32) * 20) % 36_000) as u16;
                for (c, ch) in block.channels.iter_mut().enumerate() {
                    *ch = ChannelRepr {
                        distance_raw: 2500,
                        reflectivity: (c % 16) as u8,
                    };
                }
            }
            let repr = DataPacketRepr {
                blocks,
                timestamp_us: 1_000_000 + (f64::from(k) * 1327.104) as u32,
                return_mode: ReturnMode::Strongest,
                product: Product::Vlp16,
            };
            w.write_udp(
                1_700_000_000_000_000_000 + u64::from(k) * 1_327_104,
                src,
                dst,
                &repr.to_bytes(),
            )
            .unwrap();
        }
        w.write_udp(
            1_700_000_001_000_000_000,
            src,
            SocketAddrV4::new(Ipv4Addr::BROADCAST, 9999),
            b"x",
        )
        .unwrap();
        w.flush().unwrap();
        path
    }

    /// A minimal self-deleting temp file path (no extra dependency).
    mod tempfile_path {
        pub struct TempPath(pub std::path::PathBuf);
        impl TempPath {
            pub fn new(tag: &str) -> Self {
                use std::sync::atomic::{AtomicU32, Ordering};
                static N: AtomicU32 = AtomicU32::new(0);
                let n = N.fetch_add(1, Ordering::Relaxed);
                Self(
                    std::env::temp_dir()
                        .join(format!("passangle-{tag}-{}-{n}.pcap", std::process::id())),
                )
            }
        }
        impl Drop for TempPath {
            fn drop(&mut self) {
                let _ = std::fs::remove_file(&self.0);
            }
        }
    }

    fn args(file: PathBuf) -> LidarArgs {
        LidarArgs {
            file,
            frame: None,
            csv: false,
            json: false,
            calibrate: false,
            no_vertical_offset: false,
            min_range: 0.1,
            max_range: 131.0,
            cut_angle: 0.0,
            data_port: 2368,
            position_port: 8308,
        }
    }

    fn run_to_string(args: &LidarArgs) -> anyhow::Result<String> {
        let mut out = Vec::new();
        run(args, &mut out)?;
        Ok(String::from_utf8(out).unwrap())
    }

    #[test]
    fn json_summary_counts_frames_points_and_rpm() {
        // 0.2 deg per 110.592 us cycle (about 301 rpm): one revolution is 1800 cycles = 150
        // packets; 400 packets starting at 300 deg give a partial frame, two complete, a tail.
        let capture = synthetic_capture(400, 30_000);
        let mut a = args(capture.0.clone());
        a.json = true;
        let v: serde_json::Value = serde_json::from_str(&run_to_string(&a).unwrap()).unwrap();
        assert_eq!(v["data_packets"], 400);
        assert_eq!(v["skipped_other_port"], 1);
        assert_eq!(v["points"], 400 * 384);
        assert_eq!(v["frames"], 4);
        assert_eq!(v["complete_frames"], 2);
        // A complete revolution: 1800 cycles of 0.2 deg, 2 sequences x 16 lasers each.
        assert_eq!(v["points_per_frame"]["min"], 1800 * 32);
        assert_eq!(v["points_per_frame"]["max"], 1800 * 32);
        let rpm = v["rpm"].as_f64().unwrap();
        // 0.2 deg per 110.592 us = 301.4 rpm.
        assert!((rpm - 0.2 / 360.0 / 110.592e-6 * 60.0).abs() < 0.5, "{rpm}");
        assert_eq!(v["products"]["VLP-16 (0x22)"], 400);
    }

    #[test]
    fn text_summary_names_everything() {
        let capture = synthetic_capture(20, 0);
        let text = run_to_string(&args(capture.0.clone())).unwrap();
        for needle in [
            "data packets:       20",
            "return mode:        strongest x20",
            "malformed data:     none",
        ] {
            assert!(text.contains(needle), "{needle:?} missing from\n{text}");
        }
    }

    #[test]
    fn csv_dump_of_one_frame_and_vertical_offset_switch() {
        let capture = synthetic_capture(400, 30_000);
        let mut a = args(capture.0.clone());
        a.frame = Some(1);
        a.csv = true;
        let csv = run_to_string(&a).unwrap();
        let mut lines = csv.lines();
        assert_eq!(lines.next(), Some("x,y,z,intensity,ring,time_us"));
        let rows: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|f| f.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), 1800 * 32);
        // First point of a frame cut at 0 deg: laser 0 (-15 deg, +11.2 mm), azimuth 0, r = 5 m.
        let first = &rows[0];
        let w = (-15f64).to_radians();
        assert!(
            (first[0] - 0.0).abs() < 2e-4 && (first[1] - 5.0 * w.cos()).abs() < 2e-4,
            "{first:?}"
        );
        assert!(
            (first[2] - (5.0 * w.sin() + 0.0112)).abs() < 2e-4,
            "{first:?}"
        );
        assert_eq!((first[3], first[4], first[5]), (0.0, 0.0, 0.0));
        a.no_vertical_offset = true;
        let csv = run_to_string(&a).unwrap();
        let z: f64 = csv
            .lines()
            .nth(1)
            .unwrap()
            .split(',')
            .nth(2)
            .unwrap()
            .parse()
            .unwrap();
        assert!((z - 5.0 * w.sin()).abs() < 2e-4);
    }

    #[test]
    fn no_frames_and_corrupt_captures_fail() {
        // Only the packet to port 9999: nothing to summarise.
        let capture = synthetic_capture(0, 0);
        let err = run_to_string(&args(capture.0.clone()))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("no VLP-16 frame") && err.contains("1 records skipped"),
            "{err}"
        );
        // A record mid-capture whose lengths are impossible: an error naming its byte offset,
        // not a summary of the packets before it.
        let capture = synthetic_capture(20, 0);
        let mut bytes = std::fs::read(&capture.0).unwrap();
        let at = 24 + 5 * (16 + 1248);
        bytes[at + 12..at + 16].copy_from_slice(&100u32.to_le_bytes());
        std::fs::write(&capture.0, &bytes).unwrap();
        let err = format!("{:#}", run_to_string(&args(capture.0.clone())).unwrap_err());
        assert!(
            err.contains(&format!("record 5 at byte {at} is corrupt")),
            "{err}"
        );
    }

    #[test]
    fn missing_frame_and_bad_options_are_clear_errors() {
        let capture = synthetic_capture(20, 0);
        let mut a = args(capture.0.clone());
        a.frame = Some(7);
        let err = run_to_string(&a).unwrap_err().to_string();
        assert!(
            err.contains("has only 1 frames") && err.contains("no frame 7"),
            "{err}"
        );
        let mut a = args(capture.0.clone());
        a.min_range = 200.0;
        let err = format!("{:#}", run_to_string(&a).unwrap_err());
        assert!(err.contains("min_range_m"), "{err}");
        let err = format!(
            "{:#}",
            run_to_string(&args("/nonexistent/x.pcap".into())).unwrap_err()
        );
        assert!(err.contains("/nonexistent/x.pcap"), "{err}");
    }
}
