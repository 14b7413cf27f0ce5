//! Transactions on the chip's single blocking slot (v049 表三 notes): start
//! the operation, watch the busy bit in whatever answers come next (cyclic
//! ones included), then fetch the result (or, on error bit3, the SDO abort
//! code with command 69). One at a time, taken from the fair queue
//! (`fair.rs`). What each kind of request sends and how it reads its
//! result is its handler's (`handler.rs`, one file per kind); what every
//! kind shares is here: starting reads once, polling, the deadline and
//! the grace, and handing the reply back.
//!
//! Writes (SDO download, EEPROM write, state change, raw datagrams, FoE
//! steps) start with a guarded call: they must run exactly once. Reads (SDO
//! upload, EEPROM read, PDO assignment, state refresh) may run twice
//! without harm, so they go out once, and whichever exchange comes next (a
//! FIFO exchange fitted into the operation's run, or the first poll) brings
//! the read's answer (refused or started): one exchange instead of the
//! guard's two. When that answer is lost to a bit error, the next header
//! the chip builds decides: busy, the read runs; not busy, it is sent again
//! (it never ran, or it already ended: either way a second run is the
//! answer). Never a result of the transaction before it: a GET is only
//! believed after a start the chip confirmed.
//!
//! Polls, and what the transaction wants of the link between its steps
//! ([`Active::on_chip`]): `transaction/polls.rs`.
//!
//! Cancel-safety: a caller that stops waiting is answered with a timeout at
//! once, but the operation it started still runs to its end (or is
//! abandoned with ASYNC_CMD_RESET when it overstays), and its result is never
//! fetched: the slot is free and clean before the next transaction starts.

use std::sync::Arc;
use std::time::{Duration, Instant};

use ecmxf_wire::CommandCode;
use ecmxf_wire::flags::{ControlFlags, ErrorFlags};
use ecmxf_wire::payload::control::{AsyncCmdReset, AsyncReset};

use super::handler::{Cx, Handler, Next, refused};
use super::kind::Kind;
use super::request::{Job, SlotRequest, TransferProgress};
use crate::engine::error::EngineError;
use crate::engine::telemetry::Telemetry;
use crate::link::Link;
use crate::port::{Port, PortError};

mod pace;
mod polls;

pub(crate) use pace::PollPace;

/// How long an operation may overstay its caller's deadline before it is
/// abandoned.
const GRACE: Duration = Duration::from_secs(2);

type ReplyTo = tokio::sync::oneshot::Sender<Result<Vec<u8>, EngineError>>;

/// The transaction in the slot.
#[derive(Debug)]
pub(crate) struct Active {
    request: SlotRequest,
    /// The request's kind's steps, and how far they are.
    kind: Kind,
    deadline: Instant,
    /// Who waits for the result; `None` once they gave up (orphaned).
    reply: Option<ReplyTo>,
    /// A blocking command of it went out and it waits for the chip.
    waiting: bool,
    progress: Option<Arc<TransferProgress>>,
    /// The reply's bytes (for FoE reads, the file so far): the caller's
    /// buffer, with room for any answer (see `request::reply_capacity`), so
    /// this thread copies instead of allocating.
    buffer: Vec<u8>,
    /// When the blocking command of the current step went out.
    since: Instant,
    /// When the last poll went out, and the exchange count right after it.
    polled: Option<(Instant, u64)>,
    /// The first exchange whose header the chip built after it took this
    /// step's blocking command: from then on the busy bit speaks of it.
    told_from: u64,
    /// The indices of this step's last two GET polls, newest first: an
    /// answer to either that says "not busy" is the result.
    polls: [Option<u8>; 2],
    /// The last poll was sent at once to fetch the answer of the one
    /// before it (see `waited`); the next waits for its time.
    fetching: bool,
    /// A read went out once (index, code, the exchange count right after
    /// it) and its answer has not been looked at yet.
    sent_read: Option<(u8, CommandCode, u64)>,
    /// A read's answer was lost: whether the chip ran it is not known until
    /// a header brought after this exchange says (busy: it runs; not busy:
    /// start again, a read may run twice).
    unsure_after: Option<u64>,
    /// Counted as a finished transaction before its caller hears the
    /// result, so a caller that reads the status next sees it counted.
    finished: Arc<Telemetry>,
    /// How long the engine's recent PDO assignment reads took (see `pace`).
    pace: Arc<PollPace>,
}

