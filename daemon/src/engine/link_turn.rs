//! Who gets the SPI link's next exchange: the cyclic FIFO exchange or the
//! blocking slot's transaction. A pure decision, so every rule is
//! unit-tested here; `running.rs` gathers what it needs from the port, the
//! FIFO plan and the transaction, and acts on it.
//!
//! The FIFO exchange has slack (the RxFIFO holds tens of frames, the
//! TxFIFO keeps 12 ms of inputs): it can move by a few exchanges without
//! harm. A transaction cannot: each of its exchanges waits on the one
//! before. So the link is shared by the transaction's phases (v049 表三:
//! a blocking command runs on the chip for hundreds of us; its GET reads
//! the result):
//!
//! - while the command runs on the chip, the link is free: a FIFO
//!   exchange due within the next [`PULL_FORWARD`] exchanges goes now
//!   (its headers carry the busy bit as well as a poll), once per
//!   command and only before its first poll, so it is done before the command ends instead of standing
//!   between the command's end and its result (without this an SDO read
//!   took 9 exchanges, 2.24 ms, at a 125 us cycle; with it 5);
//! - once the command ended, or a GET's answer is on its way, the
//!   transaction goes first: the FIFO only when pressing;
//! - a new transaction's start goes before a FIFO exchange that is only
//!   due, as does a transaction that follows within an exchange time of
//!   the last one's end (a client asking one after another);
//! - otherwise, when the FIFO is due: it goes if no transaction waits, or
//!   the slot had its step since the last FIFO exchange.
//!
//! "Pressing" is the outputs near their floor or two packets below the
//! level aimed at, or three packets' worth of inputs waiting (a quarter
//! of the TxFIFO at most): an exchange waits at most about a packet past
//! its due time for the slot, so the margin against a host stall stays
//! the plan's. The FIFO then goes first, at most [`SLOT_SKIPS`] times in
//! a row so the slot still moves on a link the plan fills (the shortfall
//! shows as underruns, counted and reported).

/// FIFO exchanges that may go first in a row while a transaction waits.
pub(super) const SLOT_SKIPS: u32 = 4;

/// While a blocking command runs on the chip, a FIFO exchange due within
/// this many exchange times goes at once: an SDO's slave time (hundreds
/// of us) holds one guarded FIFO call.
pub(super) const PULL_FORWARD: u32 = 4;

/// What the blocking slot is doing, as far as the link is concerned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Slot {
    /// Nothing in it or queued. `just_freed`: a transaction ended less
    /// than an exchange time ago.
    Empty {
        /// A transaction ended less than an exchange time ago.
        just_freed: bool,
    },
    /// A job is queued, none started.
    Queued,
    /// A command runs on the chip. `pulled`: a FIFO exchange was already
    /// fitted into this command's run, or it is past its start (polled):
    /// a FIFO exchange pulled in late would stand between its end and its
    /// result.
    Runs {
        /// A FIFO exchange already went, or a poll, since the command
        /// started.
        pulled: bool,
    },
    /// The transaction wants the next exchange: its command ended, or a
    /// GET's answer is on its way.
    WantsLink,
    /// A transaction in any other state (starting, deciding whether a
    /// read ran). `had_turn`: it had a step since the last FIFO exchange.
    Other {
        /// The slot had its step since the last FIFO exchange.
        had_turn: bool,
    },
}

/// What the FIFO plan says now.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Fifo {
    /// An exchange is due now.
    pub due: bool,
    /// An exchange is due within [`PULL_FORWARD`] exchange times.
    pub due_soon: bool,
    /// Outputs two packets below their aim, or three packets of inputs
    /// waiting (see the module doc).
    pub pressing: bool,
}

/// Whether the next exchange is the FIFO's; `skipped` counts FIFO
/// exchanges that went first in a row while a transaction waited.
pub(super) fn fifo_goes_first(fifo: Fifo, slot: Slot, skipped: u32) -> bool {
    let may_skip = skipped < SLOT_SKIPS;
    let urgent = fifo.pressing && may_skip;
    match slot {
        Slot::Runs { pulled: false } => (fifo.due_soon && may_skip) || urgent,
        Slot::Runs { pulled: true } => (fifo.due && may_skip) || urgent,
        Slot::WantsLink | Slot::Queued => fifo.due && urgent,
        Slot::Empty { just_freed } => fifo.due && (fifo.pressing || !just_freed),
        Slot::Other { had_turn } => fifo.due && (had_turn || urgent),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const IDLE: Fifo = Fifo { due: false, due_soon: false, pressing: false };
    const SOON: Fifo = Fifo { due: false, due_soon: true, pressing: false };
    const DUE: Fifo = Fifo { due: true, due_soon: true, pressing: false };
    const PRESSING: Fifo = Fifo { due: true, due_soon: true, pressing: true };

    #[test]
    fn a_command_running_on_the_chip_takes_one_fifo_exchange_due_soon() {
        assert!(fifo_goes_first(SOON, Slot::Runs { pulled: false }, 0), "fitted into the command's run");
        assert!(!fifo_goes_first(SOON, Slot::Runs { pulled: true }, 0), "once per command");
        assert!(fifo_goes_first(DUE, Slot::Runs { pulled: true }, 0), "a due one still goes");
        assert!(!fifo_goes_first(IDLE, Slot::Runs { pulled: false }, 0));
    }

    #[test]
    fn a_result_waiting_goes_before_a_fifo_exchange_that_is_only_due() {
        assert!(!fifo_goes_first(DUE, Slot::WantsLink, 0));
        assert!(fifo_goes_first(PRESSING, Slot::WantsLink, 0));
        assert!(!fifo_goes_first(PRESSING, Slot::WantsLink, SLOT_SKIPS), "the slot still moves");
    }

    #[test]
    fn a_new_transaction_starts_before_a_fifo_exchange_that_is_only_due() {
        assert!(!fifo_goes_first(DUE, Slot::Queued, 0));
        assert!(fifo_goes_first(PRESSING, Slot::Queued, 0));
    }

    #[test]
    fn right_after_a_transaction_a_due_fifo_exchange_waits_one_exchange_for_the_next() {
        assert!(!fifo_goes_first(DUE, Slot::Empty { just_freed: true }, 0));
        assert!(fifo_goes_first(PRESSING, Slot::Empty { just_freed: true }, 0));
        assert!(fifo_goes_first(DUE, Slot::Empty { just_freed: false }, 0));
        assert!(!fifo_goes_first(IDLE, Slot::Empty { just_freed: false }, 0));
    }

    #[test]
    fn otherwise_the_fifo_and_the_slot_take_turns_and_pressing_skips_a_bounded_number() {
        assert!(fifo_goes_first(DUE, Slot::Other { had_turn: true }, 0));
        assert!(!fifo_goes_first(DUE, Slot::Other { had_turn: false }, 0));
        for skipped in 0..SLOT_SKIPS {
            assert!(fifo_goes_first(PRESSING, Slot::Other { had_turn: false }, skipped));
        }
        assert!(!fifo_goes_first(PRESSING, Slot::Other { had_turn: false }, SLOT_SKIPS));
        assert!(!fifo_goes_first(PRESSING, Slot::Runs { pulled: true }, SLOT_SKIPS));
    }
}
