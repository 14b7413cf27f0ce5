//! A slave's two mailboxes as its ESC keeps them (ETG.1000.4 5.6, the ESC
//! sync managers in mailbox mode): the master writes a request into the
//! receive mailbox (SM0) and the slave takes it when the write reaches the
//! area's last byte; the slave's answers wait in the send mailbox (SM1),
//! one at a time, and a read that reaches the last byte frees it for the
//! next. A read of an empty send mailbox is not counted (working counter
//! 0): that is how a master polls it without reading the status first.
//!
//! Lost answers are asked for again with the repeat request (ETG.1000.4
//! 5.6.1.2): the master toggles SM1's repeat bit (register 0x080E bit 1),
//! the slave puts its last answer back and toggles its repeat
//! acknowledge (0x080F bit 1).
//!
//! The counter in a request's header tells a new request from a repeated
//! one: a request counted like the one before it (not 0) is not run again.
//! The chip counts its own CoE requests 1..=7; a host that sent its own
//! requests with a counter in the chip's sequence would see some dropped
//! ([`Mailboxes::chip_request`] keeps that sequence here).

use std::collections::VecDeque;

use ecmxf_devices::sii::MailboxArea;
use ecmxf_wire::mbx::{self, MailboxHeader, MailboxType};

/// SM1's activate register (repeat request in bit 1).
pub const SM1_ACTIVATE: u16 = 0x080E;
/// SM1's PDI control register (repeat acknowledge in bit 1).
pub const SM1_PDI_CONTROL: u16 = 0x080F;
/// SM1's status register (mailbox full in bit 3).
pub const SM1_STATUS: u16 = 0x080D;

/// Faults a test may ask the mailbox for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MailboxFaults {
    /// The next this many answers are lost on the way back: read out of
    /// the mailbox (freeing it) by a datagram that never returns.
    pub lose_answers: u32,
    /// The next this many requests are answered after a CoE emergency.
    pub emergency_first: u32,
}

/// The two mailboxes.
#[derive(Clone, Debug, Default)]
pub struct Mailboxes {
    /// Where they are (SII words 0x18..0x1B).
    pub area: MailboxArea,
    /// The receive mailbox's bytes as written so far.
    written: Vec<u8>,
    /// Answers waiting; the first is in the send mailbox.
    outbox: VecDeque<Vec<u8>>,
    /// The last answer read out, for a repeat request.
    last_read: Option<Vec<u8>>,
    /// The counter of the last request taken.
    last_counter: u8,
    /// The slave's own counter for what it sends.
    sent_counter: u8,
    /// The chip's counter for its own CoE requests to this slave.
    chip_counter: u8,
    /// Repeat request bit as last seen.
    repeat: bool,
    /// Faults asked for.
    pub faults: MailboxFaults,
    /// Requests taken, duplicates dropped, answers read, repeats served.
    pub stats: MailboxStats,
}

/// What the mailboxes did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MailboxStats {
    /// Requests taken.
    pub requests: u64,
    /// Requests dropped as repeats of the one before (same counter).
    pub duplicates: u64,
    /// Answers read out.
    pub answers_read: u64,
    /// Repeat requests served.
    pub repeats: u64,
    /// The chip's own CoE requests (SDO_REQ) run on the slave: they never
    /// pass the receive mailbox, so `requests` does not see them.
    pub chip_sdos: u64,
}

fn overlap(ado: u16, len: usize, start: u16, size: u16) -> Option<(usize, usize, usize)> {
    let (a0, a1) = (usize::from(ado), usize::from(ado) + len);
    let (s0, s1) = (usize::from(start), usize::from(start) + usize::from(size));
    let (lo, hi) = (a0.max(s0), a1.min(s1));
    // (offset in the datagram, offset in the area, count)
    (lo < hi && size > 0).then(|| (lo - a0, lo - s0, hi - lo))
}

impl Mailboxes {
    /// Empty mailboxes at `area`.
    pub fn new(area: MailboxArea) -> Self {
        Self { written: vec![0; usize::from(area.rx_size)], area, ..Self::default() }
    }

    /// Whether `ado..ado+len` touches either mailbox.
    pub fn touches(&self, ado: u16, len: usize) -> bool {
        overlap(ado, len, self.area.rx_offset, self.area.rx_size).is_some()
            || overlap(ado, len, self.area.tx_offset, self.area.tx_size).is_some()
    }

    /// A write into the receive mailbox; the request when it reached the
    /// last byte (the ESC hands it to the slave then). A request counted
    /// like the one before is dropped (ETG.1000.4: a repetition).
    pub fn write(&mut self, ado: u16, data: &[u8]) -> Option<Vec<u8>> {
        let (from, at, n) = overlap(ado, data.len(), self.area.rx_offset, self.area.rx_size)?;
        self.written[at..at + n].copy_from_slice(&data[from..from + n]);
        if at + n != usize::from(self.area.rx_size) {
            return None;
        }
        let request = std::mem::replace(&mut self.written, vec![0; usize::from(self.area.rx_size)]);
        let counter = MailboxHeader::decode(&request).map_or(0, |h| h.counter);
        if counter != 0 && counter == self.last_counter {
            self.stats.duplicates += 1;
            return None;
        }
        self.last_counter = counter;
        self.stats.requests += 1;
        Some(request)
    }

