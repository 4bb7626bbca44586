//! The reliable-delivery core shared by both ends of the radio link and by the MCU link.
//!
//! IO-free (smoltcp / quinn-proto style): the shell feeds received bytes with
//! [`ReliableLink::receive`], calls [`ReliableLink::poll`] when [`ReliableLink::poll_at`] says so,
//! and writes whatever [`ReliableLink::transmit`] returns to the serial port. Time is host
//! monotonic microseconds, passed in; the core never reads a clock.
//!
//! What it does:
//! - **Acks and retransmits.** A reliable message is sent with [`Flags::ACK_REQUESTED`] and kept
//!   until the peer's ack (same msg id and seq, [`Flags::IS_ACK`]) arrives. The retransmit timer
//!   starts when the frame actually leaves (after rate limiting), and backs off by 1.5x per attempt
//!   up to a ceiling. Retransmissions are the same bytes (same seq), as the ICD requires.
//! - **Duplicate suppression by seq.** Received reliable frames are acked every time, but delivered
//!   to the session once: `(peer, msg id, seq)` triples are remembered for
//!   [`LinkConfig::dedup_memory_us`], longer than a sender keeps retransmitting. `peer` is the
//!   radio session id (0 on the MCU link), so two handhelds never shadow each other's commands.
//! - **Heartbeats both ways.** A [`Heartbeat`] leaves every [`LinkConfig::heartbeat_period_us`];
//!   any frame accepted from the peer counts as liveness ([`ReliableLink::peer_silent_us`]). On
//!   the radio only frames that opened in a session are handed to [`ReliableLink::accept`].
//! - **Sealing.** Frames are kept as inner frames (header and payload); [`ReliableLink::transmit`]
//!   frames them as they are (MCU link), [`ReliableLink::transmit_with`] hands each to a sealing
//!   function (radio) when it leaves, so every retransmission gets its own nonce.
//! - **Rate limit.** A token bucket at the link's byte rate (57600 baud 8N1 = 5760 bytes/s) keeps
//!   the radio modem's buffer from overflowing. Control frames (acks, heartbeats, commands,
//!   progress, results) go before bulk frames (cloud preview chunks).

use std::collections::VecDeque;

use protocol::frame::{self, Deframer, Flags, HEADER_LEN, Header, MAX_FRAME_LEN};
use protocol::{Heartbeat, Message};

/// Tuning of one link end. All times are microseconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkConfig {
    /// First retransmit timeout after a reliable frame leaves.
    pub retransmit_initial_us: u64,
    /// Ceiling of the exponential backoff.
    pub retransmit_max_us: u64,
    /// Attempts before a reliable message is given up ([`LinkEvent::GaveUp`]); results use
    /// [`Delivery::Persistent`] instead, which never gives up.
    pub max_attempts: u32,
    /// Period of the heartbeats this end sends (0 = none). The radio's 200 ms let the onboard
    /// count missed beats (`run.handheld-missed-beats`) rather than wait seconds per beat.
    pub heartbeat_period_us: u64,
    /// How long received `(msg id, seq)` pairs are remembered for duplicate suppression.
    pub dedup_memory_us: u64,
    /// Link byte rate (bytes per second, after start/stop bits).
    pub bytes_per_s: u32,
    /// Largest payload this link carries (the radio's sealed frames leave less room).
    pub max_payload_len: usize,
    /// Bytes that may leave at once (token-bucket depth).
    pub burst_bytes: u32,
}

impl LinkConfig {
    /// The 57600-baud radio: about 5760 bytes/s; a 256-byte frame takes 44 ms, so the first
    /// retransmit after 400 ms leaves room for the ack's round trip through both modems. A
    /// command is tried for about two minutes (40 attempts, the last ones 3 s apart): on a radio
    /// that loses 40 % of the frames each way a try fails two times in three.
    pub const RADIO: Self = Self {
        retransmit_initial_us: 400_000,
        retransmit_max_us: 3_000_000,
        max_attempts: 40,
        heartbeat_period_us: 200_000,
        dedup_memory_us: 60_000_000,
        bytes_per_s: 5_760,
        max_payload_len: protocol::auth::MAX_INNER_PAYLOAD_LEN,
        burst_bytes: 600,
    };

