//! Where VLP-16 packets come from: a live UDP socket or a capture file, behind one small trait.
//!
//! This is the imperative shell around [`super::FrameAssembler`]: sources do the IO and stamp
//! each packet with a host receive time; the assembler stays pure.
//!
//! ```no_run
//! use vlp16::source::{PacketKind, PacketSource, PcapSource, PACKET_BUF_LEN};
//! use vlp16::{DecoderConfig, FrameAssembler};
//!
//! let mut source = PcapSource::open("run.pcap".as_ref()).unwrap();
//! let mut assembler = FrameAssembler::new(DecoderConfig::default()).unwrap();
//! let mut buf = [0u8; PACKET_BUF_LEN];
//! while let Some(meta) = source.next_packet(&mut buf).unwrap() {
//!     let payload = &buf[..meta.len];
//!     match meta.kind {
//!         PacketKind::Data => { let _ = assembler.push_data(payload, meta.recv_host_ns); }
//!         PacketKind::Position => { let _ = assembler.push_position(payload); }
//!     }
//!     while let Some(frame) = assembler.pop_frame() { println!("{} points", frame.points.len()); }
//! }
//! ```

use std::fs::File;
use std::io::{self, BufReader};
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use thiserror::Error;

use super::packet::DATA_PORT;
use super::position::POSITION_PORT;
use crate::pcap::{PcapError, PcapReader, udp_in_frame};

/// A buffer of this size holds any packet a source returns (UDP datagrams are truncated to it).
pub const PACKET_BUF_LEN: usize = 2048;
/// Receive buffer requested for live sockets (about 2.7 s of data packets).
pub const RECV_BUFFER_BYTES: usize = 4 << 20;

/// Which stream a packet came from (by UDP port).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PacketKind {
    /// Data packet (port 2368 by default).
    Data,
    /// Position packet (port 8308 by default).
    Position,
}

/// What a source says about the packet it wrote into the caller's buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PacketMeta {
    /// Which stream.
    pub kind: PacketKind,
    /// Payload length written to the buffer.
    pub len: usize,
    /// Host receive time, nanoseconds: since the source was opened on the host's monotonic clock
    /// for live UDP; the capture's wall-clock time (since the UNIX epoch) for pcap files.
    pub recv_host_ns: u64,
    /// Sender address.
    pub src: Option<SocketAddr>,
}

/// Why a source could not deliver.
#[derive(Debug, Error)]
pub enum SourceError {
    /// Socket or file IO failed.
    #[error("{what}: {source}")]
    Io {
        /// What was being done (names the address or file).
        what: String,
        /// The IO error.
        source: io::Error,
    },
    /// The capture file is unreadable from here on.
    #[error("{path}: {source}")]
    Pcap {
        /// The capture file.
        path: PathBuf,
        /// What went wrong and where.
        source: PcapError,
    },
    /// No packet within the live source's timeout.
    #[error("no VLP-16 packet within {0:?}")]
    TimedOut(Duration),
}

/// A stream of VLP-16 packets. Implementations never allocate per packet.
pub trait PacketSource {
    /// Writes the next packet's payload into `buf` and describes it; `Ok(None)` at the end of a
    /// finite stream (a capture file).
    fn next_packet(
        &mut self,
        buf: &mut [u8; PACKET_BUF_LEN],
    ) -> Result<Option<PacketMeta>, SourceError>;
}

/// Ports a source sorts packets by.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ports {
    /// Data packets.
    pub data: u16,
    /// Position packets.
    pub position: u16,
}

impl Default for Ports {
    fn default() -> Self {
        Self {
            data: DATA_PORT,
            position: POSITION_PORT,
        }
    }
}

/// Counters of what a pcap source skipped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PcapSkips {
    /// Records that were not IPv4/UDP (ARP, IPv6, TCP, fragments, unknown link types...).
    pub not_udp: u64,
    /// UDP datagrams to other ports.
    pub other_port: u64,
    /// UDP payloads longer than [`PACKET_BUF_LEN`].
    pub oversized: u64,
}

/// Packets from a pcap or pcapng file, filtered by UDP destination port.
#[derive(Debug)]
pub struct PcapSource {
    path: PathBuf,
    reader: PcapReader<BufReader<File>>,
    ports: Ports,
    skips: PcapSkips,
    /// Set when the file ended inside its last record (see [`PcapError::is_truncated_end`]).
    truncated: Option<String>,
}

impl PcapSource {
    /// Opens a capture with the default ports 2368/8308.
    pub fn open(path: &Path) -> Result<Self, SourceError> {
        Self::open_with_ports(path, Ports::default())
    }

