//! Polls cost one exchange each and say as much as they can: where the
//! result is read with a repeatable GET (SDO_GET, EEPROM_GET,
//! PDO_CONFIG_GET: a non-blocking read of the chip's result buffer, v049
//! 11/39/9), the GET itself is the
//! poll, sent once ([`Port::send_once`]); its answer, brought by whatever
//! exchange comes next, carries the busy bit *and* the result. The chip
//! builds an answer when it processes the packet (v049 圖二: the answer to
//! a packet comes out with the next one), so a GET whose own answer says
//! "not busy" ran after the operation ended and its data is the result; a
//! GET answered "busy" is ignored, one lost to a bit error is sent again.
//! A GET poll sent on its time is followed at once by another, whose
//! exchange brings the first one's answer (the result, if the operation
//! has ended) and polls again; an answer to either of the last two that
//! says "not busy" is the result. So the end is seen within one exchange of
//! the chip finishing, and no guarded GET (two exchanges) is needed.
//! Others poll with INFO_UPDATE, sent once. Polls go back to back while
//! the operation is young and every quarter of its age later (at most
//! [`MAX_POLL`]), so a slow slave's operation does not fill the link with
//! polls. What the transaction wants of the link between its steps
//! ([`Active::on_chip`]) lets the engine fit a FIFO exchange into the
//! operation's run and fetch the result before the next one (`link_turn`).

use std::time::{Duration, Instant};

use ecmxf_wire::payload::control::InfoUpdate;
use ecmxf_wire::payload::eeprom::EepromGet;
use ecmxf_wire::payload::pdo::PdoConfigGet;
use ecmxf_wire::payload::sdo::SdoGet;

use super::Active;
use crate::engine::slot::handler::{Fetch, Handler};
use crate::link::Link;
use crate::port::{Answer, Port, PortError};

/// The longest time between two polls of a waiting operation.
pub(in crate::engine::slot) const MAX_POLL: Duration = Duration::from_millis(2);

impl Active {
    /// Whether the engine may spend the next exchange on something else
    /// (the emergency question) without this transaction losing an answer:
    /// not when an exchange already brought a read's start answer that
    /// the transaction has not looked at yet (the next one would replace
    /// it). Answers to GET polls are read by their index, whichever
    /// exchange brings them.
    pub(crate) fn may_lend_an_exchange<L: Link>(&self, port: &Port<L>) -> bool {
        self.sent_read.is_none_or(|(_, _, at)| port.stats().exchanges == at)
    }

    /// When this step's blocking command went out.
    pub(crate) fn began_at(&self) -> Instant {
        self.since
    }

    /// Whether this step's command has been polled: past its start, where
    /// the rest of its run is no longer known to hold a FIFO exchange.
    pub(crate) fn polled(&self) -> bool {
        self.polls[0].is_some()
    }

    /// Whether its blocking command went out and it waits for the chip.
    pub(crate) fn waiting(&self) -> bool {
        self.waiting
    }

    /// A step's blocking command went out at `now`; headers from exchange
    /// `told_from` on were built after the chip took it.
    pub(super) fn began(&mut self, now: Instant, told_from: u64) {
        (self.since, self.polled, self.told_from) = (now, None, told_from);
        (self.polls, self.fetching) = ([None; 2], false);
    }

    /// What this transaction wants of the link now: `Some(true)` its
    /// blocking command runs on the chip (or no header since it went out
    /// can say yet), so the link is free for cyclic exchanges;
    /// `Some(false)` it wants the next exchange: the command ended, or a
    /// GET poll's result is there or on its way; `None` no command of it
    /// is out (or whether it runs is being decided). The engine fits
    /// cyclic exchanges into a command's run and fetches a result before
    /// them (`running.rs`, `fifo_first`).
    pub(crate) fn on_chip<L: Link>(&self, port: &Port<L>) -> Option<bool> {
        if !self.waiting() || self.unsure_after.is_some() {
            return None;
        }
        if let Some((_, _, at)) = self.sent_read {
            // Whatever exchange comes next brings the start's answer; once
            // one has, the transaction must look before another replaces it.
            return Some(port.stats().exchanges == at);
        }
        if self.fetched(port).is_some() || self.fetch_unanswered(port) {
            return Some(false);
        }
        Some(port.status_exchange() < self.told_from || port.status().blocking_busy())
    }

