//! The engine's errors: one enum, every variant a distinct situation a
//! caller (and later the gRPC layer) handles differently.

use std::fmt;

use ecmxf_wire::payload::sdo::SdoAbortCode;

/// Why an engine request failed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum EngineError {
    /// A request argument is wrong; names the field.
    BadArgument {
        /// The field.
        field: &'static str,
        /// Why.
        reason: String,
    },
    /// The network is not in a state that allows this.
    WrongState(String),
    /// The slave aborted an SDO transfer.
    SdoAbort {
        /// Slave.
        slave: u8,
        /// Object index.
        index: u16,
        /// Subindex.
        subindex: u8,
        /// The abort code (ETG meaning via its Display).
        code: SdoAbortCode,
    },
    /// A blocking operation failed on the chip (error bit3) with no code.
    Failed(String),
    /// The chip refused the command (error bit7: bad parameter).
    Refused(String),
    /// The deadline passed before the result came.
    Timeout,
    /// The request queue is full.
    QueueFull,
    /// The engine is not running (stopped, or recovering from a fault).
    Unavailable(String),
    /// What a slave describes itself with (its SII) is corrupt; says where.
    BadDeviceData(String),
}

impl fmt::Display for EngineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadArgument { field, reason } => write!(f, "bad {field}: {reason}"),
            Self::WrongState(s) => write!(f, "wrong state: {s}"),
            Self::SdoAbort { slave, index, subindex, code } => {
                write!(f, "SDO {index:#06x}:{subindex:02x} on slave {slave} aborted: {code}")
            }
            Self::Failed(s) => write!(f, "failed: {s}"),
            Self::Refused(s) => write!(f, "refused by the chip: {s}"),
            Self::Timeout => f.write_str("deadline exceeded"),
            Self::QueueFull => f.write_str("request queue full"),
            Self::Unavailable(s) => write!(f, "engine unavailable: {s}"),
            Self::BadDeviceData(s) => f.write_str(s),
        }
    }
}

impl std::error::Error for EngineError {}
