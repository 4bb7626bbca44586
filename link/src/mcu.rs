//! The onboard end of the MCU link (UART to the STM32 firmware).
//!
//! The session reconciles a desired motion ([`MotionIntent`]) with the firmware's reported state
//! instead of relying on acks: the link is fast and nearly clean, and the firmware reports its mode
//! at 10 Hz, so "send again while the report disagrees" is simple and robust.
//!
//! - Heartbeat every [`McuSessionConfig::heartbeat_period_us`] (20 ms). If the onboard dies the
//!   heartbeats stop and the firmware ramps to zero after its own timeout (100 ms default).
//! - `Hello` until the firmware's `Hello` arrives; then `SetConfig` until the status no longer
//!   shows `NOT_CONFIGURED`.
//! - [`MotionIntent::Drive`]: `Drive` is sent at once and again every
//!   [`McuSessionConfig::resend_us`] while the firmware reports `Idle` (a lost frame). A
//!   [`Rejected`] drive turns the intent into `Stop` and is reported, except the first one of an
//!   intent refused naming `HEARTBEAT_LOST`: the firmware asks for exactly that (heartbeats
//!   again, then a new drive command), so the drive is sent once more after `resend_us` and the
//!   refusal reported as [`McuEvent::DriveRetried`]. A heartbeat that arrived late once (a
//!   scheduling stall of the onboard over 100 ms) then does not end the run before it started;
//!   the firmware still moves only on fresh heartbeats. The firmware names only the first
//!   interlock that blocks, so if another one blocks too the retry is refused again, and that
//!   second refusal ends the intent.
//! - [`MotionIntent::Stop`]: `Stop` at once, and again while the firmware reports motion.

use protocol::common::{Heartbeat, Hello, LogLine, Role};
use protocol::mcu::{
    Drive, DriveMode, FromFirmware, Interlocks, McuConfig, Odometry, RejectReason, Rejected,
    Status, Stop,
};
use protocol::{Message, ids};

use super::reliable::{Delivery, LinkConfig, Priority, ReliableLink};

/// What the onboard wants the robot to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotionIntent {
    /// Stand still (ramp down if moving).
    Stop,
    /// Drive straight ahead at this speed.
    Drive {
        /// Forward speed, m/s.
        vx_mps: f32,
    },
    /// Zero the currents at once (an abort while moving is still a ramp; this is for faults).
    StopNow,
}

/// Tuning of the MCU session.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct McuSessionConfig {
    /// The link core.
    pub link: LinkConfig,
    /// Heartbeat period, us (20 ms).
    pub heartbeat_period_us: u64,
    /// Resend period of hello, config and commands the firmware's state disagrees with, us.
    pub resend_us: u64,
    /// The firmware configuration sent after hello.
    pub firmware: McuConfig,
    /// Acceleration of the speed profile, m/s^2.
    pub accel_mps2: f32,
    /// Jerk of the speed profile, m/s^3 (0: trapezoid).
    pub jerk_mps3: f32,
    /// The firmware counts as alive while its last status is younger than this, us.
    pub status_timeout_us: u64,
}

/// What the firmware said.
#[derive(Debug, Clone, PartialEq)]
pub enum McuEvent {
    /// Its hello (first one, or after a firmware restart).
    Hello(Hello),
    /// Wheel odometry, stamped on arrival (host monotonic).
    Odometry {
        /// Host monotonic arrival time, us.
        rx_us: u64,
        /// The report (MCU clock inside).
        odometry: Odometry,
    },
    /// A status report.
    Status(Status),
    /// A refused command.
    Rejected(Rejected),
    /// A drive refused for a stale heartbeat, sent once more (see the module docs).
    DriveRetried(Rejected),
    /// A firmware log line.
    Log(LogLine),
    /// A frame that did not decode (version, id, payload).
    Undecodable(String),
}

/// The onboard end of the MCU link. See the module docs.
#[derive(Debug)]
pub struct McuSession {
    config: McuSessionConfig,
    link: ReliableLink,
    intent: MotionIntent,
    hello: Option<Hello>,
    status: Option<(u64, Status)>,
    next_heartbeat_us: u64,
    heartbeat_counter: u32,
    next_hello_us: u64,
    next_config_us: u64,
    next_command_us: u64,
    /// The current drive intent was already sent again after a `HEARTBEAT_LOST` refusal.
    drive_retried: bool,
}

impl McuSession {
    /// A session that starts by saying hello.
    pub fn new(config: McuSessionConfig, initial_seq: u16) -> Self {
        Self {
            config,
            link: ReliableLink::new(config.link, initial_seq),
            intent: MotionIntent::Stop,
            hello: None,
            status: None,
            next_heartbeat_us: 0,
            heartbeat_counter: 0,
            next_hello_us: 0,
            next_config_us: 0,
            next_command_us: 0,
            drive_retried: false,
        }
    }

    /// The link core (stats).
    pub fn link(&self) -> &ReliableLink {
        &self.link
    }

    /// The current intent.
    pub fn intent(&self) -> MotionIntent {
        self.intent
    }

    /// Changes the intent; the command leaves at the next [`Self::poll`].
    pub fn set_intent(&mut self, intent: MotionIntent) {
        if intent != self.intent {
            self.intent = intent;
            self.next_command_us = 0;
            self.drive_retried = false;
        }
    }

    /// The firmware's hello, if it answered.
    pub fn firmware_hello(&self) -> Option<Hello> {
        self.hello
    }

    /// The last status and when it arrived.
    pub fn last_status(&self) -> Option<&Status> {
        self.status.as_ref().map(|(_, s)| s)
    }

