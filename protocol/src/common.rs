//! Messages used on both links: the frozen [`Hello`], [`Heartbeat`] and [`LogLine`].

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

use crate::bounded::Text;
use crate::message::wire_enum;

wire_enum! {
    /// Which program is at the other end.
    pub enum Role {
        /// The operator's handheld CLI (`passangle`).
        Handheld = 1,
        /// The onboard service (`passangle-onboard`).
        Onboard = 2,
        /// The STM32 firmware.
        Firmware = 3,
        /// The software-in-the-loop simulator standing in for one of the above.
        Simulator = 4,
    }
}

/// FROZEN FOREVER: id 0x0001, payload `version: u8, role: u8`, decodable from any protocol version,
/// so two ends of different versions can say so clearly. Sent first by the initiating end (onboard
/// to firmware, handheld to onboard) with ack requested; the peer answers with its own `Hello`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct Hello {
    /// The sender's [`crate::PROTOCOL_VERSION`].
    pub version: u8,
    /// The sender's role (a raw u8 so unknown future roles still decode; see [`Role`]).
    pub role: u8,
}

impl Hello {
    /// This end's `Hello` in `role`.
    pub fn new(role: Role) -> Self {
        Self {
            version: crate::PROTOCOL_VERSION,
            role: role.into(),
        }
    }

    /// The role, if it is one this version knows.
    pub fn role(&self) -> Option<Role> {
        Role::try_from(self.role).ok()
    }
}

/// Liveness signal, both links, both directions. On the MCU link the onboard sends it every 20 ms and
/// the firmware ramps to zero after its timeout (default 100 ms); on the radio both ends send it at
/// 2 Hz and the onboard stops the robot if the handheld goes silent while moving.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct Heartbeat {
    /// Sender's counter, incremented per heartbeat.
    pub counter: u32,
}

wire_enum! {
    /// Severity of a [`LogLine`].
    pub enum LogLevel {
        /// Something failed.
        Error = 1,
        /// Something is off but work goes on.
        Warn = 2,
        /// Normal progress.
        Info = 3,
        /// Detail for developers.
        Debug = 4,
    }
}

/// A log line forwarded to the peer (firmware -> onboard, onboard -> handheld).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct LogLine {
    /// Severity.
    pub level: LogLevel,
    /// The text, cut to 160 bytes.
    pub text: Text<160>,
}

crate::message::impl_message! {
    Hello => crate::ids::HELLO,
    Heartbeat => crate::ids::HEARTBEAT,
    LogLine => crate::ids::LOG_LINE,
}
