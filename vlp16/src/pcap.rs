//! A small, checked, dependency-free pcap/pcapng reader and classic-pcap writer, plus the
//! Ethernet / Linux cooked / raw IP → IPv4 → UDP unwrapping the lidar sources need.
//!
//! - [`PcapReader`] reads classic pcap (either byte order, microsecond or nanosecond stamps) and
//!   pcapng (sections in either byte order, interface descriptions with `if_tsresol`, enhanced,
//!   simple and obsolete packet blocks; other blocks are skipped). It streams from any
//!   [`std::io::Read`] with one reused buffer, so a long run recording never sits in memory.
//! - [`udp_in_frame`] finds the UDP datagram in a captured frame for link types Ethernet (1, with
//!   802.1Q/802.1ad tags), Linux cooked SLL (113) and SLL2 (276), raw IP (101, 228, and the
//!   platform-specific 12/14) and BSD loopback (0). IPv4 only; fragments are reported, not joined.
//!   Checksums are not verified on reading (captures of offloaded traffic carry zeros).
//! - [`PcapWriter`] writes classic little-endian microsecond pcap with Ethernet/IPv4/UDP frames
//!   whose lengths and IPv4/UDP checksums are correct, so Wireshark and VeloView open them.
//!
//! No-panic contract: every length read from the file is checked against what is there; a
//! truncated record or a block whose lengths disagree is an error naming the record number and
//! byte offset, never a panic. Record bodies above [`MAX_RECORD_LEN`] are refused so a corrupt
//! length cannot make the reader allocate gigabytes: the reader holds one record, so its memory is
//! bounded by [`MAX_RECORD_LEN`] whatever the file's size.
//!
//! Truncation and corruption are different errors ([`PcapError::is_truncated_end`]). A capture
//! whose last record is cut short (the recorder crashed, the disk filled) ends in
//! [`PcapError::TruncatedRecord`]: the end of file came inside a record whose header is
//! plausible, so the records before it are intact. A record header that cannot be right (a length
//! above the limit, a captured length above the original length, a sub-second field of a second or
//! more, a pcapng block whose lengths disagree) is [`PcapError::Corrupt`] /
//! [`PcapError::RecordTooLarge`] / [`PcapError::BadBlock`] at its byte offset. The reader does
//! not resynchronise after corruption: classic pcap has no record marker, so scanning for the
//! next plausible header is a guess that can invent or drop packets silently; the caller gets
//! the error and decides (`passangle replay` and `passangle lidar` exit non-zero).

use std::io::{self, Read, Write};
use std::net::{Ipv4Addr, SocketAddrV4};

use thiserror::Error;

/// Largest record (or pcapng block) body accepted, bytes.
pub const MAX_RECORD_LEN: usize = 256 * 1024;

/// Link-layer type numbers (LINKTYPE_* of the tcpdump.org registry).
pub mod link_type {
    /// BSD loopback: 4-byte host-order address family.
    pub const NULL: u32 = 0;
    /// Ethernet II.
    pub const ETHERNET: u32 = 1;
    /// Raw IP on some platforms (DLT_RAW = 12 or 14).
    pub const RAW_12: u32 = 12;
    /// Raw IP on some platforms.
    pub const RAW_14: u32 = 14;
    /// Raw IP (LINKTYPE_RAW).
    pub const RAW: u32 = 101;
    /// Linux cooked capture v1.
    pub const LINUX_SLL: u32 = 113;
    /// Raw IPv4.
    pub const IPV4: u32 = 228;
    /// Linux cooked capture v2.
    pub const LINUX_SLL2: u32 = 276;
}

/// Why a capture file could not be read further.
#[derive(Debug, Error)]
pub enum PcapError {
    /// The underlying reader failed.
    #[error("reading the capture: {0}")]
    Io(#[from] io::Error),
    /// The file does not start with a pcap or pcapng magic number.
    #[error("not a pcap or pcapng file: magic {0:#010x}")]
    BadMagic(u32),
    /// The file ends inside the file header.
    #[error("capture file header is truncated ({got} of {need} bytes)")]
    TruncatedHeader {
        /// Bytes needed.
        need: usize,
        /// Bytes present.
        got: usize,
    },
    /// The file ends inside a record.
    #[error("record {record} at byte {offset} is truncated ({got} of {need} bytes present)")]
    TruncatedRecord {
        /// Record number, from 0.
        record: u64,
        /// Byte offset of the record in the file.
        offset: u64,
        /// Bytes the record needs.
        need: usize,
        /// Bytes present.
        got: usize,
    },
    /// A record or block claims a length above [`MAX_RECORD_LEN`].
    #[error("record {record} at byte {offset} claims {len} bytes (limit {MAX_RECORD_LEN})")]
    RecordTooLarge {
        /// Record number, from 0.
        record: u64,
        /// Byte offset.
        offset: u64,
        /// Claimed length.
        len: u64,
    },
    /// A classic record header that cannot be right: the file is corrupt from `offset` on.
    #[error("record {record} at byte {offset} is corrupt: {reason}")]
    Corrupt {
        /// Record number, from 0.
        record: u64,
        /// Byte offset of the record header in the file.
        offset: u64,
        /// Which field is impossible.
        reason: String,
    },
    /// A pcapng block is inconsistent.
    #[error("pcapng block at byte {offset}: {reason}")]
    BadBlock {
        /// Byte offset of the block.
        offset: u64,
        /// What was wrong.
        reason: &'static str,
    },
}

impl PcapError {
    /// True when the file ends inside a record whose header is plausible (a capture cut short
    /// by a crash or a full disk): the records before it are intact. False for corruption and IO
    /// errors.
    pub fn is_truncated_end(&self) -> bool {
        matches!(self, Self::TruncatedRecord { .. })
    }
}

/// One captured frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Record<'a> {
    /// Capture time, nanoseconds since the UNIX epoch (capturing host's wall clock).
    pub stamp_ns: u64,
    /// Link type of the frame (see [`link_type`]).
    pub link_type: u32,
    /// The captured bytes (possibly cut by the snap length).
    pub data: &'a [u8],
    /// Length of the frame on the wire.
    pub original_len: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Endian {
    Little,
    Big,
}

impl Endian {
    fn u16(self, b: &[u8]) -> u16 {
        let a = [b[0], b[1]];
        match self {
            Self::Little => u16::from_le_bytes(a),
            Self::Big => u16::from_be_bytes(a),
        }
    }