    /// The 921600-baud UART to the firmware: nearly clean, fast. The onboard's MCU session sends its
    /// own 20 ms heartbeats, so the core's are off here.
    pub const MCU: Self = Self {
        retransmit_initial_us: 50_000,
        retransmit_max_us: 200_000,
        max_attempts: 10,
        heartbeat_period_us: 0,
        dedup_memory_us: 5_000_000,
        bytes_per_s: 92_160,
        max_payload_len: frame::MAX_PAYLOAD_LEN,
        burst_bytes: 4_096,
    };
}

/// How a message is delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delivery {
    /// Sent once, no ack (heartbeats, progress, preview chunks).
    BestEffort,
    /// Acked and retransmitted up to [`LinkConfig::max_attempts`] times.
    Reliable,
    /// Acked and retransmitted until acked, however long it takes (results).
    Persistent,
}

/// Queue a frame goes out from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Priority {
    /// Acks, heartbeats, commands, progress, results.
    Control,
    /// In front of every queued frame (an abort).
    Urgent,
    /// Cloud preview chunks: only when no control frame waits.
    Bulk,
}

/// A message received and accepted (not a duplicate, not an ack).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Received {
    /// Its header.
    pub header: Header,
    /// Its postcard payload, to be decoded by the session's message set.
    pub payload: Vec<u8>,
}

impl Received {
    /// A borrowed [`frame::Frame`] view for `ToOnboard::decode` and friends.
    pub fn frame(&self) -> frame::Frame<'_> {
        frame::Frame {
            header: self.header,
            payload: &self.payload,
        }
    }
}

/// Something the session should know about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkEvent {
    /// The peer acked a reliable message.
    Acked {
        /// Its id.
        msg_id: u16,
        /// Its seq.
        seq: u16,
    },
    /// A reliable message was given up after [`LinkConfig::max_attempts`].
    GaveUp {
        /// Its id.
        msg_id: u16,
        /// Its seq.
        seq: u16,
    },
}

/// Why a message could not be queued.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SendError {
    /// The message does not encode into a frame (a protocol bound is violated).
    #[error("message {name} does not encode into a frame: {error}")]
    Encode {
        /// Message name.
        name: &'static str,
        /// Why.
        error: frame::EncodeError,
    },
}

/// Counters for logs, status and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkStats {
    /// Frames handed to the transport (first sends and retransmits).
    pub frames_sent: u64,
    /// Bytes handed to the transport.
    pub bytes_sent: u64,
    /// Retransmissions among `frames_sent`.
    pub retransmits: u64,
    /// Valid frames received.
    pub frames_received: u64,
    /// Byte runs that were not frames (bad CRC, bad COBS, oversize, short).
    pub receive_errors: u64,
    /// Reliable frames received again (acked again, not delivered).
    pub duplicates: u64,
    /// Reliable messages given up.
    pub gave_up: u64,
}

#[derive(Debug)]
struct InFlight {
    msg_id: u16,
    seq: u16,
    bytes: Vec<u8>,
    attempts: u32,
    persistent: bool,
    /// `None` while waiting in the send queue, else when to retransmit.
    due_us: Option<u64>,
    backoff_us: u64,
}

#[derive(Debug)]
enum Queued {
    /// An inner frame (header and payload).
    Frame(Vec<u8>),
    /// A reliable inner frame, by seq.
    Reliable { seq: u16 },
    /// A finished wire frame sent as it is (the radio handshake).
    Wire(Vec<u8>),
}

