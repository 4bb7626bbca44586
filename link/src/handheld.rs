//! The handheld end of the radio link (used by `passangle measure/status/abort/fetch`).
//!
//! [`HandheldRadio::connect`] opens a session: the [`HandshakeInit`](protocol::radio::HandshakeInit) is sent again (with backoff)
//! until the onboard's reply arrives, so any one init and reply that get through connect. From
//! then on every frame both ways is sealed in the session; frames that do not open in it (plain
//! frames, forged or replayed sealed frames) are dropped and counted, never reported.
//!
//! Commands are reliable. Results are reassembled with their preview: once the result has arrived, chunks
//! still missing after a quiet spell ([`HandheldConfig::resend_quiet_us`]) are asked for again with
//! [`ResendChunks`] (32 at a time). The record files the result names (`result.json`,
//! `result.json.sig`) are reassembled byte-exact the same way, missing chunks asked for with
//! [`ResendRecordChunks`]. When the preview and every file are complete the handheld sends
//! [`ResultAck`] and reports [`HandheldEvent::Complete`]. A result that arrives again after that
//! is acked again.

use std::collections::BTreeMap;

use protocol::auth::Key;
use protocol::bounded::List;
use protocol::common::{Hello, LogLine};
use protocol::frame::{Deframer, Frame, Header, MAX_FRAME_LEN};
use protocol::ids;
use protocol::message::{self, DecodeError};
use protocol::radio::{
    Abort, FetchRun, HandshakeReply, LAB_CHUNK_LEN, LabChunk, LabRef, MAX_LAB_LEN,
    MeasurementResult, Progress, Refused, ResendChunks, ResendRecordChunks, ResultAck, RobotStatus,
    StartMeasurement, StatusRequest, ToHandheld,
};

use super::preview::Assembler;
use super::record_files::{self, ReceivedRecord, RecordError};
use super::reliable::{
    Delivery, LinkConfig, LinkEvent, Priority, Received, ReliableLink, SendError,
};
use super::session::{Entropy, Initiator, Session, SessionError};

/// Tuning of the handheld session.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandheldConfig {
    /// The link core.
    pub link: LinkConfig,
    /// Quiet time (no new chunk) after which missing chunks are asked for again.
    pub resend_quiet_us: u64,
    /// First interval between handshake inits while no reply came (grows 1.5x per try).
    pub init_retry_us: u64,
    /// Ceiling of the init interval.
    pub init_retry_max_us: u64,
}

impl Default for HandheldConfig {
    fn default() -> Self {
        Self {
            link: LinkConfig::RADIO,
            resend_quiet_us: 700_000,
            init_retry_us: 300_000,
            init_retry_max_us: 1_000_000,
        }
    }
}

/// What the operator should see.
#[derive(Debug, Clone, PartialEq)]
pub enum HandheldEvent {
    /// The session is open (the onboard answered the handshake).
    Connected {
        /// Its id.
        session: u16,
    },
    /// The onboard speaks another protocol version (its unauthenticated announcement).
    Version(Hello),
    /// Run progress.
    Progress(Progress),
    /// A result arrived (the preview follows).
    Result(MeasurementResult),
    /// A result, its whole preview and its record files, acknowledged to the onboard.
    Complete {
        /// The result.
        result: MeasurementResult,
        /// The preview, millimetres, vehicle frame.
        preview_mm: Vec<[i16; 3]>,
        /// The record files the result named, in its order: byte-exact, or why not.
        records: Vec<ReceivedRecord>,
    },
    /// Robot status.
    Status(RobotStatus),
    /// A command was refused.
    Refused(Refused),
    /// A log line from the robot.
    Log(LogLine),
    /// The onboard acked a command.
    Acked {
        /// Message id.
        msg_id: u16,
        /// Its seq.
        seq: u16,
    },
    /// A command was never acked (the robot is out of range or off).
    Lost {
        /// Message id.
        msg_id: u16,
        /// Its seq.
        seq: u16,
    },
    /// A frame from the robot did not decode (e.g. another protocol version).
    Undecodable(String),
}

#[derive(Debug)]
struct Incoming {
    result: MeasurementResult,
    preview: Assembler,
    records: Vec<Result<record_files::Assembler, RecordError>>,
    last_chunk_us: u64,
    complete: bool,
}

impl Incoming {
    fn new(result: &MeasurementResult, now_us: u64) -> Self {
        Self {
            result: result.clone(),
            preview: Assembler::new(result.run_id, result.preview_chunks),
            records: result
                .records
                .as_slice()
                .iter()
                .map(|info| record_files::Assembler::new(result.run_id, *info))
                .collect(),
            last_chunk_us: now_us,
            complete: false,
        }
    }