    /// A GET poll went out on its own time and its answer, the result if
    /// the operation has ended, is still to come: the exchange that brings
    /// it goes at once (and polls again) instead of a quarter of the
    /// operation's age later. One such fetch per timed poll, so a long
    /// operation is not polled back to back.
    pub(super) fn fetch_unanswered<L: Link>(&self, port: &Port<L>) -> bool {
        let unanswered = self.polled.is_some_and(|(_, after)| port.stats().exchanges <= after);
        self.fetch().is_some() && unanswered && !self.fetching
    }

    /// When the next poll is due: back to back while the operation is
    /// young, every quarter of its age later, at most every [`MAX_POLL`].
    /// A PDO assignment read is polled at its start, then when the reads
    /// before it ended ([`super::pace`]), and by the quarter rule only once
    /// that time has passed.
    pub(crate) fn next_poll(&self) -> Instant {
        match self.polled {
            None => self.since,
            Some((at, _)) => {
                let paced = self.expected().and_then(|e| super::pace::paced_poll(self.since, at, e));
                paced.unwrap_or_else(|| at + (at.saturating_duration_since(self.since) / 4).min(MAX_POLL))
            }
        }
    }

    /// How long this step should take, where the engine learns it: PDO
    /// assignment reads only (see [`super::pace`]).
    fn expected(&self) -> Option<std::time::Duration> {
        (self.fetch() == Some(Fetch::PdoConfig)).then(|| self.pace.expected()).flatten()
    }

    /// The GET poll found this step's read ended: its time goes to the
    /// pace, counted to the last timed poll (the one that found it, or the
    /// one its answer was fetched with, an exchange later).
    pub(super) fn note_pace(&self, now: Instant) {
        if self.fetch() == Some(Fetch::PdoConfig) {
            self.pace.ended(self.since, self.polled.map_or(now, |(at, _)| at));
        }
    }

    /// The repeatable GET that reads this step's result, if there is one:
    /// it is the poll (see the module doc).
    pub(super) fn fetch(&self) -> Option<Fetch> {
        if !self.waiting {
            return None;
        }
        self.kind.fetch()
    }

    /// Sends one poll: the result's GET where there is one, else
    /// INFO_UPDATE; either answer refreshes the busy bit.
    pub(super) fn poll<L: Link>(&mut self, port: &mut Port<L>, now: Instant) -> Result<(), PortError> {
        self.fetching = self.fetch_unanswered(port);
        let index = match self.fetch() {
            Some(Fetch::Sdo) => port.send_once(&SdoGet)?,
            Some(Fetch::Eeprom) => port.send_once(&EepromGet)?,
            Some(Fetch::PdoConfig) => port.send_once(&PdoConfigGet)?,
            None => port.send_once(&InfoUpdate)?,
        };
        self.polls = [Some(index), self.polls[0]];
        if !self.fetching {
            self.polled = Some((now, port.stats().exchanges));
        }
        Ok(())
    }

    /// The answer to one of this step's GET polls, when an exchange since
    /// the poll brought it and the chip ran the GET after the operation
    /// ended (its own header says not busy): header and data.
    pub(super) fn fetched<'p, L: Link>(&self, port: &'p Port<L>) -> Option<(u8, Answer<'p>)> {
        let code = self.fetch()?.code();
        // The newest poll answered first: an older one says less.
        let (index, a) = self.polls.iter().flatten().find_map(|&i| Some((i, port.answer_to(i, code)?)))?;
        (!a.header.blocking_busy()).then_some((index, a))
    }
}
