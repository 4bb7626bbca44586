//! The CAN bus between the firmware and the simulated ESCs, behind one small trait.
//!
//! - [`CanFrame`]: a classic CAN frame (standard or extended id, 0..=8 bytes) implementing
//!   [`embedded_can::Frame`], so `protocol::esc`'s generic helpers build and parse it.
//! - [`CanBus`]: non-blocking `send` / `try_recv`, one value per bus node.
//! - [`InProcessBus`]: a broadcast bus in memory (every node receives every frame but its own, as
//!   on SocketCAN), with an optional recorder that writes `candump -l` lines. Works everywhere.
//! - [`SocketCanBus`]: a raw SocketCAN socket on any interface (`vcan0`, `can0`). On a kernel
//!   without CAN (`socket()` fails with "address family not supported") `open` returns
//!   [`CanError::Open`] naming the interface and pointing at `hil-sim/vcan-vm`.
//!
//! Both deliver frames in send order; neither blocks. [`recv_expected`] waits (briefly, in real
//! time) for a known number of frames, which the virtual-clock runner uses over SocketCAN where
//! delivery is asynchronous inside the kernel.

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use embedded_can::{ExtendedId, Frame, Id, StandardId};

/// A classic CAN data or remote frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CanFrame {
    id: Id,
    remote: bool,
    dlc: u8,
    data: [u8; 8],
}

impl Frame for CanFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        let mut buf = [0u8; 8];
        buf.get_mut(..data.len())?.copy_from_slice(data);
        Some(Self {
            id: id.into(),
            remote: false,
            dlc: u8::try_from(data.len()).ok()?,
            data: buf,
        })
    }

    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        (dlc <= 8).then(|| Self {
            id: id.into(),
            remote: true,
            dlc: u8::try_from(dlc).unwrap_or(8),
            data: [0; 8],
        })
    }

    fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }

    fn is_remote_frame(&self) -> bool {
        self.remote
    }

    fn id(&self) -> Id {
        self.id
    }

    fn dlc(&self) -> usize {
        usize::from(self.dlc)
    }

    fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            &self.data[..usize::from(self.dlc)]
        }
    }
}

impl CanFrame {
    /// The raw id (11 or 29 bits).
    pub fn raw_id(&self) -> u32 {
        match self.id {
            Id::Standard(id) => u32::from(id.as_raw()),
            Id::Extended(id) => id.as_raw(),
        }
    }

    /// Converts any embedded-can frame (e.g. socketcan's) into this type.
    pub fn from_frame<F: Frame>(frame: &F) -> Option<Self> {
        if frame.is_remote_frame() {
            Self::new_remote(frame.id(), frame.dlc())
        } else {
            Self::new(frame.id(), frame.data())
        }
    }

    /// Converts into any embedded-can frame type.
    pub fn to_frame<F: Frame>(&self) -> Option<F> {
        if self.remote {
            F::new_remote(self.id, self.dlc())
        } else {
            F::new(self.id, self.data())
        }
    }

    /// This frame in `candump -l` log syntax (`123#0011223344556677`, `12345678#...`, `123#R`).
    pub fn to_candump(&self) -> String {
        let mut s = match self.id {
            Id::Standard(id) => format!("{:03X}#", id.as_raw()),
            Id::Extended(id) => format!("{:08X}#", id.as_raw()),
        };
        if self.remote {
            s.push('R');
        } else {
            for b in self.data() {
                let _ = write!(s, "{b:02X}");
            }
        }
        s
    }

    /// A standard-id data frame (`None` if the id is above 0x7FF or the data is too long).
    pub fn standard(id: u16, data: &[u8]) -> Option<Self> {
        Self::new(StandardId::new(id)?, data)
    }

    /// An extended-id data frame (`None` if the id is above 29 bits or the data is too long).
    pub fn extended(id: u32, data: &[u8]) -> Option<Self> {
        Self::new(ExtendedId::new(id)?, data)
    }
}