/// One end of a reliable link. See the module docs.
#[derive(Debug)]
pub struct ReliableLink {
    config: LinkConfig,
    deframer: Deframer<MAX_FRAME_LEN>,
    next_seq: u16,
    in_flight: Vec<InFlight>,
    control: VecDeque<Queued>,
    bulk: VecDeque<Queued>,
    seen: VecDeque<(u16, u16, u16, u64)>,
    events: VecDeque<LinkEvent>,
    tokens: f64,
    tokens_at_us: Option<u64>,
    last_rx_us: Option<u64>,
    next_heartbeat_us: u64,
    heartbeat_counter: u32,
    stats: LinkStats,
}

impl ReliableLink {
    /// A link end whose first seq is `initial_seq` (the shell picks it from the clock so that a
    /// restarted end does not reuse the seqs the peer still remembers).
    pub fn new(config: LinkConfig, initial_seq: u16) -> Self {
        Self {
            config,
            deframer: Deframer::new(),
            next_seq: initial_seq,
            in_flight: Vec::new(),
            control: VecDeque::new(),
            bulk: VecDeque::new(),
            seen: VecDeque::new(),
            events: VecDeque::new(),
            tokens: f64::from(config.burst_bytes),
            tokens_at_us: None,
            last_rx_us: None,
            next_heartbeat_us: 0,
            heartbeat_counter: 0,
            stats: LinkStats::default(),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &LinkConfig {
        &self.config
    }

    /// Counters.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    fn flags(delivery: Delivery) -> Flags {
        if delivery == Delivery::BestEffort {
            Flags::NONE
        } else {
            Flags::ACK_REQUESTED
        }
    }

    /// Queues `msg`; returns the seq it was given.
    pub fn send<M: Message>(
        &mut self,
        msg: &M,
        delivery: Delivery,
        priority: Priority,
    ) -> Result<u16, SendError> {
        let seq = self.next_seq;
        let header = Header::new(M::ID, seq, Self::flags(delivery));
        let mut buf = [0u8; MAX_FRAME_LEN];
        buf[..HEADER_LEN].copy_from_slice(&header.to_bytes());
        let len = frame::encode_payload(msg, &mut buf[HEADER_LEN..]).map_err(|error| {
            SendError::Encode {
                name: M::NAME,
                error,
            }
        })?;
        if len > self.config.max_payload_len {
            return Err(SendError::Encode {
                name: M::NAME,
                error: frame::EncodeError::PayloadTooLarge,
            });
        }
        self.next_seq = self.next_seq.wrapping_add(1);
        let bytes = buf[..HEADER_LEN + len].to_vec();
        let queued = if delivery == Delivery::BestEffort {
            Queued::Frame(bytes)
        } else {
            self.in_flight.push(InFlight {
                msg_id: M::ID,
                seq,
                bytes,
                attempts: 0,
                persistent: delivery == Delivery::Persistent,
                due_us: None,
                backoff_us: self.config.retransmit_initial_us,
            });
            Queued::Reliable { seq }
        };
        match priority {
            Priority::Control => self.control.push_back(queued),
            Priority::Urgent => self.control.push_front(queued),
            Priority::Bulk => self.bulk.push_back(queued),
        }
        Ok(seq)
    }

    /// Whether a reliable message with this seq is still waiting for its ack.
    pub fn is_in_flight(&self, seq: u16) -> bool {
        self.in_flight.iter().any(|f| f.seq == seq)
    }

    /// Reliable messages waiting for their ack.
    pub fn in_flight_count(&self) -> usize {
        self.in_flight.len()
    }

    /// Frames waiting in the bulk queue (the sender paces preview chunks with it).
    pub fn bulk_queued(&self) -> usize {
        self.bulk.len()
    }

    /// Drops a reliable message without waiting for its ack (a newer one replaces it).
    pub fn cancel(&mut self, seq: u16) {
        self.in_flight.retain(|f| f.seq != seq);
    }

    /// Feeds received bytes (plain frames: the MCU link); returns the accepted messages in
    /// order. Acks are consumed here (see [`Self::poll_event`]); reliable frames are acked,
    /// duplicates acked again and dropped.
    pub fn receive(&mut self, now_us: u64, bytes: &[u8]) -> Vec<Received> {
        let mut frames = Vec::new();
        let mut errors = 0u64;
        self.deframer.feed_all(bytes, |r| match r {
            Ok(f) => frames.push(Received {
                header: f.header,
                payload: f.payload.to_vec(),
            }),
            Err(_) => errors += 1,
        });
        self.stats.receive_errors += errors;
        frames
            .into_iter()
            .filter_map(|r| self.accept(now_us, 0, r))
            .collect()
    }

    /// Counts byte runs a radio end's own deframer could not read as frames.
    pub fn count_receive_errors(&mut self, n: u64) {
        self.stats.receive_errors += n;
    }

    /// Takes one received inner frame from `peer` (an authenticated radio session, or 0): the
    /// message to deliver, or `None` for acks and duplicates.
    pub fn accept(&mut self, now_us: u64, peer: u16, r: Received) -> Option<Received> {
        self.forget_old(now_us);
        self.stats.frames_received += 1;
        self.last_rx_us = Some(now_us);
        let h = r.header;
        if h.flags.contains(Flags::IS_ACK) {
            self.on_ack(h);
            return None;
        }
        if h.flags.contains(Flags::ACK_REQUESTED) {
            self.queue_ack(h);
            if self
                .seen
                .iter()
                .any(|&(p, id, seq, _)| p == peer && id == h.msg_id && seq == h.seq)
            {
                self.stats.duplicates += 1;
                return None;
            }
            self.seen.push_back((peer, h.msg_id, h.seq, now_us));
        }
        Some(r)
    }

    /// Queues a finished wire frame (the radio handshake) in front of the control queue; it
    /// leaves within the rate limit but is not sealed.
    pub fn send_wire(&mut self, frame: Vec<u8>) {
        self.control.push_front(Queued::Wire(frame));
    }

    fn on_ack(&mut self, h: Header) {
        if let Some(i) = self
            .in_flight
            .iter()
            .position(|f| f.seq == h.seq && f.msg_id == h.msg_id)
        {
            self.in_flight.swap_remove(i);
            self.events.push_back(LinkEvent::Acked {
                msg_id: h.msg_id,
                seq: h.seq,
            });
        }
    }

    fn queue_ack(&mut self, h: Header) {
        // Acks jump the queue: the peer's retransmit timer is running.
        self.control
            .push_front(Queued::Frame(h.ack().to_bytes().to_vec()));
    }

    fn forget_old(&mut self, now_us: u64) {
        while let Some(&(_, _, _, at)) = self.seen.front() {
            if now_us.saturating_sub(at) > self.config.dedup_memory_us || self.seen.len() > 4096 {
                self.seen.pop_front();
            } else {
                break;
            }
        }
    }

    /// Microseconds since the last valid frame from the peer (`None`: never heard).
    pub fn peer_silent_us(&self, now_us: u64) -> Option<u64> {
        self.last_rx_us.map(|t| now_us.saturating_sub(t))
    }

    /// Timers: heartbeats, retransmits, give-ups. Call at or after [`Self::poll_at`].
    pub fn poll(&mut self, now_us: u64) {
        if self.config.heartbeat_period_us > 0 && now_us >= self.next_heartbeat_us {
            self.next_heartbeat_us = now_us + self.config.heartbeat_period_us;
            let hb = Heartbeat {
                counter: self.heartbeat_counter,
            };
            self.heartbeat_counter = self.heartbeat_counter.wrapping_add(1);
            // A heartbeat is a tiny fixed message: encoding cannot fail.
            let _ = self.send(&hb, Delivery::BestEffort, Priority::Control);
        }
        let max_attempts = self.config.max_attempts;
        let mut i = 0;
        while i < self.in_flight.len() {
            let f = &mut self.in_flight[i];
            match f.due_us {
                Some(due) if now_us >= due => {
                    if !f.persistent && f.attempts >= max_attempts {
                        let (msg_id, seq) = (f.msg_id, f.seq);
                        self.in_flight.swap_remove(i);
                        self.stats.gave_up += 1;
                        self.events.push_back(LinkEvent::GaveUp { msg_id, seq });
                        continue;
                    }
                    f.due_us = None;
                    let seq = f.seq;
                    self.control.push_back(Queued::Reliable { seq });
                }
                _ => {}
            }
            i += 1;
        }
    }

    /// The next time [`Self::poll`] has work (a heartbeat or a retransmit), if any.
    pub fn poll_at(&self) -> Option<u64> {
        let hb = (self.config.heartbeat_period_us > 0).then_some(self.next_heartbeat_us);
        self.in_flight
            .iter()
            .filter_map(|f| f.due_us)
            .chain(hb)
            .min()
    }

    /// Whether frames wait for the rate limiter.
    pub fn has_pending_output(&self) -> bool {
        !self.control.is_empty() || !self.bulk.is_empty()
    }

    /// Bytes to write to the transport now, within the rate limit (possibly empty), each inner
    /// frame framed as it is.
    pub fn transmit(&mut self, now_us: u64) -> Vec<u8> {
        self.transmit_with(now_us, &mut |inner| {
            let mut header = [0u8; HEADER_LEN];
            header.copy_from_slice(inner.get(..HEADER_LEN)?);
            let mut buf = [0u8; MAX_FRAME_LEN];
            let n = frame::encode_raw(Header::from_bytes(header), &inner[HEADER_LEN..], &mut buf)
                .ok()?;
            Some(buf[..n].to_vec())
        })
    }

    /// Like [`Self::transmit`], but each inner frame goes through `wrap` (the radio session's
    /// seal) as it leaves. A frame `wrap` refuses (no session) is dropped; a reliable one stays
    /// in flight and is retransmitted later.
    pub fn transmit_with(
        &mut self,
        now_us: u64,
        wrap: &mut dyn FnMut(&[u8]) -> Option<Vec<u8>>,
    ) -> Vec<u8> {
        self.refill(now_us);
        let mut out = Vec::new();
        while self.tokens > 0.0 {
            let Some(q) = self.control.pop_front().or_else(|| self.bulk.pop_front()) else {
                break;
            };
            let bytes = match q {
                Queued::Wire(bytes) => bytes,
                Queued::Frame(inner) => match wrap(&inner) {
                    Some(b) => b,
                    None => continue,
                },
                Queued::Reliable { seq } => {
                    let Some(f) = self.in_flight.iter_mut().find(|f| f.seq == seq) else {
                        continue; // acked while queued
                    };
                    if f.attempts > 0 {
                        self.stats.retransmits += 1;
                    }
                    f.attempts += 1;
                    f.due_us = Some(now_us + f.backoff_us);
                    f.backoff_us = (f.backoff_us * 3 / 2).min(self.config.retransmit_max_us);
                    match wrap(&f.bytes) {
                        Some(b) => b,
                        None => continue,
                    }
                }
            };
            self.tokens -= bytes.len() as f64;
            self.stats.frames_sent += 1;
            self.stats.bytes_sent += bytes.len() as u64;
            out.extend_from_slice(&bytes);
        }
        out
    }

    fn refill(&mut self, now_us: u64) {
        let last = self.tokens_at_us.unwrap_or(now_us);
        let dt_s = now_us.saturating_sub(last) as f64 * 1e-6;
        self.tokens = (self.tokens + dt_s * f64::from(self.config.bytes_per_s))
            .min(f64::from(self.config.burst_bytes));
        self.tokens_at_us = Some(now_us);
    }

    /// The next event (acks of reliable messages, give-ups), oldest first.
    pub fn poll_event(&mut self) -> Option<LinkEvent> {
        self.events.pop_front()
    }
}

#[cfg(test)]
mod tests {
    use protocol::radio::{Abort, ToOnboard};

