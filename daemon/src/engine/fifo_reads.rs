//! How the answer to a FIFO call is fetched (`cycle.fifo_reads`;
//! docs/protocol.md §7 and §12).
//!
//! A FIFO call's read takes input frames out of the chip's TxFIFO, so its
//! answer carries frames that exist nowhere else. The chip answers a packet
//! with the next exchange:
//!
//! - **Guarded**: the call is resent at once until its answer arrives
//!   intact. Nothing is ever lost, and every call costs two exchanges.
//! - **Pipelined**: the next exchange brings the answer, whoever makes it:
//!   the next FIFO call, the emergency question, a transaction's packet.
//!   A call costs one exchange. When no exchange came within
//!   [`FETCH_WITHIN`], the call is resent to fetch its answer, as a guarded
//!   call would: inputs wait at most that much longer than guarded. An
//!   answer that another packet brought corrupt is lost with its input
//!   frames: they are counted and numbered as a gap, never passed over.
//!
//! After any sign of a bad link (a corrupt answer, the chip's count of
//! packets refused for their check word moving) pipelined calls go
//! guarded for [`GUARDED_AFTER_ERROR`]: a noisy link loses one batch, not
//! one per error. Calls that push frames from a client's frame stream
//! always go guarded: a refused call's frames would be gone (the output
//! image itself is pushed again by the next call, stream frames are not).

use std::time::{Duration, Instant};

use crate::config::FifoReads;

/// The longest an answer waits for another exchange to bring it before
/// the call is resent to fetch it: at 125 us the next call comes sooner
/// (about every 1.1 ms on the demo network); at 1 ms cycles calls are
/// rarer, and cost little of the link either way.
pub(crate) const FETCH_WITHIN: Duration = Duration::from_millis(2);

/// How long pipelined calls go guarded after a sign of a bad link.
pub(crate) const GUARDED_AFTER_ERROR: Duration = Duration::from_secs(1);

/// Link errors as the port and the chip count them: corrupt answers the
/// host saw, packets the chip refused for their check word (its header
/// count, 8 bits, which wraps: only a change counts).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct LinkErrors {
    /// Corrupt answers (`PortStats::corrupt`).
    pub corrupt: u64,
    /// The chip's SPI CRC error count (header byte 0x04).
    pub refused: u8,
}

/// Decides, call by call, whether a FIFO call is fetched at once.
#[derive(Debug)]
pub(crate) struct FetchRule {
    mode: FifoReads,
    seen: LinkErrors,
    guarded_until: Option<Instant>,
}

impl FetchRule {
    /// The rule for a run in `mode`, starting from the counts as they are.
    pub(crate) fn new(mode: FifoReads, errors: LinkErrors) -> Self {
        Self { mode, seen: errors, guarded_until: None }
    }

    /// Whether a call sent at `now` is fetched at once: in guarded mode,
    /// for a call that pushes stream frames, and for a while after the
    /// link showed an error (`errors` as counted now).
    pub(crate) fn guarded(&mut self, errors: LinkErrors, stream_frames: bool, now: Instant) -> bool {
        if errors != self.seen {
            self.seen = errors;
            self.guarded_until = Some(now + GUARDED_AFTER_ERROR);
        }
        self.mode == FifoReads::Guarded || stream_frames || self.guarded_until.is_some_and(|t| now < t)
    }

    /// An answer was lost at `now`: guarded for a while.
    pub(crate) fn answer_lost(&mut self, now: Instant) {
        self.guarded_until = Some(now + GUARDED_AFTER_ERROR);
    }

    /// When a call sent at `sent_at` and still unanswered is fetched.
    pub(crate) fn fetch_at(sent_at: Instant) -> Instant {
        sent_at + FETCH_WITHIN
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pipelined_calls_go_guarded_for_a_while_after_a_link_error() {
        let t0 = Instant::now();
        let clean = LinkErrors { corrupt: 3, refused: 1 };
        let mut rule = FetchRule::new(FifoReads::Pipelined, clean);
        assert!(!rule.guarded(clean, false, t0), "a clean link: pipelined");
        assert!(rule.guarded(clean, true, t0), "stream frames: guarded");
        let corrupt = LinkErrors { corrupt: 4, ..clean };
        assert!(rule.guarded(corrupt, false, t0), "a corrupt answer");
        assert!(rule.guarded(corrupt, false, t0 + Duration::from_millis(999)));
        assert!(!rule.guarded(corrupt, false, t0 + GUARDED_AFTER_ERROR), "a second later, clean again");
        // The chip's count of refused packets wraps: a change is what counts.
        let t1 = t0 + Duration::from_secs(5);
        assert!(rule.guarded(LinkErrors { refused: 0, ..corrupt }, false, t1));
        rule.answer_lost(t1 + Duration::from_secs(2));
        assert!(rule.guarded(LinkErrors { refused: 0, ..corrupt }, false, t1 + Duration::from_secs(2)));
    }

    #[test]
    fn guarded_mode_fetches_every_call_at_once() {
        let mut rule = FetchRule::new(FifoReads::Guarded, LinkErrors::default());
        assert!(rule.guarded(LinkErrors::default(), false, Instant::now()));
    }
}