/// Errors of a bus node.
#[derive(Debug, thiserror::Error)]
pub enum CanError {
    /// The SocketCAN interface could not be opened.
    #[error(
        "SocketCAN interface `{iface}` cannot be opened: {source} (a kernel without CAN support \
         fails here; hil-sim/vcan-vm/run.sh runs the command in a guest that has vcan0)"
    )]
    Open {
        /// Interface name.
        iface: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// Sending or receiving failed.
    #[error("CAN {op} on `{iface}` failed: {source}")]
    Io {
        /// "send" or "receive".
        op: &'static str,
        /// Interface name.
        iface: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The frame could not be converted (never for frames built by [`CanFrame`]).
    #[error("CAN frame {0:?} cannot be represented on this bus")]
    BadFrame(CanFrame),
    /// The in-process bus's lock was poisoned by a panicking node.
    #[error("the in-process CAN bus was poisoned by a panicking thread")]
    Poisoned,
}

/// One node's view of a CAN bus: non-blocking send and receive.
pub trait CanBus {
    /// Queues `frame` for transmission (never blocks).
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError>;
    /// The next received frame, if any (never blocks).
    fn try_recv(&mut self) -> Result<Option<CanFrame>, CanError>;
    /// A short name for reports (`in-process`, `socketcan:vcan0`).
    fn name(&self) -> String;
    /// Tells the node the simulation time (used to stamp recorded frames); default: ignored.
    fn set_time_us(&mut self, _now_us: u64) {}
}

/// Receives exactly `count` frames, waiting up to `timeout` of real time for the last ones (for
/// buses whose delivery is asynchronous). Returns the frames that arrived; fewer than `count` means
/// frames were lost or late.
pub fn recv_expected(
    bus: &mut dyn CanBus,
    count: usize,
    timeout: Duration,
) -> Result<Vec<CanFrame>, CanError> {
    let mut frames = Vec::with_capacity(count);
    let deadline = Instant::now() + timeout;
    while frames.len() < count {
        match bus.try_recv()? {
            Some(f) => frames.push(f),
            None if Instant::now() >= deadline => break,
            None => std::thread::yield_now(),
        }
    }
    Ok(frames)
}

/// Shared state of the in-process bus.
#[derive(Debug, Default)]
struct BusState {
    queues: Vec<VecDeque<CanFrame>>,
    log: Option<Vec<String>>,
    now_us: u64,
}

/// An in-memory broadcast CAN bus. Clone-free: make nodes with [`InProcessBus::node`].
#[derive(Debug, Clone, Default)]
pub struct InProcessBus {
    state: Arc<Mutex<BusState>>,
}

impl InProcessBus {
    /// An empty bus without a recorder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Starts recording every frame as a `candump -l` line (`(sec.usec) iface frame`).
    pub fn record(&self) {
        self.lock().log.get_or_insert_with(Vec::new);
    }

    /// The time stamped on recorded frames from now on (the runner's virtual clock), microseconds.
    pub fn set_time_us(&self, now_us: u64) {
        self.lock().now_us = now_us;
    }

    /// The recorded `candump -l` lines so far.
    pub fn recorded(&self) -> Vec<String> {
        self.lock().log.clone().unwrap_or_default()
    }

    /// A new node attached to this bus.
    pub fn node(&self) -> InProcessNode {
        let mut state = self.lock();
        state.queues.push(VecDeque::new());
        InProcessNode {
            bus: self.clone(),
            index: state.queues.len() - 1,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, BusState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// One node of an [`InProcessBus`].
#[derive(Debug)]
pub struct InProcessNode {
    bus: InProcessBus,
    index: usize,
}

impl CanBus for InProcessNode {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        let mut state = self.bus.lock();
        for (i, q) in state.queues.iter_mut().enumerate() {
            if i != self.index {
                q.push_back(*frame);
            }
        }
        let now_us = state.now_us;
        if let Some(log) = state.log.as_mut() {
            log.push(format!(
                "({}.{:06}) sim0 {}",
                now_us / 1_000_000,
                now_us % 1_000_000,
                frame.to_candump()
            ));
        }
        Ok(())
    }

    fn try_recv(&mut self) -> Result<Option<CanFrame>, CanError> {
        Ok(self
            .bus
            .lock()
            .queues
            .get_mut(self.index)
            .and_then(VecDeque::pop_front))
    }

    fn name(&self) -> String {
        "in-process".to_owned()
    }

    fn set_time_us(&mut self, now_us: u64) {
        self.bus.set_time_us(now_us);
    }
}

/// A raw SocketCAN socket on one interface, non-blocking.
pub struct SocketCanBus {
    socket: socketcan::CanSocket,
    iface: String,
}

impl std::fmt::Debug for SocketCanBus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SocketCanBus")
            .field("iface", &self.iface)
            .finish_non_exhaustive()
    }
}

impl SocketCanBus {
    /// Opens `iface` (e.g. `vcan0`) in non-blocking mode.
    pub fn open(iface: &str) -> Result<Self, CanError> {
        use socketcan::Socket as _;
        let open_err = |source| CanError::Open {
            iface: iface.to_owned(),
            source,
        };
        let socket = socketcan::CanSocket::open(iface).map_err(open_err)?;
        socket.set_nonblocking(true).map_err(open_err)?;
        Ok(Self {
            socket,
            iface: iface.to_owned(),
        })
    }

    /// Whether `iface` exists and is up on this machine (reads /sys; no socket is opened).
    pub fn interface_up(iface: &str) -> bool {
        std::fs::read_to_string(format!("/sys/class/net/{iface}/operstate"))
            .is_ok_and(|s| matches!(s.trim(), "up" | "unknown"))
    }
}

impl CanBus for SocketCanBus {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        use socketcan::Socket as _;
        let f: socketcan::CanFrame = frame.to_frame().ok_or(CanError::BadFrame(*frame))?;
        self.socket.write_frame(&f).map_err(|source| CanError::Io {
            op: "send",
            iface: self.iface.clone(),
            source,
        })
    }

    fn try_recv(&mut self) -> Result<Option<CanFrame>, CanError> {
        use socketcan::Socket as _;
        match self.socket.read_frame() {
            Ok(f) => Ok(CanFrame::from_frame(&f)),
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => Ok(None),
            Err(source) => Err(CanError::Io {
                op: "receive",
                iface: self.iface.clone(),
                source,
            }),
        }
    }

    fn name(&self) -> String {
        format!("socketcan:{}", self.iface)
    }
}

