//! The onboard end of the radio link: turns frames from the handheld into [`RadioRequest`]s for the
//! run state machine, answers what it can itself (hello, auth refusals, preview resends), and holds
//! results until the handheld acknowledges them.
//!
//! - The start command is verified with [`ReplayGuard`]: a bad tag or an old counter is refused
//!   ([`Refused`] with [`RefuseReason::BadTag`] / [`RefuseReason::Replay`]) and never reaches the
//!   run state machine, so the robot cannot move on it. After a fresh start the caller persists
//!   [`OnboardRadio::last_counter`] before acting (see `recorder::CounterFile`).
//! - A result goes out with [`Delivery::Persistent`] (retransmitted until the link acks it) and
//!   stays in [`OnboardRadio::pending_results`] until the handheld's [`ResultAck`], which comes
//!   after the handheld has the whole preview.
//! - Preview chunks are best effort and paced through the bulk queue; [`ResendChunks`] puts the
//!   wanted ones back in front.

use std::collections::VecDeque;

use protocol::auth::{AuthError, Key, ReplayGuard, Verified};
use protocol::common::{Hello, LogLevel, LogLine, Role};
use protocol::frame::Header;
use protocol::message::DecodeError;
use protocol::radio::{
    CloudChunk, MeasurementResult, Progress, RefuseReason, Refused, RobotStatus, StartMeasurement,
    ToOnboard,
};
use protocol::{Message, bounded::Text};

use super::preview;
use super::reliable::{Delivery, LinkConfig, Priority, ReliableLink, SendError};

/// Chunks kept in the link's bulk queue at a time: enough to keep the line busy, few enough that a
/// resend request or a progress message is not stuck behind a long queue.
const BULK_DEPTH: usize = 4;

/// What the handheld asked for, after authentication and decoding.
#[derive(Debug, Clone, PartialEq)]
pub enum RadioRequest {
    /// An authenticated, fresh start. Persist [`OnboardRadio::last_counter`], then act or refuse
    /// (busy, interlocked, bad parameter) with [`OnboardRadio::refuse`].
    Start {
        /// The command.
        params: StartMeasurement,
        /// Its seq (for a refusal).
        seq: u16,
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
    /// A command was refused by the session itself (authentication, version, decoding): log it.
    Refused {
        /// Why.
        reason: RefuseReason,
        /// What, for the log.
        detail: String,
    },
}

#[derive(Debug)]
struct Pending {
    result: MeasurementResult,
    result_seq: u16,
    chunks: Vec<CloudChunk>,
    to_send: VecDeque<u16>,
}

/// The onboard end of the radio link. See the module docs.
#[derive(Debug)]
pub struct OnboardRadio {
    link: ReliableLink,
    key: Key,
    guard: ReplayGuard,
    pending: Vec<Pending>,
    refused: u64,
}

impl OnboardRadio {
    /// A session with the pairing key and the persisted last start counter.
    pub fn new(link: LinkConfig, key: Key, last_counter: u64, initial_seq: u16) -> Self {
        Self {
            link: ReliableLink::new(link, initial_seq),
            key,
            guard: ReplayGuard::new(last_counter),
            pending: Vec::new(),
            refused: 0,
        }
    }

    /// The last accepted start counter (persist it after every [`RadioRequest::Start`]).
    pub fn last_counter(&self) -> u64 {
        self.guard.last_counter()
    }

    /// The link core (stats, liveness).
    pub fn link(&self) -> &ReliableLink {
        &self.link
    }

    /// Commands refused by the session (authentication, version, decoding) so far.
    pub fn refused_count(&self) -> u64 {
        self.refused
    }

    /// Microseconds since the handheld was last heard (`None`: never).
    pub fn handheld_silent_us(&self, now_us: u64) -> Option<u64> {
        self.link.peer_silent_us(now_us)
    }

    /// Feeds bytes from the radio; returns the requests in order.
    pub fn receive(&mut self, now_us: u64, bytes: &[u8]) -> Vec<RadioRequest> {
        let mut out = Vec::new();
        for r in self.link.receive(now_us, bytes) {
            let header = r.header;
            match ToOnboard::decode(&r.frame()) {
                Ok(msg) => self.on_message(header, msg, &mut out),
                Err(DecodeError::VersionMismatch { theirs }) => {
                    let detail = format!("peer speaks protocol version {theirs}");
                    self.send_hello();
                    self.refuse_into(header, RefuseReason::VersionMismatch, &detail, &mut out);
                }
                Err(e) => {
                    self.refuse_into(header, RefuseReason::Malformed, &e.to_string(), &mut out);
                }
            }
        }
        out
    }

    fn on_message(&mut self, header: Header, msg: ToOnboard, out: &mut Vec<RadioRequest>) {
        match msg {
            ToOnboard::Hello(_) => self.send_hello(),
            ToOnboard::Heartbeat(_) => {}
            ToOnboard::Start(signed) => match self.guard.verify(&self.key, header, &signed) {
                Ok(Verified::Fresh) => out.push(RadioRequest::Start {
                    params: signed.body,
                    seq: header.seq,
                }),
                Ok(Verified::Duplicate) => {}
                Err(AuthError::Replay { counter, last }) => {
                    let detail = format!("counter {counter} not above {last}");
                    self.refuse_into(header, RefuseReason::Replay, &detail, out);
                }
                Err(e) => self.refuse_into(header, RefuseReason::BadTag, &e.to_string(), out),
            },
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
                    for &i in r.indices.as_slice().iter().rev() {
                        if usize::from(i) < p.chunks.len() && !p.to_send.contains(&i) {
                            p.to_send.push_front(i);
                        }
                    }
                }
            }
            ToOnboard::StatusRequest(_) => out.push(RadioRequest::Status),
            ToOnboard::FetchRun(f) => out.push(RadioRequest::Fetch {
                run_id: f.run_id,
                seq: header.seq,
            }),
        }
    }

    fn send_hello(&mut self) {
        // Hello is two bytes: encoding cannot fail.
        let _ = self.link.send(
            &Hello::new(Role::Onboard),
            Delivery::BestEffort,
            Priority::Control,
        );
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

    /// Offers a result and its preview; held until the handheld's [`RadioRequest::ResultAck`].
    /// `result.preview_chunks` is set from the preview here. Offering a run again (a fetch)
    /// replaces the earlier offer.
    pub fn deliver(
        &mut self,
        mut result: MeasurementResult,
        preview_mm: &[[i16; 3]],
    ) -> Result<(), SendError> {
        let chunks = preview::chunks(result.run_id, preview_mm);
        result.preview_chunks = chunks.len() as u16;
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
        }
    }

    /// The next time [`Self::poll`] has timer work.
    pub fn poll_at(&self) -> Option<u64> {
        self.link.poll_at()
    }

    /// Bytes to write to the radio now.
    pub fn transmit(&mut self, now_us: u64) -> Vec<u8> {
        self.link.transmit(now_us)
    }

    /// Whether bytes wait for the rate limiter or preview chunks wait to be queued.
    pub fn has_pending_output(&self) -> bool {
        self.link.has_pending_output() || self.pending.iter().any(|p| !p.to_send.is_empty())
    }
}

/// Message id of the start command, for refusals.
pub const START_ID: u16 = <protocol::radio::SignedStart as Message>::ID;
