//! FoE transfers, several blocking steps each (v049 FOE_FUNC_REQ 139 /
//! FOE_FUNC_GET 140): a write stages the file into the chip's flash chunk by
//! chunk, then downloads it to the slave; a read uploads the file into the
//! flash, then reads it back chunk by chunk. Every step runs exactly once
//! (guarded). Progress is published after every chunk.

use std::time::{Duration, Instant};

use ecmxf_wire::payload::foe::{FOE_FLASH_SIZE, FOE_HEADER_LEN, FOE_MAX_CHUNK, FoeGet, FoeRequest, FoeTransfer};

use super::handler::{Cx, Handler, Next};
use crate::engine::error::EngineError;
use crate::link::Link;
use crate::port::PortError;

/// Where a transfer is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// Not started.
    Start,
    /// Write: a chunk is being staged into the chip's flash.
    Stage,
    /// Write: the staged file is going to the slave.
    Send,
    /// Read: the slave's file is coming into the chip's flash.
    Upload,
    /// Read: a chunk of flash is being read.
    Fetch,
}

/// A file written to or read from a slave (its name, and a write's
/// bytes, are the request's).
#[derive(Debug)]
pub(super) struct Foe {
    slave: u8,
    password: u32,
    /// A read's largest file accepted; `None` for a write.
    read: Option<u32>,
    phase: Phase,
    /// Bytes staged or read so far.
    cursor: u32,
    /// Bytes in all.
    total: u32,
}

impl Foe {
    /// A write, or with `read` (the largest file accepted) a read.
    pub(super) fn new(slave: u8, password: u32, read: Option<u32>) -> Self {
        Self { slave, password, read, phase: Phase::Start, cursor: 0, total: 0 }
    }

    fn report<L: Link>(&self, cx: &Cx<'_, L>) {
        if let Some(p) = cx.progress {
            p.set(self.cursor, self.total);
        }
    }

    /// The request to the chip for a slave-side transfer of the named file.
    fn transfer<'n, L: Link>(&self, cx: &Cx<'n, L>, file_length: u32) -> FoeTransfer<'n> {
        FoeTransfer {
            slave: self.slave,
            password: self.password,
            file_length,
            timeout_us: chip_timeout_us(cx.deadline, cx.now),
            flash_offset: 0,
            name: cx.request.file_name().as_bytes(),
        }
    }

    /// Write: stages the next chunk, or sends the file once all of it is
    /// staged.
    fn stage_next<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError> {
        let data = cx.request.payload();
        let chunk = foe_chunk(cx.port.data_size());
        let at = self.cursor as usize;
        if at < data.len() {
            let end = (at + chunk).min(data.len());
            self.phase = Phase::Stage;
            return cx.start(&FoeRequest::WriteFlash { offset: self.cursor, data: &data[at..end] });
        }
        let transfer = self.transfer(cx, data.len() as u32);
        self.phase = Phase::Send;
        cx.start(&FoeRequest::Download(transfer))
    }

    /// Read: reads the next chunk of staged flash, or finishes.
    fn fetch_next<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError> {
        if self.cursor >= self.total {
            return Ok(Next::Done(Ok(std::mem::take(cx.buffer))));
        }
        let length = (self.total - self.cursor).min(foe_chunk(cx.port.data_size()) as u32) as u16;
        self.phase = Phase::Fetch;
        cx.start(&FoeRequest::ReadFlash { offset: self.cursor, length })
    }
}

impl Handler for Foe {
    fn start<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError> {
        let data_size = cx.port.data_size();
        let name = cx.request.file_name();
        match self.read {
            None => {
                let len = cx.request.payload().len();
                if let Err(e) = check_foe(name, len, data_size) {
                    return Ok(Next::Done(Err(e)));
                }
                self.total = len as u32;
                self.report(cx);
                self.stage_next(cx)
            }
            Some(max_len) => {
                if let Err(e) = check_foe(name, max_len as usize, data_size) {
                    return Ok(Next::Done(Err(e)));
                }
                // One byte more than allowed, so that a longer file shows
                // as too long instead of arriving cut short.
                let transfer = self.transfer(cx, max_len.saturating_add(1).min(FOE_FLASH_SIZE));
                self.phase = Phase::Upload;
                cx.start(&FoeRequest::Upload(transfer))
            }
        }
    }

