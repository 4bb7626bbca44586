//! MCU-link handling: bytes from the UART in, commands out, reply frames encoded for the UART.
//!
//! [`Link`] wraps the shared IO-free [`protocol::Deframer`] and the `protocol::mcu` message set.
//! For each whole frame it:
//! - counts and drops frames that fail COBS, CRC or length checks (`link_errors`);
//! - acks frames that ask for it (same msg id and seq, `IS_ACK`, empty payload);
//! - answers `Hello` with the firmware's own `Hello` (whatever the peer's version: that is how a
//!   mismatched peer learns ours); only a `Hello` of our version lets the peer drive (`NO_HOST`
//!   is reported until then);
//! - hands `Heartbeat`, `Drive`, `Stop`, `SetConfig` and `ClearFaults` to the caller as a
//!   [`Request`], and turns a refusal into `Rejected { msg_id, seq, reason, field }`;
//! - answers undecodable payloads, unknown ids and other versions with `Rejected` too.
//!
//! Nothing here panics on any byte sequence (property-tested below; fuzzed by
//! `fuzz/fuzz_targets/firmware_link.rs`).

use protocol::bounded::Text;
use protocol::frame::{self, Feed, Flags, Frame, Header, MAX_FRAME_LEN};
use protocol::mcu::{McuConfig, RejectReason, Rejected, ToFirmware};
use protocol::message::DecodeError;
use protocol::{Hello, Message, Role};

use crate::kinematics::Twist;
use crate::machine::{Command, DriveCommand, Reject};

/// Bytes of outgoing frames one step may produce; frames that do not fit are dropped and counted.
pub const TX_CAPACITY: usize = 1024;

/// Outgoing bytes of one step.
pub type TxBuffer = heapless::Vec<u8, TX_CAPACITY>;

/// A request from the onboard computer for the controller to apply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Request {
    /// A command for the drive state machine.
    Command(Command),
    /// A configuration to merge into the current one ([`crate::Config::with_mcu`]) and apply.
    SetConfig(McuConfig),
}

/// Counters and the outgoing sequence number (apart from the deframer so both can be borrowed).
#[derive(Debug, Clone, Copy, Default)]
struct TxState {
    seq: u16,
    link_errors: u16,
    rejected_count: u16,
    tx_dropped: u32,
}

impl TxState {
    /// Encodes `msg` as the next frame and appends it to `tx` (or counts it as dropped).
    fn send<M: Message>(&mut self, msg: &M, tx: &mut TxBuffer) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        match msg.encode_frame(seq, Flags::NONE, &mut buf) {
            Ok(len) if tx.extend_from_slice(&buf[..len]).is_ok() => {}
            _ => self.tx_dropped = self.tx_dropped.saturating_add(1),
        }
    }

    fn send_ack(&mut self, header: Header, tx: &mut TxBuffer) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        match frame::encode_raw(header.ack(), &[], &mut buf) {
            Ok(len) if tx.extend_from_slice(&buf[..len]).is_ok() => {}
            _ => self.tx_dropped = self.tx_dropped.saturating_add(1),
        }
    }

    fn reject(&mut self, header: Header, reason: RejectReason, field: &str, tx: &mut TxBuffer) {
        self.rejected_count = self.rejected_count.saturating_add(1);
        let msg = Rejected {
            msg_id: header.msg_id,
            seq: header.seq,
            reason,
            field: Text::truncated(field),
        };
        self.send(&msg, tx);
    }

    /// Handles one whole frame; returns the request it carries, if any.
    fn handle(&mut self, frame: &Frame<'_>, tx: &mut TxBuffer) -> Option<Request> {
        let header = frame.header;
        let msg = match ToFirmware::decode(frame) {
            Ok(msg) => msg,
            Err(DecodeError::IsAck) => return None,
            Err(e) => {
                let reason = match e {
                    DecodeError::VersionMismatch { .. } => RejectReason::VersionMismatch,
                    DecodeError::UnknownId { .. } => RejectReason::UnknownMessage,
                    _ => {
                        self.link_errors = self.link_errors.saturating_add(1);
                        RejectReason::Malformed
                    }
                };
                self.reject(header, reason, "", tx);
                return None;
            }
        };
        if header.flags.contains(Flags::ACK_REQUESTED) {
            self.send_ack(header, tx);
        }
        match msg {
            ToFirmware::Hello(hello) => {
                self.send(&Hello::new(Role::Firmware), tx);
                (hello.version == protocol::PROTOCOL_VERSION)
                    .then_some(Request::Command(Command::Hello))
            }
            ToFirmware::Heartbeat(_) => Some(Request::Command(Command::Heartbeat)),
            ToFirmware::Drive(d) => Some(Request::Command(Command::Drive(DriveCommand {
                twist: Twist::new(d.vx_mps, d.vy_mps, d.wz_radps),
                accel_mps2: d.accel_mps2,
                jerk_mps3: d.jerk_mps3,
            }))),
            ToFirmware::Stop(s) => Some(Request::Command(Command::Stop {
                immediate: s.immediate,
            })),
            ToFirmware::SetConfig(c) => Some(Request::SetConfig(c)),
            ToFirmware::ClearFaults(_) => Some(Request::Command(Command::ClearFaults)),
        }
    }
}