    use super::*;
    use crate::sim::{LossyPipe, PipeConfig};

    fn decode_aborts(rx: &[Received]) -> Vec<u32> {
        rx.iter()
            .filter_map(|r| match ToOnboard::decode(&r.frame()) {
                Ok(ToOnboard::Abort(a)) => Some(a.run_id),
                _ => None,
            })
            .collect()
    }

    /// Drives two ends over a pipe pair for `duration_us`, returning what `b` delivered.
    fn run_pair(
        a: &mut ReliableLink,
        b: &mut ReliableLink,
        ab: &mut LossyPipe,
        ba: &mut LossyPipe,
        duration_us: u64,
    ) -> Vec<Received> {
        let mut got = Vec::new();
        let mut now = 0;
        while now < duration_us {
            a.poll(now);
            b.poll(now);
            ab.push(now, &a.transmit(now));
            ba.push(now, &b.transmit(now));
            got.extend(b.receive(now, &ab.pop(now)));
            a.receive(now, &ba.pop(now));
            now += 5_000;
        }
        got
    }

    #[test]
    fn reliable_messages_arrive_once_in_spite_of_loss_and_corruption() {
        let mut a = ReliableLink::new(LinkConfig::RADIO, 100);
        let mut b = ReliableLink::new(LinkConfig::RADIO, 900);
        let lossy = PipeConfig::radio_lossy(0.2, 0.2);
        let mut ab = LossyPipe::new(lossy, 1);
        let mut ba = LossyPipe::new(lossy, 2);
        for run_id in 0..40 {
            a.send(&Abort { run_id }, Delivery::Reliable, Priority::Control)
                .unwrap();
        }
        let got = run_pair(&mut a, &mut b, &mut ab, &mut ba, 30_000_000);
        let mut ids = decode_aborts(&got);
        ids.sort_unstable();
        assert_eq!(ids, (0..40).collect::<Vec<_>>(), "each exactly once");
        assert_eq!(a.in_flight_count(), 0, "every message acked");
        assert!(
            a.stats().retransmits > 0,
            "the loss made retransmits necessary"
        );
        assert!(
            b.stats().receive_errors > 0,
            "corruption was seen and dropped"
        );
        assert_eq!(a.stats().gave_up, 0);
    }