    /// Whether the preview and every file that can come are complete.
    fn is_complete(&self) -> bool {
        self.preview.is_complete()
            && self.records.iter().all(|r| {
                r.as_ref()
                    .map_or(true, record_files::Assembler::is_complete)
            })
    }

    /// Chunks received and expected, preview and files together.
    fn progress(&self) -> (usize, usize) {
        let total = usize::from(self.result.preview_chunks);
        let mut got = total - self.preview.missing().len().min(total);
        let mut all = total;
        for a in self.records.iter().flatten() {
            got += a.received();
            all += usize::from(a.count());
        }
        (got, all)
    }
}

/// Counters of frames the handheld dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct HandheldStats {
    /// Valid-CRC frames outside the session: dropped.
    pub unauthenticated: u64,
    /// Sealed frames that did not open (other session, bad tag, replayed nonce): dropped.
    pub unopened: u64,
    /// Handshake inits sent (first and repeats).
    pub inits_sent: u64,
}

/// The handheld end of the radio link. See the module docs.
#[derive(Debug)]
pub struct HandheldRadio {
    config: HandheldConfig,
    link: ReliableLink,
    deframer: Deframer<MAX_FRAME_LEN>,
    key: Key,
    entropy: Entropy,
    initiator: Option<Initiator>,
    next_init_us: u64,
    init_interval_us: u64,
    session: Option<Session>,
    wire_out: Vec<u8>,
    stats: HandheldStats,
    incoming: BTreeMap<u32, Incoming>,
}

impl HandheldRadio {
    /// A radio end with the pairing key; `entropy` seeds the handshake.
    pub fn new(config: HandheldConfig, key: Key, entropy: Entropy, initial_seq: u16) -> Self {
        Self {
            config,
            link: ReliableLink::new(config.link, initial_seq),
            deframer: Deframer::new(),
            key,
            entropy,
            initiator: None,
            next_init_us: 0,
            init_interval_us: config.init_retry_us,
            session: None,
            wire_out: Vec::new(),
            stats: HandheldStats::default(),
            incoming: BTreeMap::new(),
        }
    }

    /// Dropped-frame counters.
    pub fn stats(&self) -> HandheldStats {
        self.stats
    }

    /// The open session's id, if any.
    pub fn session_id(&self) -> Option<u16> {
        self.session.as_ref().map(Session::id)
    }

    /// The link core (stats, liveness).
    pub fn link(&self) -> &ReliableLink {
        &self.link
    }

    /// Starts the handshake (a new session; the init leaves at the next [`Self::poll`]).
    pub fn connect(&mut self, now_us: u64) -> Result<(), SessionError> {
        self.initiator = Some(Initiator::new(&self.key, &mut self.entropy)?);
        self.next_init_us = now_us;
        self.init_interval_us = self.config.init_retry_us;
        Ok(())
    }

    /// Whether the session is open.
    pub fn is_connected(&self) -> bool {
        self.session.is_some()
    }

    /// Sends the start. Returns the seq.
    pub fn start(&mut self, params: &StartMeasurement) -> Result<u16, SendError> {
        self.link
            .send(params, Delivery::Reliable, Priority::Control)
    }

    /// Sends a lab file as [`LabChunk`]s of upload `upload` (reliable, in order), for the start
    /// that names the returned [`LabRef`]. Returns the chunks' seqs, whose acks say it arrived.
    ///
    /// # Errors
    /// [`SendError::Encode`] for a file longer than [`MAX_LAB_LEN`]; any error of the link.
    pub fn send_lab(&mut self, upload: u16, bytes: &[u8]) -> Result<(LabRef, Vec<u16>), SendError> {
        let too_long = SendError::Encode {
            name: "LabChunk",
            error: protocol::frame::EncodeError::PayloadTooLarge,
        };
        let len = u16::try_from(bytes.len())
            .ok()
            .filter(|l| *l <= MAX_LAB_LEN)
            .ok_or(too_long)?;
        let count = u8::try_from(protocol::radio::lab_chunk_count(len)).map_err(|_| too_long)?;
        let mut seqs = Vec::new();
        for (index, part) in (0..count).zip(bytes.chunks(LAB_CHUNK_LEN)) {
            let chunk = LabChunk {
                upload,
                index,
                count,
                bytes: List::from_slice(part).ok_or(too_long)?,
            };
            seqs.push(
                self.link
                    .send(&chunk, Delivery::Reliable, Priority::Control)?,
            );
        }
        Ok((LabRef { upload, len }, seqs))
    }

    /// Sends an abort (reliable, ahead of every queued frame).
    pub fn abort(&mut self, run_id: u32) -> Result<u16, SendError> {
        // In front of anything queued: stopping the robot waits for nothing.
        self.link
            .send(&Abort { run_id }, Delivery::Reliable, Priority::Urgent)
    }