/// What a step did.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Progress {
    /// Sent something; call again.
    Sent,
    /// Nothing to send now: waiting for the chip.
    Waiting,
    /// Finished; the slot is free.
    Done,
}

impl Active {
    /// Takes a job into the slot; a job whose caller already left is dropped.
    pub(crate) fn new(job: Job, now: Instant, finished: &Arc<Telemetry>, pace: &Arc<PollPace>) -> Option<Self> {
        if job.reply.is_closed() {
            return None;
        }
        Some(Self {
            kind: Kind::of(&job.request),
            request: job.request,
            deadline: job.deadline,
            reply: Some(job.reply),
            waiting: false,
            progress: job.progress,
            buffer: job.buffer,
            since: now,
            polled: None,
            told_from: u64::MAX,
            polls: [None; 2],
            fetching: false,
            sent_read: None,
            unsure_after: None,
            finished: Arc::clone(finished),
            pace: Arc::clone(pace),
        })
    }

    /// Ends it with `e` (the engine is leaving the running state).
    pub(crate) fn fail(mut self, e: EngineError) {
        // Not run to its end: not counted.
        if let Some(reply) = self.reply.take() {
            let _ = reply.send(Err(e));
        }
    }

    fn orphaned(&self) -> bool {
        self.reply.is_none()
    }

    fn finish(mut self, result: Result<Vec<u8>, EngineError>) -> Progress {
        self.finished.transactions.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        if let Some(reply) = self.reply.take() {
            // The receiver may have gone meanwhile; nothing to do then.
            let _ = reply.send(result);
        }
        Progress::Done
    }

    /// Advances the transaction by at most one guarded call.
    pub(crate) fn step<L: Link>(
        mut self,
        port: &mut Port<L>,
        now: Instant,
    ) -> Result<(Option<Self>, Progress), PortError> {
        let gone = self.reply.as_ref().is_some_and(|r| r.is_closed());
        if gone || (now >= self.deadline && !self.orphaned()) {
            if let Some(reply) = self.reply.take() {
                let _ = reply.send(Err(EngineError::Timeout));
            }
        }
        if self.waiting { self.wait(port, now) } else { self.start(port, now) }
    }

    fn start<L: Link>(mut self, port: &mut Port<L>, now: Instant) -> Result<(Option<Self>, Progress), PortError> {
        if self.orphaned() {
            return Ok((None, Progress::Done));
        }
        let next = self.handle(port, now, None, None)?;
        self.follow(next, port, now)
    }

    /// Calls the handler: to start (`ended` is `None`), or because the
    /// chip ended its command (`Some(failed)`); `fetched`: see [`Cx`].
    fn handle<L: Link>(
        &mut self,
        port: &mut Port<L>,
        now: Instant,
        ended: Option<bool>,
        fetched: Option<u8>,
    ) -> Result<Next, PortError> {
        let mut cx = Cx {
            port,
            now,
            deadline: self.deadline,
            request: &self.request,
            buffer: &mut self.buffer,
            progress: self.progress.as_deref(),
            fetched,
        };
        match ended {
            None => self.kind.start(&mut cx),
            Some(failed) => self.kind.ended(&mut cx, failed),
        }
    }

    /// Does what the handler's step asks of the slot.
    fn follow<L: Link>(
        mut self,
        next: Next,
        port: &mut Port<L>,
        now: Instant,
    ) -> Result<(Option<Self>, Progress), PortError> {
        let exchanges = port.stats().exchanges;
        match next {
            Next::Started { refused: true } | Next::Refused => Ok(self.refused_by_chip(port)),
            Next::Started { refused: false } => {
                self.waiting = true;
                // A guarded call's own answer was built after the chip took it.
                self.began(now, exchanges);
                Ok((Some(self), Progress::Sent))
            }
            Next::ReadSent(index, code) => {
                // A step of its own, so that the engine looks at what the
                // read's own exchange brought (the answer to the packet
                // before it: an emergency question's) before another
                // exchange replaces it; the next step looks at the read's
                // answer (`read_answered`).
                self.waiting = true;
                // The exchange after this one brings the header built after the chip took it.
                self.began(now, exchanges + 1);
                self.sent_read = Some((index, code, exchanges));
                Ok((Some(self), Progress::Sent))
            }
            Next::Done(result) => Ok((None, self.finish(result))),
        }
    }

