//! The engine's state for everyone else, published without locks: the RT
//! thread stores atomics, readers load them. Individual values are exact;
//! a reader may see values from two neighbouring exchanges side by side.

use std::sync::Mutex;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering::Relaxed};

use ecmxf_wire::{EcatState, ResponseHeader};

/// What the engine is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Phase {
    /// Starting, before the link is up.
    Starting = 0,
    /// Running the bring-up sequence.
    BringUp = 1,
    /// Cyclic exchange in the target state.
    Running = 2,
    /// Recovering from a fault.
    Recovering = 3,
    /// Stopping (safe stop).
    Stopping = 4,
    /// Stopped.
    Stopped = 5,
}

impl Phase {
    fn from_u8(v: u8) -> Self {
        match v {
            1 => Self::BringUp,
            2 => Self::Running,
            3 => Self::Recovering,
            4 => Self::Stopping,
            5 => Self::Stopped,
            _ => Self::Starting,
        }
    }
}

/// The published values.
#[derive(Debug, Default)]
pub struct Telemetry {
    phase: AtomicU8,
    ecat_state: AtomicU8,
    error_byte: AtomicU8,
    status_byte: AtomicU8,
    crc_errors: AtomicU8,
    wkc_errors: AtomicU8,
    rx_fifo: AtomicU8,
    tx_fifo: AtomicU8,
    /// Exchanges clocked.
    pub exchanges: AtomicU64,
    /// Answers that failed validation.
    pub corrupt: AtomicU64,
    /// Not-ready answers.
    pub not_ready: AtomicU64,
    /// Input frames published.
    pub input_frames: AtomicU64,
    /// Input frames lost (corrupt FIFO answers).
    pub input_batches_lost: AtomicU64,
    /// Output frames pushed.
    pub output_frames: AtomicU64,
    /// Times the chip reported its RxFIFO empty in OP (FIFO error bit).
    pub fifo_alarms: AtomicU64,
    /// Blocking transactions completed.
    pub transactions: AtomicU64,
    /// Recoveries started.
    pub recoveries: AtomicU64,
    /// Longest time between two FIFO exchanges in OP, us: the margin the
    /// RxFIFO needs (a thread stalled by the OS or the hypervisor shows
    /// here).
    pub max_fifo_gap_us: AtomicU64,
    /// The number of the last configuration a client applied that the
    /// engine has taken (0: the one it started with).
    pub config_generation: AtomicU64,
    /// The engine's epoch (time 0 of every `time_ns`) on the host's
    /// CLOCK_MONOTONIC, ns: lets a client on the same host measure how old
    /// a frame is when it arrives.
    pub epoch_monotonic_ns: AtomicU64,
    /// The last bring-up or recovery reason; written only when something
    /// fails, never on the cycle path.
    last_error: Mutex<Option<String>>,
}

/// A consistent-enough copy for display.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Snapshot {
    /// Phase.
    pub phase: Phase,
    /// ECAT state byte.
    pub ecat_state: EcatState,
    /// Error byte.
    pub error_byte: u8,
    /// ECM status byte.
    pub status_byte: u8,
    /// SPI CRC error counter.
    pub crc_errors: u8,
    /// WKC error counter.
    pub wkc_errors: u8,
    /// RxFIFO frames (header, two exchanges late).
    pub rx_fifo: u8,
    /// TxFIFO frames.
    pub tx_fifo: u8,
    /// Exchanges.
    pub exchanges: u64,
    /// Answers the host found corrupt (check word, framing).
    pub corrupt: u64,
    /// Answers the chip marked not ready (its command was lost and resent).
    pub not_ready: u64,
    /// Batches of input frames lost with a corrupt FIFO answer.
    pub input_batches_lost: u64,
    /// Blocking-slot transactions completed.
    pub transactions: u64,
    /// Input frames published.
    pub input_frames: u64,
    /// Output frames pushed.
    pub output_frames: u64,
    /// FIFO alarms.
    pub fifo_alarms: u64,
    /// Recoveries.
    pub recoveries: u64,
    /// Longest gap between FIFO exchanges, us.
    pub max_fifo_gap_us: u64,
    /// The last applied configuration the engine has taken (0: the first).
    pub config_generation: u64,
}

impl Telemetry {
    /// Sets the phase.
    pub fn set_phase(&self, p: Phase) {
        self.phase.store(p as u8, Relaxed);
    }

    /// The phase.
    pub fn phase(&self) -> Phase {
        Phase::from_u8(self.phase.load(Relaxed))
    }

    /// Stores a header's status.
    pub fn header(&self, h: &ResponseHeader) {
        self.ecat_state.store(h.ecat_state.to_u8(), Relaxed);
        self.error_byte.store(h.errors.bits(), Relaxed);
        self.status_byte.store(h.status.to_byte(), Relaxed);
        self.crc_errors.store(h.crc_errors, Relaxed);
        self.wkc_errors.store(h.wkc_errors, Relaxed);
        self.rx_fifo.store(h.rx_fifo_count, Relaxed);
        self.tx_fifo.store(h.tx_fifo_count, Relaxed);
    }

    /// Records why bring-up failed or recovery started.
    pub fn set_error(&self, e: String) {
        *self.last_error.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
    }

    /// The last failure, if any.
    pub fn last_error(&self) -> Option<String> {
        self.last_error.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// A copy.
    pub fn snapshot(&self) -> Snapshot {
        Snapshot {
            phase: self.phase(),
            ecat_state: EcatState::from_u8(self.ecat_state.load(Relaxed)),
            error_byte: self.error_byte.load(Relaxed),
            status_byte: self.status_byte.load(Relaxed),
            crc_errors: self.crc_errors.load(Relaxed),
            wkc_errors: self.wkc_errors.load(Relaxed),
            rx_fifo: self.rx_fifo.load(Relaxed),
            tx_fifo: self.tx_fifo.load(Relaxed),
            exchanges: self.exchanges.load(Relaxed),
            corrupt: self.corrupt.load(Relaxed),
            not_ready: self.not_ready.load(Relaxed),
            input_batches_lost: self.input_batches_lost.load(Relaxed),
            transactions: self.transactions.load(Relaxed),
            input_frames: self.input_frames.load(Relaxed),
            output_frames: self.output_frames.load(Relaxed),
            fifo_alarms: self.fifo_alarms.load(Relaxed),
            recoveries: self.recoveries.load(Relaxed),
            max_fifo_gap_us: self.max_fifo_gap_us.load(Relaxed),
            config_generation: self.config_generation.load(Relaxed),
        }
    }
}
