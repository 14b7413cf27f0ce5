//! The engine's state for everyone else. The RT thread stores atomics,
//! readers load them ([`Telemetry::snapshot`]): individual values are exact,
//! a reader may see values from two neighbouring exchanges side by side.
//! Whoever waits for a change (a phase, a state, a configuration taken)
//! awaits the [`watch`] of snapshots instead ([`Telemetry::watch`]): the
//! engine sends one at once when the phase, network state, configuration
//! generation or recovery count changes, and at least every
//! [`ANNOUNCE_EVERY`] while it runs, so counters reach waiters too.

use super::failure::Failure;
use super::trouble::{Recent, RecentTrouble};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU8, AtomicU32, AtomicU64, Ordering::Relaxed};
use std::time::Duration;

use ecmxf_wire::{EcatState, ResponseHeader};
use tokio::sync::watch;

/// The longest the [`watch`] of snapshots goes without a new one while the
/// engine exchanges packets (counters move without a change of phase).
pub(crate) const ANNOUNCE_EVERY: Duration = Duration::from_millis(10);

/// What the engine is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum Phase {
    /// Starting, before the link is up.
    #[default]
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
    /// The phase in words ("bringing the network up"), for events and
    /// messages a user reads.
    pub fn name(self) -> &'static str {
        match self {
            Self::Starting => "starting",
            Self::BringUp => "bringing the network up",
            Self::Running => "running",
            Self::Recovering => "recovering",
            Self::Stopping => "stopping",
            Self::Stopped => "stopped",
        }
    }
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
pub(crate) struct Telemetry {
    phase: AtomicU8,
    ecat_state: AtomicU8,
    error_byte: AtomicU8,
    status_byte: AtomicU8,
    rx_fifo: AtomicU8,
    tx_fifo: AtomicU8,
    /// CRC errors the chip counted, since the daemon started (accumulated
    /// from its 8-bit counter: see [`CounterTotal`]).
    pub crc_errors: AtomicU64,
    /// Working-counter errors the chip counted, since the daemon started.
    pub wkc_errors: AtomicU64,
    /// Exchanges clocked.
    pub exchanges: AtomicU64,
    /// Answers that failed validation.
    pub corrupt: AtomicU64,
    /// Not-ready answers.
    pub not_ready: AtomicU64,
    /// Input frames received from the chip.
    pub input_frames: AtomicU64,
    /// FIFO answers lost for good, their input frames numbered as a gap
    /// (pipelined calls only: see `engine::fifo_reads`).
    pub input_batches_lost: AtomicU64,
    /// Input frames dropped because the distributor fell behind the engine.
    pub ring_overflows: AtomicU64,
    /// When the newest input frame arrived (for networks without inputs:
    /// the newest intact FIFO answer), ns since the engine's epoch.
    pub newest_input_ns: AtomicU64,
    /// How old the newest input may be before process data counts as not
    /// flowing, ns; 0 while no cyclic exchange runs (see
    /// `supervisor::flow_limit`).
    pub flow_limit_ns: AtomicU64,
    /// Output frames pushed.
    pub output_frames: AtomicU64,
    /// Times the chip reported its RxFIFO empty in OP (FIFO error bit).
    pub fifo_alarms: AtomicU64,
    /// Blocking transactions completed.
    pub transactions: AtomicU64,
    /// Recoveries started.
    pub recoveries: AtomicU64,
    /// Slaves in the network that runs (set at each bring-up).
    pub slaves: AtomicU64,
    /// INT0 stays at its ready level while packets go through
    /// (`supervisor::Int0Watch`).
    pub int0_stuck: std::sync::atomic::AtomicBool,
    /// The most slaves a running network had since the start (or the last
    /// re-init or new configuration, which accept the network as it is).
    pub slaves_seen: AtomicU64,
    /// Longest time between two FIFO exchanges in OP, us: the margin the
    /// RxFIFO needs (a thread stalled by the OS or the hypervisor shows
    /// here).
    pub max_fifo_gap_us: AtomicU64,
    /// The number of the last configuration a client applied that the
    /// engine has taken (0: the one it started with).
    pub config_generation: AtomicU64,
    /// The engine stopped because the network can never run with this
    /// configuration (a permanent bring-up error, e.g. the link budget):
    /// restarting the daemon cannot help.
    pub refused: std::sync::atomic::AtomicBool,
    /// The engine's epoch (time 0 of every `time_ns`) on the host's
    /// CLOCK_MONOTONIC, ns: lets a client on the same host measure how old
    /// a frame is when it arrives.
    pub epoch_monotonic_ns: AtomicU64,
    /// The last bring-up or recovery reason; written only when something
    /// fails, never on the cycle path.
    last_error: Mutex<Option<Failure>>,
    /// Snapshots for waiters (see the module comment).
    changes: watch::Sender<Snapshot>,
    /// The latest write-to-wire latencies of client output writes.
    pub output_latency: LatencyWindow,
    /// Writes that reached the wire later than the budget.
    pub output_latency_misses: AtomicU64,
    /// Input frames never received: dropped by the chip (TxFIFO full) or
    /// carried by a lost FIFO answer.
    pub inputs_dropped_by_chip: AtomicU64,
    /// The latest run of RxFIFO alarms (health, see [`RecentTrouble`]).
    pub recent_fifo_alarms: RecentTrouble,
    /// The latest run of input frames the chip dropped.
    pub recent_chip_drops: RecentTrouble,
    /// The latest run of FIFO exchanges later than the process-data limit
    /// after the one before (the host stalled); figure: the gap, us.
    pub recent_long_gaps: RecentTrouble,
    /// A client holds the network below the target state on purpose:
    /// stale inputs are no stall then.
    pub stall_excused: std::sync::atomic::AtomicBool,
    /// `newest_input_ns + 1` of the stall already announced (see
    /// [`Telemetry::claim_stall_notice`]); 0: none.
    stall_noticed: AtomicU64,
}

