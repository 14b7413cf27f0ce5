//! Transactions on the chip's single blocking slot (v049 表三 notes): start
//! the operation, watch the busy bit in whatever answers come next (cyclic
//! ones included), then fetch the result (or, on error bit3, the SDO abort
//! code with command 69). One at a time, taken from the fair queue
//! (`fair.rs`). Multi-step FoE transfers live in `foe.rs`.
//!
//! Writes (SDO download, EEPROM write, state change, raw datagrams) start
//! with a guarded call: they must run exactly once. Reads (SDO upload,
//! EEPROM read, PDO assignment, state refresh) may run twice without harm,
//! so they go out once, and whichever exchange comes next (a FIFO exchange
//! fitted into the operation's run, or the first poll) brings the read's
//! answer (refused or started): one exchange instead of the guard's two. When that answer is
//! lost to a bit error, the next header the chip builds decides: busy, the
//! read runs; not busy, it is sent again (it never ran, or it already
//! ended: either way a second run is the answer). Never a result of the
//! transaction before it: a GET is only believed after a start the chip
//! confirmed.
//!
//! Polls cost one exchange each and say as much as they can: where the
//! result is read with a repeatable GET (SDO_GET, EEPROM_GET: a non-blocking
//! read of the chip's result buffer, v049 11/39), the GET itself is the
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
//!
//! Cancel-safety: a caller that stops waiting is answered with a timeout at
//! once, but the operation it started still runs to its end (or is
//! abandoned with ASYNC_CMD_RESET when it overstays), and its result is never
//! fetched: the slot is free and clean before the next transaction starts.

use std::sync::Arc;
use std::time::{Duration, Instant};

use ecmxf_wire::CommandCode;
use ecmxf_wire::flags::{ControlFlags, ErrorFlags};
use ecmxf_wire::payload::cia402::{Cia402GetStatusword, Cia402StateGet};
use ecmxf_wire::payload::control::{AsyncCmdReset, AsyncReset, InfoUpdate};
use ecmxf_wire::payload::ecat_init::StateUpdate;
use ecmxf_wire::payload::eeprom::{EepromAccess, EepromGet, EepromRequest};
use ecmxf_wire::payload::emergency::CoeEmergencyGet;
use ecmxf_wire::payload::foe::{FOE_FLASH_SIZE, FoeRequest, FoeTransfer};
use ecmxf_wire::payload::pdo::{PdoConfigForm, PdoConfigGet, PdoConfigReq};
use ecmxf_wire::payload::raw::{RAW_HEADER_LEN, RawGet, RawRequest};
use ecmxf_wire::payload::sdo::{
    SDO_REQ_HEADER_LEN, SdoAbortCode, SdoAbortCodeGet, SdoAccess, SdoGet, SdoGetReply, SdoRequest,
};
use ecmxf_wire::payload::slave_info::SlaveInfoGet;
use ecmxf_wire::payload::state::{StateCheck, StateGet, StateReply};

use super::request::{Immediate, Job, SlotRequest, TransferProgress};
use crate::engine::error::{EngineError, WrongState};
use crate::link::Link;
use crate::port::{Answer, Port, PortError};
use foe::{check_foe, chip_timeout_us};

mod foe;

/// How long an operation may overstay its caller's deadline before it is
/// abandoned.
const GRACE: Duration = Duration::from_secs(2);
/// SDO timeout given to the chip, us.
const SDO_TIMEOUT_US: u32 = 1_000_000;
/// The longest time between two polls of a waiting operation.
pub(super) const MAX_POLL: Duration = Duration::from_millis(2);

#[derive(Debug, PartialEq, Eq)]
enum Step {
    /// Not started.
    Start,
    /// Waiting for the busy bit to clear.
    Wait,
    /// An EEPROM write done; its read-back started.
    Verify,
    /// FoE write: a chunk is being staged into the chip's flash.
    FoeStage,
    /// FoE write: the staged file is going to the slave.
    FoeSend,
    /// FoE read: the slave's file is coming into the chip's flash.
    FoeUpload,
    /// FoE read: a chunk of flash is being read.
    FoeFetch,
}

