//! SII EEPROM words (v049 EEPROM_REQ 38; the result with EEPROM_GET 39).
//! A read is sent once and its EEPROM_GET is the poll. A write runs
//! exactly once (guarded), then is verified by reading the word back.

use ecmxf_wire::payload::eeprom::{EepromAccess, EepromGet, EepromRequest};

use super::handler::{Cx, Fetch, Handler, Next, fetched_or_call, fill};
use crate::engine::error::EngineError;
use crate::link::Link;
use crate::port::PortError;

/// EEPROM timeout given to the chip, us.
const EEPROM_TIMEOUT_US: u32 = 100_000;

/// A read of a word pair, or a write of one word and its read-back.
#[derive(Debug)]
pub(super) struct Eeprom {
    slave: u8,
    word: u16,
    /// The value a write writes; `None` for a read.
    write: Option<u16>,
    /// A write ended; its read-back runs.
    verifying: bool,
}

impl Eeprom {
    /// A read of 4 bytes from `word`, or with `write` a write of it.
    pub(super) fn new(slave: u8, word: u16, write: Option<u16>) -> Self {
        Self { slave, word, write, verifying: false }
    }

    fn request(&self, access: EepromAccess) -> EepromRequest {
        EepromRequest { slave: self.slave.into(), access, timeout_us: EEPROM_TIMEOUT_US }
    }
}

impl Handler for Eeprom {
    fn start<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError> {
        match self.write {
            None => cx.read(&self.request(EepromAccess::Read { address: self.word })),
            Some(value) => cx.start(&self.request(EepromAccess::Write { address: self.word, value })),
        }
    }

    fn fetch(&self) -> Option<Fetch> {
        (self.write.is_none() || self.verifying).then_some(Fetch::Eeprom)
    }

    fn ended<L: Link>(&mut self, cx: &mut Cx<'_, L>, failed: bool) -> Result<Next, PortError> {
        let (slave, word) = (self.slave, self.word);
        if failed {
            return Ok(Next::Done(Err(EngineError::Failed(format!("EEPROM word {word:#06x} of slave {slave}")))));
        }
        if self.write.is_some() && !self.verifying {
            // Read it back. Its own answer is not looked at: EEPROM_GET's
            // judges the read-back.
            cx.port.call(&self.request(EepromAccess::Read { address: word }))?;
            self.verifying = true;
            return Ok(Next::Started { refused: false });
        }
        let a = fetched_or_call(cx.port, cx.fetched, &EepromGet)?;
        let reply = a.answer_to(&EepromGet).ok();
        Ok(Next::Done(match reply {
            Some(r) if r.error == 0 && r.data.len() >= 2 => match self.write {
                Some(value) if r.data[..2] != value.to_le_bytes() => {
                    let got = u16::from_le_bytes([r.data[0], r.data[1]]);
                    Err(EngineError::Failed(format!(
                        "EEPROM word {word:#06x} of slave {slave} reads back {got:#06x}, wrote {value:#06x}"
                    )))
                }
                _ => Ok(fill(cx.buffer, &[r.data])),
            },
            Some(r) => {
                Err(EngineError::Failed(format!("EEPROM word {word:#06x} of slave {slave}: error code {}", r.error)))
            }
            None => Err(EngineError::Failed(format!("EEPROM word {word:#06x} of slave {slave}: unreadable answer"))),
        }))
    }
}