    #[test]
    fn duplicates_are_acked_but_delivered_once() {
        let mut a = ReliableLink::new(LinkConfig::RADIO, 7);
        let mut b = ReliableLink::new(LinkConfig::RADIO, 0);
        a.send(&Abort { run_id: 3 }, Delivery::Reliable, Priority::Control)
            .unwrap();
        let bytes = a.transmit(0);
        assert_eq!(decode_aborts(&b.receive(0, &bytes)), vec![3]);
        assert!(
            b.receive(10, &bytes).is_empty(),
            "retransmission not delivered again"
        );
        assert_eq!(b.stats().duplicates, 1);
        // Both receptions were acked: two ack frames queued.
        let acks = b.transmit(20);
        let mut d = Deframer::<MAX_FRAME_LEN>::new();
        let mut n = 0;
        d.feed_all(&acks, |f| {
            assert!(f.unwrap().header.flags.contains(Flags::IS_ACK));
            n += 1;
        });
        assert_eq!(n, 2);
        a.receive(30, &acks);
        assert_eq!(
            a.poll_event(),
            Some(LinkEvent::Acked {
                msg_id: protocol::ids::ABORT,
                seq: 7
            })
        );
        assert_eq!(a.in_flight_count(), 0);
    }

    #[test]
    fn gives_up_after_max_attempts_with_backoff() {
        let mut a = ReliableLink::new(LinkConfig::RADIO, 0);
        a.send(&Abort { run_id: 1 }, Delivery::Reliable, Priority::Control)
            .unwrap();
        let mut sends = Vec::new();
        let mut now = 0;
        while a.in_flight_count() > 0 && now < 120_000_000 {
            a.poll(now);
            let out = a.transmit(now);
            // Heartbeats go out too; count only frames of the Abort (longer than a heartbeat).
            let mut d = Deframer::<MAX_FRAME_LEN>::new();
            d.feed_all(&out, |f| {
                if f.unwrap().header.msg_id == protocol::ids::ABORT {
                    sends.push(now);
                }
            });
            now += 1_000;
        }
        assert_eq!(sends.len(), LinkConfig::RADIO.max_attempts as usize);
        let gaps: Vec<u64> = sends.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(
            gaps.windows(2).all(|g| g[1] >= g[0]),
            "backoff grows: {gaps:?}"
        );
        assert!(*gaps.last().unwrap() <= LinkConfig::RADIO.retransmit_max_us + 1_000);
        assert_eq!(
            a.poll_event(),
            Some(LinkEvent::GaveUp {
                msg_id: protocol::ids::ABORT,
                seq: 0
            })
        );
    }

