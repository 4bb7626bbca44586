//! The [`Message`] trait, explicit message ids, wire enums and the per-direction message sets.

use postcard::experimental::max_size::MaxSize;
use serde::{Serialize, de::DeserializeOwned};

use crate::frame::{self, EncodeError, Flags, Frame, Header};

/// A message type with a fixed id on the wire.
pub trait Message: Serialize + DeserializeOwned + MaxSize {
    /// The message id in the frame header (see [`crate::ids`]).
    const ID: u16;
    /// Human-readable name for logs and errors.
    const NAME: &'static str;

    /// Encodes this message as a whole frame into `out`; returns the frame length.
    fn encode_frame(&self, seq: u16, flags: Flags, out: &mut [u8]) -> Result<usize, EncodeError> {
        frame::encode(Header::new(Self::ID, seq, flags), self, out)
    }
}

/// Why a frame's payload did not decode as the expected message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum DecodeError {
    /// The sender speaks another protocol version (only `Hello` decodes across versions).
    VersionMismatch {
        /// The version in the frame header.
        theirs: u8,
    },
    /// The message id is not one this end accepts on this link.
    UnknownId {
        /// The id seen.
        msg_id: u16,
    },
    /// The payload is not a valid encoding of the message named by the id.
    Malformed {
        /// The message id.
        msg_id: u16,
    },
    /// The payload decoded but bytes were left over.
    TrailingBytes {
        /// The message id.
        msg_id: u16,
    },
    /// The frame is an ack (empty payload), not a message.
    IsAck,
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::VersionMismatch { theirs } => write!(
                f,
                "peer speaks protocol version {theirs}, this end speaks {}",
                crate::PROTOCOL_VERSION
            ),
            Self::UnknownId { msg_id } => write!(f, "unknown message id {msg_id:#06x}"),
            Self::Malformed { msg_id } => {
                write!(f, "malformed payload for message id {msg_id:#06x}")
            }
            Self::TrailingBytes { msg_id } => {
                write!(f, "trailing bytes after message id {msg_id:#06x}")
            }
            Self::IsAck => write!(f, "frame is an ack"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DecodeError {}

/// Decodes the payload of `frame` as `M`, checking version and id. `Hello` decodes from any version.
pub fn decode<M: Message>(frame: &Frame<'_>) -> Result<M, DecodeError> {
    let msg_id = frame.header.msg_id;
    if frame.header.flags.contains(Flags::IS_ACK) {
        return Err(DecodeError::IsAck);
    }
    if frame.header.version != crate::PROTOCOL_VERSION && M::ID != crate::ids::HELLO {
        return Err(DecodeError::VersionMismatch {
            theirs: frame.header.version,
        });
    }
    if msg_id != M::ID {
        return Err(DecodeError::UnknownId { msg_id });
    }
    let (msg, rest) = postcard::take_from_bytes::<M>(frame.payload)
        .map_err(|_| DecodeError::Malformed { msg_id })?;
    if !rest.is_empty() {
        return Err(DecodeError::TrailingBytes { msg_id });
    }
    Ok(msg)
}

/// Worst-case encoded frame length of `M`, delimiter included.
pub const fn max_frame_len<M: Message>() -> usize {
    frame::max_frame_len(M::POSTCARD_MAX_SIZE)
}

/// Defines a one-byte wire enum with explicit values (never declaration order), serialised as u8.
macro_rules! wire_enum {
    ($(#[$meta:meta])* pub enum $name:ident { $($(#[$vmeta:meta])* $variant:ident = $value:literal,)+ }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
        #[serde(into = "u8", try_from = "u8")]
        #[repr(u8)]
        pub enum $name { $($(#[$vmeta])* $variant = $value,)+ }

        impl From<$name> for u8 {
            fn from(v: $name) -> u8 { v as u8 }
        }

        impl TryFrom<u8> for $name {
            type Error = crate::message::UnknownValue;
            fn try_from(v: u8) -> Result<Self, crate::message::UnknownValue> {
                match v {
                    $($value => Ok(Self::$variant),)+
                    other => Err(crate::message::UnknownValue(other)),
                }
            }
        }

        impl postcard::experimental::max_size::MaxSize for $name {
            const POSTCARD_MAX_SIZE: usize = 1;
        }

        impl $name {
            /// Every value, in wire-value order.
            pub const ALL: &'static [Self] = &[$(Self::$variant,)+];

            /// The variant's name.
            pub const fn name(self) -> &'static str {
                match self { $(Self::$variant => stringify!($variant),)+ }
            }
        }

        impl core::fmt::Display for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}
pub(crate) use wire_enum;

/// A wire enum received a value it does not define.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnknownValue(pub u8);

impl core::fmt::Display for UnknownValue {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "unknown enum value {}", self.0)
    }
}

/// Defines a named bit set (u32 on the wire) whose set bits can be listed by name.
macro_rules! bit_set {
    ($(#[$meta:meta])* pub struct $name:ident($int:ty) { $($(#[$vmeta:meta])* const $flag:ident = $bit:literal;)+ }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
                 postcard::experimental::max_size::MaxSize)]
        pub struct $name(pub $int);

        impl $name {
            $($(#[$vmeta])* pub const $flag: Self = Self(1 << $bit);)+
            /// No bit set.
            pub const EMPTY: Self = Self(0);
            /// Every defined bit with its name.
            pub const NAMES: &'static [(Self, &'static str)] = &[$((Self::$flag, stringify!($flag)),)+];

            /// Whether every bit of `other` is set.
            pub const fn contains(self, other: Self) -> bool { self.0 & other.0 == other.0 }
            /// Whether no bit is set.
            pub const fn is_empty(self) -> bool { self.0 == 0 }
            /// Sets the bits of `other`.
            pub fn insert(&mut self, other: Self) { self.0 |= other.0; }
            /// Clears the bits of `other`.
            pub fn remove(&mut self, other: Self) { self.0 &= !other.0; }
            /// Both sets together.
            #[must_use]
            pub const fn union(self, other: Self) -> Self { Self(self.0 | other.0) }
            /// Names of the set bits, in bit order (undefined bits are not listed).
            pub fn names(self) -> impl Iterator<Item = &'static str> {
                Self::NAMES.iter().filter(move |(f, _)| self.contains(*f)).map(|(_, n)| *n)
            }
        }

        impl core::fmt::Display for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                let mut first = true;
                for name in self.names() {
                    if !first { f.write_str("|")?; }
                    f.write_str(name)?;
                    first = false;
                }
                if first { f.write_str("none")?; }
                Ok(())
            }
        }
    };
}
pub(crate) use bit_set;

