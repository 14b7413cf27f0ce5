//! Requests from async code to the engine thread: each with a deadline and
//! a one-shot reply. A caller that stops waiting drops its receiver; the
//! engine sees that and never starts, or cleanly finishes, the work.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU32, AtomicUsize, Ordering};
use std::time::Instant;

use ecmxf_wire::EcatState;
use ecmxf_wire::payload::cia402::{Cia402CtlSet, Cia402StateSet};
use ecmxf_wire::payload::gpio::{GpioConfig, GpioFunc};
use ecmxf_wire::payload::periph::{AdcOp, DacOp, QeiOp};
use ecmxf_wire::payload::raw::DatagramHead;
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

/// A request in flight.
#[derive(Debug)]
pub struct Job {
    /// What.
    pub request: Request,
    /// When the caller stops waiting.
    pub deadline: Instant,
    /// Where the result goes: data bytes (empty when there are none).
    pub reply: oneshot::Sender<Result<Vec<u8>, EngineError>>,
    /// Where long transfers (FoE) report how far they are.
    pub progress: Option<Arc<TransferProgress>>,
    /// Who asked (0: no client), for fair turns on the blocking slot.
    pub client: u64,
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

/// One chunk of a write into the host-side output image. Fixed size, so
/// queuing one allocates nothing. A client write longer than one chunk is
/// several chunks with the same `batch`, queued back to back; the engine
/// applies them together (see [`OutputAssembler`]) so a frame never carries
/// half of a write, e.g. new targets for one axis and old ones for the next.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputWrite {
    /// Which client write this chunk belongs to.
    pub batch: u32,
    /// Whether this is the write's last chunk.
    pub last: bool,
    /// Byte offset in the output frame.
    pub offset: u32,
    /// Bytes used of `data`.
    pub len: u8,
    /// The bytes.
    pub data: [u8; OUTPUT_CHUNK],
}

/// Bytes per [`OutputWrite`].
pub const OUTPUT_CHUNK: usize = 32;

/// Collects the chunks of one client write and applies them at once.
#[derive(Debug)]
pub struct OutputAssembler {
    pending: Vec<OutputWrite>,
    batch: Option<u32>,
}

impl Default for OutputAssembler {
    fn default() -> Self {
        // 16 KiB of writes in one batch before the vector grows.
        Self { pending: Vec::with_capacity(512), batch: None }
    }
}

impl OutputAssembler {
    /// Takes a chunk; on a write's last chunk, copies the whole write into
    /// `image` (bytes beyond it are ignored). A write whose last chunk never
    /// came (its sender found the queue full) is dropped when the next one
    /// starts: a partial write is never applied.
    pub fn push(&mut self, w: OutputWrite, image: Option<&mut [u8]>) {
        if self.batch != Some(w.batch) {
            self.pending.clear();
            self.batch = Some(w.batch);
        }
        self.pending.push(w);
        if !w.last {
            return;
        }
        if let Some(image) = image {
            for p in &self.pending {
                let at = p.offset as usize;
                let n = usize::from(p.len).min(OUTPUT_CHUNK);
                if let Some(dst) = image.get_mut(at..at + n) {
                    dst.copy_from_slice(&p.data[..n]);
                }
            }
        }
        self.pending.clear();
        self.batch = None;
    }
}

/// Who writes the outputs: counted leases, and a flag the last one raises
/// as it goes, so the engine can apply `outputs.on_last_writer_gone`
/// without a lock or a message on the cycle path.
#[derive(Debug, Default)]
pub struct Writers {
    count: AtomicUsize,
    gone: AtomicBool,
}

impl Writers {
    /// A writer arrives.
    pub fn acquire(&self) {
        self.count.fetch_add(1, Ordering::AcqRel);
    }

    /// A writer leaves; the last one raises the flag.
    pub fn release(&self) {
        if self.count.fetch_sub(1, Ordering::AcqRel) == 1 {
            self.gone.store(true, Ordering::Release);
        }
    }

    /// Writers now.
    pub fn count(&self) -> usize {
        self.count.load(Ordering::Acquire)
    }

    /// Whether the last writer left since the previous call, and no new one
    /// came meanwhile.
    pub fn take_gone(&self) -> bool {
        self.gone.swap(false, Ordering::AcqRel) && self.count() == 0
    }
}

/// A whole-network action a client asked for, picked up by the engine at
/// its next loop turn (no queue: asking twice is asking once).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NetworkAction {
    /// Scan again and redo the bring-up from the configuration.
    Reinit = 1,
    /// Warm-reset the chip (cmd 127), then redo the bring-up.
    WarmReset = 2,
}

/// The pending [`NetworkAction`], if any.
#[derive(Debug, Default)]
pub struct PendingAction(AtomicU8);

impl PendingAction {
    /// Asks for `a` (a warm reset wins over a re-init).
    pub fn request(&self, a: NetworkAction) {
        self.0.fetch_max(a as u8, Ordering::AcqRel);
    }

    /// Takes the pending action.
    pub fn take(&self) -> Option<NetworkAction> {
        match self.0.swap(0, Ordering::AcqRel) {
            1 => Some(NetworkAction::Reinit),
            2 => Some(NetworkAction::WarmReset),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chunk(batch: u32, last: bool, offset: u32, byte: u8) -> OutputWrite {
        OutputWrite { batch, last, offset, len: 2, data: [byte; OUTPUT_CHUNK] }
    }

    #[test]
    fn writes_apply_whole_or_not_at_all() {
        let mut a = OutputAssembler::default();
        let mut image = [0u8; 8];
        a.push(chunk(1, false, 0, 1), Some(&mut image));
        assert_eq!(image, [0; 8], "nothing before the last chunk");
        a.push(chunk(1, true, 4, 1), Some(&mut image));
        assert_eq!(image, [1, 1, 0, 0, 1, 1, 0, 0]);
        // Batch 2 lost its last chunk; batch 3 must not carry it in.
        a.push(chunk(2, false, 2, 2), Some(&mut image));
        a.push(chunk(3, true, 6, 3), Some(&mut image));
        assert_eq!(image, [1, 1, 0, 0, 1, 1, 3, 3]);
        // Out of range bytes are ignored, not a panic.
        a.push(chunk(4, true, 7, 4), Some(&mut image));
        a.push(chunk(5, true, u32::MAX, 4), Some(&mut image));
        assert_eq!(image, [1, 1, 0, 0, 1, 1, 3, 3]);
    }

    #[test]
    fn a_warm_reset_wins_and_an_action_is_taken_once() {
        let a = PendingAction::default();
        assert_eq!(a.take(), None);
        a.request(NetworkAction::Reinit);
        a.request(NetworkAction::WarmReset);
        a.request(NetworkAction::Reinit);
        assert_eq!(a.take(), Some(NetworkAction::WarmReset));
        assert_eq!(a.take(), None);
    }

    #[test]
    fn only_the_last_writer_leaving_counts() {
        let w = Writers::default();
        assert!(!w.take_gone());
        w.acquire();
        w.acquire();
        w.release();
        assert!(!w.take_gone(), "one writer is left");
        w.release();
        assert!(w.take_gone());
        assert!(!w.take_gone(), "reported once");
        w.acquire();
        w.release();
        w.acquire();
        assert!(!w.take_gone(), "a new writer came before the engine looked");
    }
}