type ReplyTo = tokio::sync::oneshot::Sender<Result<Vec<u8>, EngineError>>;

/// The transaction in the slot.
#[derive(Debug)]
pub(crate) struct Active {
    request: SlotRequest,
    deadline: Instant,
    /// Who waits for the result; `None` once they gave up (orphaned).
    reply: Option<ReplyTo>,
    step: Step,
    progress: Option<Arc<TransferProgress>>,
    /// FoE: bytes staged or read so far.
    cursor: u32,
    /// FoE: bytes in all.
    total: u32,
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
}

/// The reply made of `parts`, in the caller's `buffer` (taken: an empty
/// `Vec` does not allocate).
fn fill(buffer: &mut Vec<u8>, parts: &[&[u8]]) -> Vec<u8> {
    buffer.clear();
    for p in parts {
        buffer.extend_from_slice(p);
    }
    std::mem::take(buffer)
}

/// Whether the chip refused the command (error bit7: bad parameter).
fn refused(a: &Answer<'_>) -> bool {
    a.header.errors.contains(ErrorFlags::COMMAND_ERROR)
}

/// A repeatable GET that reads a blocking operation's result and polls
/// its busy bit at once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Fetch {
    /// SDO_GET (v049 11).
    Sdo,
    /// EEPROM_GET (v049 39).
    Eeprom,
}

impl Fetch {
    fn code(self) -> CommandCode {
        match self {
            Self::Sdo => CommandCode::SdoGet,
            Self::Eeprom => CommandCode::EepromGet,
        }
    }
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
    pub(crate) fn new(job: Job, now: Instant) -> Option<Self> {
        if job.reply.is_closed() {
            return None;
        }
        Some(Self {
            request: job.request,
            deadline: job.deadline,
            reply: Some(job.reply),
            step: Step::Start,
            progress: job.progress,
            cursor: 0,
            total: 0,
            buffer: job.buffer,
            since: now,
            polled: None,
            told_from: u64::MAX,
            polls: [None; 2],
            fetching: false,
            sent_read: None,
            unsure_after: None,
        })
    }

    /// Ends it with `e` (the engine is leaving the running state).
    pub(crate) fn fail(self, e: EngineError) {
        let _ = self.finish(Err(e));
    }

    fn orphaned(&self) -> bool {
        self.reply.is_none()
    }

    fn finish(mut self, result: Result<Vec<u8>, EngineError>) -> Progress {
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
        match self.step {
            Step::Start => self.start(port, now),
            _ => self.wait(port, now),
        }
    }

