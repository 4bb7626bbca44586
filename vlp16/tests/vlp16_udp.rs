//! The live UDP source on 127.0.0.1:0: packets written to a capture with `PcapWriter` are read
//! back with `PcapSource` and replayed over loopback into a `UdpSource`; both paths must decode
//! to the same frames.

#![allow(clippy::unwrap_used)]

use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::time::Duration;

use vlp16::pcap::PcapWriter;
use vlp16::source::{PACKET_BUF_LEN, PacketKind, PacketSource, PcapSource, SourceError, UdpSource};
use vlp16::{
    BlockRepr, ChannelRepr, DataPacketRepr, DecoderConfig, FrameAssembler, PositionPacketRepr,
    PpsStatus, Product, ReturnMode,
};

const PACKETS: u32 = 200;

fn data_packet(k: u32) -> [u8; 1206] {
    let mut blocks = [BlockRepr::default(); 12];
    for (b, block) in blocks.iter_mut().enumerate() {
        block.azimuth_raw = ((k * 12 + b as u32) * 40 % 36_000) as u16;
        for (c, ch) in block.channels.iter_mut().enumerate() {
            // Some zero returns so the counts are not trivially 384 per packet.
            let distance_raw = if (c + k as usize).is_multiple_of(7) {
                0
            } else {
                1_000 + c as u16
            };
            *ch = ChannelRepr {
                distance_raw,
                reflectivity: c as u8,
            };
        }
    }
    DataPacketRepr {
        blocks,
        timestamp_us: k * 1_327,
        return_mode: ReturnMode::Strongest,
        product: Product::Vlp16,
    }
    .to_bytes()
}

fn position_packet(k: u32) -> [u8; 512] {
    PositionPacketRepr::new(k * 1_327, PpsStatus::Locked, "$GPRMC,,V,,,,,,,,,,N*53").to_bytes()
}

/// Decodes packets from a source until `data` data packets arrived; returns (points, frames,
/// position packets).
fn decode(source: &mut impl PacketSource, data: u32) -> (u64, u64, u64) {
    let mut asm = FrameAssembler::new(DecoderConfig::default()).unwrap();
    let mut buf = [0u8; PACKET_BUF_LEN];
    let mut seen = 0;
    while seen < data {
        let Some(meta) = source.next_packet(&mut buf).unwrap() else {
            break;
        };
        match meta.kind {
            PacketKind::Data => {
                seen += 1;
                asm.push_data(&buf[..meta.len], meta.recv_host_ns).unwrap();
            }
            PacketKind::Position => {
                asm.push_position(&buf[..meta.len]).unwrap();
            }
        }
    }
    asm.finish();
    let frames = std::iter::from_fn(|| asm.pop_frame()).count() as u64;
    (asm.stats().points, frames, asm.stats().position_packets)
}

#[test]
fn udp_replay_decodes_like_the_capture() {
    // Write the capture.
    let path = std::env::temp_dir().join(format!("passangle-udp-{}.pcap", std::process::id()));
    {
        let mut w = PcapWriter::new(std::fs::File::create(&path).unwrap()).unwrap();
        let sensor = Ipv4Addr::new(192, 168, 1, 201);
        for k in 0..PACKETS {
            let stamp_ns = 1_000_000_000 + u64::from(k) * 1_327_104;
            let data = (
                SocketAddrV4::new(sensor, 2368),
                SocketAddrV4::new(Ipv4Addr::BROADCAST, 2368),
            );
            w.write_udp(stamp_ns, data.0, data.1, &data_packet(k))
                .unwrap();
            if k % 14 == 0 {
                let pos = (
                    SocketAddrV4::new(sensor, 8308),
                    SocketAddrV4::new(Ipv4Addr::BROADCAST, 8308),
                );
                w.write_udp(stamp_ns, pos.0, pos.1, &position_packet(k))
                    .unwrap();
            }
        }
    }
    let mut pcap = PcapSource::open(&path).unwrap();
    let from_pcap = decode(&mut pcap, PACKETS);
    std::fs::remove_file(&path).unwrap();
    assert_eq!(from_pcap.2, u64::from(PACKETS.div_ceil(14)));
    assert!(from_pcap.1 >= 2, "{from_pcap:?}");

    // Replay it over loopback.
    let localhost = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    let mut udp = UdpSource::bind(localhost, Some(localhost), Duration::from_secs(5)).unwrap();
    let data_addr = udp.data_addr().unwrap();
    let position_addr = udp.position_addr().unwrap();
    let sender = std::thread::spawn(move || {
        let socket = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        for k in 0..PACKETS {
            if k % 14 == 0 {
                socket.send_to(&position_packet(k), position_addr).unwrap();
            }
            socket.send_to(&data_packet(k), data_addr).unwrap();
            if k % 20 == 0 {
                // Pace a little so a small kernel receive buffer cannot overflow.
                std::thread::sleep(Duration::from_millis(2));
            }
        }
    });
    let from_udp = decode(&mut udp, PACKETS);
    sender.join().unwrap();
    assert_eq!(from_udp.0, from_pcap.0, "points");
    assert_eq!(from_udp.1, from_pcap.1, "frames");
    // Position packets are polled before each data read, so all but possibly the last arrive.
    assert!(
        from_udp.2 + 1 >= from_pcap.2,
        "{from_udp:?} vs {from_pcap:?}"
    );
}

#[test]
fn udp_source_times_out_with_a_clear_error() {
    let localhost = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    let mut udp = UdpSource::bind(localhost, None, Duration::from_millis(30)).unwrap();
    let mut buf = [0u8; PACKET_BUF_LEN];
    let err = udp.next_packet(&mut buf).unwrap_err();
    assert!(matches!(err, SourceError::TimedOut(_)), "{err}");
    assert!(err.to_string().contains("30ms"), "{err}");
}

#[test]
fn binding_a_taken_port_names_the_address() {
    let taken = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
    let addr = taken.local_addr().unwrap();
    // SO_REUSEADDR does not let a second UDP socket share a unicast port with a socket that did
    // not set it, so this bind fails.
    let err = UdpSource::bind(addr, None, Duration::from_millis(10)).unwrap_err();
    assert!(err.to_string().contains(&addr.to_string()), "{err}");
}