    /// A read of the send mailbox: `Some(false)` (not counted) while it is
    /// empty, `None` when the datagram was lost on its way back after the
    /// ESC had freed the mailbox (a lost-answer fault).
    pub fn read(&mut self, ado: u16, out: &mut [u8]) -> Option<bool> {
        let Some((from, at, n)) = overlap(ado, out.len(), self.area.tx_offset, self.area.tx_size) else {
            return Some(false);
        };
        let Some(front) = self.outbox.front() else { return Some(false) };
        for (k, b) in out[from..from + n].iter_mut().enumerate() {
            *b = front.get(at + k).copied().unwrap_or(0);
        }
        if at + n != usize::from(self.area.tx_size) {
            return Some(true);
        }
        let answer = self.outbox.pop_front().unwrap_or_default();
        self.last_read = Some(answer);
        self.stats.answers_read += 1;
        if self.faults.lose_answers > 0 {
            self.faults.lose_answers -= 1;
            out.fill(0);
            return None;
        }
        Some(true)
    }

    /// Queues an answer: `body` of `kind`, with the slave's next counter.
    pub fn post(&mut self, kind: MailboxType, address: u16, body: &[u8]) {
        self.sent_counter = mbx::next_counter(self.sent_counter);
        let header = MailboxHeader { address, ..MailboxHeader::new(kind, 0, self.sent_counter) };
        let mut message = vec![0; mbx::HEADER_LEN + body.len()];
        if mbx::Message::write(header, body, &mut message).is_ok() {
            self.outbox.push_back(message);
        }
    }

    /// The mailbox sync managers deactivated (the slave back in INIT):
    /// what was written and every answer not read yet are gone, as an
    /// ESC's buffers are when their sync manager is switched off
    /// (ETG.1000.4, the mailbox lives only from PRE-OP on). The counters
    /// stay: the slave's next message is counted on.
    pub fn reset(&mut self) {
        self.written.fill(0);
        self.outbox.clear();
        self.last_read = None;
    }

    /// Whether an answer waits in the send mailbox (SM1 status bit 3).
    pub fn full(&self) -> bool {
        !self.outbox.is_empty()
    }

    /// The repeat request bit as written now: a toggle puts the last answer
    /// back in the send mailbox. Returns the acknowledge bit to show.
    pub fn repeat_request(&mut self, bit: bool) -> bool {
        if bit != self.repeat {
            self.repeat = bit;
            if let Some(last) = self.last_read.clone() {
                self.outbox.push_front(last);
                self.stats.repeats += 1;
            }
        }
        self.repeat
    }

    /// The chip ran one of its own CoE requests (SDO_REQ): it counted it
    /// in its sequence, which the slave now remembers as the last counter.
    pub fn chip_request(&mut self) {
        self.stats.chip_sdos += 1;
        self.chip_counter = mbx::next_counter(self.chip_counter);
        self.last_counter = self.chip_counter;
    }

    /// Answers waiting.
    pub fn waiting(&self) -> usize {
        self.outbox.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area() -> MailboxArea {
        MailboxArea { rx_offset: 0x1000, rx_size: 32, tx_offset: 0x1080, tx_size: 32 }
    }

    fn request(counter: u8) -> Vec<u8> {
        let mut m = vec![0u8; 32];
        mbx::Message::write(MailboxHeader::new(MailboxType::Coe, 0, counter), &[1, 2, 3, 4], &mut m).unwrap();
        m
    }

    #[test]
    fn a_request_is_taken_when_its_last_byte_is_written() {
        let mut m = Mailboxes::new(area());
        let r = request(0);
        assert_eq!(m.write(0x1000, &r[..20]), None);
        assert_eq!(m.write(0x1000 + 20, &r[20..]).as_deref(), Some(&r[..]));
        assert_eq!(m.write(0x1000, &r).as_deref(), Some(&r[..]), "counter 0 is never a repetition");
    }

    #[test]
    fn a_reset_drops_what_was_not_read_and_takes_the_next_request_whole() {
        let mut m = Mailboxes::new(area());
        m.post(MailboxType::Coe, 0, &[6, 0, 0, 0]);
        let r = request(0);
        assert_eq!(m.write(0x1000, &r[..20]), None);
        m.reset();
        assert!(!m.full(), "an answer left over from before INIT is gone");
        let mut out = [0u8; 32];
        assert_eq!(m.read(0x1080, &mut out), Some(false));
        assert_eq!(m.write(0x1000, &r).as_deref(), Some(&r[..]), "the half-written request is gone too");
    }

    #[test]
    fn a_repeated_counter_is_not_run_again_and_the_chips_counters_count() {
        let mut m = Mailboxes::new(area());
        assert!(m.write(0x1000, &request(3)).is_some());
        assert!(m.write(0x1000, &request(3)).is_none());
        m.chip_request();
        assert!(m.write(0x1000, &request(1)).is_none(), "the chip's first request was counted 1");
        assert_eq!(m.stats.duplicates, 2);
    }

    #[test]
    fn an_answer_is_read_once_and_a_repeat_puts_it_back() {
        let mut m = Mailboxes::new(area());
        let mut out = [0u8; 32];
        assert_eq!(m.read(0x1080, &mut out), Some(false), "empty: not counted");
        m.post(MailboxType::Coe, 0, &[9, 9]);
        assert_eq!(m.read(0x1080, &mut out[..8]), Some(true), "the start: counted, not freed");
        assert_eq!(m.read(0x1080, &mut out), Some(true));
        assert_eq!(&out[6..8], &[9, 9]);
        assert_eq!(m.read(0x1080, &mut out), Some(false), "freed");
        assert!(m.repeat_request(true));
        assert_eq!(m.read(0x1080, &mut out), Some(true), "the last answer again");
        m.faults.lose_answers = 1;
        m.post(MailboxType::Coe, 0, &[7]);
        assert_eq!(m.read(0x1080, &mut out), None, "read out and lost");
        assert!(!m.repeat_request(false));
        assert!(m.read(0x1080, &mut out) == Some(true) && out[6] == 7);
    }
}
