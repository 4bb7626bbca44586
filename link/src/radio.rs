//! The onboard end of the radio link: opens the handheld's sealed frames, turns them into
//! [`RadioRequest`]s for the run state machine, answers what it can itself (handshakes, preview
//! resends), and holds results until the handheld acknowledges them.
//!
//! - Only frames that open in a session of a paired key ([`SessionTable`]) reach the link core:
//!   everything else (plain frames of any message, forged or replayed sealed frames, inits for
//!   unknown keys) is dropped and counted in [`RadioStats`]; it changes no state and does not
//!   count as liveness. Handshake replies and version announcements are rate limited.
//! - Replies are sealed for the session the handheld last spoke in, so each handheld hears the
//!   answers to its own commands; any paired handheld may abort.
//! - A result goes out with [`Delivery::Persistent`] (retransmitted until the link acks it) and
//!   stays in [`OnboardRadio::pending_results`] until the handheld's [`ResultAck`](protocol::radio::ResultAck), which comes
//!   after the handheld has the whole preview.
//! - Preview chunks are best effort and paced through the bulk queue; [`ResendChunks`](protocol::radio::ResendChunks) puts the
//!   wanted ones back in front. The run's record files follow the preview the same way as
//!   [`RecordChunk`]s, resent on [`ResendRecordChunks`](protocol::radio::ResendRecordChunks).
//! - Per-session rate limit: commands beyond [`COMMANDS_PER_S`] (burst [`COMMAND_BURST`]) are
//!   dropped unacked (the sender retries); aborts and acks are never limited.

use std::collections::VecDeque;

use protocol::auth::Key;
use protocol::bounded::List;
use protocol::common::{Hello, LogLevel, LogLine, Role};
use protocol::frame::{Deframer, Header, MAX_FRAME_LEN};
use protocol::message::{self, DecodeError};
use protocol::radio::{
    CloudChunk, HandshakeInit, LAB_CHUNK_LEN, LabChunk, LabRef, MAX_LAB_LEN, MeasurementResult,
    Progress, RecordChunk, RecordFile, RefuseReason, Refused, RobotStatus, StartMeasurement,
    ToOnboard, lab_chunk_count,
};
use protocol::{Message, bounded::Text, ids};

use super::chunks::ChunkSet;
use super::preview;
use super::record_files::{self, OutgoingRecord};
use super::reliable::{Delivery, LinkConfig, Priority, Received, ReliableLink, SendError};
use super::session::{Entropy, InitOutcome, SessionError, SessionTable};

/// Commands per second one session may send (beyond the burst).
pub const COMMANDS_PER_S: f64 = 10.0;
/// Commands one session may send at once.
pub const COMMAND_BURST: f64 = 20.0;
/// Handshake replies and version announcements per second, all senders together.
const REPLIES_PER_S: f64 = 4.0;

/// Chunks kept in the link's bulk queue at a time: enough to keep the line busy, few enough that a
/// resend request or a progress message is not stuck behind a long queue.
const BULK_DEPTH: usize = 4;

/// What the handheld asked for, after authentication and decoding.
#[derive(Debug, Clone, PartialEq)]
pub enum RadioRequest {
    /// A start from a paired handheld: act or refuse (busy, interlocked, bad parameter) with
    /// [`OnboardRadio::refuse`].
    Start {
        /// The command.
        params: StartMeasurement,
        /// The lab file the start names ([`StartMeasurement::lab`]): `None` when it names none,
        /// `Err` (what is wrong, for the refusal) when its chunks did not all arrive in this
        /// session or do not add up to its length.
        lab: Option<Result<Vec<u8>, String>>,
        /// Its seq (for a refusal).
        seq: u16,
        /// Id of the pairing key of the session it came in.
        key_id: u32,
    },
    /// Abort: stop first.
    Abort {
        /// The run (0: whatever runs).
        run_id: u32,
    },
    /// The handheld has the result and preview of this run.
    ResultAck {
        /// The run.
        run_id: u32,
    },
    /// Send an earlier run again ([`OnboardRadio::deliver`], or refuse with `UnknownRun`).
    Fetch {
        /// The run.
        run_id: u32,
        /// Its seq (for a refusal).
        seq: u16,
    },
    /// Answer with [`OnboardRadio::send_status`].
    Status,
    /// A message inside a session did not decode (refused to the handheld): log it.
    Refused {
        /// Why.
        reason: RefuseReason,
        /// What, for the log.
        detail: String,
    },
}

