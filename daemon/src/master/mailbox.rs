//! Which mailbox protocols each slave speaks, from its SII (word 0x1C,
//! ETG.1000.6 table 2): an SDO to a slave without CoE is answered at once,
//! naming the slave, instead of being sent and timing out in the chip a
//! second later as "SDO protocol timeout", which names neither the slave
//! nor the cause. Read once per device identity (one EEPROM request) the
//! first time an SDO goes to a slave of it, and kept while the same device
//! sits at that position: its twins on the line take the word it gave
//! (the protocols are the product's, written into the SII per product and
//! revision), so a line of 100 identical slaves costs one request, not a
//! hundred, when the process image is laid out.

use ecmxf_devices::sii::protocol;

use super::per_slave::PerSlave;
use super::{Call, Master};
use crate::engine::error::{EngineError, WrongState};

/// SII word of the mailbox protocols.
const PROTOCOLS_WORD: u16 = 0x1C;

/// The mailbox protocols read so far, by slave position.
pub(crate) type MailboxProtocols = PerSlave<u16>;

impl Master {
    /// Ok when `slave` speaks CoE, or when its SII cannot say (the SDO then
    /// goes out and the slave answers for itself); [`WrongState::NoCoe`]
    /// when its SII lists the mailbox protocols and CoE is not among them.
    pub(crate) async fn check_coe(&self, slave: u8, call: Call) -> Result<(), EngineError> {
        match self.protocols(slave, call).await {
            Some(p) if p & protocol::COE == 0 => {
                Err(EngineError::WrongState(WrongState::NoCoe { slave, protocols: p }))
            }
            _ => Ok(()),
        }
    }

    /// The same for FoE ([`WrongState::NoFoe`]): a transfer to a slave
    /// without it is answered at once, not as the chip's bare failure.
    pub(crate) async fn check_foe(&self, slave: u8, call: Call) -> Result<(), EngineError> {
        match self.protocols(slave, call).await {
            Some(p) if p & protocol::FOE == 0 => {
                Err(EngineError::WrongState(WrongState::NoFoe { slave, protocols: p }))
            }
            _ => Ok(()),
        }
    }

    /// The mailbox protocols `slave`'s SII lists, read once; `None` when it
    /// cannot be read.
    async fn protocols(&self, slave: u8, call: Call) -> Option<u16> {
        let identity = self.identity(slave)?;
        if let Some(p) = self.mailbox.get(slave, identity) {
            return Some(p);
        }
        if let Some(p) = self.mailbox.of_identity(identity) {
            self.mailbox.put(slave, identity, p);
            return Some(p);
        }
        let words = self.eeprom_read(slave, PROTOCOLS_WORD, call).await.ok()?;
        let p = u16::from_le_bytes([words[0], words[1]]);
        self.mailbox.put(slave, identity, p);
        Some(p)
    }
}