/// Defines an enum over the messages one end accepts from one peer, with id dispatch.
macro_rules! message_set {
    ($(#[$meta:meta])* pub enum $name:ident { $($(#[$vmeta:meta])* $variant:ident($ty:ty),)+ }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, PartialEq)]
        pub enum $name { $($(#[$vmeta])* $variant($ty),)+ }

        impl $name {
            /// Decodes a frame into the message its id names.
            pub fn decode(frame: &crate::frame::Frame<'_>) -> Result<Self, crate::message::DecodeError> {
                match frame.header.msg_id {
                    $(<$ty as crate::message::Message>::ID => crate::message::decode::<$ty>(frame).map(Self::$variant),)+
                    msg_id => {
                        if frame.header.flags.contains(crate::frame::Flags::IS_ACK) {
                            Err(crate::message::DecodeError::IsAck)
                        } else {
                            Err(crate::message::DecodeError::UnknownId { msg_id })
                        }
                    }
                }
            }

            /// The message id of this variant.
            pub const fn msg_id(&self) -> u16 {
                match self { $(Self::$variant(_) => <$ty as crate::message::Message>::ID,)+ }
            }

            /// The message name of this variant.
            pub const fn name(&self) -> &'static str {
                match self { $(Self::$variant(_) => <$ty as crate::message::Message>::NAME,)+ }
            }

            /// Encodes this message as a whole frame into `out`; returns the frame length.
            pub fn encode_frame(
                &self,
                seq: u16,
                flags: crate::frame::Flags,
                out: &mut [u8],
            ) -> Result<usize, crate::frame::EncodeError> {
                match self { $(Self::$variant(m) => crate::message::Message::encode_frame(m, seq, flags, out),)+ }
            }

            /// Largest postcard payload of any message in this set.
            pub const MAX_PAYLOAD_LEN: usize = {
                let mut max = 0;
                $(
                    let len = <$ty as postcard::experimental::max_size::MaxSize>::POSTCARD_MAX_SIZE;
                    if len > max { max = len; }
                )+
                max
            };

            /// Largest encoded frame of any message in this set, delimiter included.
            pub const MAX_FRAME_LEN: usize = {
                let mut max = 0;
                $(
                    let len = crate::message::max_frame_len::<$ty>();
                    if len > max { max = len; }
                )+
                max
            };
        }

        $(
            impl From<$ty> for $name {
                fn from(m: $ty) -> Self { Self::$variant(m) }
            }
        )+
    };
}
pub(crate) use message_set;

/// Implements [`Message`] for a type with an id constant.
macro_rules! impl_message {
    ($($ty:ty => $id:path,)+) => {
        $(
            impl crate::message::Message for $ty {
                const ID: u16 = $id;
                const NAME: &'static str = stringify!($ty);
            }
        )+
    };
}
pub(crate) use impl_message;