    #[test]
    fn persistent_messages_never_give_up() {
        let mut a = ReliableLink::new(LinkConfig::RADIO, 0);
        a.send(
            &Abort { run_id: 1 },
            Delivery::Persistent,
            Priority::Control,
        )
        .unwrap();
        for now in (0..200_000_000).step_by(10_000) {
            a.poll(now);
            a.transmit(now);
        }
        assert_eq!(a.in_flight_count(), 1);
        assert_eq!(a.stats().gave_up, 0);
    }

    #[test]
    fn rate_limit_holds_the_byte_rate() {
        let mut a = ReliableLink::new(LinkConfig::RADIO, 0);
        for run_id in 0..2_000 {
            a.send(&Abort { run_id }, Delivery::BestEffort, Priority::Bulk)
                .unwrap();
        }
        let mut bytes = 0usize;
        for now in (0..2_000_000).step_by(10_000) {
            bytes += a.transmit(now).len();
        }
        // 2 s at 5760 B/s plus the initial burst, plus at most one frame of overshoot.
        let limit = 2 * 5_760 + 600 + MAX_FRAME_LEN;
        assert!(bytes <= limit, "{bytes} > {limit}");
        assert!(bytes >= 2 * 5_760 - MAX_FRAME_LEN, "{bytes} too few");
    }

