//! The handheld end of the radio link (used by `passangle measure/status/abort/fetch`).
//!
//! Commands are reliable; the start is signed with the pairing key over the exact header it
//! travels under. Results are reassembled with their preview: once the result has arrived, chunks
//! still missing after a quiet spell ([`HandheldConfig::resend_quiet_us`]) are asked for again with
//! [`ResendChunks`] (32 at a time); when the preview is complete the handheld sends [`ResultAck`]
//! and reports [`HandheldEvent::Complete`]. A result that arrives again after that is acked again.

use std::collections::BTreeMap;

use protocol::auth::{self, Key};
use protocol::bounded::List;
use protocol::common::{Hello, LogLine, Role};
use protocol::message::DecodeError;
use protocol::radio::{
    Abort, FetchRun, MeasurementResult, Progress, Refused, ResendChunks, ResultAck, RobotStatus,
    SignedStart, StartMeasurement, StatusRequest, ToHandheld,
};

use super::preview::Assembler;
use super::reliable::{Delivery, LinkConfig, LinkEvent, Priority, ReliableLink, SendError};

/// Tuning of the handheld session.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandheldConfig {
    /// The link core.
    pub link: LinkConfig,
    /// Quiet time (no new chunk) after which missing chunks are asked for again.
    pub resend_quiet_us: u64,
}

impl Default for HandheldConfig {
    fn default() -> Self {
        Self {
            link: LinkConfig::RADIO,
            resend_quiet_us: 700_000,
        }
    }
}

/// What the operator should see.
#[derive(Debug, Clone, PartialEq)]
pub enum HandheldEvent {
    /// The onboard answered our hello.
    Hello(Hello),
    /// Run progress.
    Progress(Progress),
    /// A result arrived (the preview follows).
    Result(MeasurementResult),
    /// A result and its whole preview, acknowledged to the onboard.
    Complete {
        /// The result.
        result: MeasurementResult,
        /// The preview, millimetres, vehicle frame.
        preview_mm: Vec<[i16; 3]>,
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
    last_chunk_us: u64,
    complete: bool,
}

/// The handheld end of the radio link. See the module docs.
#[derive(Debug)]
pub struct HandheldRadio {
    config: HandheldConfig,
    link: ReliableLink,
    key: Key,
    incoming: BTreeMap<u32, Incoming>,
}

impl HandheldRadio {
    /// A session with the pairing key.
    pub fn new(config: HandheldConfig, key: Key, initial_seq: u16) -> Self {
        Self {
            config,
            link: ReliableLink::new(config.link, initial_seq),
            key,
            incoming: BTreeMap::new(),
        }
    }

    /// The link core (stats, liveness).
    pub fn link(&self) -> &ReliableLink {
        &self.link
    }

    /// Says hello (reliable).
    pub fn hello(&mut self) -> Result<u16, SendError> {
        self.link.send(
            &Hello::new(Role::Handheld),
            Delivery::Reliable,
            Priority::Control,
        )
    }

    /// Sends the signed start with `counter` (never reused for this key; e.g. microseconds since
    /// the Unix epoch, kept above the last one used). Returns the seq.
    pub fn start(&mut self, params: StartMeasurement, counter: u64) -> Result<u16, SendError> {
        let header = self.link.next_header::<SignedStart>(Delivery::Reliable);
        let signed = auth::sign(&self.key, header, counter, params).map_err(SendError::Auth)?;
        self.link
            .send(&signed, Delivery::Reliable, Priority::Control)
    }

    /// Sends an abort (reliable; not authenticated, stopping is always allowed).
    pub fn abort(&mut self, run_id: u32) -> Result<u16, SendError> {
        self.link
            .send(&Abort { run_id }, Delivery::Reliable, Priority::Control)
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

    /// Preview chunks received and expected for `run_id`, if its result has arrived.
    pub fn preview_progress(&self, run_id: u32) -> Option<(usize, usize)> {
        self.incoming.get(&run_id).map(|i| {
            let missing = i.preview.missing().len();
            let total = usize::from(i.result.preview_chunks);
            (total - missing.min(total), total)
        })
    }

    /// Feeds bytes from the radio; returns what happened, in order.
    pub fn receive(&mut self, now_us: u64, bytes: &[u8]) -> Vec<HandheldEvent> {
        let mut out = Vec::new();
        for r in self.link.receive(now_us, bytes) {
            match ToHandheld::decode(&r.frame()) {
                Ok(msg) => self.on_message(now_us, msg, &mut out),
                Err(DecodeError::IsAck) => {}
                Err(e) => out.push(HandheldEvent::Undecodable(e.to_string())),
            }
        }
        self.drain_link_events(&mut out);
        out
    }

    fn on_message(&mut self, now_us: u64, msg: ToHandheld, out: &mut Vec<HandheldEvent>) {
        match msg {
            ToHandheld::Hello(h) => out.push(HandheldEvent::Hello(h)),
            ToHandheld::Heartbeat(_) => {}
            ToHandheld::Progress(p) => out.push(HandheldEvent::Progress(p)),
            ToHandheld::Result(result) => {
                let run_id = result.run_id;
                if let Some(i) = self.incoming.get(&run_id)
                    && i.complete
                {
                    self.ack_result(run_id);
                    return;
                }
                let count = result.preview_chunks;
                let entry = self.incoming.entry(run_id).or_insert_with(|| Incoming {
                    result: result.clone(),
                    preview: Assembler::new(run_id, count),
                    last_chunk_us: now_us,
                    complete: false,
                });
                if entry.result != result {
                    // A fetch re-offered the run with another preview size: start over.
                    *entry = Incoming {
                        result: result.clone(),
                        preview: Assembler::new(run_id, count),
                        last_chunk_us: now_us,
                        complete: false,
                    };
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
            ToHandheld::Status(s) => out.push(HandheldEvent::Status(s)),
            ToHandheld::Refused(r) => out.push(HandheldEvent::Refused(r)),
            ToHandheld::LogLine(l) => out.push(HandheldEvent::Log(l)),
        }
    }

    fn check_complete(&mut self, run_id: u32, out: &mut Vec<HandheldEvent>) {
        let Some(i) = self.incoming.get_mut(&run_id) else {
            return;
        };
        if i.complete || !i.preview.is_complete() {
            return;
        }
        i.complete = true;
        out.push(HandheldEvent::Complete {
            result: i.result.clone(),
            preview_mm: i.preview.points_mm(),
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
        self.link.poll(now_us);
        let quiet = self.config.resend_quiet_us;
        let mut wanted = Vec::new();
        for (run_id, i) in &mut self.incoming {
            if i.complete || now_us.saturating_sub(i.last_chunk_us) < quiet {
                continue;
            }
            let missing: Vec<u16> = i.preview.missing().into_iter().take(32).collect();
            if !missing.is_empty() {
                // Wait another quiet spell before asking again.
                i.last_chunk_us = now_us;
                wanted.push((*run_id, missing));
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
        [self.link.poll_at(), resend].into_iter().flatten().min()
    }

    /// Bytes to write to the radio now.
    pub fn transmit(&mut self, now_us: u64) -> Vec<u8> {
        self.link.transmit(now_us)
    }
}