    /// Hello seen and a status younger than the timeout.
    pub fn firmware_ok(&self, now_us: u64) -> bool {
        self.hello.is_some()
            && self
                .status
                .is_some_and(|(at, _)| now_us.saturating_sub(at) <= self.config.status_timeout_us)
    }

    /// Interlocks blocking motion now; `NO_HOST` (firmware unheard) when no status has arrived.
    pub fn interlocks(&self) -> Interlocks {
        self.status
            .map_or(Interlocks::NO_HOST, |(_, s)| s.interlocks)
    }

    /// The battery voltage of the latest status, mV (0: not measured, or no status yet).
    pub fn battery_mv(&self) -> u16 {
        self.status.map_or(0, |(_, s)| s.battery_mv)
    }

    /// Whether the firmware reports the wheels at rest (idle or faulted with zero currents).
    pub fn at_rest(&self) -> bool {
        self.status
            .is_some_and(|(_, s)| matches!(s.mode, DriveMode::Idle | DriveMode::Faulted))
    }

    /// Feeds bytes from the UART.
    pub fn receive(&mut self, now_us: u64, bytes: &[u8]) -> Vec<McuEvent> {
        let mut out = Vec::new();
        for r in self.link.receive(now_us, bytes) {
            match FromFirmware::decode(&r.frame()) {
                Ok(FromFirmware::Hello(h)) => {
                    if self.hello.is_none() {
                        out.push(McuEvent::Hello(h));
                    }
                    self.hello = Some(h);
                }
                Ok(FromFirmware::Odometry(odometry)) => out.push(McuEvent::Odometry {
                    rx_us: now_us,
                    odometry,
                }),
                Ok(FromFirmware::Status(s)) => {
                    if s.interlocks.contains(Interlocks::NO_HOST) && self.hello.is_some() {
                        // The firmware restarted: say hello and configure again.
                        self.hello = None;
                        self.next_hello_us = 0;
                    }
                    self.status = Some((now_us, s));
                    out.push(McuEvent::Status(s));
                }
                Ok(FromFirmware::Rejected(r)) => {
                    let stale_heartbeat = r.reason == RejectReason::Interlocked
                        && Interlocks::HEARTBEAT_LOST.names().next() == Some(r.field.as_str());
                    let driving = matches!(self.intent, MotionIntent::Drive { .. });
                    if r.msg_id == ids::DRIVE && driving && stale_heartbeat && !self.drive_retried {
                        self.drive_retried = true;
                        self.next_command_us = now_us + self.config.resend_us;
                        out.push(McuEvent::DriveRetried(r));
                        continue;
                    }
                    if r.msg_id == ids::DRIVE {
                        self.intent = MotionIntent::Stop;
                        self.next_command_us = 0;
                    }
                    out.push(McuEvent::Rejected(r));
                }
                Ok(FromFirmware::LogLine(l)) => out.push(McuEvent::Log(l)),
                Err(protocol::DecodeError::IsAck) => {}
                Err(e) => out.push(McuEvent::Undecodable(e.to_string())),
            }
        }
        out
    }

    fn send<M: Message>(&mut self, msg: &M) {
        // MCU messages have small fixed bounds: encoding cannot fail.
        let _ = self.link.send(msg, Delivery::BestEffort, Priority::Control);
    }

    /// Timers: heartbeat, hello/config/command resends.
    pub fn poll(&mut self, now_us: u64) {
        let c = self.config;
        if now_us >= self.next_heartbeat_us {
            self.next_heartbeat_us = now_us + c.heartbeat_period_us;
            let hb = Heartbeat {
                counter: self.heartbeat_counter,
            };
            self.heartbeat_counter = self.heartbeat_counter.wrapping_add(1);
            self.send(&hb);
        }
        if self.hello.is_none() {
            if now_us >= self.next_hello_us {
                self.next_hello_us = now_us + c.resend_us;
                self.send(&Hello::new(Role::Onboard));
            }
            return;
        }
        let configured = self
            .status
            .is_some_and(|(_, s)| !s.interlocks.contains(Interlocks::NOT_CONFIGURED));
        if !configured && now_us >= self.next_config_us && self.at_rest_or_unknown() {
            self.next_config_us = now_us + c.resend_us;
            self.send(&c.firmware);
        }
        if now_us < self.next_command_us {
            return;
        }
        let mode = self.status.map(|(_, s)| s.mode);
        match self.intent {
            MotionIntent::Drive { vx_mps } => {
                if !matches!(mode, Some(DriveMode::Ramping | DriveMode::Cruising))
                    || self.next_command_us == 0
                {
                    self.send(&Drive {
                        vx_mps,
                        vy_mps: 0.0,
                        wz_radps: 0.0,
                        accel_mps2: c.accel_mps2,
                        jerk_mps3: c.jerk_mps3,
                    });
                }
            }
            MotionIntent::Stop | MotionIntent::StopNow => {
                if !matches!(mode, Some(DriveMode::Idle | DriveMode::Faulted))
                    || self.next_command_us == 0
                {
                    self.send(&Stop {
                        immediate: self.intent == MotionIntent::StopNow,
                    });
                }
            }
        }
        self.next_command_us = now_us + c.resend_us;
    }

    fn at_rest_or_unknown(&self) -> bool {
        self.status.is_none() || self.at_rest()
    }

    /// The next time [`Self::poll`] has work.
    pub fn poll_at(&self) -> u64 {
        self.next_heartbeat_us.min(if self.hello.is_none() {
            self.next_hello_us
        } else {
            self.next_command_us.min(self.next_config_us)
        })
    }

    /// Bytes to write to the UART now.
    pub fn transmit(&mut self, now_us: u64) -> Vec<u8> {
        self.link.transmit(now_us)
    }
}
