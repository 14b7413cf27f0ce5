//! Transactions on the chip's single blocking slot (v049 表三 notes): start
//! the operation with a guarded call, watch the busy bit in whatever answers
//! come next (cyclic ones included), then fetch the result (or, on error
//! bit3, the SDO abort code with command 69). One at a time, in order.
//!
//! Cancel-safety: a caller that stops waiting is answered with a timeout at
//! once, but the operation it started still runs to its end (or is
//! abandoned with ASYNC_CMD_RESET when it overstays), and its result is never
//! fetched: the slot is free and clean before the next transaction starts.

use std::time::{Duration, Instant};

use ecmxf_wire::flags::{ControlFlags, ErrorFlags};
use ecmxf_wire::payload::control::{AsyncCmdReset, AsyncReset};
use ecmxf_wire::payload::eeprom::{EepromAccess, EepromGet, EepromReply, EepromRequest};
use ecmxf_wire::payload::sdo::{
    SDO_REQ_HEADER_LEN, SdoAbortCode, SdoAbortCodeGet, SdoAbortReply, SdoAccess, SdoGet, SdoRequest,
};
use ecmxf_wire::payload::slave_info::SlaveInfoGet;
use ecmxf_wire::payload::state::StateCheck;
use ecmxf_wire::{Reply, ReplyFields};

use super::error::EngineError;
use super::job::{Job, Request};
use crate::link::Link;
use crate::port::{Answer, Port, PortError};

/// How long an operation may overstay its caller's deadline before it is
/// abandoned.
const GRACE: Duration = Duration::from_secs(2);
/// SDO timeout given to the chip, us.
const SDO_TIMEOUT_US: u32 = 1_000_000;

#[derive(Debug, PartialEq, Eq)]
enum Step {
    /// Not started.
    Start,
    /// Waiting for the busy bit to clear.
    Wait,
    /// An EEPROM write done; its read-back started.
    Verify,
}

type ReplyTo = tokio::sync::oneshot::Sender<Result<Vec<u8>, EngineError>>;

/// The transaction in the slot.
#[derive(Debug)]
pub struct Active {
    request: Request,
    deadline: Instant,
    /// Who waits for the result; `None` once they gave up (orphaned).
    reply: Option<ReplyTo>,
    step: Step,
}

fn fields(a: &Answer<'_>) -> ReplyFields {
    ReplyFields { value: a.header.return_value, data_len: a.header.data_len }
}

/// What a step did.
#[derive(Debug, PartialEq, Eq)]
pub enum Progress {
    /// Sent something; call again.
    Sent,
    /// Nothing to send now: waiting for the chip.
    Waiting,
    /// Finished; the slot is free.
    Done,
}

