//! The running loop's rules, as data: what sends the engine back to
//! bring-up and what is only worth an alarm. Every rule takes the time as a
//! parameter and reads nothing but what it is given (answer headers, slave
//! counts, input frame counts), so each is unit-tested with synthetic
//! headers and times.
//!
//! - [`Supervisor::header`]: every answer's header. The chip reset (NOP or
//!   ETHERNET_READY gone, v049 表四), the network in ERROR, working-counter
//!   errors for longer than [`WKC_STREAK`], the exchange stopped by the
//!   chip (PDO_CONFIGURED gone), and the rising edge of the FIFO error bit
//!   (one alarm per time the RxFIFO ran dry, not one per header showing it).
//! - [`Supervisor::census`]: the slave count, asked every [`CENSUS`] while
//!   the slot is idle (slaves plugged in or out), and INT0's edges
//!   ([`Int0Watch`]: a line stuck at its ready level degrades the health).
//! - [`Supervisor::fifo_answer`]: input frames must keep coming while the
//!   chip answers ([`FlowWatch`]).
//! - [`RecoverCause`]: why, carried to events, logs and the API.

mod cause;
mod flow;
mod int0;

use std::time::{Duration, Instant};

use ecmxf_wire::flags::{ErrorFlags, StatusFlags};
use ecmxf_wire::{EcatState, ResponseHeader};

// Re-exported by the master as its own (the one door).
#[allow(unreachable_pub)]
pub use cause::RecoverCause;
pub(crate) use cause::SlaveFault;
#[cfg(test)]
use flow::STALL_ANSWERS;
pub(crate) use flow::{FlowWatch, flow_limit};
pub(crate) use int0::{Int0Watch, SILENT_EXCHANGES as INT0_SILENT_EXCHANGES};

/// Working-counter errors this long in a row mean a slave left the
/// exchange (lost, or dropped to a lower state): recover.
pub(crate) const WKC_STREAK: Duration = Duration::from_millis(50);
/// A streak ends after this long without a new WKC error.
pub(crate) const WKC_QUIET: Duration = Duration::from_millis(20);
/// How often the engine counts the slaves while the slot is idle.
pub(crate) const CENSUS: Duration = Duration::from_secs(1);

/// What a header says that is not a fault.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct HeaderNews {
    /// The RxFIFO just ran dry (the error bit's rising edge, with outputs):
    /// count an alarm.
    pub ran_dry: bool,
    /// The FIFO error bit is set: ask the chip to clear it.
    pub clear_fifo_error: bool,
}

/// What a run of the cyclic exchange looks like, for the rules.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct RunShape {
    /// Slaves at bring-up.
    pub slaves: usize,
    /// Whether process data is exchanged (a FIFO plan runs).
    pub cyclic: bool,
    /// Whether there are outputs (without them, nothing can run dry).
    pub has_outputs: bool,
    /// How long input frames may be missing ([`flow_limit`]).
    pub flow_limit: Duration,
}

/// The rules of one run, with what they remember between answers.
#[derive(Clone, Debug)]
pub(crate) struct Supervisor {
    shape: RunShape,
    flow: FlowWatch,
    /// The chip's raw WKC error counter in the last header.
    wkc_raw: u8,
    /// (first WKC error of a streak, last one seen).
    wkc_streak: Option<(Instant, Instant)>,
    /// The FIFO error bit (with outputs) in the last header.
    fifo_dry: bool,
    last_census: Instant,
    /// A stall an answer confirmed, for the loop to act on.
    stall: Option<RecoverCause>,
    /// INT0's edges at the censuses.
    pub int0: Int0Watch,
}

impl Supervisor {
    /// A run starting at `now`; `wkc_raw` is the WKC counter in the header
    /// before it. A FIFO error bit left from before the run (a fault, the
    /// bring-up) is cleared, not reported.
    pub(crate) fn new(shape: RunShape, wkc_raw: u8, now: Instant) -> Self {
        Self {
            shape,
            flow: FlowWatch::new(shape.flow_limit, now),
            wkc_raw,
            wkc_streak: None,
            fifo_dry: true,
            last_census: now,
            stall: None,
            int0: Int0Watch::default(),
        }
    }