    fn start<L: Link>(mut self, port: &mut Port<L>, now: Instant) -> Result<(Option<Self>, Progress), PortError> {
        if self.orphaned() {
            return Ok((None, Progress::Done));
        }
        let data_size = port.data_size();
        // Reads: once; the next exchange brings the answer (see the module doc).
        match self.request {
            SlotRequest::SdoRead { slave, index, subindex, complete } => {
                let access = SdoAccess::Read { max_len: (data_size - SDO_REQ_HEADER_LEN) as u16 };
                let timeout_us = SDO_TIMEOUT_US;
                let req = SdoRequest { slave, index, subindex, complete_access: complete, timeout_us, access };
                return self.read_started(port, &req, now);
            }
            SlotRequest::EepromRead { slave, word } => {
                let access = EepromAccess::Read { address: word };
                return self.read_started(
                    port,
                    &EepromRequest { slave: slave.into(), access, timeout_us: 100_000 },
                    now,
                );
            }
            SlotRequest::PdoConfigRead { slave, assign_index } => {
                return self.read_started(
                    port,
                    &PdoConfigReq { slave, assign_index, form: PdoConfigForm::Manual },
                    now,
                );
            }
            SlotRequest::GetState { .. } => return self.read_started(port, &StateUpdate, now),
            _ => {}
        }
        let answer = refused(&match &self.request {
            SlotRequest::SdoWrite { slave, index, subindex, complete, data } => {
                if data.len() + SDO_REQ_HEADER_LEN > data_size {
                    let field = "data";
                    let reason = format!("{} bytes do not fit one {data_size}-byte data section", data.len());
                    return Ok((None, self.finish(Err(EngineError::BadArgument { field, reason }))));
                }
                port.call(&SdoRequest {
                    slave: *slave,
                    index: *index,
                    subindex: *subindex,
                    complete_access: *complete,
                    timeout_us: SDO_TIMEOUT_US,
                    access: SdoAccess::Write(data),
                })?
            }
            SlotRequest::EepromWrite { slave, word, value } => port.call(&EepromRequest {
                slave: (*slave).into(),
                access: EepromAccess::Write { address: *word, value: *value },
                timeout_us: 100_000,
            })?,
            SlotRequest::SetState { target, state } => port.call(&StateCheck { target: *target, state: *state })?,
            SlotRequest::SdoRead { .. }
            | SlotRequest::EepromRead { .. }
            | SlotRequest::PdoConfigRead { .. }
            | SlotRequest::GetState { .. } => unreachable!("reads start in read_started"),
            SlotRequest::Raw { head, data } => {
                if data.len() + RAW_HEADER_LEN > data_size {
                    let reason = format!("{} bytes do not fit one {data_size}-byte data section", data.len());
                    return Ok((None, self.finish(Err(EngineError::BadArgument { field: "data", reason }))));
                }
                port.call(&RawRequest { head: *head, data })?
            }
            SlotRequest::FoeWrite { name, data, .. } => {
                if let Err(e) = check_foe(name, data.len(), data_size) {
                    return Ok((None, self.finish(Err(e))));
                }
                self.total = data.len() as u32;
                self.report();
                return self.foe_stage_next(port, now);
            }
            SlotRequest::FoeRead { slave, name, password, max_len } => {
                if let Err(e) = check_foe(name, *max_len as usize, data_size) {
                    return Ok((None, self.finish(Err(e))));
                }
                let transfer = FoeTransfer {
                    slave: *slave,
                    password: *password,
                    // One byte more than allowed, so that a longer file shows
                    // as too long instead of arriving cut short.
                    file_length: max_len.saturating_add(1).min(FOE_FLASH_SIZE),
                    timeout_us: chip_timeout_us(self.deadline, now),
                    flash_offset: 0,
                    name: name.as_bytes(),
                };
                let refused = refused(&port.call(&FoeRequest::Upload(transfer))?);
                return self.started(port, refused, Step::FoeUpload, now);
            }
            SlotRequest::Immediate(command) => {
                let a = match command {
                    Immediate::GpioConfig(c) => port.call(c)?,
                    Immediate::Gpio(c) => port.call(c)?,
                    Immediate::Qei(c) => port.call(c)?,
                    Immediate::Dac(c) => port.call(c)?,
                    Immediate::Adc(c) => port.call(c)?,
                    Immediate::Cia402StateSet(c) => port.call(c)?,
                    Immediate::Cia402CtlSet(c) => port.call(c)?,
                    Immediate::Cia402StateGet(axis) => port.call(&Cia402StateGet(*axis))?,
                    Immediate::Cia402Statusword(axis) => port.call(&Cia402GetStatusword(*axis))?,
                    Immediate::Emergencies(n) => port.call(&CoeEmergencyGet(*n))?,
                };
                if refused(&a) {
                    return Ok(self.refused_by_chip(port));
                }
                // Relayed as the chip gave it: the client reads the
                // peripheral's answer (api/peripherals.rs).
                let out = fill(&mut self.buffer, &[&[a.header.return_value], a.relayed()]);
                return Ok((None, self.finish(Ok(out))));
            }
            SlotRequest::SlaveInfo { slave, item } => {
                let a = port.call(&SlaveInfoGet { slave: *slave, item: *item })?;
                let refused = a.header.errors.contains(ErrorFlags::COMMAND_ERROR);
                // Relayed: the master reads it by its item (master/transactions.rs).
                let data = fill(&mut self.buffer, &[a.relayed()]);
                if refused {
                    port.pending_control |= ControlFlags::CLEAR_COMMAND_ERROR;
                    return Ok((
                        None,
                        self.finish(Err(EngineError::BadArgument { field: "slave", reason: "no such slave".into() })),
                    ));
                }
                return Ok((None, self.finish(Ok(data))));
            }
        });
        self.started(port, answer, Step::Wait, now)
    }