impl Active {
    /// Takes a job into the slot; a job whose caller already left is dropped.
    pub fn new(job: Job) -> Option<Self> {
        if job.reply.is_closed() {
            return None;
        }
        Some(Self { request: job.request, deadline: job.deadline, reply: Some(job.reply), step: Step::Start })
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
    pub fn step<L: Link>(mut self, port: &mut Port<L>, now: Instant) -> Result<(Option<Self>, Progress), PortError> {
        let gone = self.reply.as_ref().is_some_and(|r| r.is_closed());
        if gone || (now >= self.deadline && !self.orphaned()) {
            if let Some(reply) = self.reply.take() {
                let _ = reply.send(Err(EngineError::Timeout));
            }
        }
        match self.step {
            Step::Start => self.start(port),
            Step::Wait | Step::Verify => self.wait(port, now),
        }
    }

    fn start<L: Link>(mut self, port: &mut Port<L>) -> Result<(Option<Self>, Progress), PortError> {
        if self.orphaned() {
            return Ok((None, Progress::Done));
        }
        let data_size = port.data_size();
        let answer = match &self.request {
            Request::SdoRead { slave, index, subindex, complete } => port.call(&SdoRequest {
                slave: *slave,
                index: *index,
                subindex: *subindex,
                complete_access: *complete,
                timeout_us: SDO_TIMEOUT_US,
                access: SdoAccess::Read { max_len: (data_size - SDO_REQ_HEADER_LEN) as u16 },
            })?,
            Request::SdoWrite { slave, index, subindex, complete, data } => {
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
            Request::EepromRead { slave, word } => port.call(&EepromRequest {
                slave: (*slave).into(),
                access: EepromAccess::Read { address: *word },
                timeout_us: 100_000,
            })?,
            Request::EepromWrite { slave, word, value } => port.call(&EepromRequest {
                slave: (*slave).into(),
                access: EepromAccess::Write { address: *word, value: *value },
                timeout_us: 100_000,
            })?,
            Request::SetState { target, state } => port.call(&StateCheck { target: *target, state: *state })?,
            Request::SlaveInfo { slave, item } => {
                let a = port.call(&SlaveInfoGet { slave: *slave, item: *item })?;
                let refused = a.header.errors.contains(ErrorFlags::COMMAND_ERROR);
                let data = a.data.to_vec();
                if refused {
                    port.pending_control |= ControlFlags::CLEAR_COMMAND_ERROR;
                    return Ok((
                        None,
                        self.finish(Err(EngineError::BadArgument { field: "slave", reason: "no such slave".into() })),
                    ));
                }
                return Ok((None, self.finish(Ok(data))));
            }
        };
        if answer.header.errors.contains(ErrorFlags::COMMAND_ERROR) {
            port.pending_control |= ControlFlags::CLEAR_COMMAND_ERROR;
            let what = format!("{:?}", self.request);
            return Ok((None, self.finish(Err(EngineError::Refused(what)))));
        }
        self.step = Step::Wait;
        Ok((Some(self), Progress::Sent))
    }

    fn wait<L: Link>(mut self, port: &mut Port<L>, now: Instant) -> Result<(Option<Self>, Progress), PortError> {
        let status = *port.status();
        if status.blocking_busy() {
            if self.orphaned() && now >= self.deadline + GRACE {
                // Overstayed: abandon it so the slot is free.
                port.call(&AsyncCmdReset(AsyncReset::ABANDON_PREVIOUS | AsyncReset::CLEAR_BUSY))?;
                port.pending_control |= ControlFlags::CLEAR_BLOCKING_ERROR;
                return Ok((None, Progress::Done));
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
        let request = self.request.clone();
        let result = match (&request, failed) {
            (
                Request::SdoRead { slave, index, subindex, .. } | Request::SdoWrite { slave, index, subindex, .. },
                true,
            ) => {
                let a = port.call(&SdoAbortCodeGet)?;
                let code = SdoAbortReply::decode(&fields(&a), a.data).map_or(SdoAbortCode::GENERAL, |r| r.0);
                Err(EngineError::SdoAbort { slave: *slave, index: *index, subindex: *subindex, code })
            }
            (Request::SdoRead { .. }, false) => {
                let a = port.call(&SdoGet)?;
                Ok(a.data.to_vec())
            }
            (Request::SdoWrite { .. }, false) => Ok(Vec::new()),
            (Request::EepromRead { slave, word } | Request::EepromWrite { slave, word, .. }, true) => {
                Err(EngineError::Failed(format!("EEPROM word {word:#06x} of slave {slave}")))
            }
            (Request::EepromWrite { slave, word, .. }, false) if self.step == Step::Wait => {
                // Read it back.
                port.call(&EepromRequest {
                    slave: (*slave).into(),
                    access: EepromAccess::Read { address: *word },
                    timeout_us: 100_000,
                })?;
                self.step = Step::Verify;
                return Ok((Some(self), Progress::Sent));
            }
            (Request::EepromRead { slave, word }, false) | (Request::EepromWrite { slave, word, .. }, false) => {
                let a = port.call(&EepromGet)?;
                let reply = EepromReply::decode(&fields(&a), a.data).ok();
                match reply {
                    Some(r) if r.error == 0 && r.data.len() >= 2 => {
                        let data = r.data.to_vec();
                        if let Request::EepromWrite { value, .. } = request {
                            if data[..2] != value.to_le_bytes() {
                                let got = u16::from_le_bytes([data[0], data[1]]);
                                return Ok((None, self.finish(Err(EngineError::Failed(format!(
                                    "EEPROM word {word:#06x} of slave {slave} reads back {got:#06x}, wrote {value:#06x}"
                                ))))));
                            }
                        }
                        Ok(data)
                    }
                    Some(r) => Err(EngineError::Failed(format!(
                        "EEPROM word {word:#06x} of slave {slave}: error code {}",
                        r.error
                    ))),
                    None => {
                        Err(EngineError::Failed(format!("EEPROM word {word:#06x} of slave {slave}: unreadable answer")))
                    }
                }
            }
            (Request::SetState { state, .. }, true) => Err(EngineError::WrongState(format!("a slave refused {state}"))),
            (Request::SetState { .. }, false) => Ok(Vec::new()),
            (Request::SlaveInfo { .. }, _) => Ok(Vec::new()),
        };
        Ok((None, self.finish(result)))
    }
}
