//! CoE emergencies, noticed by the engine within a few milliseconds.
//!
//! The chip keeps the last eight emergency records with a running number
//! (v049 COE_EMERGENCY, 83) but raises no interrupt flag for them (v049
//! 綜合中斷 lists EtherCAT frame, FIFO marks, CRC and WKC errors only). So
//! the engine asks for all eight every [`POLL`] and emits each record whose
//! number is new as an event stamped with the time it was read. Polling
//! from the async side took a blocking-slot turn and happened every 500 ms
//! (emergencies arrived 279-431 ms late, with no time). Here the question
//! costs one exchange: it is sent once ([`Port::send_once`]) and its answer
//! read from whatever exchange comes next; a lost answer is simply asked
//! again. All eight records fit the packet the link clocks anyway, so one
//! question both notices and reads them: no second round trip when one is
//! new. With cyclic data the question waits (from [`POLL`] up to
//! [`POLL_LONGEST`]) for a FIFO exchange to go just after it, so that
//! exchange brings the answer and none is made to fetch it; during a
//! transaction it stands in for one of its polls.
//!
//! The pace is the link's: at 125 us on the demo network the FIFO needs
//! about 890 calls a second and the question about 150 more (every 4 ms it
//! was 220, a fifth of the link's idle traffic). The worst case from an
//! emergency to its event is [`POLL_LONGEST`] plus the exchange that brings
//! the answer ([`ANSWER_WAIT`] at most): 8 ms, inside the 10 ms the
//! emergency test holds the daemon to.

use std::time::Duration;

use ecmxf_wire::Request;
use ecmxf_wire::payload::emergency::{CoeEmergencyGet, EMERGENCY_MAX, EmergencyRecord};

/// The watch's question: every record the chip keeps.
const ALL: CoeEmergencyGet = CoeEmergencyGet(EMERGENCY_MAX);

use crate::link::Link;
use crate::port::{Port, PortError};

/// How often the records are read, at the soonest.
pub(crate) const POLL: Duration = Duration::from_millis(6);

/// With cyclic data a question waits for a FIFO exchange to ride along
/// with, but never longer than this since the last one.
pub(crate) const POLL_LONGEST: Duration = Duration::from_millis(7);

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
    /// Asks for the records; the answer comes with the next exchange (see
    /// [`EmergencyWatch::check`]). The exchange refreshes the status header
    /// like any other, so it can stand in for a status poll.
    pub(crate) fn ask<L: Link>(&mut self, port: &mut Port<L>) -> Result<(), PortError> {
        let index = port.send_once(&ALL)?;
        self.asked = Some((port.stats().exchanges, index));
        Ok(())
    }

    /// Whether a question is out.
    pub(crate) fn asked(&self) -> bool {
        self.asked.is_some()
    }

    /// After the exchange that followed [`EmergencyWatch::ask`]: calls
    /// `emit` with each record not seen before, oldest first. The first
    /// look only learns where the history stands (what came before the
    /// daemon is in GetEmergencies). Allocates nothing.
    pub(crate) fn check<L: Link>(
        &mut self,
        port: &mut Port<L>,
        emit: impl FnMut(EmergencyRecord),
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
        let Some(Ok(reply)) = answer.map(|a| a.answer_to(&ALL)) else { return Ok(()) };
        let mut records = [EmergencyRecord::default(); EMERGENCY_MAX as usize];
        let mut n = 0;
        for r in reply.records().filter(|r| !r.is_empty()) {
            if n < records.len() {
                records[n] = r;
                n += 1;
            }
        }
        self.take(&mut records[..n], emit);
        Ok(())
    }

    /// The records of one answer (any order): emits the new ones, oldest
    /// first, and remembers the newest.
    fn take(&mut self, found: &mut [EmergencyRecord], mut emit: impl FnMut(EmergencyRecord)) {
        // Ordered by distance from the first record, centred on it: the
        // running numbers wrap, and a key is a total order whatever a chip
        // sends (a comparison by `after` is not, and a sort may panic on one).
        if let Some(pivot) = found.first().map(|r| r.number) {
            found.sort_unstable_by_key(|r| r.number.wrapping_sub(pivot).wrapping_add(0x8000));
        }
        let first_look = !std::mem::replace(&mut self.looked, true);
        let Some(newest) = found.last().map(|r| r.number) else { return };
        if self.newest == Some(newest) {
            return;
        }
        let last = self.newest.replace(newest);
        if first_look {
            return;
        }
        // A chip that reset counts from 1 again: everything it holds is new.
        let is_new = |n: u16| last.is_none_or(|l| !after(newest, l) || after(n, l));
        for r in found.iter().filter(|r| is_new(r.number)) {
            emit(*r);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(number: u16) -> EmergencyRecord {
        EmergencyRecord { number, error_code: number, ..EmergencyRecord::default() }
    }

    fn seen(watch: &mut EmergencyWatch, numbers: &[u16]) -> Vec<u16> {
        let mut found: Vec<EmergencyRecord> = numbers.iter().map(|n| record(*n)).collect();
        let mut out = Vec::new();
        watch.take(&mut found, |r| out.push(r.number));
        out
    }

    #[test]
    fn new_records_are_emitted_once_oldest_first() {
        let mut w = EmergencyWatch::default();
        assert_eq!(seen(&mut w, &[3, 1, 2]), [0u16; 0], "the first look only learns where the history stands");
        assert_eq!(seen(&mut w, &[3, 1, 2]), [0u16; 0]);
        assert_eq!(seen(&mut w, &[5, 3, 4, 2]), [4, 5], "in any order the chip keeps them");
        assert_eq!(seen(&mut w, &[2, 1]), [1, 2], "a chip that reset counts from 1 again: all new");
        let mut w = EmergencyWatch::default();
        assert_eq!(seen(&mut w, &[65_534, 65_533]), [0u16; 0]);
        assert_eq!(seen(&mut w, &[65_535, 1, 65_534, 0, 65_533]), [65_535, 0, 1], "past the wrap");
        // What no chip sends (repeats, numbers half the range apart) is
        // taken as it comes, without a panic.
        let got = seen(&mut w, &[7, 7, 0x8007, 7, 0xC007]);
        assert!(got.contains(&7), "{got:?}");
    }

    #[test]
    fn an_empty_history_then_the_first_record() {
        let mut w = EmergencyWatch::default();
        assert_eq!(seen(&mut w, &[]), [0u16; 0]);
        assert_eq!(seen(&mut w, &[1]), [1]);
    }

    #[test]
    fn running_numbers_wrap() {
        assert!(after(5, 4));
        assert!(!after(4, 4));
        assert!(after(2, 65_530), "past the wrap");
        assert!(!after(65_530, 2));
    }
}