    /// Opens a capture, sorting by the given destination ports.
    pub fn open_with_ports(path: &Path, ports: Ports) -> Result<Self, SourceError> {
        let file = File::open(path).map_err(|source| SourceError::Io {
            what: format!("opening {}", path.display()),
            source,
        })?;
        let reader =
            PcapReader::new(BufReader::with_capacity(1 << 16, file)).map_err(|source| {
                SourceError::Pcap {
                    path: path.to_owned(),
                    source,
                }
            })?;
        Ok(Self {
            path: path.to_owned(),
            reader,
            ports,
            skips: PcapSkips::default(),
            truncated: None,
        })
    }

    /// What was skipped so far.
    pub fn skips(&self) -> PcapSkips {
        self.skips
    }

    /// If the file ended inside its last record: the reader's message. The packets before it
    /// were delivered; [`PacketSource::next_packet`] then reports the end of stream. A corrupt
    /// record anywhere is an error of [`PacketSource::next_packet`] instead.
    pub fn truncated(&self) -> Option<&str> {
        self.truncated.as_deref()
    }
}

impl PacketSource for PcapSource {
    fn next_packet(
        &mut self,
        buf: &mut [u8; PACKET_BUF_LEN],
    ) -> Result<Option<PacketMeta>, SourceError> {
        loop {
            let record = match self.reader.next_record() {
                Ok(Some(record)) => record,
                Ok(None) => return Ok(None),
                Err(PcapError::Io(source)) => {
                    return Err(SourceError::Io {
                        what: format!("reading {}", self.path.display()),
                        source,
                    });
                }
                Err(err) if err.is_truncated_end() => {
                    // A cut-short last record (a crash while recording): deliver what came
                    // before, remember why it stopped.
                    self.truncated = Some(err.to_string());
                    return Ok(None);
                }
                Err(source) => {
                    // Corruption: the reader cannot tell where the next record starts, so the
                    // stream ends in an error naming the byte offset; the caller decides.
                    return Err(SourceError::Pcap {
                        path: self.path.clone(),
                        source,
                    });
                }
            };
            let Ok(udp) = udp_in_frame(record.link_type, record.data) else {
                self.skips.not_udp += 1;
                continue;
            };
            let kind = match udp.dst.port() {
                p if p == self.ports.data => PacketKind::Data,
                p if p == self.ports.position => PacketKind::Position,
                _ => {
                    self.skips.other_port += 1;
                    continue;
                }
            };
            if udp.payload.len() > PACKET_BUF_LEN {
                self.skips.oversized += 1;
                continue;
            }
            buf[..udp.payload.len()].copy_from_slice(udp.payload);
            return Ok(Some(PacketMeta {
                kind,
                len: udp.payload.len(),
                recv_host_ns: record.stamp_ns,
                src: Some(SocketAddr::V4(udp.src)),
            }));
        }
    }
}

/// Live packets from UDP sockets: one for data, optionally one for position packets.
///
/// The data socket blocks up to `timeout`; the position socket is polled without blocking before
/// each data read (position packets come about once per 14 data packets). Receive times are on
/// the host's monotonic clock, in nanoseconds since the source was opened.
#[derive(Debug)]
pub struct UdpSource {
    data: UdpSocket,
    position: Option<UdpSocket>,
    timeout: Duration,
    epoch: Instant,
}

fn io_error(what: String) -> impl FnOnce(io::Error) -> SourceError {
    move |source| SourceError::Io { what, source }
}

fn bind(addr: SocketAddr) -> Result<UdpSocket, SourceError> {
    let socket = socket2::Socket::new(
        socket2::Domain::for_address(addr),
        socket2::Type::DGRAM,
        Some(socket2::Protocol::UDP),
    )
    .map_err(io_error(format!("creating a UDP socket for {addr}")))?;
    socket
        .set_reuse_address(true)
        .map_err(io_error(format!("SO_REUSEADDR on {addr}")))?;
    // Best effort: the kernel caps it at net.core.rmem_max; the default is enough at 10 Hz.
    if let Err(err) = socket.set_recv_buffer_size(RECV_BUFFER_BYTES) {
        tracing::warn!("could not set a {RECV_BUFFER_BYTES}-byte receive buffer on {addr}: {err}");
    }
    socket
        .bind(&addr.into())
        .map_err(io_error(format!("binding UDP {addr}")))?;
    Ok(socket.into())
}

