//! CoE emergencies, noticed by the engine within a few milliseconds.
//!
//! The chip keeps the last eight emergency records with a running number
//! (v049 COE_EMERGENCY, 83) but raises no interrupt flag for them (v049
//! 綜合中斷 lists EtherCAT frame, FIFO marks, CRC and WKC errors only). So
//! the engine asks for the newest record every [`POLL`] and, when its number
//! moved, for all eight, and emits each new one as an event stamped with the
//! time it was read. Polling from the async side took a blocking-slot turn
//! and happened every 500 ms (emergencies arrived 279-431 ms late, with no
//! time). Here the question costs one exchange: it is sent once
//! ([`Port::send_once`]) and its answer read from whatever exchange comes
//! next; a lost answer is simply asked again. With cyclic data the question
//! waits (from [`POLL`] up to [`POLL_LONGEST`]) for a FIFO exchange to go
//! just after it, so that exchange brings the answer and none is made to
//! fetch it; during a transaction it stands in for one of its polls.

use std::time::Duration;

use ecmxf_wire::Request;
use ecmxf_wire::payload::emergency::{CoeEmergencyGet, EMERGENCY_MAX, EmergencyRecord};

/// The watch's question: the newest record only.
const NEWEST: CoeEmergencyGet = CoeEmergencyGet(1);

use crate::link::Link;
use crate::port::{Port, PortError};

/// How often the newest record is read, at the soonest: an emergency reaches
/// clients within [`POLL_LONGEST`] plus one exchange (the goal: 10 ms).
pub(crate) const POLL: Duration = Duration::from_millis(4);

/// With cyclic data a question waits for a FIFO exchange to ride along
/// with, but never longer than this since the last one.
pub(crate) const POLL_LONGEST: Duration = Duration::from_millis(6);

/// How long an asked question may wait for an exchange to bring its answer
/// before the engine makes one for it (idle slot, slow cycle).
pub(crate) const ANSWER_WAIT: Duration = Duration::from_millis(1);

/// Remembers the newest record seen, across recoveries.
#[derive(Debug, Default)]
pub(crate) struct EmergencyWatch {
    /// Whether the history was looked at once.
    looked: bool,
    /// The newest running number seen (None: the history was empty).
    newest: Option<u16>,
    /// A question is out (the exchange count right after it); its answer
    /// comes with the next exchange.
    asked: Option<(u64, u8)>,
}

/// Whether running number `n` comes after `last` (the numbers are u16 and wrap).
fn after(n: u16, last: u16) -> bool {
    (n.wrapping_sub(last) as i16) > 0
}

impl EmergencyWatch {
    /// Asks for the newest record; its answer comes with the next exchange
    /// (see [`EmergencyWatch::check`]). The exchange refreshes the status
    /// header like any other, so it can stand in for a status poll.
    pub(crate) fn ask<L: Link>(&mut self, port: &mut Port<L>) -> Result<(), PortError> {
        let index = port.send_once(&NEWEST)?;
        self.asked = Some((port.stats().exchanges, index));
        Ok(())
    }

    /// Whether a question is out.
    pub(crate) fn asked(&self) -> bool {
        self.asked.is_some()
    }

    /// After the exchange that followed [`EmergencyWatch::ask`]: when the
    /// newest record is new, reads the history and calls `emit` with each
    /// record not seen before, oldest first. The first look only learns
    /// where the history stands (what came before the daemon is in
    /// GetEmergencies). Allocates nothing.
    pub(crate) fn check<L: Link>(
        &mut self,
        port: &mut Port<L>,
        mut emit: impl FnMut(EmergencyRecord),
    ) -> Result<(), PortError> {
        let index = match self.asked {
            None => return Ok(()),
            // No exchange since the question: its answer is not here yet.
            Some((n, _)) if port.stats().exchanges == n => return Ok(()),
            Some((_, index)) => index,
        };
        self.asked = None;
        // Lost: asked again next time.
        let answer = port.answer_to(index, <CoeEmergencyGet as Request<'_>>::CODE);
        let Some(Ok(reply)) = answer.map(|a| a.answer_to(&NEWEST)) else { return Ok(()) };
        let Some(newest) = reply.records().next() else { return Ok(()) };
        let first_look = !std::mem::replace(&mut self.looked, true);
        if newest.is_empty() || self.newest == Some(newest.number) {
            return Ok(());
        }
        let last = self.newest.replace(newest.number);
        if first_look {
            return Ok(());
        }
        // A chip that reset counts from 1 again: everything it holds is new.
        let is_new = |n: u16| last.is_none_or(|l| !after(newest.number, l) || after(n, l));
        let mut records = [EmergencyRecord::default(); EMERGENCY_MAX as usize];
        let mut n = 0;
        {
            for r in port.ask(&CoeEmergencyGet(EMERGENCY_MAX))?.records() {
                if !r.is_empty() && is_new(r.number) && n < records.len() {
                    records[n] = r;
                    n += 1;
                }
            }
        }
        let found = &mut records[..n];
        found.sort_unstable_by(|a, b| {
            if after(a.number, b.number) { std::cmp::Ordering::Greater } else { std::cmp::Ordering::Less }
        });
        for r in found.iter() {
            emit(*r);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn running_numbers_wrap() {
        assert!(after(5, 4));
        assert!(!after(4, 4));
        assert!(after(2, 65_530), "past the wrap");
        assert!(!after(65_530, 2));
    }
}