/// The latest [`LatencyWindow::LEN`] latencies, us, written by the engine
/// without a lock; readers copy them and take percentiles.
#[derive(Debug)]
pub(crate) struct LatencyWindow {
    samples: [AtomicU32; LatencyWindow::LEN],
    recorded: AtomicU64,
}

impl Default for LatencyWindow {
    fn default() -> Self {
        Self { samples: std::array::from_fn(|_| AtomicU32::new(0)), recorded: AtomicU64::new(0) }
    }
}

/// Percentiles of a [`LatencyWindow`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct LatencyStats {
    /// Median, us.
    pub p50_us: u32,
    /// 99th percentile, us.
    pub p99_us: u32,
    /// Samples they are taken over.
    pub samples: usize,
}

impl LatencyWindow {
    /// Samples kept.
    pub(crate) const LEN: usize = 512;

    /// Records one latency (the engine thread).
    pub(crate) fn record(&self, us: u32) {
        let n = self.recorded.load(Relaxed);
        self.samples[(n % Self::LEN as u64) as usize].store(us, Relaxed);
        self.recorded.store(n + 1, Relaxed);
    }

    /// Median and 99th percentile of the latest samples; `None` before the
    /// first. Sorts a copy: for readers, never the engine thread.
    pub(crate) fn stats(&self) -> Option<LatencyStats> {
        let n = (self.recorded.load(Relaxed) as usize).min(Self::LEN);
        if n == 0 {
            return None;
        }
        let mut v: Vec<u32> = self.samples[..n].iter().map(|a| a.load(Relaxed)).collect();
        v.sort_unstable();
        let at = |p: f64| v[((n - 1) as f64 * p).round() as usize];
        Some(LatencyStats { p50_us: at(0.5), p99_us: at(0.99), samples: n })
    }
}

/// A total accumulated from one of the chip's 8-bit counters (CRC errors,
/// WKC errors: v049 header bytes 21/22), which wrap at 256 and restart at
/// 0 when the chip resets. Each header adds the rise since the one before
/// it (mod 256); after a reset or re-init the first header is a new
/// baseline. Headers come at least every few ms, far fewer than 256 errors
/// apart.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct CounterTotal {
    last: Option<u8>,
    /// Errors counted since the start.
    pub total: u64,
}

impl CounterTotal {
    /// Adds what the counter rose by since the last header; returns the total.
    pub(crate) fn update(&mut self, raw: u8) -> u64 {
        if let Some(last) = self.last {
            self.total += u64::from(raw.wrapping_sub(last));
        }
        self.last = Some(raw);
        self.total
    }

    /// The next value is a baseline (the chip reset, or its counter was
    /// cleared).
    pub(crate) fn rebase(&mut self) {
        self.last = None;
    }
}