    /// Asks for the robot status.
    pub fn request_status(&mut self) -> Result<u16, SendError> {
        self.link
            .send(&StatusRequest {}, Delivery::Reliable, Priority::Control)
    }

    /// Asks for an earlier run's result and preview.
    pub fn fetch(&mut self, run_id: u32) -> Result<u16, SendError> {
        // Forget what we had of it: the offer that answers is reassembled and reported again.
        self.incoming.remove(&run_id);
        self.link
            .send(&FetchRun { run_id }, Delivery::Reliable, Priority::Control)
    }

    /// Whether a command is still waiting for its ack.
    pub fn is_in_flight(&self, seq: u16) -> bool {
        self.link.is_in_flight(seq)
    }

    /// Chunks (preview and record files together) received and expected for `run_id`, if its
    /// result has arrived.
    pub fn preview_progress(&self, run_id: u32) -> Option<(usize, usize)> {
        self.incoming.get(&run_id).map(Incoming::progress)
    }

    /// Feeds bytes from the radio; returns what happened, in order.
    pub fn receive(&mut self, now_us: u64, bytes: &[u8]) -> Vec<HandheldEvent> {
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
        self.drain_link_events(&mut out);
        out
    }

    fn on_frame(
        &mut self,
        now_us: u64,
        header: Header,
        payload: &[u8],
        out: &mut Vec<HandheldEvent>,
    ) {
        let frame = Frame { header, payload };
        if header.version != protocol::PROTOCOL_VERSION {
            self.stats.unauthenticated += 1;
            match message::decode::<Hello>(&frame) {
                Ok(h) => out.push(HandheldEvent::Version(h)),
                Err(e) => out.push(HandheldEvent::Undecodable(e.to_string())),
            }
            return;
        }
        match header.msg_id {
            ids::SEALED => {
                let Some(session) = self.session.as_mut().filter(|s| s.id() == header.seq) else {
                    self.stats.unopened += 1;
                    return;
                };
                let sid = session.id();
                let Ok((inner, inner_payload)) = session.open(payload) else {
                    self.stats.unopened += 1;
                    return;
                };
                let r = Received {
                    header: inner,
                    payload: inner_payload,
                };
                if let Some(r) = self.link.accept(now_us, sid, r) {
                    match ToHandheld::decode(&r.frame()) {
                        Ok(msg) => self.on_message(now_us, msg, out),
                        Err(DecodeError::IsAck) => {}
                        Err(e) => out.push(HandheldEvent::Undecodable(e.to_string())),
                    }
                }
            }
            ids::HANDSHAKE_REPLY => {
                let (Some(initiator), Ok(reply)) = (
                    self.initiator.take(),
                    message::decode::<HandshakeReply>(&frame),
                ) else {
                    self.stats.unauthenticated += 1;
                    return;
                };
                if let Ok(session) = initiator.finish(&reply) {
                    out.push(HandheldEvent::Connected {
                        session: session.id(),
                    });
                    self.session = Some(session);
                } else {
                    // A forged or mangled reply spent the handshake: start a new one.
                    self.stats.unauthenticated += 1;
                    let _ = self.connect(now_us);
                }
            }
            _ => self.stats.unauthenticated += 1,
        }
    }

    fn on_message(&mut self, now_us: u64, msg: ToHandheld, out: &mut Vec<HandheldEvent>) {
        match msg {
            ToHandheld::Hello(_) | ToHandheld::Heartbeat(_) => {}
            ToHandheld::Progress(p) => out.push(HandheldEvent::Progress(p)),
            ToHandheld::Result(result) => {
                let run_id = result.run_id;
                if let Some(i) = self.incoming.get(&run_id)
                    && i.complete
                {
                    self.ack_result(run_id);
                    return;
                }
                let entry = self
                    .incoming
                    .entry(run_id)
                    .or_insert_with(|| Incoming::new(&result, now_us));
                if entry.result != result {
                    // A fetch re-offered the run with another preview or other files: start over.
                    *entry = Incoming::new(&result, now_us);
                }
                out.push(HandheldEvent::Result(result));
                self.check_complete(run_id, out);
            }
            ToHandheld::CloudChunk(chunk) => {
                if let Some(i) = self.incoming.get_mut(&chunk.run_id)
                    && i.preview.add(&chunk)
                {
                    i.last_chunk_us = now_us;
                    self.check_complete(chunk.run_id, out);
                }
            }
            ToHandheld::RecordChunk(chunk) => {
                if let Some(i) = self.incoming.get_mut(&chunk.run_id)
                    && i.records
                        .iter_mut()
                        .flatten()
                        .any(|a| a.file() == chunk.file && a.add(&chunk))
                {
                    i.last_chunk_us = now_us;
                    self.check_complete(chunk.run_id, out);
                }
            }
            ToHandheld::Status(s) => out.push(HandheldEvent::Status(s)),
            ToHandheld::Refused(r) => out.push(HandheldEvent::Refused(r)),
            ToHandheld::LogLine(l) => out.push(HandheldEvent::Log(l)),
        }
    }