/// Parses a `candump -l` log (as written by can-utils' `candump -l` / `-L`, or by
/// [`InProcessBus::record`]) into `(stamp_us, iface, frame)` records, naming the first bad line.
pub fn parse_candump_log(text: &str) -> Result<Vec<(u64, String, CanFrame)>, String> {
    let mut out = Vec::new();
    let mut reader = socketcan::dump::Reader::from_reader(text.as_bytes());
    for n in 1.. {
        let rec = match reader.next_record() {
            Ok(Some(rec)) => rec,
            Ok(None) => break,
            Err(e) => return Err(format!("candump log record {n}: {e}")),
        };
        let frame = match &rec.frame {
            socketcan::CanAnyFrame::Normal(f) => CanFrame::from_frame(f),
            socketcan::CanAnyFrame::Remote(f) => CanFrame::from_frame(f),
            other => {
                return Err(format!(
                    "candump log record {n}: not a classic data/remote frame: {other:?}"
                ));
            }
        }
        .ok_or_else(|| format!("candump log record {n}: frame does not fit"))?;
        out.push((rec.t_us, rec.device, frame));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_process_bus_broadcasts_to_others_only() {
        let bus = InProcessBus::new();
        let mut a = bus.node();
        let mut b = bus.node();
        let mut c = bus.node();
        let f = CanFrame::standard(0x201, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        a.send(&f).unwrap();
        assert_eq!(a.try_recv().unwrap(), None);
        assert_eq!(b.try_recv().unwrap(), Some(f));
        assert_eq!(c.try_recv().unwrap(), Some(f));
        assert_eq!(b.try_recv().unwrap(), None);
    }

    #[test]
    fn recorder_writes_candump_lines_that_parse_back() {
        let bus = InProcessBus::new();
        bus.record();
        let mut a = bus.node();
        bus.set_time_us(1_234_567);
        let f = CanFrame::standard(0x200, &[0x03, 0xE8, 0, 0, 0, 0, 0xFF, 0x01]).unwrap();
        a.send(&f).unwrap();
        let e = CanFrame::extended(0x1234_5678, &[0xAB]).unwrap();
        a.send(&e).unwrap();
        let lines = bus.recorded();
        assert_eq!(lines[0], "(1.234567) sim0 200#03E800000000FF01");
        let parsed = parse_candump_log(&lines.join("\n")).unwrap();
        assert_eq!(parsed.len(), 2);
        assert_eq!(parsed[0].0, 1_234_567);
        assert_eq!(parsed[0].1, "sim0");
        assert_eq!(parsed[0].2, f);
        assert_eq!(parsed[1].2, e);
    }

    #[test]
    fn candump_parser_names_the_bad_line() {
        let err = parse_candump_log("(0.000001) vcan0 200#00\n(x) vcan0 200#00").unwrap_err();
        assert!(err.contains("record 2"), "{err}");
    }

    #[test]
    fn candump_parser_never_panics_on_mangled_logs() {
        // Seeded mutations of a valid log (the cargo-fuzz target `candump_log` does this with
        // coverage guidance): truncation, byte flips, insertions. Errors are fine; panics are not.
        use rand::{Rng, SeedableRng};
        let good = "(1.000001) vcan0 200#03E80000FC180000\n(1.000002) vcan0 201#1000049FFE0C2300\n\
                    (1.000003) vcan0 12345678#R\n(1.000004) vcan0 7FF#\n";
        let alphabet = b"0123456789ABCDEFabcdef#.()R \n-_xX\t";
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        for _ in 0..20_000 {
            let mut bytes = good.as_bytes().to_vec();
            for _ in 0..rng.random_range(1..6) {
                let i = rng.random_range(0..bytes.len());
                match rng.random_range(0..3) {
                    0 => bytes.truncate(i),
                    1 => bytes[i] = alphabet[rng.random_range(0..alphabet.len())],
                    _ => bytes.insert(i, alphabet[rng.random_range(0..alphabet.len())]),
                }
                if bytes.is_empty() {
                    break;
                }
            }
            let text = String::from_utf8_lossy(&bytes);
            let _ = parse_candump_log(&text);
        }
    }

    #[test]
    fn socketcan_open_failure_is_an_error_not_a_panic() {
        // On a kernel without AF_CAN this fails at socket(); elsewhere the interface does not exist.
        let err = SocketCanBus::open("passangle-no-such-if").unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("passangle-no-such-if"), "{msg}");
    }

    #[test]
    fn frame_conversions_round_trip_through_socketcan_frames() {
        let f = CanFrame::standard(0x203, &[9, 8, 7]).unwrap();
        let s: socketcan::CanFrame = f.to_frame().unwrap();
        assert_eq!(CanFrame::from_frame(&s), Some(f));
        let r = CanFrame::new_remote(StandardId::new(0x7FF).unwrap(), 2).unwrap();
        assert_eq!(r.to_candump(), "7FF#R");
        assert_eq!(r.data(), &[] as &[u8]);
    }
}