    /// Starts a read (a blocking command that may run twice without harm)
    /// with one exchange instead of a guarded call: `req` once. The next
    /// exchange, whichever it is (the first poll, a FIFO call, the
    /// emergency question), brings its answer; the next step looks at it
    /// ([`Active::read_answered`]). A step of its own, so that the engine
    /// looks at what the read's own exchange brought (the answer to the
    /// packet before it: an emergency question's) before another exchange
    /// replaces it.
    fn read_started<'a, L: Link, R: ecmxf_wire::Request<'a>>(
        mut self,
        port: &mut Port<L>,
        req: &R,
        now: Instant,
    ) -> Result<(Option<Self>, Progress), PortError> {
        let index = port.send_once(req)?;
        self.step = Step::Wait;
        // The exchange after this one brings the header built after the chip took it.
        self.began(now, port.stats().exchanges + 1);
        self.sent_read = Some((index, R::CODE, port.stats().exchanges));
        Ok((Some(self), Progress::Sent))
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
        match port.previous() {
            Some(a) if a.header.index == index && a.header.code == code && !a.header.is_nop() => {
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
        let what = self.describe();
        (None, self.finish(Err(EngineError::Refused(what))))
    }

    /// After a blocking command went out: refused (its answer has the command
    /// error bit), or
    /// now waiting in `next`.
    fn started<L: Link>(
        mut self,
        port: &mut Port<L>,
        refused: bool,
        next: Step,
        now: Instant,
    ) -> Result<(Option<Self>, Progress), PortError> {
        if refused {
            return Ok(self.refused_by_chip(port));
        }
        self.step = next;
        // A guarded call's own answer was built after the chip took it.
        self.began(now, port.stats().exchanges);
        Ok((Some(self), Progress::Sent))
    }

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
        self.step != Step::Start
    }

    /// A step's blocking command went out at `now`; headers from exchange
    /// `told_from` on were built after the chip took it.
    fn began(&mut self, now: Instant, told_from: u64) {
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
    fn fetch_unanswered<L: Link>(&self, port: &Port<L>) -> bool {
        let unanswered = self.polled.is_some_and(|(_, after)| port.stats().exchanges <= after);
        self.fetch().is_some() && unanswered && !self.fetching
    }

    /// When the next poll is due: back to back while the operation is
    /// young, every quarter of its age later, at most every [`MAX_POLL`].
    pub(crate) fn next_poll(&self) -> Instant {
        match self.polled {
            None => self.since,
            Some((at, _)) => at + (at.saturating_duration_since(self.since) / 4).min(MAX_POLL),
        }
    }

    /// The repeatable GET that reads this step's result, if there is one:
    /// it is the poll (see the module doc).
    fn fetch(&self) -> Option<Fetch> {
        match (&self.request, &self.step) {
            (SlotRequest::SdoRead { .. }, Step::Wait) => Some(Fetch::Sdo),
            (SlotRequest::EepromRead { .. }, Step::Wait) | (SlotRequest::EepromWrite { .. }, Step::Verify) => {
                Some(Fetch::Eeprom)
            }
            _ => None,
        }
    }

    /// Sends one poll: the result's GET where there is one, else
    /// INFO_UPDATE; either answer refreshes the busy bit.
    fn poll<L: Link>(&mut self, port: &mut Port<L>, now: Instant) -> Result<(), PortError> {
        self.fetching = self.fetch_unanswered(port);
        let index = match self.fetch() {
            Some(Fetch::Sdo) => port.send_once(&SdoGet)?,
            Some(Fetch::Eeprom) => port.send_once(&EepromGet)?,
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
    fn fetched<'p, L: Link>(&self, port: &'p Port<L>) -> Option<Answer<'p>> {
        let code = self.fetch()?.code();
        let a = port.previous()?;
        let ours = self.polls.contains(&Some(a.header.index));
        (ours && a.header.code == code && !a.header.is_nop() && !a.header.blocking_busy()).then_some(a)
    }

    /// The request in words, for errors.
    fn describe(&self) -> String {
        self.request.to_string()
    }

    fn report(&self) {
        if let Some(p) = &self.progress {
            p.set(self.cursor, self.total);
        }
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
                this.step = Step::Start;
                return this.start(port, now);
            }
        }
        this.waited(port, now)
    }