/// The wire reason and field of a refusal.
pub fn reject_reason(reject: &Reject) -> (RejectReason, &'static str) {
    match reject {
        Reject::OutOfRange(field) => (RejectReason::OutOfRange, field),
        Reject::BadConfig(e) => (RejectReason::OutOfRange, e.mcu_field()),
        Reject::Interlocked(i) | Reject::FaultsPersist(i) => {
            (RejectReason::Interlocked, i.names().next().unwrap_or(""))
        }
        Reject::Busy => (RejectReason::Interlocked, "not idle"),
    }
}

/// MCU-link state: the deframer, the outgoing sequence number and the counters.
#[derive(Debug, Clone, Default)]
pub struct Link {
    deframer: protocol::Deframer<MAX_FRAME_LEN>,
    state: TxState,
}

impl Link {
    /// A link with nothing received yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Frames dropped (COBS, CRC, oversize, malformed payload) since boot.
    pub fn link_errors(&self) -> u16 {
        self.state.link_errors
    }

    /// Commands rejected since boot.
    pub fn rejected_count(&self) -> u16 {
        self.state.rejected_count
    }

    /// Outgoing frames dropped because a step's TX buffer was full.
    pub fn tx_dropped(&self) -> u32 {
        self.state.tx_dropped
    }

    /// Feeds received bytes (any chunking). For each request, `apply` is called in order; a
    /// refusal it returns is answered with `Rejected`. Replies go into `tx`.
    pub fn receive(
        &mut self,
        bytes: &[u8],
        tx: &mut TxBuffer,
        mut apply: impl FnMut(Request) -> Result<(), Reject>,
    ) {
        let mut rest = bytes;
        while !rest.is_empty() {
            rest = match self.deframer.feed(rest) {
                Feed::Consumed => break,
                Feed::Frame { frame, remaining } => {
                    let header = frame.header;
                    if let Some(request) = self.state.handle(&frame, tx)
                        && let Err(reject) = apply(request)
                    {
                        let (reason, field) = reject_reason(&reject);
                        self.state.reject(header, reason, field, tx);
                    }
                    remaining
                }
                Feed::Error { remaining, .. } => {
                    self.state.link_errors = self.state.link_errors.saturating_add(1);
                    remaining
                }
            };
        }
    }