    fn u32(self, b: &[u8]) -> u32 {
        let a = [b[0], b[1], b[2], b[3]];
        match self {
            Self::Little => u32::from_le_bytes(a),
            Self::Big => u32::from_be_bytes(a),
        }
    }
}

/// Timestamp resolution: units per second as a power of ten or of two.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Resolution {
    Decimal(u8),
    Binary(u8),
}

impl Resolution {
    fn to_ns(self, ticks: u64) -> u64 {
        match self {
            Self::Decimal(v) if v <= 9 => ticks.saturating_mul(10u64.pow(u32::from(9 - v))),
            Self::Decimal(v) => {
                let div = 10u128.checked_pow(u32::from(v - 9)).unwrap_or(u128::MAX);
                (u128::from(ticks) / div) as u64
            }
            Self::Binary(v) => {
                let ns = u128::from(ticks) * 1_000_000_000;
                ns.checked_shr(u32::from(v)).unwrap_or(0) as u64
            }
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Interface {
    link_type: u32,
    resolution: Resolution,
}

#[derive(Debug)]
enum Format {
    Classic {
        endian: Endian,
        nanos: bool,
        link_type: u32,
    },
    Ng {
        endian: Endian,
        interfaces: Vec<Interface>,
    },
}

/// Streaming reader of pcap and pcapng files.
#[derive(Debug)]
pub struct PcapReader<R: Read> {
    reader: R,
    format: Format,
    buf: Vec<u8>,
    record: u64,
    offset: u64,
}

const PCAPNG_SHB: u32 = 0x0A0D_0D0A;
const PCAPNG_BYTE_ORDER: u32 = 0x1A2B_3C4D;

/// Reads up to `buf.len()` bytes; returns how many were read (short only at end of file).
fn read_full<R: Read>(reader: &mut R, buf: &mut [u8]) -> io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match reader.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

impl<R: Read> PcapReader<R> {
    /// Reads the file header (classic) or the first section header (pcapng).
    pub fn new(mut reader: R) -> Result<Self, PcapError> {
        let mut head = [0u8; 24];
        let got = read_full(&mut reader, &mut head[..4])?;
        if got < 4 {
            return Err(PcapError::TruncatedHeader { need: 4, got });
        }
        let magic = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
        let mut this = Self {
            reader,
            format: Format::Ng {
                endian: Endian::Little,
                interfaces: Vec::new(),
            },
            buf: Vec::new(),
            record: 0,
            offset: 4,
        };
        if magic == PCAPNG_SHB {
            this.read_section_header(0)?;
            return Ok(this);
        }
        let (endian, nanos) = match magic {
            0xa1b2_c3d4 => (Endian::Little, false),
            0xa1b2_3c4d => (Endian::Little, true),
            0xd4c3_b2a1 => (Endian::Big, false),
            0x4d3c_b2a1 => (Endian::Big, true),
            other => return Err(PcapError::BadMagic(other)),
        };
        let got = read_full(&mut this.reader, &mut head[4..])?;
        if got < 20 {
            return Err(PcapError::TruncatedHeader {
                need: 24,
                got: got + 4,
            });
        }
        this.offset = 24;
        // Link type: low 16 bits of the last field (the upper bits carry FCS information).
        let link_type = endian.u32(&head[20..24]) & 0xFFFF;
        this.format = Format::Classic {
            endian,
            nanos,
            link_type,
        };
        Ok(this)
    }

    /// Records returned so far.
    pub fn records_read(&self) -> u64 {
        self.record
    }

    /// The next packet record, `None` at a clean end of file.
    pub fn next_record(&mut self) -> Result<Option<Record<'_>>, PcapError> {
        let found = match self.format {
            Format::Classic {
                endian,
                nanos,
                link_type,
            } => self.next_classic(endian, nanos, link_type)?,
            Format::Ng { .. } => self.next_ng()?,
        };
        Ok(
            found.map(|(stamp_ns, link_type, start, len, original_len)| {
                self.record += 1;
                Record {
                    stamp_ns,
                    link_type,
                    data: &self.buf[start..start + len],
                    original_len,
                }
            }),
        )
    }

    /// Reads `len` bytes into the buffer (from index 0); `Ok(false)` on a clean EOF before any
    /// byte when `eof_ok`.
    fn fill(&mut self, len: usize, record_offset: u64, eof_ok: bool) -> Result<bool, PcapError> {
        if len > MAX_RECORD_LEN {
            return Err(PcapError::RecordTooLarge {
                record: self.record,
                offset: record_offset,
                len: len as u64,
            });
        }
        self.buf.resize(len, 0);
        let got = read_full(&mut self.reader, &mut self.buf[..len])?;
        self.offset += got as u64;
        if got == len {
            Ok(true)
        } else if got == 0 && eof_ok {
            Ok(false)
        } else {
            Err(PcapError::TruncatedRecord {
                record: self.record,
                offset: record_offset,
                need: len,
                got,
            })
        }
    }

    #[allow(clippy::type_complexity)]
    fn next_classic(
        &mut self,
        endian: Endian,
        nanos: bool,
        link_type: u32,
    ) -> Result<Option<(u64, u32, usize, usize, u32)>, PcapError> {
        let record_offset = self.offset;
        if !self.fill(16, record_offset, true)? {
            return Ok(None);
        }
        let seconds = u64::from(endian.u32(&self.buf[0..4]));
        let fraction = u64::from(endian.u32(&self.buf[4..8]));
        let captured = endian.u32(&self.buf[8..12]) as usize;
        let original_len = endian.u32(&self.buf[12..16]);
        let corrupt = |reason: String| PcapError::Corrupt {
            record: self.record,
            offset: record_offset,
            reason,
        };
        if captured > MAX_RECORD_LEN {
            return Err(PcapError::RecordTooLarge {
                record: self.record,
                offset: record_offset,
                len: captured as u64,
            });
        }
        let per_second = if nanos { 1_000_000_000 } else { 1_000_000 };
        if fraction >= per_second {
            return Err(corrupt(format!(
                "sub-second field {fraction} is not below {per_second}"
            )));
        }
        if captured > original_len as usize {
            return Err(corrupt(format!(
                "captured length {captured} exceeds the original length {original_len}"
            )));
        }
        let stamp_ns = seconds * 1_000_000_000 + if nanos { fraction } else { fraction * 1000 };
        self.fill(captured, record_offset, false)?;
        Ok(Some((stamp_ns, link_type, 0, captured, original_len)))
    }

    /// Reads the rest of a section header block whose type was already read at `block_offset`.
    fn read_section_header(&mut self, block_offset: u64) -> Result<(), PcapError> {
        let mut raw = [0u8; 8];
        let got = read_full(&mut self.reader, &mut raw)?;
        self.offset += got as u64;
        if got < 8 {
            return Err(PcapError::TruncatedHeader {
                need: 12,
                got: got + 4,
            });
        }
        let endian = match u32::from_le_bytes([raw[4], raw[5], raw[6], raw[7]]) {
            PCAPNG_BYTE_ORDER => Endian::Little,
            m if m.swap_bytes() == PCAPNG_BYTE_ORDER => Endian::Big,
            _ => {
                return Err(PcapError::BadBlock {
                    offset: block_offset,
                    reason: "section header byte-order magic is not 0x1a2b3c4d",
                });
            }
        };
        let total = endian.u32(&raw[0..4]) as usize;
        if total < 28 || !total.is_multiple_of(4) {
            return Err(PcapError::BadBlock {
                offset: block_offset,
                reason: "section header length is below 28 or not a multiple of 4",
            });
        }
        // The rest: version, section length, options, trailing length.
        self.fill(total - 12, block_offset, false)?;
        self.format = Format::Ng {
            endian,
            interfaces: Vec::new(),
        };
        Ok(())
    }

    #[allow(clippy::type_complexity)]
    fn next_ng(&mut self) -> Result<Option<(u64, u32, usize, usize, u32)>, PcapError> {
        loop {
            let block_offset = self.offset;
            if !self.fill(4, block_offset, true)? {
                return Ok(None);
            }
            let Format::Ng { endian, .. } = self.format else {
                return Ok(None);
            };
            let block_type = endian.u32(&self.buf[0..4]);
            if block_type == PCAPNG_SHB {
                self.read_section_header(block_offset)?;
                continue;
            }
            self.fill(4, block_offset, false)?;
            let total = endian.u32(&self.buf[0..4]) as usize;
            if total < 12 || !total.is_multiple_of(4) {
                return Err(PcapError::BadBlock {
                    offset: block_offset,
                    reason: "block length is below 12 or not a multiple of 4",
                });
            }
            self.fill(total - 8, block_offset, false)?;
            let body_len = total - 12;
            let trailer = endian.u32(&self.buf[body_len..body_len + 4]) as usize;
            if trailer != total {
                return Err(PcapError::BadBlock {
                    offset: block_offset,
                    reason: "trailing block length differs from the leading one",
                });
            }
            if let Some(found) = self.ng_block(block_type, body_len, endian, block_offset)? {
                return Ok(Some(found));
            }
        }
    }

    /// Interprets a block body in `self.buf[..body_len]`; returns a packet when it is one.
    #[allow(clippy::type_complexity)]
    fn ng_block(
        &mut self,
        block_type: u32,
        body_len: usize,
        endian: Endian,
        offset: u64,
    ) -> Result<Option<(u64, u32, usize, usize, u32)>, PcapError> {
        let body = &self.buf[..body_len];
        let bad = |reason| PcapError::BadBlock { offset, reason };
        let Format::Ng { interfaces, .. } = &mut self.format else {
            return Ok(None);
        };
        match block_type {
            // Interface description.
            1 => {
                if body.len() < 8 {
                    return Err(bad("interface description shorter than 8 bytes"));
                }
                let link_type = u32::from(endian.u16(&body[0..2]));
                let resolution = parse_tsresol(&body[8..], endian);
                interfaces.push(Interface {
                    link_type,
                    resolution,
                });
                Ok(None)
            }
            // Enhanced packet (6) and obsolete packet (2) blocks.
            2 | 6 => {
                if body.len() < 20 {
                    return Err(bad("packet block shorter than 20 bytes"));
                }
                let interface_id = if block_type == 6 {
                    endian.u32(&body[0..4]) as usize
                } else {
                    usize::from(endian.u16(&body[0..2]))
                };
                let interface = *interfaces
                    .get(interface_id)
                    .ok_or(bad("packet names an interface that was not described"))?;
                let ticks = (u64::from(endian.u32(&body[4..8])) << 32)
                    | u64::from(endian.u32(&body[8..12]));
                let captured = endian.u32(&body[12..16]) as usize;
                let original_len = endian.u32(&body[16..20]);
                if captured > body.len() - 20 {
                    return Err(bad("captured length runs past the block"));
                }
                let stamp_ns = interface.resolution.to_ns(ticks);
                Ok(Some((
                    stamp_ns,
                    interface.link_type,
                    20,
                    captured,
                    original_len,
                )))
            }
            // Simple packet: interface 0, no timestamp.
            3 => {
                if body.len() < 4 {
                    return Err(bad("simple packet block shorter than 4 bytes"));
                }
                let interface = *interfaces
                    .first()
                    .ok_or(bad("simple packet before any interface"))?;
                let original_len = endian.u32(&body[0..4]);
                let captured = (original_len as usize).min(body.len() - 4);
                Ok(Some((0, interface.link_type, 4, captured, original_len)))
            }
            _ => Ok(None),
        }
    }
}

/// Finds `if_tsresol` (option 9) in an interface description's options; default microseconds.
fn parse_tsresol(mut options: &[u8], endian: Endian) -> Resolution {
    while options.len() >= 4 {
        let code = endian.u16(&options[0..2]);
        let len = usize::from(endian.u16(&options[2..4]));
        if code == 0 {
            break;
        }
        let padded = (len + 3) & !3;
        if options.len() < 4 + padded {
            break;
        }
        if code == 9 && len >= 1 {
            let v = options[4];
            return if v & 0x80 == 0 {
                Resolution::Decimal(v)
            } else {
                Resolution::Binary(v & 0x7f)
            };
        }
        options = &options[4 + padded..];
    }
    Resolution::Decimal(6)
}

/// Why a captured frame holds no usable UDP datagram.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum NetError {
    /// The link type is not one of those listed in the module docs.
    #[error("link type {0} is not supported (Ethernet, Linux cooked, raw IP, BSD loopback)")]
    UnsupportedLinkType(u32),
    /// The frame ends inside a header.
    #[error("frame truncated inside the {0} header")]
    Truncated(&'static str),
    /// Not IPv4 (e.g. ARP, IPv6).
    #[error("not IPv4 (ethertype or version {0:#06x})")]
    NotIpv4(u16),
    /// IPv4 but not UDP.
    #[error("IPv4 protocol {0} is not UDP")]
    NotUdp(u8),
    /// An IPv4 fragment (not reassembled).
    #[error("IPv4 fragment (not reassembled)")]
    Fragment,
    /// IPv4 header fields disagree with the frame.
    #[error("bad IPv4 header: {0}")]
    BadIpv4(&'static str),
    /// UDP length field disagrees with the IP payload.
    #[error("bad UDP length {0}")]
    BadUdpLength(u16),
}

/// A UDP datagram found in a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UdpDatagram<'a> {
    /// Source address and port.
    pub src: SocketAddrV4,
    /// Destination address and port.
    pub dst: SocketAddrV4,
    /// The UDP payload.
    pub payload: &'a [u8],
}

const ETHERTYPE_IPV4: u16 = 0x0800;

fn be16(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_be_bytes([*b.get(at)?, *b.get(at + 1)?]))
}

/// Finds the IPv4 packet in a frame of the given link type.
fn ip_in_frame(link_type: u32, frame: &[u8]) -> Result<&[u8], NetError> {
    let (ethertype, rest) = match link_type {
        link_type::ETHERNET => {
            let mut at = 12;
            let mut ethertype = be16(frame, at).ok_or(NetError::Truncated("Ethernet"))?;
            while ethertype == 0x8100 || ethertype == 0x88a8 {
                at += 4;
                ethertype = be16(frame, at).ok_or(NetError::Truncated("802.1Q"))?;
            }
            (ethertype, &frame[at + 2..])
        }
        link_type::LINUX_SLL => {
            let ethertype = be16(frame, 14).ok_or(NetError::Truncated("Linux cooked"))?;
            (ethertype, &frame[16..])
        }
        link_type::LINUX_SLL2 => {
            let ethertype = be16(frame, 0).ok_or(NetError::Truncated("Linux cooked v2"))?;
            if frame.len() < 20 {
                return Err(NetError::Truncated("Linux cooked v2"));
            }
            (ethertype, &frame[20..])
        }
        link_type::NULL => {
            let family = frame.get(..4).ok_or(NetError::Truncated("loopback"))?;
            let le = u32::from_le_bytes([family[0], family[1], family[2], family[3]]);
            let ethertype = if le == 2 || le.swap_bytes() == 2 {
                ETHERTYPE_IPV4
            } else {
                0
            };
            (ethertype, &frame[4..])
        }
        link_type::RAW | link_type::RAW_12 | link_type::RAW_14 | link_type::IPV4 => {
            let version = frame.first().ok_or(NetError::Truncated("IP"))? >> 4;
            let ethertype = if version == 4 {
                ETHERTYPE_IPV4
            } else {
                u16::from(version)
            };
            (ethertype, frame)
        }
        other => return Err(NetError::UnsupportedLinkType(other)),
    };
    if ethertype == ETHERTYPE_IPV4 {
        Ok(rest)
    } else {
        Err(NetError::NotIpv4(ethertype))
    }
}

/// Finds the UDP datagram in a captured frame. Never panics.
pub fn udp_in_frame(link_type: u32, frame: &[u8]) -> Result<UdpDatagram<'_>, NetError> {
    let ip = ip_in_frame(link_type, frame)?;
    if ip.len() < 20 {
        return Err(NetError::Truncated("IPv4"));
    }
    if ip[0] >> 4 != 4 {
        return Err(NetError::NotIpv4(u16::from(ip[0] >> 4)));
    }
    let header_len = usize::from(ip[0] & 0x0f) * 4;
    let total_len = usize::from(u16::from_be_bytes([ip[2], ip[3]]));
    if header_len < 20 || total_len < header_len {
        return Err(NetError::BadIpv4("header or total length too small"));
    }
    // Old VLP-16 firmware sends position packets whose IPv4 total length (1234) exceeds the
    // frame (540 bytes of IP); like Wireshark, trust the bytes present and let the UDP length
    // decide. A capture cut by its snap length still fails the UDP length check below.
    let total_len = total_len.min(ip.len());
    if header_len > total_len {
        return Err(NetError::Truncated("IPv4 options"));
    }
    let flags_fragment = u16::from_be_bytes([ip[6], ip[7]]);
    if flags_fragment & 0x3fff != 0 {
        return Err(NetError::Fragment);
    }
    if ip[9] != 17 {
        return Err(NetError::NotUdp(ip[9]));
    }
    let src_ip = Ipv4Addr::new(ip[12], ip[13], ip[14], ip[15]);
    let dst_ip = Ipv4Addr::new(ip[16], ip[17], ip[18], ip[19]);
    let udp = &ip[header_len..total_len];
    if udp.len() < 8 {
        return Err(NetError::Truncated("UDP"));
    }
    let udp_len = u16::from_be_bytes([udp[4], udp[5]]);
    if usize::from(udp_len) < 8 || usize::from(udp_len) > udp.len() {
        return Err(NetError::BadUdpLength(udp_len));
    }
    Ok(UdpDatagram {
        src: SocketAddrV4::new(src_ip, u16::from_be_bytes([udp[0], udp[1]])),
        dst: SocketAddrV4::new(dst_ip, u16::from_be_bytes([udp[2], udp[3]])),
        payload: &udp[8..usize::from(udp_len)],
    })
}