    fn waited<L: Link>(mut self, port: &mut Port<L>, now: Instant) -> Result<(Option<Self>, Progress), PortError> {
        // The GET poll that ran after the end is the newest word on the
        // operation; else the newest header.
        let status = self.fetched(port).map_or(*port.status(), |a| a.header);
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
        }
        if self.orphaned() {
            return Ok((None, Progress::Done));
        }
        let foe_step = matches!(self.step, Step::FoeStage | Step::FoeSend | Step::FoeUpload | Step::FoeFetch);
        if foe_step {
            if failed {
                let what = self.describe();
                return Ok((None, self.finish(Err(EngineError::Failed(what)))));
            }
            return self.foe_continue(port, now);
        }
        if !failed && self.fetched(port).is_none() && self.fetch_unanswered(port) {
            // A GET poll's answer is on its way: the exchange that brings
            // it (a poll again) ends the read, one exchange where a
            // guarded GET would take two.
            self.poll(port, now)?;
            return Ok((Some(self), Progress::Sent));
        }
        // Borrowed, not cloned: a request may hold data (an SDO write's).
        let result = match (&self.request, failed) {
            (
                SlotRequest::SdoRead { slave, index, subindex, .. }
                | SlotRequest::SdoWrite { slave, index, subindex, .. },
                true,
            ) => {
                let answer = port.call(&SdoAbortCodeGet)?.answer_to(&SdoAbortCodeGet);
                let code = answer.map_or(SdoAbortCode::GENERAL, |r| r.0);
                Err(EngineError::SdoAbort { slave: *slave, index: *index, subindex: *subindex, code })
            }
            (SlotRequest::SdoRead { .. }, false) => {
                let a = match self.fetched(port) {
                    Some(a) => a,
                    None => port.call(&SdoGet)?,
                };
                // SDO_GET's return value is the read's error code: data
                // with a nonzero code is not this read's value.
                match a.answer_to(&SdoGet) {
                    Ok(SdoGetReply { status: 0, data }) => Ok(fill(&mut self.buffer, &[data])),
                    Err(error) => Err(EngineError::BadAnswer { what: self.describe(), error }),
                    Ok(SdoGetReply { status: code, .. }) => {
                        let what = self.request.to_string();
                        Err(EngineError::Failed(format!("{what}: SDO_GET reports error code {code}")))
                    }
                }
            }
            (SlotRequest::SdoWrite { .. }, false) => Ok(Vec::new()),
            (SlotRequest::EepromRead { slave, word } | SlotRequest::EepromWrite { slave, word, .. }, true) => {
                Err(EngineError::Failed(format!("EEPROM word {word:#06x} of slave {slave}")))
            }
            (SlotRequest::EepromWrite { slave, word, .. }, false) if self.step == Step::Wait => {
                // Read it back.
                port.call(&EepromRequest {
                    slave: (*slave).into(),
                    access: EepromAccess::Read { address: *word },
                    timeout_us: 100_000,
                })?;
                self.step = Step::Verify;
                self.began(now, port.stats().exchanges);
                return Ok((Some(self), Progress::Sent));
            }
            (SlotRequest::EepromRead { slave, word }, false)
            | (SlotRequest::EepromWrite { slave, word, .. }, false) => {
                let a = match self.fetched(port) {
                    Some(a) => a,
                    None => port.call(&EepromGet)?,
                };
                let reply = a.answer_to(&EepromGet).ok();
                match reply {
                    Some(r) if r.error == 0 && r.data.len() >= 2 => match &self.request {
                        SlotRequest::EepromWrite { value, .. } if r.data[..2] != value.to_le_bytes() => {
                            let got = u16::from_le_bytes([r.data[0], r.data[1]]);
                            Err(EngineError::Failed(format!(
                                "EEPROM word {word:#06x} of slave {slave} reads back {got:#06x}, wrote {value:#06x}"
                            )))
                        }
                        _ => Ok(fill(&mut self.buffer, &[r.data])),
                    },
                    Some(r) => Err(EngineError::Failed(format!(
                        "EEPROM word {word:#06x} of slave {slave}: error code {}",
                        r.error
                    ))),
                    None => {
                        Err(EngineError::Failed(format!("EEPROM word {word:#06x} of slave {slave}: unreadable answer")))
                    }
                }
            }
            (SlotRequest::SetState { state, .. }, true) => Err(EngineError::WrongState(WrongState::Refused(*state))),
            (SlotRequest::SetState { .. }, false) => Ok(Vec::new()),
            (SlotRequest::GetState { .. }, true) => {
                Err(EngineError::Failed("the slaves' states could not be refreshed".into()))
            }
            (SlotRequest::GetState { target }, false) => {
                let req = StateGet(*target);
                let a = port.call(&req)?;
                match a.answer_to(&req) {
                    Ok(StateReply(state)) if !refused(&a) => Ok(fill(&mut self.buffer, &[&[state.to_u8()]])),
                    _ => {
                        port.pending_control |= ControlFlags::CLEAR_COMMAND_ERROR;
                        Err(EngineError::BadArgument { field: "slave", reason: format!("no such slave: {target}") })
                    }
                }
            }
            (SlotRequest::SlaveInfo { .. } | SlotRequest::Immediate(_), _) => Ok(Vec::new()),
            (SlotRequest::PdoConfigRead { slave, assign_index }, true) => Err(EngineError::Failed(format!(
                "PDO assignment {assign_index:#06x} of slave {slave} could not be read"
            ))),
            (SlotRequest::PdoConfigRead { .. }, false) => {
                // Relayed: the master reads it as PDO_CONFIG_GET's reply
                // (master/pdos.rs).
                let a = port.call(&PdoConfigGet)?;
                Ok(fill(&mut self.buffer, &[a.relayed()]))
            }
            (SlotRequest::Raw { .. }, true) => Err(EngineError::Failed(self.describe())),
            (SlotRequest::Raw { .. }, false) => match port.call(&RawGet)?.answer_to(&RawGet) {
                Ok(r) => Ok(fill(&mut self.buffer, &[&r.working_counter.to_le_bytes(), r.data])),
                Err(error) => Err(EngineError::BadAnswer { what: self.describe(), error }),
            },
            // Handled above.
            (SlotRequest::FoeWrite { .. } | SlotRequest::FoeRead { .. }, _) => Ok(Vec::new()),
        };
        Ok((None, self.finish(result)))
    }
}