    /// Encodes `msg` as the next outgoing frame into `tx`.
    pub fn send<M: Message>(&mut self, msg: &M, tx: &mut TxBuffer) {
        self.state.send(msg, tx);
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use protocol::mcu::{ClearFaults, Drive, FromFirmware, Stop};
    use protocol::{Deframer, Heartbeat};

    fn frame_of<M: Message>(msg: &M, seq: u16, flags: Flags) -> heapless::Vec<u8, MAX_FRAME_LEN> {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let len = msg.encode_frame(seq, flags, &mut buf).unwrap();
        heapless::Vec::from_slice(&buf[..len]).unwrap()
    }

    /// Decodes every frame in `tx` as something the firmware sends (or an ack header).
    fn replies(tx: &[u8]) -> Vec<(Header, Option<FromFirmware>)> {
        let mut d = Deframer::<MAX_FRAME_LEN>::new();
        let mut out = Vec::new();
        d.feed_all(tx, |f| {
            let f = f.unwrap();
            if f.header.flags.contains(Flags::IS_ACK) {
                out.push((f.header, None));
            } else {
                out.push((f.header, Some(FromFirmware::decode(&f).unwrap())));
            }
        });
        out
    }

    #[test]
    fn hello_is_answered_acked_and_enables_the_host() {
        let mut link = Link::new();
        let mut tx = TxBuffer::new();
        let mut got = Vec::new();
        let bytes = frame_of(&Hello::new(Role::Onboard), 7, Flags::ACK_REQUESTED);
        link.receive(&bytes, &mut tx, |r| {
            got.push(r);
            Ok(())
        });
        assert_eq!(got, [Request::Command(Command::Hello)]);
        let r = replies(&tx);
        assert_eq!(r.len(), 2);
        assert_eq!((r[0].0.msg_id, r[0].0.seq), (protocol::ids::HELLO, 7));
        assert!(r[0].0.flags.contains(Flags::IS_ACK));
        assert_eq!(
            r[1].1,
            Some(FromFirmware::Hello(Hello::new(Role::Firmware)))
        );
    }

    #[test]
    fn hello_of_another_version_is_answered_but_not_accepted() {
        let mut link = Link::new();
        let mut tx = TxBuffer::new();
        let mut buf = [0u8; MAX_FRAME_LEN];
        let header = Header {
            version: 9,
            msg_id: protocol::ids::HELLO,
            seq: 1,
            flags: Flags::NONE,
        };
        let len = frame::encode(
            header,
            &Hello {
                version: 9,
                role: 2,
            },
            &mut buf,
        )
        .unwrap();
        let mut got = Vec::new();
        link.receive(&buf[..len], &mut tx, |r| {
            got.push(r);
            Ok(())
        });
        assert!(got.is_empty());
        assert_eq!(
            replies(&tx)[0].1,
            Some(FromFirmware::Hello(Hello::new(Role::Firmware)))
        );
    }

    #[test]
    fn commands_map_and_refusals_are_answered() {
        let mut link = Link::new();
        let mut tx = TxBuffer::new();
        let drive = Drive {
            vx_mps: 0.3,
            vy_mps: 0.0,
            wz_radps: 0.0,
            accel_mps2: 0.5,
            jerk_mps3: 2.0,
        };
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&frame_of(&Heartbeat { counter: 1 }, 1, Flags::NONE));
        bytes.extend_from_slice(&frame_of(&drive, 2, Flags::NONE));
        bytes.extend_from_slice(&frame_of(&Stop { immediate: true }, 3, Flags::NONE));
        bytes.extend_from_slice(&frame_of(&ClearFaults {}, 4, Flags::NONE));
        let mut got = Vec::new();
        // Feed one byte at a time: chunking must not matter.
        for b in &bytes {
            link.receive(core::slice::from_ref(b), &mut tx, |r| {
                got.push(r);
                if matches!(r, Request::Command(Command::Drive(_))) {
                    Err(Reject::OutOfRange("vx_mps"))
                } else {
                    Ok(())
                }
            });
        }
        assert_eq!(got.len(), 4);
        assert_eq!(got[0], Request::Command(Command::Heartbeat));
        let Request::Command(Command::Drive(d)) = got[1] else {
            panic!("{:?}", got[1])
        };
        assert_eq!((d.twist.vx_mps, d.accel_mps2, d.jerk_mps3), (0.3, 0.5, 2.0));
        assert_eq!(got[2], Request::Command(Command::Stop { immediate: true }));
        assert_eq!(got[3], Request::Command(Command::ClearFaults));
        let r = replies(&tx);
        assert_eq!(r.len(), 1);
        let Some(FromFirmware::Rejected(rej)) = &r[0].1 else {
            panic!("{r:?}")
        };
        assert_eq!(
            (rej.msg_id, rej.seq, rej.reason),
            (protocol::ids::DRIVE, 2, RejectReason::OutOfRange)
        );
        assert_eq!(rej.field.as_str(), "vx_mps");
        assert_eq!(link.rejected_count(), 1);
    }