    fn check_complete(&mut self, run_id: u32, out: &mut Vec<HandheldEvent>) {
        let Some(i) = self.incoming.get_mut(&run_id) else {
            return;
        };
        if i.complete || !i.is_complete() {
            return;
        }
        i.complete = true;
        let records = i
            .result
            .records
            .as_slice()
            .iter()
            .zip(&i.records)
            .map(|(info, a)| ReceivedRecord {
                file: info.file,
                bytes: match a {
                    // Complete: the bytes are there and of the announced length.
                    Ok(a) => Ok(a.bytes().unwrap_or_default()),
                    Err(e) => Err(e.clone()),
                },
            })
            .collect();
        out.push(HandheldEvent::Complete {
            result: i.result.clone(),
            preview_mm: i.preview.points_mm(),
            records,
        });
        self.ack_result(run_id);
    }

    fn ack_result(&mut self, run_id: u32) {
        let _ = self
            .link
            .send(&ResultAck { run_id }, Delivery::Reliable, Priority::Control);
    }

    fn drain_link_events(&mut self, out: &mut Vec<HandheldEvent>) {
        while let Some(e) = self.link.poll_event() {
            out.push(match e {
                LinkEvent::Acked { msg_id, seq } => HandheldEvent::Acked { msg_id, seq },
                LinkEvent::GaveUp { msg_id, seq } => HandheldEvent::Lost { msg_id, seq },
            });
        }
    }

    /// Timers: heartbeats, retransmits, preview resend requests. Returns link events (acks,
    /// commands given up).
    pub fn poll(&mut self, now_us: u64) -> Vec<HandheldEvent> {
        if let Some(init) = &self.initiator
            && now_us >= self.next_init_us
        {
            self.wire_out.extend_from_slice(init.init_frame());
            self.stats.inits_sent += 1;
            self.next_init_us = now_us + self.init_interval_us;
            self.init_interval_us =
                (self.init_interval_us * 3 / 2).min(self.config.init_retry_max_us);
        }
        if self.session.is_none() {
            // Nothing but the handshake leaves before the session: commands wait in the queue.
            return Vec::new();
        }
        self.link.poll(now_us);
        let quiet = self.config.resend_quiet_us;
        let mut wanted = Vec::new();
        let mut wanted_records = Vec::new();
        for (run_id, i) in &mut self.incoming {
            if i.complete || now_us.saturating_sub(i.last_chunk_us) < quiet {
                continue;
            }
            let mut asked = false;
            let missing: Vec<u16> = i.preview.missing().into_iter().take(32).collect();
            if !missing.is_empty() {
                asked = true;
                wanted.push((*run_id, missing));
            }
            for a in i.records.iter().flatten() {
                let missing: Vec<u16> = a.missing().into_iter().take(32).collect();
                if !missing.is_empty() {
                    asked = true;
                    wanted_records.push((*run_id, a.file(), missing));
                }
            }
            if asked {
                // Wait another quiet spell before asking again.
                i.last_chunk_us = now_us;
            }
        }
        for (run_id, missing) in wanted {
            if let Some(indices) = List::from_slice(&missing) {
                let _ = self.link.send(
                    &ResendChunks { run_id, indices },
                    Delivery::Reliable,
                    Priority::Control,
                );
            }
        }
        for (run_id, file, missing) in wanted_records {
            if let Some(indices) = List::from_slice(&missing) {
                let _ = self.link.send(
                    &ResendRecordChunks {
                        run_id,
                        file,
                        indices,
                    },
                    Delivery::Reliable,
                    Priority::Control,
                );
            }
        }
        let mut out = Vec::new();
        self.drain_link_events(&mut out);
        out
    }

    /// The next time [`Self::poll`] has timer work.
    pub fn poll_at(&self) -> Option<u64> {
        let resend = self
            .incoming
            .values()
            .filter(|i| !i.complete)
            .map(|i| i.last_chunk_us + self.config.resend_quiet_us)
            .min();
        let init = self.initiator.as_ref().map(|_| self.next_init_us);
        [self.link.poll_at(), resend, init]
            .into_iter()
            .flatten()
            .min()
    }

    /// Bytes to write to the radio now: handshake inits, then sealed frames of the session.
    pub fn transmit(&mut self, now_us: u64) -> Vec<u8> {
        let mut out = std::mem::take(&mut self.wire_out);
        if let Some(session) = self.session.as_mut() {
            out.extend(
                self.link
                    .transmit_with(now_us, &mut |inner| session.seal(inner)),
            );
        }
        out
    }
}