/// Source MAC written by [`PcapWriter`] (Velodyne's OUI 60:76:88).
pub const WRITER_SRC_MAC: [u8; 6] = [0x60, 0x76, 0x88, 0x00, 0x00, 0x01];
/// Largest UDP payload an IPv4 datagram can carry.
pub const MAX_UDP_PAYLOAD: usize = 65_507;

/// The Internet checksum (RFC 1071) of `chunks` concatenated (each chunk of even length except
/// possibly the last).
fn internet_checksum(chunks: &[&[u8]]) -> u16 {
    let mut sum: u32 = 0;
    for chunk in chunks {
        let mut pairs = chunk.chunks_exact(2);
        for pair in &mut pairs {
            sum += u32::from(u16::from_be_bytes([pair[0], pair[1]]));
        }
        if let [last] = pairs.remainder() {
            sum += u32::from(*last) << 8;
        }
    }
    while sum > 0xffff {
        sum = (sum & 0xffff) + (sum >> 16);
    }
    !(sum as u16)
}

/// Appends an Ethernet II / IPv4 / UDP frame carrying `payload` to `out` (broadcast destination
/// MAC, [`WRITER_SRC_MAC`], TTL 64, don't-fragment set, both checksums filled in).
pub fn build_udp_frame(
    src: SocketAddrV4,
    dst: SocketAddrV4,
    payload: &[u8],
    out: &mut Vec<u8>,
) -> io::Result<()> {
    if payload.len() > MAX_UDP_PAYLOAD {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "UDP payload of {} bytes exceeds {MAX_UDP_PAYLOAD}",
                payload.len()
            ),
        ));
    }
    let udp_len = (8 + payload.len()) as u16;
    let ip_len = 20 + udp_len;
    out.extend_from_slice(&[0xff; 6]);
    out.extend_from_slice(&WRITER_SRC_MAC);
    out.extend_from_slice(&ETHERTYPE_IPV4.to_be_bytes());
    let mut ip = [0u8; 20];
    ip[0] = 0x45;
    ip[2..4].copy_from_slice(&ip_len.to_be_bytes());
    ip[6] = 0x40; // don't fragment
    ip[8] = 64;
    ip[9] = 17;
    ip[12..16].copy_from_slice(&src.ip().octets());
    ip[16..20].copy_from_slice(&dst.ip().octets());
    let ip_checksum = internet_checksum(&[&ip]);
    ip[10..12].copy_from_slice(&ip_checksum.to_be_bytes());
    out.extend_from_slice(&ip);
    let mut udp = [0u8; 8];
    udp[0..2].copy_from_slice(&src.port().to_be_bytes());
    udp[2..4].copy_from_slice(&dst.port().to_be_bytes());
    udp[4..6].copy_from_slice(&udp_len.to_be_bytes());
    let mut pseudo = [0u8; 12];
    pseudo[0..4].copy_from_slice(&src.ip().octets());
    pseudo[4..8].copy_from_slice(&dst.ip().octets());
    pseudo[9] = 17;
    pseudo[10..12].copy_from_slice(&udp_len.to_be_bytes());
    let udp_checksum = match internet_checksum(&[&pseudo, &udp, payload]) {
        0 => 0xffff,
        c => c,
    };
    udp[6..8].copy_from_slice(&udp_checksum.to_be_bytes());
    out.extend_from_slice(&udp);
    out.extend_from_slice(payload);
    Ok(())
}

