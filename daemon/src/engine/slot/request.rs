//! What async code asks of the blocking slot: a [`SlotRequest`] wrapped in
//! a [`Job`] with a deadline and a one-shot reply. A caller that stops
//! waiting drops its receiver; the engine sees that and never starts, or
//! cleanly finishes, the work.

use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Instant;

use ecmxf_wire::EcatState;
use ecmxf_wire::payload::cia402::{Cia402CtlSet, Cia402StateSet};
use ecmxf_wire::payload::gpio::{GpioConfig, GpioFunc};
use ecmxf_wire::payload::periph::{AdcOp, DacOp, QeiOp};
use ecmxf_wire::payload::raw::DatagramHead;
use ecmxf_wire::payload::slave_info::SlaveInfoCode;
use ecmxf_wire::payload::state::SlaveSelector;
use tokio::sync::oneshot;

use crate::engine::error::EngineError;

/// What to do.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum SlotRequest {
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
    /// The state the slaves report now (STATE_UPDATE, then STATE_GET; the
    /// result is one byte, the state).
    GetState {
        /// Which slaves (All: the network's lowest state, as the chip reports it).
        target: SlaveSelector,
    },
    /// One item of slave information.
    SlaveInfo {
        /// Slave.
        slave: u8,
        /// Item.
        item: SlaveInfoCode,
    },
    /// A slave's PDO assignment and mapping as the slave reports it
    /// (cmds 8/9; at most 3 PDOs of 8 entries are carried).
    PdoConfigRead {
        /// Slave.
        slave: u8,
        /// 0x1C12 (RxPDO) or 0x1C13 (TxPDO).
        assign_index: u16,
    },
    /// One raw EtherCAT datagram (cmds 137/138). The result is the working
    /// counter (u16, little-endian) followed by the returned data.
    Raw {
        /// Addressing and size.
        head: DatagramHead,
        /// Bytes a writing datagram sends (empty for reads).
        data: Vec<u8>,
    },
    /// A file written to a slave over FoE: staged into the chip's flash in
    /// chunks, then downloaded (cmd 139 ops 4 then 2).
    FoeWrite {
        /// Slave.
        slave: u8,
        /// File name.
        name: String,
        /// FoE password, 0 when none.
        password: u32,
        /// The file.
        data: Vec<u8>,
    },
    /// A file read from a slave over FoE: uploaded into the chip's flash,
    /// then read back in chunks (cmd 139 ops 1 then 3, cmd 140).
    FoeRead {
        /// Slave.
        slave: u8,
        /// File name.
        name: String,
        /// FoE password, 0 when none.
        password: u32,
        /// Largest file accepted.
        max_len: u32,
    },
    /// A non-blocking chip command (peripherals, the CiA402 helper, the
    /// emergency history): answered in the next packet, never occupies the
    /// blocking slot's busy bit. The result is the return value byte
    /// followed by the answer's data.
    Immediate(Immediate),
}

/// The non-blocking commands the API reaches (v049 表三: commands 26..35,
/// 74 and 83 are not in the blocking list).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Immediate {
    /// GPIO_CONFIG_SET (31).
    GpioConfig(GpioConfig),
    /// GPIO_FUNC_OP (32).
    Gpio(GpioFunc),
    /// QEI_FUNC_OP (33).
    Qei(QeiOp),
    /// DAC_FUNC_OP (34).
    Dac(DacOp),
    /// ADC_FUNC_OP (35).
    Adc(AdcOp),
    /// 402_STATE_SET (27): the helper walks an axis to a state.
    Cia402StateSet(Cia402StateSet),
    /// 402_CTL_SET (29): the helper's control byte (one fault reset...).
    Cia402CtlSet(Cia402CtlSet),
    /// 402_STATE_GET (28) of an axis.
    Cia402StateGet(u8),
    /// 402_GET_STATUSWORD (74) of an axis.
    Cia402Statusword(u8),
    /// COE_EMERGENCY (83): the last n (1..=8) emergency records.
    Emergencies(u8),
}

impl SlotRequest {
    /// The bytes the request carries to the chip: an SDO download's, a raw
    /// datagram's, an FoE file; empty for the others.
    pub(super) fn payload(&self) -> &[u8] {
        match self {
            Self::SdoWrite { data, .. } | Self::Raw { data, .. } | Self::FoeWrite { data, .. } => data,
            _ => &[],
        }
    }

