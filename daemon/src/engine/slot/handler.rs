//! What one kind of request does on the blocking slot, apart from what
//! every transaction shares: a [`Handler`] sends its kind's commands and
//! reads its results; the transaction (`transaction.rs`) watches the busy
//! bit, polls, keeps deadlines and hands the reply back. A handler says
//! what it did with a [`Next`], and never waits: it is called once to
//! start and once each time the chip ends one of its blocking commands.
//!
//! `kind.rs` is the one place a request picks its handler.

use std::time::Instant;

use ecmxf_wire::flags::ErrorFlags;
use ecmxf_wire::{CommandCode, Request};

use super::request::{SlotRequest, TransferProgress};
use crate::engine::error::EngineError;
use crate::link::Link;
use crate::port::{Answer, Port, PortError};

/// What a handler did.
#[derive(Debug)]
pub(super) enum Next {
    /// A blocking command went out guarded; `refused`: its own answer has
    /// the command error bit (v049 error bit7), so it never ran. Else the
    /// transaction waits for the busy bit to clear, then calls
    /// [`Handler::ended`].
    Started {
        /// The chip refused it.
        refused: bool,
    },
    /// A read (a blocking command that may run twice without harm) went
    /// out once ([`Port::send_once`]): its index and code. The next
    /// exchange brings its answer (see the transaction's module doc).
    ReadSent(u8, CommandCode),
    /// A command answered at once was refused (error bit7).
    Refused,
    /// The transaction's result: the slot is free.
    Done(Result<Vec<u8>, EngineError>),
}

/// A repeatable GET that reads a blocking operation's result and polls
/// its busy bit at once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Fetch {
    /// SDO_GET (v049 11).
    Sdo,
    /// EEPROM_GET (v049 39).
    Eeprom,
    /// PDO_CONFIG_GET (v049 9).
    PdoConfig,
}

impl Fetch {
    pub(super) fn code(self) -> CommandCode {
        match self {
            Self::Sdo => CommandCode::SdoGet,
            Self::Eeprom => CommandCode::EepromGet,
            Self::PdoConfig => CommandCode::PdoConfigGet,
        }
    }
}

/// What a handler may use for a step: the port, and the transaction's
/// parts that are not the slot's bookkeeping.
pub(super) struct Cx<'a, L: Link> {
    pub(super) port: &'a mut Port<L>,
    pub(super) now: Instant,
    /// When the caller stops waiting.
    pub(super) deadline: Instant,
    /// The request, for its bytes and for errors in words.
    pub(super) request: &'a SlotRequest,
    /// The caller's buffer, with room for any answer (see
    /// `request::reply_capacity`): this thread copies instead of
    /// allocating.
    pub(super) buffer: &'a mut Vec<u8>,
    /// Where a long transfer reports how far it is.
    pub(super) progress: Option<&'a TransferProgress>,
    /// The index of this step's GET poll whose answer, built after the
    /// operation ended, is the result ([`Cx::fetched_answer`]): no other
    /// call needed.
    pub(super) fetched: Option<u8>,
}

/// The result's GET answer the polls already brought (`fetched`, see
/// [`Cx::fetched`]), else the GET called now.
pub(super) fn fetched_or_call<'p, 'r, L: Link, R: Request<'r>>(
    port: &'p mut Port<L>,
    fetched: Option<u8>,
    get: &R,
) -> Result<Answer<'p>, PortError> {
    match fetched.filter(|&i| port.answer_to(i, R::CODE).is_some()) {
        Some(i) => port.answer_to(i, R::CODE).ok_or(PortError::NoAnswer { code: R::CODE, attempts: 0, last: None }),
        None => port.call(get),
    }
}

impl<L: Link> Cx<'_, L> {
    /// Sends a blocking command guarded.
    pub(super) fn start<'r, R: Request<'r>>(&mut self, req: &R) -> Result<Next, PortError> {
        Ok(Next::Started { refused: refused(&self.port.call(req)?) })
    }

    /// Sends a read once; the next exchange brings its answer.
    pub(super) fn read<'r, R: Request<'r>>(&mut self, req: &R) -> Result<Next, PortError> {
        Ok(Next::ReadSent(self.port.send_once(req)?, R::CODE))
    }

    /// The request in words, for errors.
    pub(super) fn what(&self) -> String {
        self.request.to_string()
    }
}

/// The reply made of `parts`, in the caller's `buffer` (taken: an empty
/// `Vec` does not allocate).
pub(super) fn fill(buffer: &mut Vec<u8>, parts: &[&[u8]]) -> Vec<u8> {
    buffer.clear();
    for p in parts {
        buffer.extend_from_slice(p);
    }
    std::mem::take(buffer)
}

/// Whether the chip refused the command (error bit7: bad parameter).
pub(super) fn refused(a: &Answer<'_>) -> bool {
    a.header.errors.contains(ErrorFlags::COMMAND_ERROR)
}

/// One kind of request's steps.
pub(super) trait Handler {
    /// Sends the first command (or answers at once: a bad argument, a
    /// command answered in its own exchange). Called again when a read
    /// sent once must run again.
    fn start<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError>;

    /// The repeatable GET that reads the waiting step's result, if there
    /// is one: it is the poll (else INFO_UPDATE is).
    fn fetch(&self) -> Option<Fetch> {
        None
    }

    /// The chip ended the last blocking command; `failed`: its error
    /// bit3. Not called once the caller has gone: nothing reads a result
    /// then.
    fn ended<L: Link>(&mut self, cx: &mut Cx<'_, L>, failed: bool) -> Result<Next, PortError>;
}