    #[test]
    fn control_frames_overtake_bulk() {
        let mut a = ReliableLink::new(LinkConfig::RADIO, 0);
        for run_id in 0..100 {
            a.send(&Abort { run_id }, Delivery::BestEffort, Priority::Bulk)
                .unwrap();
        }
        a.transmit(0);
        a.send(
            &Abort { run_id: 999 },
            Delivery::Reliable,
            Priority::Control,
        )
        .unwrap();
        let out = a.transmit(20_000);
        let mut b = ReliableLink::new(LinkConfig::RADIO, 0);
        assert_eq!(decode_aborts(&b.receive(0, &out)).first(), Some(&999));
    }

    #[test]
    fn heartbeats_keep_the_peer_alive() {
        let mut a = ReliableLink::new(LinkConfig::RADIO, 0);
        let mut b = ReliableLink::new(LinkConfig::RADIO, 0);
        assert_eq!(b.peer_silent_us(0), None);
        for now in (0..3_000_000).step_by(10_000) {
            a.poll(now);
            b.receive(now, &a.transmit(now));
            assert!(now < 10_000 || b.peer_silent_us(now).unwrap() <= 200_000);
        }
        // The last heartbeat left at 2.8 s.
        assert_eq!(b.peer_silent_us(5_000_000), Some(2_200_000));
    }
}