    /// Judges the header of an answer at `now`. `held`: a client holds
    /// the slaves below the target state on purpose, so missing working
    /// counters and frames are not faults (a streak counts from when the
    /// hold ends).
    pub(crate) fn header(&mut self, h: &ResponseHeader, held: bool, now: Instant) -> Result<HeaderNews, RecoverCause> {
        if h.is_nop() || !h.status.flags.contains(StatusFlags::ETHERNET_READY) {
            return Err(RecoverCause::ChipReset);
        }
        if h.ecat_state == EcatState::Error {
            return Err(RecoverCause::SlaveError(Vec::new()));
        }
        if held {
            self.wkc_streak = None;
            self.wkc_raw = h.wkc_errors;
        } else if h.wkc_errors != self.wkc_raw {
            self.wkc_raw = h.wkc_errors;
            let first = self.wkc_streak.map_or(now, |(f, _)| f);
            self.wkc_streak = Some((first, now));
            if now.saturating_duration_since(first) > WKC_STREAK {
                return Err(RecoverCause::WkcStreak(WKC_STREAK));
            }
        } else if self.wkc_streak.is_some_and(|(_, last)| now.saturating_duration_since(last) > WKC_QUIET) {
            self.wkc_streak = None;
        }
        if self.shape.cyclic && !h.status.flags.contains(StatusFlags::PDO_CONFIGURED) {
            return Err(RecoverCause::ExchangeStopped);
        }
        let error_bit = h.errors.contains(ErrorFlags::FIFO_ERROR);
        let dry = self.shape.has_outputs && error_bit;
        let news = HeaderNews { ran_dry: dry && !self.fifo_dry, clear_fifo_error: error_bit };
        self.fifo_dry = dry;
        Ok(news)
    }

    /// Whether the slaves should be counted now (the caller asks only
    /// while the blocking slot is idle).
    pub(crate) fn census_due(&self, now: Instant) -> bool {
        now.saturating_duration_since(self.last_census) >= CENSUS
    }

    /// The chip counted `slaves` at `now`.
    pub(crate) fn census(&mut self, slaves: usize, now: Instant) -> Result<(), RecoverCause> {
        self.last_census = now;
        if slaves != self.shape.slaves {
            return Err(RecoverCause::SlaveCount { from: self.shape.slaves, to: slaves });
        }
        Ok(())
    }

    /// An intact FIFO answer at `now` carried `frames` input frames. A
    /// network without inputs counts the answer itself as the sign of
    /// life. Returns whether it counts as a frame of fresh data.
    pub(crate) fn fifo_answer(&mut self, frames: usize, has_inputs: bool, now: Instant) -> bool {
        let alive = if has_inputs { frames } else { 1 };
        if let Some(stall) = self.flow.answer(alive, now) {
            self.stall.get_or_insert(stall);
        }
        alive > 0
    }

    /// Whether any input frame arrived in this run (the engine is
    /// "running" from the first one).
    pub(crate) fn flowed(&self) -> bool {
        self.flow.flowed()
    }

    /// The stall an answer confirmed, once; `held`: a deliberate pause of
    /// the exchange is not a stall (the clock starts again at `now`).
    pub(crate) fn take_stall(&mut self, held: bool, now: Instant) -> Option<RecoverCause> {
        if held {
            self.flow.excuse(now);
            self.stall = None;
            return None;
        }
        self.stall.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    fn shape() -> RunShape {
        RunShape { slaves: 3, cyclic: true, has_outputs: true, flow_limit: 50 * MS }
    }

    /// A healthy header in OP with the exchange running.
    fn header(wkc: u8) -> ResponseHeader {
        let mut h = ResponseHeader { ecat_state: EcatState::Op, wkc_errors: wkc, ..Default::default() };
        h.code = ecmxf_wire::CommandCode::PdoDataFifoOp;
        h.status.flags = StatusFlags::ETHERNET_READY | StatusFlags::PDO_CONFIGURED;
        h
    }

    #[test]
    fn a_healthy_header_is_no_news() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(shape(), 0, t0);
        for k in 0..100u32 {
            assert_eq!(s.header(&header(0), false, t0 + k * MS), Ok(HeaderNews::default()));
        }
    }

