//! One typed request, and where the chip answers with data or a return value
//! one typed reply, per command code (v049 命令說明, one section per command).
//!
//! A [`Request`] writes the data section and returns the header fields it sets
//! (parameter, command data 0..3, data length, header options); it can be read
//! back from a received command, which is what the simulator does. A [`Reply`]
//! is the same for the response's return value and data. Both directions are
//! implemented for every type, so every type round-trips in tests.
//!
//! Each request names what answers it ([`Request::Answer`]: a reply, or
//! [`Done`]), so the host reads an answer through the request that asked
//! (`ResponsePacket::answer_to`, [`crate::read_answer`]) and never picks
//! answer bytes apart by hand.
//!
//! Modules follow the manual's grouping: network and DC, PDO, SDO, state,
//! slave info, FIFO, SPI link, CiA402 helper, GPIO, QEI/DAC/ADC, EEPROM,
//! interrupts, CoE emergencies, raw datagrams, FoE, MDIO, mailbox, chip
//! control. [`AnyRequest`] parses a command by its code.

use crate::command::CommandCode;
use crate::error::{EncodeError, PayloadError};
use crate::flags::HeaderOptions;

mod any;
pub mod cia402;
pub mod control;
pub mod ecat_init;
pub mod eeprom;
pub mod emergency;
pub mod fifo;
pub mod foe;
pub mod gpio;
pub mod interrupt;
pub mod mailbox;
pub mod mdio;
pub mod pdo;
pub mod periph;
pub mod raw;
pub mod sdo;
pub mod slave_info;
pub mod spi;
pub mod state;

pub use any::AnyRequest;

/// The header fields a request sets besides the code (v049 表一 0x04..0x10).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct RequestFields {
    /// 0x0D: command parameter.
    pub parameter: u8,
    /// 0x04..0x08: command data 0..3.
    pub param: [u8; 4],
    /// 0x0E: valid data length, or a per-command value.
    pub data_len: u16,
    /// 0x08: header options (ECAT_INIT only, so far).
    pub options: HeaderOptions,
}

impl RequestFields {
    /// Fields with only a parameter.
    pub const fn parameter(parameter: u8) -> Self {
        Self { parameter, param: [0; 4], data_len: 0, options: HeaderOptions::empty() }
    }
}

/// The header fields a reply sets besides the echoed code (v049 表二 0x0D..0x10).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct ReplyFields {
    /// 0x0D: return value.
    pub value: u8,
    /// 0x0E: valid data length.
    pub data_len: u16,
}

/// A command's payload: how it sits in the header and data section.
pub trait Request<'a>: Sized {
    /// The command code it belongs to.
    const CODE: CommandCode;
    /// Writes the data section (which arrives zeroed) and returns the header
    /// fields.
    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError>;
    /// Reads it back from a received command's fields and whole data section.
    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError>;

    /// What the chip answers to it: a [`Reply`], or [`Done`] where the
    /// answer's header is all there is (v049: each command's "回傳值" and
    /// "回傳資料" paragraphs). Naming it here is what lets the host decode
    /// an answer by the request that asked for it, never by hand.
    type Answer<'r>: FromAnswer<'r, Self>;
}

/// What the host reads out of the answer to a request `Q`: its return
/// value and valid data, read with the request at hand, since some answers
/// do not say what they are (SLAVE_INFO's data is the item asked for).
/// Every [`Reply`] is one, whatever asked; [`Done`] is the answer that
/// carries nothing.
pub trait FromAnswer<'r, Q>: Sized {
    /// Reads it from a response's fields and valid data.
    fn from_answer(request: &Q, fields: &ReplyFields, data: &'r [u8]) -> Result<Self, PayloadError>;
}

impl<'r, Q, T: Reply<'r>> FromAnswer<'r, Q> for T {
    fn from_answer(_request: &Q, fields: &ReplyFields, data: &'r [u8]) -> Result<Self, PayloadError> {
        T::decode(fields, data)
    }
}

/// The answer of a command that only runs: whether it ran is in the
/// header's error flags, and there is nothing else to read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Done;

impl<Q> FromAnswer<'_, Q> for Done {
    fn from_answer(_request: &Q, _fields: &ReplyFields, _data: &[u8]) -> Result<Self, PayloadError> {
        Ok(Self)
    }
}

/// The chip's answer to a command: return value and data.
pub trait Reply<'a>: Sized {
    /// The command code it answers.
    const CODE: CommandCode;
    /// Writes the data section (which arrives zeroed) and returns the header
    /// fields.
    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError>;
    /// Reads it from a response's fields and valid data.
    fn decode(fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError>;
}

