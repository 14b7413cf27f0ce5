//! What sends the running engine back to bring-up, as data: the causes
//! ([`RecoverCause`]) and the rule that process data must keep flowing
//! ([`FlowWatch`]). The rules take the time as a parameter so they are
//! tested with synthetic times, not the clock.

use std::fmt;
use std::time::{Duration, Instant};

use super::cyclic::MAX_EXCHANGE_INTERVAL;
use crate::port::PortError;

/// Why the engine left the running loop to bring the network up again.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RecoverCause {
    /// The link to the chip failed (I/O error, far end gone): it is opened
    /// again before the next bring-up.
    Link(String),
    /// The chip stopped answering in time or coherently (INT0 stuck, no
    /// intact answer).
    Chip(String),
    /// The chip's status is back to its power-up values.
    ChipReset,
    /// The network state is ERROR; which slaves and their AL status codes.
    SlaveError(String),
    /// The number of slaves on the ring changed.
    SlaveCount {
        /// Slaves at bring-up.
        from: usize,
        /// Slaves now.
        to: usize,
    },
    /// Working-counter errors for at least this long.
    WkcStreak(Duration),
    /// The chip stopped the process-data exchange (working-counter limit).
    ExchangeStopped,
    /// No input frame arrived for `age`, longer than `limit`, while the
    /// chip kept answering.
    InputStall {
        /// Time since the newest input frame.
        age: Duration,
        /// The limit in force.
        limit: Duration,
    },
    /// A client applied a new configuration.
    NewConfig,
    /// A client asked for a re-init.
    ReinitRequested,
    /// A client asked for a warm reset of the chip.
    WarmResetRequested,
}

impl RecoverCause {
    /// The cause of a failed exchange.
    pub fn from_port(e: &PortError) -> Self {
        match e {
            PortError::Link(l) => Self::Link(l.to_string()),
            other => Self::Chip(other.to_string()),
        }
    }

    /// The cause as one stable word (the log's and the API's `cause`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Link(_) => "link",
            Self::Chip(_) => "chip",
            Self::ChipReset => "chip_reset",
            Self::SlaveError(_) => "slave_error",
            Self::SlaveCount { .. } => "slave_count",
            Self::WkcStreak(_) => "wkc_streak",
            Self::ExchangeStopped => "exchange_stopped",
            Self::InputStall { .. } => "input_stall",
            Self::NewConfig => "new_config",
            Self::ReinitRequested => "reinit_requested",
            Self::WarmResetRequested => "warm_reset_requested",
        }
    }

    /// Whether the link itself must be opened again.
    pub fn needs_reopen(&self) -> bool {
        matches!(self, Self::Link(_))
    }
}

impl fmt::Display for RecoverCause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Link(e) => write!(f, "link failed: {e}"),
            Self::Chip(e) => write!(f, "chip: {e}"),
            Self::ChipReset => f.write_str("chip reset (status back to power-up values)"),
            Self::SlaveError(s) => write!(f, "a slave reports an error or is missing: {s}"),
            Self::SlaveCount { from, to } => write!(f, "slave count changed from {from} to {to}"),
            Self::WkcStreak(d) => write!(f, "working-counter errors for {d:?}: a slave is not exchanging"),
            Self::ExchangeStopped => f.write_str("process-data exchange stopped (working-counter limit)"),
            Self::InputStall { age, limit } => write!(
                f,
                "process data stalled: no input frame for {} ms (limit {} ms) while the chip answers",
                age.as_millis(),
                limit.as_millis()
            ),
            Self::NewConfig => f.write_str("new configuration from a client"),
            Self::ReinitRequested => f.write_str("re-init requested by a client"),
            Self::WarmResetRequested => f.write_str("warm reset requested by a client"),
        }
    }
}

/// Intact FIFO answers without inputs, after the limit passed, that make a
/// stall. More than one: after a host stall the first answers carry what
/// the chip had before (answers are one exchange behind), the next ones the
/// frames that queued up meanwhile.
pub const STALL_ANSWERS: u32 = 3;

/// The longest an input frame may be missing before the data counts as not
/// flowing, for a DC cycle `cycle`: the engine exchanges at least every
/// [`MAX_EXCHANGE_INTERVAL`], frames arrive two exchanges late, plus a few
/// cycles and a margin for a loaded host. About 60 ms at a 1 ms cycle, so
/// health reports a stop well within 100 ms; long cycles get three of
/// their own.
pub fn flow_limit(cycle: Duration) -> Duration {
    const MARGIN: Duration = Duration::from_millis(30);
    (MAX_EXCHANGE_INTERVAL + cycle * 3 + MARGIN).max(cycle * 3)
}