/// A consistent-enough copy for display.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Snapshot {
    /// Phase.
    pub phase: Phase,
    /// ECAT state byte.
    pub ecat_state: EcatState,
    /// Error byte.
    pub error_byte: u8,
    /// ECM status byte.
    pub status_byte: u8,
    /// SPI CRC errors since the daemon started.
    pub crc_errors: u64,
    /// WKC errors since the daemon started.
    pub wkc_errors: u64,
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
    /// Input frames dropped because the distributor fell behind.
    pub ring_overflows: u64,
    /// When the newest input frame arrived, ns since the engine's epoch.
    pub newest_input_ns: u64,
    /// Process-data freshness limit, ns (0: no cyclic exchange running).
    pub flow_limit_ns: u64,
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
    /// Slaves in the network that runs.
    pub slaves: u64,
    /// INT0 stays at its ready level while packets go through.
    pub int0_stuck: bool,
    /// The most slaves a running network had since the start (or the
    /// last re-init or new configuration).
    pub slaves_seen: u64,
    /// Longest gap between FIFO exchanges, us.
    pub max_fifo_gap_us: u64,
    /// The last applied configuration the engine has taken (0: the first).
    pub config_generation: u64,
    /// Client writes that reached the wire later than the budget.
    pub output_latency_misses: u64,
    /// Input frames the chip dropped (TxFIFO full).
    pub inputs_dropped_by_chip: u64,
    /// The latest run of RxFIFO alarms.
    pub recent_fifo_alarms: Recent,
    /// The latest run of input frames the chip dropped.
    pub recent_chip_drops: Recent,
    /// The latest run of FIFO exchanges later than the process-data limit
    /// (worst: the longest gap, us).
    pub recent_long_gaps: Recent,
}

impl Snapshot {
    /// The chip's status flags from the last header.
    pub fn status_flags(&self) -> ecmxf_wire::flags::StatusFlags {
        ecmxf_wire::flags::StatusFlags::from_bits_retain(self.status_byte)
    }

    /// The chip's error flags from the last header.
    pub fn error_flags(&self) -> ecmxf_wire::flags::ErrorFlags {
        ecmxf_wire::flags::ErrorFlags::from_bits_retain(self.error_byte)
    }

    /// What a waiter may be waiting for: when it changes, the engine sends
    /// a snapshot at once (see `Telemetry::announce`).
    pub fn key(&self) -> (Phase, EcatState, u64, u64) {
        (self.phase, self.ecat_state, self.config_generation, self.recoveries)
    }

    /// How old the newest input frame is at `now_ns` (ns since the
    /// engine's epoch), and the limit; `None` while no cyclic exchange runs.
    pub fn input_age(&self, now_ns: u64) -> Option<(Duration, Duration)> {
        (self.flow_limit_ns > 0).then(|| {
            (
                Duration::from_nanos(now_ns.saturating_sub(self.newest_input_ns)),
                Duration::from_nanos(self.flow_limit_ns),
            )
        })
    }
}

impl Telemetry {
    /// Sets the phase.
    pub(crate) fn set_phase(&self, p: Phase) {
        self.phase.store(p as u8, Relaxed);
    }

    /// The phase.
    pub(crate) fn phase(&self) -> Phase {
        Phase::from_u8(self.phase.load(Relaxed))
    }

    /// Stores a header's status.
    pub(crate) fn header(&self, h: &ResponseHeader) {
        self.ecat_state.store(h.ecat_state.to_u8(), Relaxed);
        self.error_byte.store(h.errors.bits(), Relaxed);
        self.status_byte.store(h.status.to_byte(), Relaxed);
        self.rx_fifo.store(h.rx_fifo_count, Relaxed);
        self.tx_fifo.store(h.tx_fifo_count, Relaxed);
    }

    /// Forgets the network's state: the engine is bringing it up again, and
    /// until it answers, the state from before the fault is not the truth.
    pub(crate) fn forget_network(&self) {
        self.ecat_state.store(EcatState::None.to_u8(), Relaxed);
        self.flow_limit_ns.store(0, Relaxed);
        self.recent_fifo_alarms.forget();
        self.recent_chip_drops.forget();
        self.recent_long_gaps.forget();
    }

    /// Claims the one event of the stall that began after the newest input
    /// frame: true for the first to ask, the engine when it sees the stall
    /// itself, or the distributor when the engine is held up in a link call
    /// (see [`Telemetry::unannounced_stall`]). A new frame makes the next
    /// stall a new one.
    pub(crate) fn claim_stall_notice(&self) -> bool {
        let key = self.newest_input_ns.load(Relaxed) + 1;
        self.stall_noticed.swap(key, Relaxed) != key
    }

    /// How long no input frame came, us, when process data should flow, is
    /// older than its limit at `now_ns`, and nobody announced that stall
    /// yet (this call claims it). For the distributor: the engine notices
    /// a stall only between link calls, and a link that stops answering
    /// holds a call for its whole answer limit.
    pub(crate) fn unannounced_stall(&self, now_ns: u64) -> Option<u64> {
        let limit = self.flow_limit_ns.load(Relaxed);
        if limit == 0 || self.phase() != Phase::Running || self.stall_excused.load(Relaxed) {
            return None;
        }
        let age = now_ns.saturating_sub(self.newest_input_ns.load(Relaxed));
        (age > limit && self.claim_stall_notice()).then_some(age / 1000)
    }