/// Counters of what the radio end dropped or did, for logs, status and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RadioStats {
    /// Valid-CRC frames outside any session (plain messages of any kind): dropped.
    pub unauthenticated: u64,
    /// Sealed frames that did not open (unknown session, bad tag, replayed nonce): dropped.
    pub unopened: u64,
    /// Handshake inits refused (unknown key, bad Noise message, late copies).
    pub inits_refused: u64,
    /// Sessions opened.
    pub sessions_opened: u64,
    /// Commands dropped by the per-session rate limit.
    pub rate_limited: u64,
    /// Handshake replies or version announcements not sent (reply rate limit).
    pub replies_suppressed: u64,
}

#[derive(Debug, Clone, Copy)]
struct Bucket {
    tokens: f64,
    at_us: u64,
}

impl Bucket {
    fn new(burst: f64, now_us: u64) -> Self {
        Self {
            tokens: burst,
            at_us: now_us,
        }
    }

    fn take(&mut self, now_us: u64, rate: f64, burst: f64) -> bool {
        let dt = now_us.saturating_sub(self.at_us) as f64 * 1e-6;
        self.tokens = (self.tokens + dt * rate).min(burst);
        self.at_us = now_us;
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

#[derive(Debug)]
struct Pending {
    result: MeasurementResult,
    result_seq: u16,
    chunks: Vec<CloudChunk>,
    to_send: VecDeque<u16>,
    records: Vec<PendingRecord>,
}

#[derive(Debug)]
struct PendingRecord {
    file: RecordFile,
    chunks: Vec<RecordChunk>,
    to_send: VecDeque<u16>,
}

/// Puts the wanted chunk indices (those that exist and are not queued) back in front.
fn requeue(to_send: &mut VecDeque<u16>, wanted: &[u16], len: usize) {
    for &i in wanted.iter().rev() {
        if usize::from(i) < len && !to_send.contains(&i) {
            to_send.push_front(i);
        }
    }
}

/// The onboard end of the radio link. See the module docs.
#[derive(Debug)]
pub struct OnboardRadio {
    link: ReliableLink,
    deframer: Deframer<MAX_FRAME_LEN>,
    sessions: SessionTable,
    /// The session the handheld last spoke in: replies are sealed for it.
    active: Option<u16>,
    pending: Vec<Pending>,
    refused: u64,
    stats: RadioStats,
    replies: Bucket,
    limits: Vec<(u16, Bucket)>,
    /// The lab file being sent ahead of a start (one at a time: a chunk of another upload or
    /// session starts over; bounded by [`MAX_LAB_LEN`]).
    lab: Option<LabUpload>,
}

/// A lab file's chunks as they arrive.
#[derive(Debug)]
struct LabUpload {
    session: u16,
    upload: u16,
    chunks: ChunkSet<u8>,
}

impl OnboardRadio {
    /// A radio end for the paired `keys`; `entropy` seeds the handshakes.
    pub fn new(link: LinkConfig, keys: Vec<Key>, entropy: Entropy, initial_seq: u16) -> Self {
        Self {
            link: ReliableLink::new(link, initial_seq),
            deframer: Deframer::new(),
            sessions: SessionTable::new(keys, entropy),
            active: None,
            pending: Vec::new(),
            refused: 0,
            stats: RadioStats::default(),
            replies: Bucket::new(REPLIES_PER_S, 0),
            limits: Vec::new(),
            lab: None,
        }
    }

    /// The link core (stats, liveness).
    pub fn link(&self) -> &ReliableLink {
        &self.link
    }

    /// What was dropped, refused or opened so far.
    pub fn stats(&self) -> RadioStats {
        self.stats
    }

    /// Sessions held (confirmed or not).
    pub fn session_count(&self) -> usize {
        self.sessions.len()
    }

    /// Commands refused inside sessions (undecodable) so far.
    pub fn refused_count(&self) -> u64 {
        self.refused
    }

    /// Microseconds since the handheld was last heard in a session (`None`: never).
    pub fn handheld_silent_us(&self, now_us: u64) -> Option<u64> {
        self.link.peer_silent_us(now_us)
    }

    /// Feeds bytes from the radio; returns the requests in order.
    pub fn receive(&mut self, now_us: u64, bytes: &[u8]) -> Vec<RadioRequest> {
        let mut frames = Vec::new();
        let mut errors = 0u64;
        self.deframer.feed_all(bytes, |r| match r {
            Ok(f) => frames.push((f.header, f.payload.to_vec())),
            Err(_) => errors += 1,
        });
        self.link.count_receive_errors(errors);
        let mut out = Vec::new();
        for (header, payload) in frames {
            self.on_frame(now_us, header, &payload, &mut out);
        }
        out
    }

    fn on_frame(
        &mut self,
        now_us: u64,
        header: Header,
        payload: &[u8],
        out: &mut Vec<RadioRequest>,
    ) {
        if header.version != protocol::PROTOCOL_VERSION {
            // Tell a handheld of another version which one this robot speaks (rate limited).
            self.stats.unauthenticated += 1;
            self.send_hello(now_us);
            return;
        }
        match header.msg_id {
            ids::SEALED => {
                let session = header.seq;
                match self.sessions.open(now_us, session, payload) {
                    Ok((inner, inner_payload)) => {
                        self.active = Some(session);
                        // Over the session's rate: dropped before the link core, so unacked
                        // (the sender retries later).
                        let limited = !inner.flags.contains(protocol::frame::Flags::IS_ACK)
                            && !matches!(
                                inner.msg_id,
                                ids::ABORT | ids::HEARTBEAT | ids::RESULT_ACK
                            );
                        if limited && !self.allow(now_us, session) {
                            self.stats.rate_limited += 1;
                            return;
                        }
                        let r = Received {
                            header: inner,
                            payload: inner_payload,
                        };
                        if let Some(r) = self.link.accept(now_us, session, r) {
                            self.on_inner(session, &r, out);
                        }
                    }
                    Err(_) => self.stats.unopened += 1,
                }
            }
            ids::HANDSHAKE_INIT => {
                let frame = protocol::frame::Frame { header, payload };
                let outcome = message::decode::<HandshakeInit>(&frame)
                    .map_err(|_| SessionError::Size)
                    .and_then(|init| self.sessions.on_init(&init));
                match outcome {
                    Ok(InitOutcome::New { reply, .. }) => {
                        self.stats.sessions_opened += 1;
                        self.send_reply(now_us, reply);
                    }
                    Ok(InitOutcome::Repeat { reply }) => self.send_reply(now_us, reply),
                    Err(_) => self.stats.inits_refused += 1,
                }
            }
            _ => self.stats.unauthenticated += 1,
        }
    }

    fn send_reply(&mut self, now_us: u64, reply: Vec<u8>) {
        if self.replies.take(now_us, REPLIES_PER_S, REPLIES_PER_S) {
            self.link.send_wire(reply);
        } else {
            self.stats.replies_suppressed += 1;
        }
    }

    fn on_inner(&mut self, session: u16, r: &Received, out: &mut Vec<RadioRequest>) {
        let header = r.header;
        match ToOnboard::decode(&r.frame()) {
            Ok(msg) => self.on_message(header, session, msg, out),
            Err(DecodeError::IsAck) => {}
            Err(e) => {
                self.refuse_into(header, RefuseReason::Malformed, &e.to_string(), out);
            }
        }
    }

    fn allow(&mut self, now_us: u64, session: u16) -> bool {
        if let Some((_, b)) = self.limits.iter_mut().find(|(s, _)| *s == session) {
            return b.take(now_us, COMMANDS_PER_S, COMMAND_BURST);
        }
        // One bucket per session held; buckets of sessions gone are dropped.
        let sessions = &self.sessions;
        self.limits.retain(|(s, _)| sessions.key_of(*s).is_some());
        let mut b = Bucket::new(COMMAND_BURST, now_us);
        let ok = b.take(now_us, COMMANDS_PER_S, COMMAND_BURST);
        self.limits.push((session, b));
        ok
    }

    fn on_message(
        &mut self,
        header: Header,
        session: u16,
        msg: ToOnboard,
        out: &mut Vec<RadioRequest>,
    ) {
        match msg {
            ToOnboard::Hello(_) | ToOnboard::Heartbeat(_) => {}
            ToOnboard::Start(params) => out.push(RadioRequest::Start {
                lab: self.take_lab(session, params.lab),
                params,
                seq: header.seq,
                key_id: self.sessions.key_of(session).unwrap_or(0),
            }),
            ToOnboard::LabChunk(c) => self.on_lab_chunk(session, &c),
            ToOnboard::Abort(a) => out.push(RadioRequest::Abort { run_id: a.run_id }),
            ToOnboard::ResultAck(a) => {
                if let Some(i) = self
                    .pending
                    .iter()
                    .position(|p| p.result.run_id == a.run_id)
                {
                    let p = self.pending.remove(i);
                    self.link.cancel(p.result_seq);
                }
                out.push(RadioRequest::ResultAck { run_id: a.run_id });
            }
            ToOnboard::ResendChunks(r) => {
                if let Some(p) = self
                    .pending
                    .iter_mut()
                    .find(|p| p.result.run_id == r.run_id)
                {
                    requeue(&mut p.to_send, r.indices.as_slice(), p.chunks.len());
                }
            }
            ToOnboard::ResendRecordChunks(r) => {
                if let Some(f) = self
                    .pending
                    .iter_mut()
                    .filter(|p| p.result.run_id == r.run_id)
                    .flat_map(|p| p.records.iter_mut())
                    .find(|f| f.file == r.file)
                {
                    requeue(&mut f.to_send, r.indices.as_slice(), f.chunks.len());
                }
            }
            ToOnboard::StatusRequest(_) => out.push(RadioRequest::Status),
            ToOnboard::FetchRun(f) => out.push(RadioRequest::Fetch {
                run_id: f.run_id,
                seq: header.seq,
            }),
        }
    }

    /// Keeps a lab chunk: one whose count is out of range, or whose bytes do not fit its place
    /// (every chunk but the last is full), is dropped; the start then finds the file incomplete.
    fn on_lab_chunk(&mut self, session: u16, c: &LabChunk) {
        let count = u16::from(c.count);
        let full = usize::from(c.index) + 1 < usize::from(c.count);
        if count == 0
            || count > lab_chunk_count(MAX_LAB_LEN)
            || (full && c.bytes.as_slice().len() != LAB_CHUNK_LEN)
        {
            return;
        }
        let same = self.lab.as_ref().is_some_and(|l| {
            l.session == session && l.upload == c.upload && l.chunks.count() == count
        });
        if !same {
            self.lab = Some(LabUpload {
                session,
                upload: c.upload,
                chunks: ChunkSet::new(count),
            });
        }
        if let Some(l) = &mut self.lab {
            l.chunks.insert(u16::from(c.index), c.bytes.as_slice());
        }
    }

    /// The lab file a start names, taken from what arrived in its session.
    fn take_lab(&mut self, session: u16, lab: LabRef) -> Option<Result<Vec<u8>, String>> {
        if lab.len == 0 {
            return None;
        }
        let expected = lab_chunk_count(lab.len);
        Some(
            match self
                .lab
                .take_if(|l| l.session == session && l.upload == lab.upload)
            {
                None => Err(format!("lab file: none of its {expected} chunks arrived")),
                Some(l) if l.chunks.count() != expected || !l.chunks.is_complete() => Err(format!(
                    "lab file: {} of its {expected} chunks arrived",
                    l.chunks.received()
                )),
                Some(l) => {
                    let bytes = l.chunks.joined();
                    if bytes.len() == usize::from(lab.len) {
                        Ok(bytes)
                    } else {
                        Err(format!(
                            "lab file: {} bytes arrived, the start names {}",
                            bytes.len(),
                            lab.len
                        ))
                    }
                }
            },
        )
    }

    fn send_hello(&mut self, now_us: u64) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        // Hello is two bytes: encoding cannot fail.
        if let Ok(n) =
            Hello::new(Role::Onboard).encode_frame(0, protocol::frame::Flags::NONE, &mut buf)
        {
            self.send_reply(now_us, buf[..n].to_vec());
        }
    }

    fn refuse_into(
        &mut self,
        header: Header,
        reason: RefuseReason,
        detail: &str,
        out: &mut Vec<RadioRequest>,
    ) {
        self.refused += 1;
        self.refuse(header.msg_id, header.seq, reason, detail);
        out.push(RadioRequest::Refused {
            reason,
            detail: format!(
                "message {:#06x} seq {}: {detail}",
                header.msg_id, header.seq
            ),
        });
    }

    /// Refuses the command `msg_id`/`seq` (reliable).
    pub fn refuse(&mut self, msg_id: u16, seq: u16, reason: RefuseReason, detail: &str) {
        let refused = Refused {
            msg_id,
            seq,
            reason,
            detail: Text::truncated(detail),
        };
        // Bounded text: encoding cannot fail.
        let _ = self
            .link
            .send(&refused, Delivery::Reliable, Priority::Control);
    }

    /// Sends progress (best effort: the next one replaces a lost one).
    pub fn send_progress(&mut self, progress: &Progress) -> Result<(), SendError> {
        self.link
            .send(progress, Delivery::BestEffort, Priority::Control)
            .map(drop)
    }

    /// Sends the robot status (reliable: it answers a request).
    pub fn send_status(&mut self, status: &RobotStatus) -> Result<(), SendError> {
        self.link
            .send(status, Delivery::Reliable, Priority::Control)
            .map(drop)
    }

    /// Forwards a log line (best effort, cut to the protocol's 160 bytes).
    pub fn send_log(&mut self, level: LogLevel, text: &str) {
        let line = LogLine {
            level,
            text: Text::truncated(text),
        };
        let _ = self
            .link
            .send(&line, Delivery::BestEffort, Priority::Control);
    }

    /// Offers a result and its preview without record files (see [`Self::deliver_with_records`]).
    pub fn deliver(
        &mut self,
        result: MeasurementResult,
        preview_mm: &[[i16; 3]],
    ) -> Result<(), SendError> {
        self.deliver_with_records(result, preview_mm, &[])
    }

    /// Offers a result, its preview and the run's record files (sent byte-exact after the
    /// preview); held until the handheld's [`RadioRequest::ResultAck`], which comes once it has
    /// all of them. `result.preview_chunks` and `result.records` are set here; a file longer than
    /// [`protocol::radio::MAX_RECORD_LEN`] is announced with its length and not sent. Offering a
    /// run again (a fetch) replaces the earlier offer.
    pub fn deliver_with_records(
        &mut self,
        mut result: MeasurementResult,
        preview_mm: &[[i16; 3]],
        records: &[OutgoingRecord],
    ) -> Result<(), SendError> {
        let chunks = preview::chunks(result.run_id, preview_mm);
        result.preview_chunks = chunks.len() as u16;
        let infos: Vec<_> = records
            .iter()
            .take(protocol::radio::MAX_RECORD_FILES)
            .map(OutgoingRecord::info)
            .collect();
        // At most MAX_RECORD_FILES: always fits.
        result.records = List::from_slice(&infos).unwrap_or_default();
        let records: Vec<PendingRecord> = records
            .iter()
            .take(protocol::radio::MAX_RECORD_FILES)
            .map(|r| {
                let chunks = record_files::chunks(result.run_id, r);
                PendingRecord {
                    file: r.file,
                    to_send: (0..chunks.len() as u16).collect(),
                    chunks,
                }
            })
            .collect();
        if let Some(i) = self
            .pending
            .iter()
            .position(|p| p.result.run_id == result.run_id)
        {
            let old = self.pending.remove(i);
            self.link.cancel(old.result_seq);
        }
        let result_seq = self
            .link
            .send(&result, Delivery::Persistent, Priority::Control)?;
        self.pending.push(Pending {
            result,
            result_seq,
            to_send: (0..chunks.len() as u16).collect(),
            chunks,
            records,
        });
        Ok(())
    }

    /// Results not yet acknowledged by the handheld.
    pub fn pending_results(&self) -> u16 {
        self.pending.len().min(usize::from(u16::MAX)) as u16
    }

    /// Timers and preview pacing. Call often (at least at [`Self::poll_at`]).
    pub fn poll(&mut self, now_us: u64) {
        self.link.poll(now_us);
        for p in &mut self.pending {
            while self.link.bulk_queued() < BULK_DEPTH {
                let Some(i) = p.to_send.pop_front() else {
                    break;
                };
                if let Some(chunk) = p.chunks.get(usize::from(i)) {
                    let _ = self.link.send(chunk, Delivery::BestEffort, Priority::Bulk);
                }
            }
            // The record files after the preview, one file after the other.
            for f in &mut p.records {
                while self.link.bulk_queued() < BULK_DEPTH {
                    let Some(i) = f.to_send.pop_front() else {
                        break;
                    };
                    if let Some(chunk) = f.chunks.get(usize::from(i)) {
                        let _ = self.link.send(chunk, Delivery::BestEffort, Priority::Bulk);
                    }
                }
            }
        }
    }

    /// The next time [`Self::poll`] has timer work.
    pub fn poll_at(&self) -> Option<u64> {
        self.link.poll_at()
    }

    /// Bytes to write to the radio now: handshake replies as they are, everything else sealed
    /// for the session the handheld last spoke in (dropped while there is none).
    pub fn transmit(&mut self, now_us: u64) -> Vec<u8> {
        let sessions = &mut self.sessions;
        let active = self.active;
        self.link
            .transmit_with(now_us, &mut |inner| sessions.seal(active?, inner))
    }

    /// Whether bytes wait for the rate limiter or preview chunks wait to be queued.
    pub fn has_pending_output(&self) -> bool {
        self.link.has_pending_output()
            || self
                .pending
                .iter()
                .any(|p| !p.to_send.is_empty() || p.records.iter().any(|f| !f.to_send.is_empty()))
    }
}

/// Message id of the start command, for refusals.
pub const START_ID: u16 = <StartMeasurement as Message>::ID;
