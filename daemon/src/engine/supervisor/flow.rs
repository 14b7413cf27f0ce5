//! The rule that process data must keep flowing while the chip answers
//! ([`FlowWatch`]), and the limit it uses ([`flow_limit`]).

use std::time::{Duration, Instant};

use super::RecoverCause;
use crate::engine::cyclic::MAX_EXCHANGE_INTERVAL;

/// Intact FIFO answers without inputs, after the limit passed, that make a
/// stall. More than one: after a host stall the first answers carry what
/// the chip had before (answers are one exchange behind), the next ones the
/// frames that queued up meanwhile.
pub(super) const STALL_ANSWERS: u32 = 3;

/// The longest an input frame may be missing before the data counts as not
/// flowing, for a DC cycle `cycle`: the engine exchanges at least every
/// [`MAX_EXCHANGE_INTERVAL`], frames arrive two exchanges late, plus a few
/// cycles and a margin for a loaded host. About 60 ms at a 1 ms cycle, so
/// health reports a stop well within 100 ms; long cycles get three of
/// their own.
pub(crate) fn flow_limit(cycle: Duration) -> Duration {
    const MARGIN: Duration = Duration::from_millis(30);
    (MAX_EXCHANGE_INTERVAL + cycle * 3 + MARGIN).max(cycle * 3)
}

/// Watches that input frames keep arriving while the chip answers.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FlowWatch {
    limit: Duration,
    newest: Instant,
    flowed: bool,
    empty_after_limit: u32,
}

impl FlowWatch {
    /// Starts watching at `now` (the start of a run counts as the newest
    /// frame, so a run that never delivers one is a stall too).
    pub(crate) fn new(limit: Duration, now: Instant) -> Self {
        Self { limit, newest: now, flowed: false, empty_after_limit: 0 }
    }

    /// Whether any frame arrived in this run.
    pub(crate) fn flowed(&self) -> bool {
        self.flowed
    }

    /// An intact FIFO answer arrived at `now` with `frames` input frames.
    /// Returns the stall, if this answer confirms one.
    pub(crate) fn answer(&mut self, frames: usize, now: Instant) -> Option<RecoverCause> {
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
    pub(crate) fn excuse(&mut self, now: Instant) {
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
}
