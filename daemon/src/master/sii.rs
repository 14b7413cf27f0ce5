//! Reading a slave's SII EEPROM the way its layout asks (ETG.1000.6 5.4,
//! ETG.2010): the 64-word fixed area, then the category headers, each
//! category's body read only when the caller wants it. A full image takes
//! seconds over the chip's two-words-per-request EEPROM_REQ (cmd 38); the
//! PDO categories of a terminal take a hundred or more requests, so a
//! reader that wants only some categories skips the fixed area but for its
//! size word, and what one slave's categories say is kept for every slave
//! of the same identity ([`SiiCache`]).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use ecmxf_devices::sii::{Sii, SiiError, category};
use tokio::sync::OnceCell;

use super::{Call, Identity, Master};
use crate::engine::error::EngineError;

/// Where the category area starts (word 0x40).
const CATEGORIES: u16 = 0x40;
/// The fixed area's EEPROM size word (ETG.1000.6 table 2: word 0x3E, size
/// in KiB less one); 0x3F, the version, comes in the same request.
const SIZE_WORD: u16 = 0x3E;

/// Parsed SII categories by slave identity. Slaves of one vendor, product
/// and revision carry the same description (the ESI they were programmed
/// from; a configuration tool reads one ESI for all of them too), so a
/// line of sixteen identical terminals costs one read, not sixteen. Only
/// the category area is kept: nothing per device (serial, alias, station
/// configuration) is. Forgotten whenever the daemon writes an EEPROM.
#[derive(Debug, Default)]
pub(crate) struct SiiCache {
    by_identity: Mutex<HashMap<Identity, Arc<OnceCell<Arc<Sii>>>>>,
}

impl SiiCache {
    fn cell(&self, identity: Identity) -> Arc<OnceCell<Arc<Sii>>> {
        let mut map = self.by_identity.lock().unwrap_or_else(|e| e.into_inner());
        Arc::clone(map.entry(identity).or_default())
    }

    /// Forgets every description (an EEPROM was written).
    pub(crate) fn forget(&self) {
        self.by_identity.lock().unwrap_or_else(|e| e.into_inner()).clear();
    }
}

/// Which category bodies to read.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Categories<'a> {
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
    /// With [`Categories::Only`] the fixed area is not wanted: only its size
    /// word is read (the rest stays 0), one request instead of 32.
    pub(crate) async fn sii_words(
        &self,
        slave: u8,
        which: Categories<'_>,
        call: Call,
    ) -> Result<Vec<u16>, EngineError> {
        let mut words = match which {
            Categories::All => self.eeprom_read_words(slave, 0, CATEGORIES, call).await?,
            Categories::Only(_) => {
                let mut fixed = vec![0; usize::from(SIZE_WORD)];
                fixed.extend(self.eeprom_read_words(slave, SIZE_WORD, CATEGORIES - SIZE_WORD, call).await?);
                fixed
            }
        };
        let size = words.get(0x3E).map_or(0x1_0000, |&n| (u32::from(n) + 1) * 64).min(0x1_0000);
        let mut at = u32::from(CATEGORIES);
        while at + 2 <= size {
            let head = self.eeprom_read_words(slave, at as u16, 2, call).await?;
            words.extend_from_slice(&head);
            if head[0] == category::END || head[0] == 0 {
                break;
            }
            let len = u32::from(head[1]);
            if at + 2 + len > size {
                let (offset, len, size) = (at as usize * 2, len as usize * 2, size as usize * 2);
                let error = SiiError::PastEepromSize { kind: head[0], offset, len, size };
                return Err(EngineError::BadDeviceData { slave, error });
            }
            if which.wants(head[0]) {
                let body = self.eeprom_read_words(slave, (at + 2) as u16, len as u16, call).await?;
                words.extend_from_slice(&body);
            } else {
                words.resize(words.len() + len as usize, 0);
            }
            at += 2 + len;
        }
        Ok(words)
    }

    /// The SII parsed, with the bodies `which` asks for.
    pub(crate) async fn sii(&self, slave: u8, which: Categories<'_>, call: Call) -> Result<Sii, EngineError> {
        let words = self.sii_words(slave, which, call).await?;
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        Sii::parse(&bytes).map_err(|error| EngineError::BadDeviceData { slave, error })
    }

    /// The categories `which` asks for, read once per slave identity (see
    /// [`SiiCache`]): `which` must be the same set for every caller of
    /// this, as only the PDO description's reader is. A slave whose
    /// identity bring-up did not learn (all zero) is always read.
    pub(crate) async fn sii_described(
        &self,
        slave: u8,
        which: Categories<'_>,
        call: Call,
    ) -> Result<Arc<Sii>, EngineError> {
        match self.identity(slave).filter(|&id| id != (0, 0, 0)) {
            Some(id) => {
                let cell = self.sii_cache.cell(id);
                cell.get_or_try_init(|| async { self.sii(slave, which, call).await.map(Arc::new) }).await.cloned()
            }
            None => self.sii(slave, which, call).await.map(Arc::new),
        }
    }
}