    /// An FoE transfer's file name; empty for the others.
    pub(super) fn file_name(&self) -> &str {
        match self {
            Self::FoeWrite { name, .. } | Self::FoeRead { name, .. } => name,
            _ => "",
        }
    }
}

/// The request in words, for errors a client reads.
impl std::fmt::Display for SlotRequest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::SdoRead { slave, index, subindex, .. } => {
                write!(f, "SDO read {index:#06x}:{subindex:02x} of slave {slave}")
            }
            Self::SdoWrite { slave, index, subindex, .. } => {
                write!(f, "SDO write {index:#06x}:{subindex:02x} to slave {slave}")
            }
            Self::EepromRead { slave, word } => write!(f, "EEPROM read of word {word:#06x} of slave {slave}"),
            Self::EepromWrite { slave, word, .. } => write!(f, "EEPROM write of word {word:#06x} of slave {slave}"),
            Self::SetState { target, state } => write!(f, "{state} for {target}"),
            Self::GetState { target } => write!(f, "state of {target}"),
            Self::SlaveInfo { slave, item } => write!(f, "{item} of slave {slave}"),
            Self::PdoConfigRead { slave, assign_index } => {
                write!(f, "PDO assignment {assign_index:#06x} of slave {slave}")
            }
            Self::Raw { head, .. } => {
                write!(f, "{} datagram ADP {:#06x} ADO {:#06x}", head.command, head.adp, head.ado)
            }
            Self::FoeWrite { slave, name, .. } => write!(f, "FoE write of {name:?} to slave {slave}"),
            Self::FoeRead { slave, name, .. } => write!(f, "FoE read of {name:?} from slave {slave}"),
            Self::Immediate(i) => f.write_str(match i {
                Immediate::GpioConfig(_) => "GPIO configuration",
                Immediate::Gpio(_) => "GPIO operation",
                Immediate::Qei(_) => "encoder (QEI) operation",
                Immediate::Dac(_) => "DAC operation",
                Immediate::Adc(_) => "ADC read",
                Immediate::Cia402StateSet(_) => "CiA 402 helper state",
                Immediate::Cia402CtlSet(_) => "CiA 402 helper control",
                Immediate::Cia402StateGet(_) => "CiA 402 helper state read",
                Immediate::Cia402Statusword(_) => "CiA 402 statusword read",
                Immediate::Emergencies(_) => "emergency read",
            }),
        }
    }
}

/// A request in flight.
#[derive(Debug)]
pub(crate) struct Job {
    /// What.
    pub request: SlotRequest,
    /// When the caller stops waiting.
    pub deadline: Instant,
    /// Where the result goes: data bytes (empty when there are none).
    pub reply: oneshot::Sender<Result<Vec<u8>, EngineError>>,
    /// Where long transfers (FoE) report how far they are.
    pub progress: Option<Arc<TransferProgress>>,
    /// Who asked (0: no client), for fair turns on the blocking slot.
    pub client: u64,
    /// Where the reply's bytes go: allocated by the caller with
    /// [`reply_capacity`], so the engine thread copies instead of
    /// allocating.
    pub buffer: Vec<u8>,
}

/// The most bytes a reply to `request` can hold: one answer's data section
/// and the two bytes a raw datagram's working counter adds; an FoE read
/// holds the whole file, up to its `max_len`.
pub(crate) fn reply_capacity(request: &SlotRequest) -> usize {
    match request {
        SlotRequest::FoeRead { max_len, .. } => *max_len as usize,
        _ => ecmxf_wire::DATA_MAX + 2,
    }
}

/// Bytes moved so far of a long transfer, readable at any time without a
/// lock (the engine thread stores, anyone loads).
#[derive(Debug, Default)]
pub struct TransferProgress {
    done: AtomicU32,
    total: AtomicU32,
}

impl TransferProgress {
    /// (bytes done, bytes in all; 0 while not yet known).
    pub fn get(&self) -> (u32, u32) {
        (self.done.load(Ordering::Relaxed), self.total.load(Ordering::Relaxed))
    }

    pub(crate) fn set(&self, done: u32, total: u32) {
        self.total.store(total, Ordering::Relaxed);
        self.done.store(done, Ordering::Relaxed);
    }
}