/// Watches that input frames keep arriving while the chip answers.
#[derive(Clone, Copy, Debug)]
pub struct FlowWatch {
    limit: Duration,
    newest: Instant,
    flowed: bool,
    empty_after_limit: u32,
}

impl FlowWatch {
    /// Starts watching at `now` (the start of a run counts as the newest
    /// frame, so a run that never delivers one is a stall too).
    pub fn new(limit: Duration, now: Instant) -> Self {
        Self { limit, newest: now, flowed: false, empty_after_limit: 0 }
    }

    /// The limit in force.
    pub fn limit(&self) -> Duration {
        self.limit
    }

    /// Whether any frame arrived in this run.
    pub fn flowed(&self) -> bool {
        self.flowed
    }

    /// An intact FIFO answer arrived at `now` with `frames` input frames.
    /// Returns the stall, if this answer confirms one.
    pub fn answer(&mut self, frames: usize, now: Instant) -> Option<RecoverCause> {
        if frames > 0 {
            self.newest = now;
            self.flowed = true;
            self.empty_after_limit = 0;
            return None;
        }
        let age = now.saturating_duration_since(self.newest);
        if age <= self.limit {
            return None;
        }
        self.empty_after_limit += 1;
        (self.empty_after_limit >= STALL_ANSWERS).then_some(RecoverCause::InputStall { age, limit: self.limit })
    }

    /// Forgets the past: a deliberate pause of the exchange (a client held
    /// the network below OP) is not a stall.
    pub fn excuse(&mut self, now: Instant) {
        self.newest = now;
        self.empty_after_limit = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn the_limit_fits_the_cycle_and_the_100_ms_goal() {
        assert!(flow_limit(Duration::from_micros(125)) < 60 * MS);
        assert!(flow_limit(MS) <= 70 * MS);
        let slow = flow_limit(Duration::from_secs(1));
        assert!(slow >= Duration::from_secs(3) && slow < Duration::from_millis(3100), "three cycles of a slow network");
    }

    #[test]
    fn frames_keep_it_quiet() {
        let t0 = Instant::now();
        let mut w = FlowWatch::new(50 * MS, t0);
        for k in 1..1000u32 {
            assert_eq!(w.answer(1, t0 + k * MS), None);
        }
        assert!(w.flowed());
    }

    #[test]
    fn empty_answers_within_the_limit_are_normal() {
        let t0 = Instant::now();
        let mut w = FlowWatch::new(50 * MS, t0);
        w.answer(2, t0);
        for k in 1..=50u32 {
            assert_eq!(w.answer(0, t0 + k * MS), None, "{k} ms");
        }
    }

    #[test]
    fn a_stall_needs_the_limit_and_three_empty_answers_after_it() {
        let t0 = Instant::now();
        let mut w = FlowWatch::new(50 * MS, t0);
        w.answer(1, t0);
        // A host stall of 200 ms: the first answers after it are empty...
        assert_eq!(w.answer(0, t0 + 200 * MS), None);
        assert_eq!(w.answer(0, t0 + 201 * MS), None);
        // ...then the frames queued meanwhile arrive: no stall.
        assert_eq!(w.answer(40, t0 + 202 * MS), None);
        // A real stop: empty answers past the limit.
        assert_eq!(w.answer(0, t0 + 260 * MS), None);
        assert_eq!(w.answer(0, t0 + 261 * MS), None);
        assert_eq!(w.answer(0, t0 + 262 * MS), Some(RecoverCause::InputStall { age: 60 * MS, limit: 50 * MS }));
    }

    #[test]
    fn a_run_that_never_delivers_is_a_stall() {
        let t0 = Instant::now();
        let mut w = FlowWatch::new(10 * MS, t0);
        let stall = (1..=20u32).find_map(|k| w.answer(0, t0 + k * MS));
        assert!(matches!(stall, Some(RecoverCause::InputStall { .. })));
        assert!(!w.flowed());
    }

    #[test]
    fn an_excused_pause_starts_the_clock_again() {
        let t0 = Instant::now();
        let mut w = FlowWatch::new(10 * MS, t0);
        w.excuse(t0 + 100 * MS);
        assert_eq!(w.answer(0, t0 + 105 * MS), None);
    }

    #[test]
    fn causes_read_as_sentences() {
        let c = RecoverCause::InputStall { age: 80 * MS, limit: 62 * MS };
        assert_eq!(
            c.to_string(),
            "process data stalled: no input frame for 80 ms (limit 62 ms) while the chip answers"
        );
        assert!(RecoverCause::Link("link closed".into()).needs_reopen());
        assert!(!RecoverCause::ChipReset.needs_reopen());
    }
}
