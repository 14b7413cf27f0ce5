//! Reading a slave's SII EEPROM the way its layout asks (ETG.1000.6 5.4,
//! ETG.2010): the 64-word fixed area, then the category headers, each
//! category's body read only when the caller wants it. A full image takes
//! seconds over the chip's two-words-per-request EEPROM_REQ (cmd 38); the
//! PDO categories of a terminal take a few dozen requests.

use ecmxf_devices::sii::{Sii, category};

use super::Master;
use crate::engine::error::EngineError;

/// Where the category area starts (word 0x40).
const CATEGORIES: u16 = 0x40;

/// Which category bodies to read.
#[derive(Clone, Copy, Debug)]
pub enum Categories<'a> {
    /// Every one (a dump).
    All,
    /// Only these types; the others are skipped over (their words stay 0).
    Only(&'a [u16]),
}

impl Categories<'_> {
    fn wants(self, kind: u16) -> bool {
        match self {
            Self::All => true,
            Self::Only(kinds) => kinds.contains(&kind),
        }
    }
}

impl Master {
    /// The SII image as words: the fixed area, every category header up to
    /// the end marker, and the bodies `which` asks for. A category that
    /// runs past the EEPROM's own size (word 0x3E: (n + 1) x 128 bytes) is a
    /// corrupt image, an error naming its offset: never read on into
    /// whatever the EEPROM answers there.
    pub async fn sii_words(&self, slave: u8, which: Categories<'_>) -> Result<Vec<u16>, EngineError> {
        let mut words = self.eeprom_read_words(slave, 0, CATEGORIES, None).await?;
        let size = words.get(0x3E).map_or(0x1_0000, |&n| (u32::from(n) + 1) * 64).min(0x1_0000);
        let mut at = u32::from(CATEGORIES);
        while at + 2 <= size {
            let head = self.eeprom_read_words(slave, at as u16, 2, None).await?;
            words.extend_from_slice(&head);
            if head[0] == category::END || head[0] == 0 {
                break;
            }
            let len = u32::from(head[1]);
            if at + 2 + len > size {
                return Err(EngineError::BadDeviceData(format!(
                    "slave {slave}'s SII is corrupt: category {:#06x} at byte offset {:#06x} is {} bytes long and runs past the EEPROM's size of {} bytes (word 0x3E)",
                    head[0],
                    at * 2,
                    len * 2,
                    size * 2
                )));
            }
            if which.wants(head[0]) {
                let body = self.eeprom_read_words(slave, (at + 2) as u16, len as u16, None).await?;
                words.extend_from_slice(&body);
            } else {
                words.resize(words.len() + len as usize, 0);
            }
            at += 2 + len;
        }
        Ok(words)
    }

    /// The SII parsed, with the bodies `which` asks for.
    pub async fn sii(&self, slave: u8, which: Categories<'_>) -> Result<Sii, EngineError> {
        let words = self.sii_words(slave, which).await?;
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        Sii::parse(&bytes).map_err(|e| EngineError::BadDeviceData(format!("slave {slave}'s SII: {e}")))
    }
}
