//! FoE transfers, several blocking steps each (v049 FOE_FUNC_REQ 139 /
//! FOE_FUNC_GET 140): a write stages the file into the chip's flash chunk by
//! chunk, then downloads it to the slave; a read uploads the file into the
//! flash, then reads it back chunk by chunk. Progress is published after
//! every chunk.

use std::time::{Duration, Instant};

use ecmxf_wire::payload::foe::{FOE_FLASH_SIZE, FOE_HEADER_LEN, FOE_MAX_CHUNK, FoeGet, FoeRequest, FoeTransfer};

use super::{Active, Progress, Step, refused};
use crate::engine::error::EngineError;
use crate::engine::slot::SlotRequest;
use crate::link::Link;
use crate::port::{Port, PortError};

impl Active {
    /// FoE write: stages the next chunk, or sends the file once all of it is
    /// staged.
    pub(super) fn foe_stage_next<L: Link>(
        self,
        port: &mut Port<L>,
        now: Instant,
    ) -> Result<(Option<Self>, Progress), PortError> {
        let SlotRequest::FoeWrite { slave, name, password, data } = &self.request else {
            return Ok((None, Progress::Done));
        };
        let chunk = foe_chunk(port.data_size());
        let at = self.cursor as usize;
        if at < data.len() {
            let end = (at + chunk).min(data.len());
            let refused = refused(&port.call(&FoeRequest::WriteFlash { offset: self.cursor, data: &data[at..end] })?);
            return self.started(port, refused, Step::FoeStage, now);
        }
        let transfer = FoeTransfer {
            slave: *slave,
            password: *password,
            file_length: data.len() as u32,
            timeout_us: chip_timeout_us(self.deadline, now),
            flash_offset: 0,
            name: name.as_bytes(),
        };
        let refused = refused(&port.call(&FoeRequest::Download(transfer))?);
        self.started(port, refused, Step::FoeSend, now)
    }

    /// FoE read: reads the next chunk of staged flash, or finishes.
    pub(super) fn foe_fetch_next<L: Link>(
        mut self,
        port: &mut Port<L>,
        now: Instant,
    ) -> Result<(Option<Self>, Progress), PortError> {
        if self.cursor >= self.total {
            let file = std::mem::take(&mut self.buffer);
            return Ok((None, self.finish(Ok(file))));
        }
        let length = (self.total - self.cursor).min(foe_chunk(port.data_size()) as u32) as u16;
        let refused = refused(&port.call(&FoeRequest::ReadFlash { offset: self.cursor, length })?);
        self.started(port, refused, Step::FoeFetch, now)
    }

    /// Continues a multi-step transfer once the chip finished a step.
    pub(super) fn foe_continue<L: Link>(
        mut self,
        port: &mut Port<L>,
        now: Instant,
    ) -> Result<(Option<Self>, Progress), PortError> {
        match self.step {
            Step::FoeStage => {
                let chunk = foe_chunk(port.data_size()) as u32;
                self.cursor = (self.cursor + chunk).min(self.total);
                self.report();
                self.foe_stage_next(port, now)
            }
            Step::FoeSend => Ok((None, self.finish(Ok(Vec::new())))),
            Step::FoeUpload => {
                let stored = port.ask(&FoeGet)?.0.first_chunk::<4>().map(|b| u32::from_le_bytes(*b));
                let max = match &self.request {
                    SlotRequest::FoeRead { max_len, .. } => *max_len,
                    _ => 0,
                };
                let Some(stored) = stored else {
                    let what = format!("{}: the chip reports no file length", self.describe());
                    return Ok((None, self.finish(Err(EngineError::Failed(what)))));
                };
                if stored > max {
                    let what = format!("{}: the file is longer than the {max} bytes allowed", self.describe());
                    return Ok((None, self.finish(Err(EngineError::Failed(what)))));
                }
                self.total = stored;
                // The caller made room for `max` bytes: no allocation here.
                self.buffer.clear();
                self.buffer.reserve(stored as usize);
                self.report();
                self.foe_fetch_next(port, now)
            }
            Step::FoeFetch => {
                let want = ((self.total - self.cursor) as usize).min(foe_chunk(port.data_size()));
                let got = port.call(&FoeGet)?.answer_to(&FoeGet).map(|r| r.0).unwrap_or_default();
                if got.len() < want {
                    let what = format!("{}: a flash read returned {} of {want} bytes", self.describe(), got.len());
                    return Ok((None, self.finish(Err(EngineError::Failed(what)))));
                }
                self.buffer.extend_from_slice(&got[..want]);
                self.cursor += want as u32;
                self.report();
                self.foe_fetch_next(port, now)
            }
            _ => Ok((None, Progress::Done)),
        }
    }
}

/// FoE bytes per packet: a flash chunk, or what fits the data section.
pub(super) fn foe_chunk(data_size: usize) -> usize {
    (FOE_MAX_CHUNK as usize).min(data_size.saturating_sub(FOE_HEADER_LEN)).max(1)
}

/// A FoE request's arguments, checked before anything goes to the chip.
pub(super) fn check_foe(name: &str, len: usize, data_size: usize) -> Result<(), EngineError> {
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
pub(super) fn chip_timeout_us(deadline: Instant, now: Instant) -> u32 {
    let left = deadline.saturating_duration_since(now).max(Duration::from_secs(1));
    left.as_micros().min(u128::from(u32::MAX)) as u32
}