/// Writes classic pcap (little-endian, microsecond stamps, Ethernet link type).
#[derive(Debug)]
pub struct PcapWriter<W: Write> {
    writer: W,
    frame: Vec<u8>,
}

impl<W: Write> PcapWriter<W> {
    /// Writes the 24-byte file header.
    pub fn new(mut writer: W) -> io::Result<Self> {
        let mut header = [0u8; 24];
        header[0..4].copy_from_slice(&0xa1b2_c3d4u32.to_le_bytes());
        header[4..6].copy_from_slice(&2u16.to_le_bytes());
        header[6..8].copy_from_slice(&4u16.to_le_bytes());
        header[16..20].copy_from_slice(&65_535u32.to_le_bytes());
        header[20..24].copy_from_slice(&link_type::ETHERNET.to_le_bytes());
        writer.write_all(&header)?;
        Ok(Self {
            writer,
            frame: Vec::with_capacity(1600),
        })
    }

    /// Appends one record holding an Ethernet/IPv4/UDP frame with `payload`, stamped `stamp_ns`
    /// nanoseconds since the UNIX epoch (written with microsecond resolution).
    pub fn write_udp(
        &mut self,
        stamp_ns: u64,
        src: SocketAddrV4,
        dst: SocketAddrV4,
        payload: &[u8],
    ) -> io::Result<()> {
        self.frame.clear();
        build_udp_frame(src, dst, payload, &mut self.frame)?;
        let seconds = u32::try_from(stamp_ns / 1_000_000_000).map_err(|_| {
            io::Error::new(io::ErrorKind::InvalidInput, "pcap stamp beyond year 2106")
        })?;
        let micros = ((stamp_ns % 1_000_000_000) / 1000) as u32;
        let len = self.frame.len() as u32;
        let mut header = [0u8; 16];
        header[0..4].copy_from_slice(&seconds.to_le_bytes());
        header[4..8].copy_from_slice(&micros.to_le_bytes());
        header[8..12].copy_from_slice(&len.to_le_bytes());
        header[12..16].copy_from_slice(&len.to_le_bytes());
        self.writer.write_all(&header)?;
        self.writer.write_all(&self.frame)
    }

