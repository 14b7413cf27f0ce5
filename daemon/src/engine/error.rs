//! The engine's errors: one enum, every variant a distinct situation a
//! caller (and later the gRPC layer) handles differently.

use std::fmt;

use ecmxf_devices::sii::SiiError;
use ecmxf_wire::payload::sdo::SdoAbortCode;
use ecmxf_wire::{EcatState, PayloadError};

use super::failure::Failure;
use super::supervisor::RecoverCause;
use super::telemetry::Phase;

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
    WrongState(WrongState),
    /// The slave did not complete a FoE transfer. The chip passes on no
    /// FoE error code or text (v049 FOE_FUNC_REQ: only its error bit).
    FoeRefused {
        /// Slave.
        slave: u8,
        /// The file.
        name: String,
        /// A write (else a read).
        write: bool,
    },
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
    Unavailable(NotRunning),
    /// What a slave describes itself with (its SII) is corrupt; says where.
    BadDeviceData {
        /// The slave.
        slave: u8,
        /// What is wrong with it.
        error: SiiError,
    },
    /// An answer of the chip does not read as its command's reply.
    BadAnswer {
        /// What was asked, in words.
        what: String,
        /// What did not read.
        error: PayloadError,
    },
    /// The network did not come (back) up; the failure that stopped it.
    NotUp {
        /// What was waited for.
        waited_for: &'static str,
        /// The last failure.
        failure: Failure,
    },
}

impl fmt::Display for EngineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadArgument { field, reason } => write!(f, "bad {field}: {reason}"),
            Self::WrongState(s) => write!(f, "wrong state: {s}"),
            Self::SdoAbort { slave, index, subindex, code } => {
                write!(f, "SDO {index:#06x}:{subindex:02x} on slave {slave} aborted: {code}")
            }
            Self::FoeRefused { slave, name, write } => write!(
                f,
                "slave {slave} did not complete the FoE {} of {name:?}: no such file, a wrong password, or one it \
                 does not take (the chip passes on no FoE error code)",
                if *write { "write" } else { "read" }
            ),
            Self::Failed(s) => write!(f, "failed: {s}"),
            Self::Refused(s) => write!(f, "refused by the chip: {s}"),
            Self::Timeout => f.write_str("deadline exceeded"),
            Self::QueueFull => f.write_str("request queue full"),
            Self::Unavailable(s) => write!(f, "engine unavailable: {s}"),
            Self::BadDeviceData { slave, error } => write!(f, "slave {slave}'s SII is corrupt: {error}"),
            Self::BadAnswer { what, error } => write!(f, "{what}: unreadable answer: {error}"),
            Self::NotUp { waited_for, failure } => write!(f, "{waited_for}: {failure}"),
        }
    }
}

impl std::error::Error for EngineError {}

/// Why the network's state does not allow a request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WrongState {
    /// A slave refused the state asked for (STATE_CHECK failed).
    Refused(EcatState),
    /// A step of a state walk was refused, by this slave (see
    /// `master::states`).
    StepRefused {
        /// The slave.
        slave: u8,
        /// The state asked for.
        asked: EcatState,
        /// The state it is in, if it could be read.
        state: Option<EcatState>,
        /// Its AL status code, if it could be read.
        al_status: Option<u16>,
    },
    /// Nothing to stream: no slave maps a TxPDO.
    NoInputs,
    /// The slave does not speak CoE: its SII's mailbox protocols (word
    /// 0x1C) do not list it.
    NoCoe {
        /// The slave.
        slave: u8,
        /// The protocols its SII lists (ETG.1000.6 table 2 bits).
        protocols: u16,
    },
    /// The slave does not speak FoE: its SII's mailbox protocols do not
    /// list it.
    NoFoe {
        /// The slave.
        slave: u8,
        /// The protocols its SII lists.
        protocols: u16,
    },
}

/// The mailbox protocols of an SII's word 0x1C, by name ("none" for none).
fn protocol_names(protocols: u16) -> String {
    let names: Vec<&str> = [(0x01, "AoE"), (0x02, "EoE"), (0x04, "CoE"), (0x08, "FoE"), (0x10, "SoE"), (0x20, "VoE")]
        .into_iter()
        .filter(|(bit, _)| protocols & bit != 0)
        .map(|(_, name)| name)
        .collect();
    if names.is_empty() { "none".to_string() } else { names.join(", ") }
}

impl fmt::Display for WrongState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Refused(state) => write!(f, "a slave refused {state}"),
            Self::StepRefused { slave, asked, state, al_status } => {
                write!(f, "slave {slave} refused {asked}")?;
                if let Some(s) = state {
                    write!(f, ": it is in {s}")?;
                }
                match al_status {
                    Some(c) if *c != 0 => {
                        write!(f, ", AL status {c:#06x} ({})", ecmxf_wire::al_status_text(*c))
                    }
                    _ => Ok(()),
                }
            }
            Self::NoInputs => f.write_str("the process image has no inputs (no slave maps a TxPDO)"),
            Self::NoCoe { slave, protocols } => write!(
                f,
                "slave {slave} has no CoE mailbox (the mailbox protocols its SII lists: {})",
                protocol_names(*protocols)
            ),
            Self::NoFoe { slave, protocols } => write!(
                f,
                "slave {slave} has no FoE (the mailbox protocols its SII lists: {})",
                protocol_names(*protocols)
            ),
        }
    }
}

/// Why the engine cannot take a request now.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum NotRunning {
    /// The engine stopped, or its thread is gone.
    Stopped,
    /// It is bringing the network up (at start, or after a fault).
    BringingUp,
    /// A fault sent it back to bring-up.
    Recovering(RecoverCause),
    /// The network is not running: the engine's phase, and why it last
    /// failed if it said.
    Phase {
        /// The phase.
        phase: Phase,
        /// The last bring-up or recovery failure.
        last_error: Option<Failure>,
    },
}

impl fmt::Display for NotRunning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Stopped => f.write_str("engine stopped"),
            Self::BringingUp => f.write_str("bringing the network up"),
            Self::Recovering(why) => write!(f, "recovering: {why}"),
            Self::Phase { last_error: Some(why), .. } => write!(f, "the network is not running: {why}"),
            Self::Phase { phase, last_error: None } => write!(f, "the network is not running: {}", phase.name()),
        }
    }
}