    /// Records why bring-up failed or recovery started.
    pub(crate) fn set_error(&self, e: Failure) {
        *self.last_error.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
    }

    /// The last failure, if any.
    pub(crate) fn last_error(&self) -> Option<Failure> {
        self.last_error.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// What a waiter may be waiting for, from the values now (as
    /// [`Snapshot::key`]): a change is announced at once.
    pub(crate) fn key(&self) -> (Phase, EcatState, u64, u64) {
        (
            self.phase(),
            EcatState::from_u8(self.ecat_state.load(Relaxed)),
            self.config_generation.load(Relaxed),
            self.recoveries.load(Relaxed),
        )
    }

    /// Sends the snapshot to every waiter; returns what was sent. Nothing
    /// here allocates: the value is a copy, the waiters' list is intrusive.
    pub(crate) fn announce(&self) -> Snapshot {
        let s = self.snapshot();
        self.changes.send_replace(s);
        s
    }

    /// Snapshots as the engine announces them; the current one at once.
    pub(crate) fn watch(&self) -> watch::Receiver<Snapshot> {
        self.changes.subscribe()
    }

    /// A copy.
    pub(crate) fn snapshot(&self) -> Snapshot {
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
            ring_overflows: self.ring_overflows.load(Relaxed),
            newest_input_ns: self.newest_input_ns.load(Relaxed),
            flow_limit_ns: self.flow_limit_ns.load(Relaxed),
            transactions: self.transactions.load(Relaxed),
            input_frames: self.input_frames.load(Relaxed),
            output_frames: self.output_frames.load(Relaxed),
            fifo_alarms: self.fifo_alarms.load(Relaxed),
            recoveries: self.recoveries.load(Relaxed),
            slaves: self.slaves.load(Relaxed),
            int0_stuck: self.int0_stuck.load(Relaxed),
            slaves_seen: self.slaves_seen.load(Relaxed),
            max_fifo_gap_us: self.max_fifo_gap_us.load(Relaxed),
            config_generation: self.config_generation.load(Relaxed),
            output_latency_misses: self.output_latency_misses.load(Relaxed),
            inputs_dropped_by_chip: self.inputs_dropped_by_chip.load(Relaxed),
            recent_fifo_alarms: self.recent_fifo_alarms.read(),
            recent_chip_drops: self.recent_chip_drops.read(),
            recent_long_gaps: self.recent_long_gaps.read(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn totals_survive_the_8_bit_wrap() {
        let mut c = CounterTotal::default();
        assert_eq!(c.update(5), 0, "the first header is the baseline");
        assert_eq!(c.update(248), 243);
        // 248 -> 163 is 171 more, not 85 fewer.
        assert_eq!(c.update(163), 243 + 171);
        assert_eq!(c.update(163), 414, "no rise, no count");
    }

    #[test]
    fn a_chip_reset_starts_a_new_baseline() {
        let mut c = CounterTotal::default();
        c.update(0);
        c.update(200);
        c.rebase();
        assert_eq!(c.update(3), 200, "the reset's 0..3 is not counted as 59");
        assert_eq!(c.update(4), 201);
    }

    #[test]
    fn latency_percentiles_come_from_the_latest_samples() {
        let w = LatencyWindow::default();
        assert_eq!(w.stats(), None);
        for us in 1..=100 {
            w.record(us);
        }
        assert_eq!(w.stats(), Some(LatencyStats { p50_us: 51, p99_us: 99, samples: 100 }));
        // The window slides: old samples are overwritten.
        for _ in 0..LatencyWindow::LEN {
            w.record(7);
        }
        assert_eq!(w.stats(), Some(LatencyStats { p50_us: 7, p99_us: 7, samples: LatencyWindow::LEN }));
    }

    #[test]
    fn the_age_counts_from_the_newest_frame() {
        let t = Telemetry::default();
        assert_eq!(t.snapshot().input_age(5), None, "nothing expected before the cyclic exchange runs");
        t.newest_input_ns.store(1_000_000, Relaxed);
        t.flow_limit_ns.store(50_000_000, Relaxed);
        assert_eq!(t.snapshot().input_age(31_000_000), Some((Duration::from_millis(30), Duration::from_millis(50))));
        t.forget_network();
        assert_eq!(t.snapshot().input_age(31_000_000), None);
    }
}
