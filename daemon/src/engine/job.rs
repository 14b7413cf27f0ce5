//! Requests from async code to the engine thread: each with a deadline and
//! a one-shot reply. A caller that stops waiting drops its receiver; the
//! engine sees that and never starts, or cleanly finishes, the work.

use std::time::Instant;

use ecmxf_wire::EcatState;
use ecmxf_wire::payload::slave_info::SlaveInfoCode;
use ecmxf_wire::payload::state::SlaveSelector;
use tokio::sync::oneshot;

use super::error::EngineError;

/// What to do.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Request {
    /// SDO upload.
    SdoRead {
        /// Slave.
        slave: u8,
        /// Index.
        index: u16,
        /// Subindex.
        subindex: u8,
        /// Complete access.
        complete: bool,
    },
    /// SDO download.
    SdoWrite {
        /// Slave.
        slave: u8,
        /// Index.
        index: u16,
        /// Subindex.
        subindex: u8,
        /// Complete access.
        complete: bool,
        /// Bytes.
        data: Vec<u8>,
    },
    /// One SII word pair (4 bytes from `word`).
    EepromRead {
        /// Slave.
        slave: u8,
        /// Word address.
        word: u16,
    },
    /// One SII word, verified by reading it back.
    EepromWrite {
        /// Slave.
        slave: u8,
        /// Word address.
        word: u16,
        /// Value.
        value: u16,
    },
    /// Request a state.
    SetState {
        /// Which slaves.
        target: SlaveSelector,
        /// State.
        state: EcatState,
    },
    /// One item of slave information.
    SlaveInfo {
        /// Slave.
        slave: u8,
        /// Item.
        item: SlaveInfoCode,
    },
}

impl Request {
    /// Whether the request uses the chip's blocking slot.
    pub fn is_blocking(&self) -> bool {
        !matches!(self, Self::SlaveInfo { .. })
    }
}

/// A request in flight.
#[derive(Debug)]
pub struct Job {
    /// What.
    pub request: Request,
    /// When the caller stops waiting.
    pub deadline: Instant,
    /// Where the result goes: data bytes (empty when there are none).
    pub reply: oneshot::Sender<Result<Vec<u8>, EngineError>>,
}

/// A write into the host-side output image, applied before the next frames
/// are pushed. Fixed size, so queuing one allocates nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputWrite {
    /// Byte offset in the output frame.
    pub offset: u32,
    /// Bytes used of `data`.
    pub len: u8,
    /// The bytes.
    pub data: [u8; 32],
}
