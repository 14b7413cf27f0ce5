//! The codec's errors: one enum per direction of work, each `Copy`, each
//! naming exactly what was wrong so a log line or a gRPC status can say it.

use core::fmt;

use crate::check::CheckType;
use crate::command::CommandCode;

/// Building a packet failed; nothing usable was written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EncodeError {
    /// The buffer's length is not a packet length (32 + data section of
    /// 32..=1408 bytes).
    PacketLength {
        /// The length given.
        len: usize,
    },
    /// The payload does not fit in the data section.
    PayloadTooLarge {
        /// Bytes the payload needs.
        needed: usize,
        /// Bytes the data section has.
        capacity: usize,
    },
    /// A field's value is outside what the manual allows.
    FieldOutOfRange {
        /// The field, as the manual names it.
        field: &'static str,
        /// The value given.
        value: u32,
        /// Smallest allowed value.
        min: u32,
        /// Largest allowed value.
        max: u32,
    },
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::PacketLength { len } => {
                write!(f, "{len} bytes is not an ECM-XF packet length (64..=1440: 24 header + 32..=1408 data + 8)")
            }
            Self::PayloadTooLarge { needed, capacity } => {
                write!(f, "payload needs {needed} bytes but the data section holds {capacity}")
            }
            Self::FieldOutOfRange { field, value, min, max } => {
                write!(f, "{field} = {value} is out of range {min}..={max}")
            }
        }
    }
}

impl core::error::Error for EncodeError {}

/// A received packet failed validation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// The buffer's length is not a packet length.
    PacketLength {
        /// The length received.
        len: usize,
    },
    /// The check word was 0x87654321: the chip was clocked before it was ready
    /// and the command sent in the same transfer was not taken (the vendor
    /// driver's reading, not in the manuals; docs/protocol.md §4). Not
    /// corruption: resend.
    ChipNotReady,
    /// Bytes 0..4 are not 0xA1A2A3A4.
    StartWord {
        /// What was there.
        found: u32,
    },
    /// The last four bytes are not 0x56575859.
    EndWord {
        /// What was there.
        found: u32,
    },
    /// The check word does not match the header and data section.
    CheckWord {
        /// The check type the packet was validated with.
        check_type: CheckType,
        /// The check word computed over the packet.
        expected: u32,
        /// The check word in the packet.
        found: u32,
    },
    /// The header's valid-data length is larger than the data section.
    DataLength {
        /// The length in the header.
        declared: u16,
        /// The data section's size.
        capacity: usize,
    },
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::PacketLength { len } => write!(f, "{len} bytes is not an ECM-XF packet length"),
            Self::ChipNotReady => f.write_str("chip not ready (check word 0x87654321): the command was not taken"),
            Self::StartWord { found } => write!(f, "bad start word {found:#010x} (want 0xa1a2a3a4)"),
            Self::EndWord { found } => write!(f, "bad end word {found:#010x} (want 0x56575859)"),
            Self::CheckWord { check_type, expected, found } => {
                write!(f, "{check_type} check word mismatch: packet has {found:#010x}, computed {expected:#010x}")
            }
            Self::DataLength { declared, capacity } => {
                write!(f, "header declares {declared} valid data bytes but the data section holds {capacity}")
            }
        }
    }
}

impl core::error::Error for DecodeError {}

/// A command's or reply's payload could not be interpreted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PayloadError {
    /// The packet carries another command code than the payload type expects.
    WrongCommand {
        /// The code the payload type belongs to.
        expected: CommandCode,
        /// The code in the packet.
        found: CommandCode,
    },
    /// The response is a NOP (ECM status bit5): it answers no command.
    Nop,
    /// The data ended before a field.
    TooShort {
        /// The field that was cut.
        field: &'static str,
        /// Bytes needed up to the end of that field.
        needed: usize,
        /// Bytes available.
        available: usize,
    },
    /// A field holds a value the manual does not allow.
    InvalidValue {
        /// The field, as the manual names it.
        field: &'static str,
        /// The value found.
        value: u32,
    },
    /// A command code the manual does not list.
    UnknownCommand {
        /// The raw code.
        code: u8,
    },
    /// The header's data length is not the one the manual gives the
    /// command's data layout.
    DataLength {
        /// The command.
        command: CommandCode,
        /// The length its layout has.
        expected: u16,
        /// The length the header declares.
        found: u16,
    },
}

impl fmt::Display for PayloadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::WrongCommand { expected, found } => {
                write!(f, "expected a {expected} packet, got {found}")
            }
            Self::Nop => f.write_str("response is a NOP (answers no command)"),
            Self::TooShort { field, needed, available } => {
                write!(f, "data too short for {field}: needs {needed} bytes, has {available}")
            }
            Self::InvalidValue { field, value } => write!(f, "invalid {field}: {value} ({value:#x})"),
            Self::UnknownCommand { code } => write!(f, "unknown command code {code}"),
            Self::DataLength { command, expected, found } => {
                write!(f, "{command} declares {found} data bytes; its layout has {expected}")
            }
        }
    }
}

impl core::error::Error for PayloadError {}