    /// Flushes the underlying writer.
    pub fn flush(&mut self) -> io::Result<()> {
        self.writer.flush()
    }

    /// Returns the underlying writer (not flushed).
    pub fn into_inner(self) -> W {
        self.writer
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn addr(a: [u8; 4], port: u16) -> SocketAddrV4 {
        SocketAddrV4::new(Ipv4Addr::from(a), port)
    }

    fn written(payloads: &[&[u8]]) -> Vec<u8> {
        let mut w = PcapWriter::new(Vec::new()).unwrap();
        for (i, p) in payloads.iter().enumerate() {
            let stamp_ns = 1_700_000_000_123_456_000 + i as u64 * 1_000;
            w.write_udp(
                stamp_ns,
                addr([192, 168, 1, 201], 2368),
                addr([255; 4], 2368),
                p,
            )
            .unwrap();
        }
        w.into_inner()
    }

    #[test]
    fn writer_round_trips_through_reader() {
        let bytes = written(&[b"hello", &[7u8; 1206]]);
        assert_eq!(&bytes[..4], &[0xd4, 0xc3, 0xb2, 0xa1]);
        let mut r = PcapReader::new(&bytes[..]).unwrap();
        let rec = r.next_record().unwrap().unwrap();
        assert_eq!(rec.stamp_ns, 1_700_000_000_123_456_000);
        assert_eq!(rec.link_type, link_type::ETHERNET);
        assert_eq!(rec.data.len(), 42 + 5);
        let udp = udp_in_frame(rec.link_type, rec.data).unwrap();
        assert_eq!(udp.payload, b"hello");
        assert_eq!(udp.src, addr([192, 168, 1, 201], 2368));
        let rec = r.next_record().unwrap().unwrap();
        assert_eq!(rec.data.len(), 1248);
        assert_eq!(
            udp_in_frame(rec.link_type, rec.data).unwrap().payload,
            &[7u8; 1206]
        );
        assert!(r.next_record().unwrap().is_none());
    }

    #[test]
    fn writer_checksums_verify_to_zero() {
        let mut frame = Vec::new();
        let payload = b"odd-length payload!";
        build_udp_frame(
            addr([10, 0, 0, 1], 1234),
            addr([10, 0, 0, 2], 2368),
            payload,
            &mut frame,
        )
        .unwrap();
        let ip = &frame[14..34];
        // A correct header checksums to zero (all-ones sum).
        assert_eq!(internet_checksum(&[ip]), 0);
        let udp = &frame[34..];
        let mut pseudo = Vec::new();
        pseudo.extend_from_slice(&ip[12..20]);
        pseudo.extend_from_slice(&[0, 17]);
        pseudo.extend_from_slice(&(udp.len() as u16).to_be_bytes());
        assert_eq!(internet_checksum(&[&pseudo, udp]), 0);
        // Known value of the IPv4 header for this frame (computed independently by hand:
        // 0x4500+0x002f+0x4000+0x4011+0x0a00+0x0001+0x0a00+0x0002 = 0xd943 -> !0xd943).
        assert_eq!(u16::from_be_bytes([ip[10], ip[11]]), !0xd943);
    }

    #[test]
    fn truncated_record_is_an_error_naming_the_record() {
        let bytes = written(&[b"one", b"two"]);
        let cut = &bytes[..bytes.len() - 2];
        let mut r = PcapReader::new(cut).unwrap();
        assert!(r.next_record().unwrap().is_some());
        let err = r.next_record().unwrap_err();
        assert!(
            matches!(
                err,
                PcapError::TruncatedRecord {
                    record: 1,
                    offset: 85,
                    need: 45,
                    got: 43
                }
            ),
            "{err:?}"
        );
        assert!(err.to_string().contains("record 1 at byte 85"));
    }

    #[test]
    fn bad_magic_and_huge_record_are_refused() {
        assert!(matches!(
            PcapReader::new(&b"GIF89a.................."[..]),
            Err(PcapError::BadMagic(_))
        ));
        let mut bytes = written(&[b"x"]);
        bytes[24 + 8..24 + 12].copy_from_slice(&u32::MAX.to_le_bytes());
        let mut r = PcapReader::new(&bytes[..]).unwrap();
        assert!(matches!(
            r.next_record(),
            Err(PcapError::RecordTooLarge { .. })
        ));
    }

    #[test]
    fn corrupt_record_mid_file_is_corruption_at_its_offset() {
        let bytes = written(&[b"one", b"two", b"three"]);
        // Record 1 starts at 24 + 16 + 45 = 85; its original length below its captured length.
        let mut bad = bytes.clone();
        bad[85 + 12..85 + 16].copy_from_slice(&10u32.to_le_bytes());
        let mut r = PcapReader::new(&bad[..]).unwrap();
        assert!(r.next_record().unwrap().is_some());
        let err = r.next_record().unwrap_err();
        assert!(!err.is_truncated_end(), "{err:?}");
        assert!(
            err.to_string()
                .starts_with("record 1 at byte 85 is corrupt"),
            "{err}"
        );
        // A microsecond field of a second or more.
        let mut bad = bytes.clone();
        bad[85 + 4..85 + 8].copy_from_slice(&1_000_000u32.to_le_bytes());
        let mut r = PcapReader::new(&bad[..]).unwrap();
        r.next_record().unwrap();
        assert!(matches!(
            r.next_record(),
            Err(PcapError::Corrupt {
                record: 1,
                offset: 85,
                ..
            })
        ));
        // A length above the limit mid-file is not a truncated end either.
        let mut bad = bytes.clone();
        bad[85 + 8..85 + 12].copy_from_slice(&u32::MAX.to_le_bytes());
        let mut r = PcapReader::new(&bad[..]).unwrap();
        r.next_record().unwrap();
        assert!(!r.next_record().unwrap_err().is_truncated_end());
        // A cut-short last record is.
        let mut r = PcapReader::new(&bytes[..bytes.len() - 1]).unwrap();
        r.next_record().unwrap();
        r.next_record().unwrap();
        assert!(r.next_record().unwrap_err().is_truncated_end());
    }

    #[test]
    fn ipv4_header_longer_than_the_packet_is_an_error() {
        // IHL 15 (60 bytes) with 30 bytes of IP present: the header runs past the packet.
        let mut ip = vec![0u8; 30];
        ip[0] = 0x4f;
        ip[2..4].copy_from_slice(&60u16.to_be_bytes());
        ip[9] = 17;
        assert_eq!(
            udp_in_frame(link_type::RAW, &ip),
            Err(NetError::Truncated("IPv4 options"))
        );
        // The same inside an Ethernet frame, with a total length above the bytes present.
        let mut eth = vec![0u8; 12];
        eth.extend_from_slice(&ETHERTYPE_IPV4.to_be_bytes());
        ip[2..4].copy_from_slice(&1500u16.to_be_bytes());
        eth.extend_from_slice(&ip);
        assert_eq!(
            udp_in_frame(link_type::ETHERNET, &eth),
            Err(NetError::Truncated("IPv4 options"))
        );
    }

    fn ng_block(block_type: u32, body: &[u8]) -> Vec<u8> {
        let padded = (body.len() + 3) & !3;
        let total = (12 + padded) as u32;
        let mut b = Vec::new();
        b.extend_from_slice(&block_type.to_le_bytes());
        b.extend_from_slice(&total.to_le_bytes());
        b.extend_from_slice(body);
        b.resize(8 + padded, 0);
        b.extend_from_slice(&total.to_le_bytes());
        b
    }

    #[test]
    fn pcapng_with_sll_and_nanosecond_resolution() {
        let mut shb = Vec::new();
        shb.extend_from_slice(&PCAPNG_BYTE_ORDER.to_le_bytes());
        shb.extend_from_slice(&[1, 0, 0, 0]);
        shb.extend_from_slice(&u64::MAX.to_le_bytes());
        let mut idb = Vec::new();
        idb.extend_from_slice(&(link_type::LINUX_SLL as u16).to_le_bytes());
        idb.extend_from_slice(&[0, 0, 0, 0, 0, 0]);
        idb.extend_from_slice(&[9, 0, 1, 0, 9, 0, 0, 0, 0, 0, 0, 0]); // if_tsresol = 9, end
        // An SLL frame: 16-byte header with protocol 0x0800, then IPv4/UDP from the builder.
        let mut eth = Vec::new();
        build_udp_frame(
            addr([192, 168, 1, 201], 8308),
            addr([255; 4], 8308),
            b"pos",
            &mut eth,
        )
        .unwrap();
        let mut sll = vec![0u8; 14];
        sll.extend_from_slice(&[0x08, 0x00]);
        sll.extend_from_slice(&eth[14..]);
        let ticks: u64 = 1_234_567_890_123;
        let mut epb = Vec::new();
        epb.extend_from_slice(&0u32.to_le_bytes());
        epb.extend_from_slice(&((ticks >> 32) as u32).to_le_bytes());
        epb.extend_from_slice(&(ticks as u32).to_le_bytes());
        epb.extend_from_slice(&(sll.len() as u32).to_le_bytes());
        epb.extend_from_slice(&(sll.len() as u32).to_le_bytes());
        epb.extend_from_slice(&sll);
        let mut file = ng_block(PCAPNG_SHB, &shb);
        file.extend(ng_block(1, &idb));
        file.extend(ng_block(5, b"statistics block, skipped"));
        file.extend(ng_block(6, &epb));
        let mut r = PcapReader::new(&file[..]).unwrap();
        let rec = r.next_record().unwrap().unwrap();
        assert_eq!(rec.stamp_ns, ticks);
        assert_eq!(rec.link_type, link_type::LINUX_SLL);
        let udp = udp_in_frame(rec.link_type, rec.data).unwrap();
        assert_eq!((udp.payload, udp.dst.port()), (&b"pos"[..], 8308));
        assert!(r.next_record().unwrap().is_none());
        // The same frame as raw IP.
        assert_eq!(
            udp_in_frame(link_type::RAW, &eth[14..]).unwrap().payload,
            b"pos"
        );
    }

    #[test]
    fn frames_that_are_not_udp_say_why() {
        let mut eth = Vec::new();
        build_udp_frame(
            addr([1, 2, 3, 4], 1),
            addr([5, 6, 7, 8], 2),
            b"abc",
            &mut eth,
        )
        .unwrap();
        let mut arp = eth.clone();
        arp[12..14].copy_from_slice(&0x0806u16.to_be_bytes());
        assert_eq!(udp_in_frame(1, &arp), Err(NetError::NotIpv4(0x0806)));
        let mut tcp = eth.clone();
        tcp[14 + 9] = 6;
        assert_eq!(udp_in_frame(1, &tcp), Err(NetError::NotUdp(6)));
        let mut frag = eth.clone();
        frag[14 + 6] = 0x20; // more fragments
        assert_eq!(udp_in_frame(1, &frag), Err(NetError::Fragment));
        assert_eq!(udp_in_frame(1, &eth[..40]), Err(NetError::Truncated("UDP")));
        assert_eq!(udp_in_frame(1, &eth[..44]), Err(NetError::BadUdpLength(11)));
        assert_eq!(
            udp_in_frame(147, &eth),
            Err(NetError::UnsupportedLinkType(147))
        );
    }

    proptest! {
        #[test]
        fn reader_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..2000)) {
            if let Ok(mut r) = PcapReader::new(&bytes[..]) {
                while let Ok(Some(rec)) = r.next_record() {
                    let _ = udp_in_frame(rec.link_type, rec.data);
                }
            }
        }