    #[test]
    fn garbage_and_unknown_ids_are_counted_and_answered() {
        let mut link = Link::new();
        let mut tx = TxBuffer::new();
        // Corrupt one byte of a heartbeat frame: CRC fails, counted, no reply.
        let mut bad = frame_of(&Heartbeat { counter: 5 }, 9, Flags::NONE);
        bad[2] ^= 0x40;
        link.receive(&bad, &mut tx, |_| panic!("no request from a corrupt frame"));
        assert_eq!(link.link_errors(), 1);
        assert!(tx.is_empty());
        // A frame with a radio-link id: UnknownMessage.
        let mut buf = [0u8; MAX_FRAME_LEN];
        let len = frame::encode_raw(
            Header::new(protocol::ids::ABORT, 3, Flags::NONE),
            &[],
            &mut buf,
        )
        .unwrap();
        link.receive(&buf[..len], &mut tx, |_| panic!("no request"));
        let r = replies(&tx);
        let Some(FromFirmware::Rejected(rej)) = &r[0].1 else {
            panic!("{r:?}")
        };
        assert_eq!(rej.reason, RejectReason::UnknownMessage);
        // A drive frame whose payload is truncated: Malformed.
        tx.clear();
        let len = frame::encode_raw(
            Header::new(protocol::ids::DRIVE, 4, Flags::NONE),
            &[1, 2],
            &mut buf,
        )
        .unwrap();
        link.receive(&buf[..len], &mut tx, |_| panic!("no request"));
        let r = replies(&tx);
        let Some(FromFirmware::Rejected(rej)) = &r[0].1 else {
            panic!("{r:?}")
        };
        assert_eq!(rej.reason, RejectReason::Malformed);
        assert_eq!(link.link_errors(), 2);
    }

    #[test]
    fn reject_reasons_name_the_field_or_interlock() {
        use crate::safety::Interlocks;
        let i = Interlocks::HEARTBEAT_LOST.union(Interlocks::CAN_BUS_OFF);
        assert_eq!(
            reject_reason(&Reject::Interlocked(i)),
            (RejectReason::Interlocked, "HEARTBEAT_LOST")
        );
        let e = crate::config::ConfigError::OutOfRange("geometry.half_track_m");
        assert_eq!(
            reject_reason(&Reject::BadConfig(e)),
            (RejectReason::OutOfRange, "half_width_m")
        );
    }

    #[test]
    fn full_tx_buffer_drops_and_counts() {
        let mut link = Link::new();
        let mut tx = TxBuffer::new();
        let status_like = Hello::new(Role::Firmware);
        for _ in 0..2000 {
            link.send(&status_like, &mut tx);
        }
        assert!(tx.len() <= TX_CAPACITY);
        assert!(link.tx_dropped() > 0);
    }

    proptest! {
        #[test]
        fn receive_never_panics(chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..300), 0..8)) {
            let mut link = Link::new();
            for chunk in chunks {
                let mut tx = TxBuffer::new();
                link.receive(&chunk, &mut tx, |_| Err(Reject::Busy));
            }
        }

        #[test]
        fn valid_frames_survive_surrounding_garbage(
            pre in proptest::collection::vec(any::<u8>(), 0..100),
            counter: u32,
        ) {
            let mut link = Link::new();
            let mut tx = TxBuffer::new();
            let mut bytes = pre.clone();
            bytes.push(0); // the garbage ends at a delimiter, as any real frame does
            bytes.extend_from_slice(&frame_of(&Heartbeat { counter }, 1, Flags::NONE));
            let mut n = 0;
            link.receive(&bytes, &mut tx, |r| {
                if r == Request::Command(Command::Heartbeat) { n += 1; }
                Ok(())
            });
            prop_assert!(n >= 1);
        }
    }
}