    /// The answer to a read sent once: brought by the exchange after it
    /// (the first poll, sent now when no exchange came since). Refused: the
    /// error. Lost (corrupt, or replaced by a later answer: not the echo of
    /// the read): decided later (`unsure_after`). `Err(self)` to go on.
    fn read_answered<L: Link>(
        mut self,
        port: &mut Port<L>,
        now: Instant,
    ) -> Result<Result<(Option<Self>, Progress), Self>, PortError> {
        let Some((index, code, at)) = self.sent_read.take() else { return Ok(Err(self)) };
        let polled_now = port.stats().exchanges == at;
        if polled_now {
            self.poll(port, now)?;
        }
        match port.answer_to(index, code) {
            Some(a) => {
                if refused(&a) {
                    return Ok(Ok(self.refused_by_chip(port)));
                }
            }
            _ => self.unsure_after = Some(at + 1),
        }
        if polled_now { Ok(Ok((Some(self), Progress::Sent))) } else { Ok(Err(self)) }
    }

    /// The chip refused the command (error bit7): the bit is cleared with
    /// the next packet and the caller gets [`EngineError::Refused`].
    fn refused_by_chip<L: Link>(self, port: &mut Port<L>) -> (Option<Self>, Progress) {
        port.pending_control |= ControlFlags::CLEAR_COMMAND_ERROR;
        let what = self.request.to_string();
        (None, self.finish(Err(EngineError::Refused(what))))
    }

    fn wait<L: Link>(self, port: &mut Port<L>, now: Instant) -> Result<(Option<Self>, Progress), PortError> {
        let mut this = match self.read_answered(port, now)? {
            Ok(done) => return Ok(done),
            Err(this) => this,
        };
        if let Some(after) = this.unsure_after {
            // Only a header built after the chip took the packet that
            // followed the read tells: busy, it runs; else run it again.
            if port.status_exchange() <= after {
                if now >= this.next_poll() {
                    this.poll(port, now)?;
                    return Ok((Some(this), Progress::Sent));
                }
                return Ok((Some(this), Progress::Waiting));
            }
            this.unsure_after = None;
            if !port.status().blocking_busy() {
                this.waiting = false;
                return this.start(port, now);
            }
        }
        this.waited(port, now)
    }

    fn waited<L: Link>(mut self, port: &mut Port<L>, now: Instant) -> Result<(Option<Self>, Progress), PortError> {
        // The GET poll that ran after the end is the newest word on the
        // operation; else the newest header.
        let fetched = self.fetched(port).map(|(index, a)| (index, a.header));
        let status = fetched.map_or(*port.status(), |(_, h)| h);
        if status.blocking_busy() {
            if self.orphaned() && now >= self.deadline + GRACE {
                // Overstayed: abandon it so the slot is free.
                port.call(&AsyncCmdReset(AsyncReset::ABANDON_PREVIOUS | AsyncReset::CLEAR_BUSY))?;
                port.pending_control |= ControlFlags::CLEAR_BLOCKING_ERROR;
                return Ok((None, Progress::Done));
            }
            if self.fetch_unanswered(port) || now >= self.next_poll() {
                self.poll(port, now)?;
                return Ok((Some(self), Progress::Sent));
            }
            return Ok((Some(self), Progress::Waiting));
        }
        let failed = status.errors.contains(ErrorFlags::BLOCKING_FAILED);
        if failed {
            port.pending_control |= ControlFlags::CLEAR_BLOCKING_ERROR;
        } else if fetched.is_some() {
            self.note_pace(now);
        }
        if self.orphaned() {
            return Ok((None, Progress::Done));
        }
        if !failed && fetched.is_none() && self.fetch_unanswered(port) {
            // A GET poll's answer is on its way: the exchange that brings
            // it (a poll again) ends the read, one exchange where a
            // guarded GET would take two.
            self.poll(port, now)?;
            return Ok((Some(self), Progress::Sent));
        }
        let next = self.handle(port, now, Some(failed), fetched.map(|(index, _)| index))?;
        self.follow(next, port, now)
    }
}