        #[test]
        fn mutated_captures_never_panic(at in 0usize..150, byte in any::<u8>()) {
            let mut bytes = written(&[b"first payload", b"second"]);
            let at = at % bytes.len();
            bytes[at] = byte;
            if let Ok(mut r) = PcapReader::new(&bytes[..]) {
                while let Ok(Some(rec)) = r.next_record() {
                    let _ = udp_in_frame(rec.link_type, rec.data);
                }
            }
        }

        #[test]
        fn udp_in_frame_never_panics(link in 0u32..300, bytes in prop::collection::vec(any::<u8>(), 0..100)) {
            let _ = udp_in_frame(link, &bytes);
        }

        #[test]
        fn writer_round_trips_any_payload(payload in prop::collection::vec(any::<u8>(), 0..1500), port in any::<u16>()) {
            let mut w = PcapWriter::new(Vec::new()).unwrap();
            w.write_udp(5_000, addr([10, 1, 2, 3], port), addr([10, 3, 2, 1], 2368), &payload).unwrap();
            let bytes = w.into_inner();
            let mut r = PcapReader::new(&bytes[..]).unwrap();
            let rec = r.next_record().unwrap().unwrap();
            prop_assert_eq!(rec.stamp_ns, 5_000);
            let udp = udp_in_frame(rec.link_type, rec.data).unwrap();
            prop_assert_eq!(udp.payload, &payload[..]);
            prop_assert_eq!(udp.src.port(), port);
        }
    }
}