/// A request with no payload at all: only the code matters.
macro_rules! bare_request {
    ($($(#[$doc:meta])* $name:ident => $code:ident -> $answer:ty;)*) => {$(
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
        pub struct $name;

        impl<'a> $crate::payload::Request<'a> for $name {
            const CODE: $crate::CommandCode = $crate::CommandCode::$code;
            type Answer<'r> = $answer;
            fn encode(&self, _data: &mut [u8]) -> Result<$crate::payload::RequestFields, $crate::EncodeError> {
                Ok($crate::payload::RequestFields::default())
            }
            fn decode(_fields: &$crate::payload::RequestFields, _data: &'a [u8]) -> Result<Self, $crate::PayloadError> {
                Ok(Self)
            }
        }
    )*};
}
pub(crate) use bare_request;

/// A reply whose only content is the header's return value byte.
macro_rules! value_reply {
    ($($(#[$doc:meta])* $name:ident => $code:ident;)*) => {$(
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
        pub struct $name(pub u8);

        impl<'a> $crate::payload::Reply<'a> for $name {
            const CODE: $crate::CommandCode = $crate::CommandCode::$code;
            fn encode(&self, _data: &mut [u8]) -> Result<$crate::payload::ReplyFields, $crate::EncodeError> {
                Ok($crate::payload::ReplyFields { value: self.0, data_len: 0 })
            }
            fn decode(fields: &$crate::payload::ReplyFields, _data: &'a [u8]) -> Result<Self, $crate::PayloadError> {
                Ok(Self(fields.value))
            }
        }
    )*};
}
pub(crate) use value_reply;

/// A request whose only content is the header's parameter byte.
macro_rules! parameter_request {
    ($($(#[$doc:meta])* $name:ident => $code:ident -> $answer:ty;)*) => {$(
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
        pub struct $name(pub u8);

        impl<'a> $crate::payload::Request<'a> for $name {
            const CODE: $crate::CommandCode = $crate::CommandCode::$code;
            type Answer<'r> = $answer;
            fn encode(&self, _data: &mut [u8]) -> Result<$crate::payload::RequestFields, $crate::EncodeError> {
                Ok($crate::payload::RequestFields::parameter(self.0))
            }
            fn decode(fields: &$crate::payload::RequestFields, _data: &'a [u8]) -> Result<Self, $crate::PayloadError> {
                Ok(Self(fields.parameter))
            }
        }
    )*};
}
pub(crate) use parameter_request;

/// A reply carrying one little-endian integer in the data section. Decoding
/// accepts the data length the chip gives (1..=size bytes): the manual does
/// not always say the width.
macro_rules! int_data_reply {
    ($($(#[$doc:meta])* $name:ident($ty:ty) => $code:ident;)*) => {$(
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
        pub struct $name(pub $ty);

        impl<'a> $crate::payload::Reply<'a> for $name {
            const CODE: $crate::CommandCode = $crate::CommandCode::$code;
            fn encode(&self, data: &mut [u8]) -> Result<$crate::payload::ReplyFields, $crate::EncodeError> {
                let bytes = self.0.to_le_bytes();
                let mut w = $crate::bytes::Writer::new(data);
                w.bytes(&bytes)?;
                Ok($crate::payload::ReplyFields { value: 0, data_len: w.len_u16() })
            }
            fn decode(_fields: &$crate::payload::ReplyFields, data: &'a [u8]) -> Result<Self, $crate::PayloadError> {
                let mut bytes = [0u8; core::mem::size_of::<$ty>()];
                if data.is_empty() {
                    return Err($crate::PayloadError::TooShort { field: stringify!($name), needed: bytes.len(), available: 0 });
                }
                let n = data.len().min(bytes.len());
                bytes[..n].copy_from_slice(&data[..n]);
                Ok(Self(<$ty>::from_le_bytes(bytes)))
            }
        }
    )*};
}
pub(crate) use int_data_reply;

/// Checks that the header declares the data length the manual gives the
/// command (v049, "資料長度" under each command): a packet laid out for
/// another length would have its fields read from the wrong offsets (the
/// vendor driver's PDO_CONFIG_REQ with 156 bytes where the layout has 4),
/// so the chip refuses it whole (error bit7) instead of executing it.
/// Only commands with a data layout are checked; for the others the length
/// field is unused or "a per-command value" (v049 表一 0x0E).
pub(crate) fn fixed_len(fields: &RequestFields, command: CommandCode, expected: u16) -> Result<(), PayloadError> {
    if fields.data_len == expected {
        Ok(())
    } else {
        Err(PayloadError::DataLength { command, expected, found: fields.data_len })
    }
}

/// Takes the valid part of a data section, by a length field.
pub(crate) fn valid<'a>(field: &'static str, data: &'a [u8], len: usize) -> Result<&'a [u8], PayloadError> {
    data.get(..len).ok_or(PayloadError::TooShort { field, needed: len, available: data.len() })
}

#[cfg(test)]
pub(crate) mod testing {
    //! Round-trip helpers shared by every payload module's tests.
    use super::*;
    use crate::framing::DATA_MAX;

    /// Encodes `req` into a zeroed maximal data section and decodes it back.
    pub fn request_round_trip<R>(req: &R) -> (RequestFields, std::vec::Vec<u8>)
    where
        R: for<'a> Request<'a> + PartialEq + core::fmt::Debug,
    {
        let mut data = [0u8; DATA_MAX];
        let fields = req.encode(&mut data).expect("encode");
        let back = R::decode(&fields, &data).expect("decode");
        assert_eq!(&back, req);
        (fields, data.to_vec())
    }

    /// Same for replies; decoding sees only the valid data, as on the wire.
    pub fn reply_round_trip<R>(reply: &R) -> (ReplyFields, std::vec::Vec<u8>)
    where
        R: for<'a> Reply<'a> + PartialEq + core::fmt::Debug,
    {
        let mut data = [0u8; DATA_MAX];
        let fields = reply.encode(&mut data).expect("encode");
        let valid = &data[..usize::from(fields.data_len)];
        let back = R::decode(&fields, valid).expect("decode");
        assert_eq!(&back, reply);
        (fields, valid.to_vec())
    }
}
