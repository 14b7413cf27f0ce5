//! `ecmxf-wire`: the SPI packet codec of the NEXTW ECM-XF EtherCAT master chip.
//!
//! Pure and allocation-free: no I/O, no clock, no logging, `no_std`. Everything
//! the daemon and the simulator say to each other passes through here, so every
//! byte position is taken from the manual (Traditional Chinese v049, which wins
//! over English v031; v031 only for `SDO_REQ`, whose v049 text is cut short).
//!
//! # Map
//! - [`framing`]: packet sizes, start/end words, finding a packet boundary in a
//!   byte stream.
//! - [`check`]: the check word (fixed value, CRC-8, CRC-16, CRC-32).
//! - [`flags`]: the typed bit sets of both headers (control, error, ECM status,
//!   interrupt flags, GPIO lines) and the ECAT state.
//! - [`command`]: every command code, its name and whether it is blocking.
//! - [`header`]: the 24-byte command and response headers.
//! - [`packet`]: whole packets: encode into a caller's buffer, decode and
//!   validate.
//! - [`payload`]: one typed request/reply per command code, behind the
//!   [`Request`] and [`Reply`] traits; [`AnyRequest`] parses any command.
//! - [`mbx`]: EtherCAT mailbox messages (ETG.1000.4/.6): header, CoE, SDO
//!   transfers and SDO Information, for what the host sends a slave's
//!   mailbox through raw datagrams and what an ETG.8200 gateway carries.
//! - [`error`]: the three error enums (encode, decode, payload).
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(test)]
extern crate std;

pub mod al_status;
mod bytes;
pub mod check;
pub mod command;
pub mod error;
pub mod flags;
pub mod framing;
pub mod header;
pub mod limits;
pub mod mbx;
pub mod packet;
pub mod payload;

pub use al_status::al_status_text;
pub use check::CheckType;
pub use command::CommandCode;
pub use error::{DecodeError, EncodeError, PayloadError};
pub use flags::{ControlFlags, EcatState, EcmStatus, ErrorFlags, GpioMask, HeaderOptions, InterruptFlags, StatusFlags};
pub use framing::{DATA_DEFAULT, DATA_MAX, DATA_MIN, PacketLayout};
pub use header::{CommandHeader, HEADER_LEN, ResponseHeader};
pub use packet::{
    CommandPacket, ResponsePacket, decode_command, decode_response, encode_command, encode_reply, encode_request,
    encode_response, read_answer,
};
pub use payload::{AnyRequest, Done, FromAnswer, Reply, ReplyFields, Request, RequestFields};