    #[test]
    fn a_chip_reset_and_an_error_state_recover_at_once() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(shape(), 0, t0);
        let mut reset = header(0);
        reset.status.flags.remove(StatusFlags::ETHERNET_READY);
        assert_eq!(s.header(&reset, false, t0), Err(RecoverCause::ChipReset));
        assert_eq!(s.header(&ResponseHeader::default(), false, t0), Err(RecoverCause::ChipReset), "a NOP answer");
        let mut error = header(0);
        error.ecat_state = EcatState::Error;
        assert!(matches!(s.header(&error, true, t0), Err(RecoverCause::SlaveError(_))), "even when held");
    }

    #[test]
    fn wkc_errors_recover_only_as_a_streak_longer_than_the_limit() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(shape(), 0, t0);
        // A rising counter every 10 ms: a streak; recover once it is
        // longer than WKC_STREAK.
        let mut k = 0u8;
        let verdict = loop {
            k += 1;
            let r = s.header(&header(k), false, t0 + u32::from(k) * 10 * MS);
            if r.is_err() || k == 20 {
                break (k, r);
            }
        };
        assert_eq!(verdict, (7, Err(RecoverCause::WkcStreak(WKC_STREAK))), "60 ms after the first error");
    }

    #[test]
    fn a_streak_ends_after_a_quiet_spell_and_a_hold_forgives() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(shape(), 0, t0);
        // Errors 40 ms apart, each after a quiet spell: never a streak.
        for k in 1..=10u8 {
            let at = t0 + u32::from(k) * 40 * MS;
            assert!(s.header(&header(k - 1), false, at - MS).is_ok());
            assert!(s.header(&header(k), false, at).is_ok(), "error {k}");
            assert!(s.header(&header(k), false, at + 25 * MS).is_ok());
        }
        // Held below target: the counter may run, no streak counts...
        let t1 = t0 + Duration::from_secs(1);
        for k in 0..20u8 {
            assert!(s.header(&header(100 + k), true, t1 + u32::from(k) * 10 * MS).is_ok());
        }
        // ...and one starts from the end of the hold.
        let t2 = t1 + 200 * MS;
        assert!(s.header(&header(200), false, t2).is_ok());
        assert!(s.header(&header(201), false, t2 + 40 * MS).is_ok());
        assert!(s.header(&header(202), false, t2 + 51 * MS).is_err());
    }

    #[test]
    fn the_fifo_error_bit_alarms_once_per_rising_edge() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(shape(), 0, t0);
        let mut dry = header(0);
        dry.errors = ErrorFlags::FIFO_ERROR;
        // Left from before the run: cleared, not reported.
        assert_eq!(s.header(&dry, false, t0), Ok(HeaderNews { ran_dry: false, clear_fifo_error: true }));
        assert_eq!(s.header(&header(0), false, t0 + MS), Ok(HeaderNews::default()));
        assert_eq!(s.header(&dry, false, t0 + 2 * MS), Ok(HeaderNews { ran_dry: true, clear_fifo_error: true }));
        // Headers lag the clear: the bit showing again is the same alarm.
        assert_eq!(s.header(&dry, false, t0 + 3 * MS), Ok(HeaderNews { ran_dry: false, clear_fifo_error: true }));
        // Without outputs nothing runs dry; the bit is still cleared.
        let mut inputs_only = Supervisor::new(RunShape { has_outputs: false, ..shape() }, 0, t0);
        assert!(inputs_only.header(&header(0), false, t0).is_ok());
        assert_eq!(inputs_only.header(&dry, false, t0 + MS), Ok(HeaderNews { ran_dry: false, clear_fifo_error: true }));
    }

    #[test]
    fn a_stopped_exchange_matters_only_when_one_runs() {
        let t0 = Instant::now();
        let mut stopped = header(0);
        stopped.status.flags.remove(StatusFlags::PDO_CONFIGURED);
        let mut s = Supervisor::new(shape(), 0, t0);
        assert_eq!(s.header(&stopped, false, t0), Err(RecoverCause::ExchangeStopped));
        let mut no_cyclic = Supervisor::new(RunShape { cyclic: false, has_outputs: false, ..shape() }, 0, t0);
        assert!(no_cyclic.header(&stopped, false, t0).is_ok());
    }

    #[test]
    fn the_census_is_due_every_second_and_a_changed_count_recovers() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(shape(), 0, t0);
        assert!(!s.census_due(t0 + 999 * MS));
        assert!(s.census_due(t0 + CENSUS));
        assert_eq!(s.census(3, t0 + CENSUS), Ok(()));
        assert!(!s.census_due(t0 + CENSUS + 500 * MS), "counted again a second after the last count");
        assert_eq!(s.census(2, t0 + 2 * CENSUS), Err(RecoverCause::SlaveCount { from: 3, to: 2 }));
    }

    #[test]
    fn a_stall_is_taken_once_and_a_hold_excuses_it() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(shape(), 0, t0);
        assert!(s.fifo_answer(2, true, t0));
        assert!(s.flowed());
        for k in 1..=STALL_ANSWERS {
            assert!(!s.fifo_answer(0, true, t0 + (60 + k) * MS));
        }
        assert!(matches!(s.take_stall(false, t0 + 70 * MS), Some(RecoverCause::InputStall { .. })));
        assert_eq!(s.take_stall(false, t0 + 71 * MS), None, "taken once");
        // Held: the same silence is not a stall.
        let mut held = Supervisor::new(shape(), 0, t0);
        for k in 1..=10 {
            held.fifo_answer(0, true, t0 + k * 20 * MS);
            assert_eq!(held.take_stall(true, t0 + k * 20 * MS), None);
        }
        // A network without inputs lives on intact answers alone.
        let mut outputs_only = Supervisor::new(shape(), 0, t0);
        for k in 1..=200 {
            assert!(outputs_only.fifo_answer(0, false, t0 + k * MS));
        }
        assert_eq!(outputs_only.take_stall(false, t0 + 200 * MS), None);
    }
}