    fn ended<L: Link>(&mut self, cx: &mut Cx<'_, L>, failed: bool) -> Result<Next, PortError> {
        if failed {
            // The slave-side steps are the slave's to refuse; staging and
            // reading the chip's flash are the chip's.
            if matches!(self.phase, Phase::Send | Phase::Upload) {
                let name = cx.request.file_name().to_owned();
                return Ok(Next::Done(Err(EngineError::FoeRefused {
                    slave: self.slave,
                    name,
                    write: self.read.is_none(),
                })));
            }
            return Ok(Next::Done(Err(EngineError::Failed(cx.what()))));
        }
        match self.phase {
            Phase::Stage => {
                let chunk = foe_chunk(cx.port.data_size()) as u32;
                self.cursor = (self.cursor + chunk).min(self.total);
                self.report(cx);
                self.stage_next(cx)
            }
            Phase::Send => Ok(Next::Done(Ok(Vec::new()))),
            Phase::Upload => {
                let stored = cx.port.ask(&FoeGet)?.0.first_chunk::<4>().map(|b| u32::from_le_bytes(*b));
                let max = self.read.unwrap_or(0);
                let Some(stored) = stored else {
                    let what = format!("{}: the chip reports no file length", cx.what());
                    return Ok(Next::Done(Err(EngineError::Failed(what))));
                };
                if stored > max {
                    let what = format!("{}: the file is longer than the {max} bytes allowed", cx.what());
                    return Ok(Next::Done(Err(EngineError::Failed(what))));
                }
                self.total = stored;
                // The caller made room for `max` bytes: no allocation here.
                cx.buffer.clear();
                cx.buffer.reserve(stored as usize);
                self.report(cx);
                self.fetch_next(cx)
            }
            Phase::Fetch => {
                let want = ((self.total - self.cursor) as usize).min(foe_chunk(cx.port.data_size()));
                let got = cx.port.call(&FoeGet)?.answer_to(&FoeGet).map(|r| r.0).unwrap_or_default();
                if got.len() < want {
                    let n = got.len();
                    let what = format!("{}: a flash read returned {n} of {want} bytes", cx.what());
                    return Ok(Next::Done(Err(EngineError::Failed(what))));
                }
                cx.buffer.extend_from_slice(&got[..want]);
                self.cursor += want as u32;
                self.report(cx);
                self.fetch_next(cx)
            }
            // Never: `ended` follows a started step.
            Phase::Start => Ok(Next::Done(Ok(Vec::new()))),
        }
    }
}

/// FoE bytes per packet: a flash chunk, or what fits the data section.
fn foe_chunk(data_size: usize) -> usize {
    (FOE_MAX_CHUNK as usize).min(data_size.saturating_sub(FOE_HEADER_LEN)).max(1)
}

/// A FoE request's arguments, checked before anything goes to the chip.
fn check_foe(name: &str, len: usize, data_size: usize) -> Result<(), EngineError> {
    if name.is_empty() {
        return Err(EngineError::BadArgument { field: "name", reason: "a FoE file needs a name".into() });
    }
    if name.len() + FOE_HEADER_LEN > data_size {
        let reason = format!("{} bytes do not fit one {data_size}-byte data section", name.len());
        return Err(EngineError::BadArgument { field: "name", reason });
    }
    if len > FOE_FLASH_SIZE as usize {
        let reason = format!("{len} bytes exceed the chip's {FOE_FLASH_SIZE}-byte staging flash");
        return Err(EngineError::BadArgument { field: "length", reason });
    }
    Ok(())
}

/// The timeout handed to the chip for a slave-side transfer: what is left of
/// the caller's deadline, at least one second.
fn chip_timeout_us(deadline: Instant, now: Instant) -> u32 {
    let left = deadline.saturating_duration_since(now).max(Duration::from_secs(1));
    left.as_micros().min(u128::from(u32::MAX)) as u32
}