impl UdpSource {
    /// Binds the data address (e.g. `0.0.0.0:2368`) and, if given, the position address
    /// (`0.0.0.0:8308`). `timeout` bounds each wait for a data packet.
    pub fn bind(
        data: SocketAddr,
        position: Option<SocketAddr>,
        timeout: Duration,
    ) -> Result<Self, SourceError> {
        let data_socket = bind(data)?;
        data_socket
            .set_read_timeout(Some(timeout))
            .map_err(io_error(format!("setting a read timeout on {data}")))?;
        let position_socket = match position {
            Some(addr) => {
                let socket = bind(addr)?;
                socket
                    .set_nonblocking(true)
                    .map_err(io_error(format!("non-blocking mode on {addr}")))?;
                Some(socket)
            }
            None => None,
        };
        Ok(Self {
            data: data_socket,
            position: position_socket,
            timeout,
            epoch: Instant::now(),
        })
    }

    /// The bound data address (useful after binding port 0).
    pub fn data_addr(&self) -> Result<SocketAddr, SourceError> {
        self.data
            .local_addr()
            .map_err(io_error("reading the data socket address".into()))
    }

    /// The bound position address.
    pub fn position_addr(&self) -> Option<SocketAddr> {
        self.position.as_ref().and_then(|s| s.local_addr().ok())
    }

    fn stamp_ns(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_nanos()).unwrap_or(u64::MAX)
    }
}

impl PacketSource for UdpSource {
    fn next_packet(
        &mut self,
        buf: &mut [u8; PACKET_BUF_LEN],
    ) -> Result<Option<PacketMeta>, SourceError> {
        if let Some(position) = &self.position {
            match position.recv_from(buf) {
                Ok((len, src)) => {
                    return Ok(Some(PacketMeta {
                        kind: PacketKind::Position,
                        len,
                        recv_host_ns: self.stamp_ns(),
                        src: Some(src),
                    }));
                }
                Err(err) if err.kind() == io::ErrorKind::WouldBlock => {}
                Err(source) => {
                    return Err(SourceError::Io {
                        what: "receiving position packets".into(),
                        source,
                    });
                }
            }
        }
        match self.data.recv_from(buf) {
            Ok((len, src)) => Ok(Some(PacketMeta {
                kind: PacketKind::Data,
                len,
                recv_host_ns: self.stamp_ns(),
                src: Some(src),
            })),
            Err(err)
                if matches!(
                    err.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                Err(SourceError::TimedOut(self.timeout))
            }
            Err(source) => Err(SourceError::Io {
                what: "receiving data packets".into(),
                source,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::net::{Ipv4Addr, SocketAddrV4};

    use super::*;
    use crate::pcap::PcapWriter;

    fn capture(name: &str, records: usize) -> (PathBuf, Vec<u8>) {
        let mut w = PcapWriter::new(Vec::new()).unwrap();
        let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
        let dst = SocketAddrV4::new(Ipv4Addr::BROADCAST, DATA_PORT);
        for k in 0..records {
            w.write_udp(1_000_000 * k as u64, src, dst, &[k as u8; 100])
                .unwrap();
        }
        let path = std::env::temp_dir().join(format!(
            "passangle-source-{name}-{}.pcap",
            std::process::id()
        ));
        (path, w.into_inner())
    }

    fn drain(path: &Path) -> (usize, Result<(), SourceError>, Option<String>) {
        let mut source = PcapSource::open(path).unwrap();
        let mut buf = [0u8; PACKET_BUF_LEN];
        let mut n = 0;
        let end = loop {
            match source.next_packet(&mut buf) {
                Ok(Some(_)) => n += 1,
                Ok(None) => break Ok(()),
                Err(e) => break Err(e),
            }
        };
        (n, end, source.truncated().map(str::to_owned))
    }

    #[test]
    fn corrupt_record_mid_file_is_an_error_not_a_truncated_end() {
        // 10 records of 16 + 142 bytes after the 24-byte header; corrupt record 3's lengths.
        let (path, mut bytes) = capture("corrupt", 10);
        let at = 24 + 3 * 158;
        bytes[at + 8..at + 12].copy_from_slice(&900_000u32.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let (n, end, truncated) = drain(&path);
        std::fs::remove_file(&path).unwrap();
        assert_eq!(n, 3);
        assert_eq!(truncated, None);
        let err = end.unwrap_err().to_string();
        assert!(
            err.contains(&format!("record 3 at byte {at}")) && err.contains("passangle-source"),
            "{err}"
        );
    }

    #[test]
    fn cut_short_last_record_ends_the_stream_with_a_note() {
        let (path, bytes) = capture("cut", 10);
        std::fs::write(&path, &bytes[..bytes.len() - 50]).unwrap();
        let (n, end, truncated) = drain(&path);
        std::fs::remove_file(&path).unwrap();
        assert_eq!(n, 9);
        assert!(end.is_ok());
        assert!(truncated.unwrap().contains("record 9"));
    }
}
