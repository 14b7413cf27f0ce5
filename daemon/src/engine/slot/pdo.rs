//! A slave's PDO assignment and mapping as the slave reports it: read
//! into the chip (v049 ECAT_PDO_CONFIG_REQ 8, a read sent once), then
//! fetched (ECAT_PDO_CONFIG_GET 9, which is also the poll: its answer
//! after the read ended is the result) and relayed as the chip gave it.

use ecmxf_wire::payload::pdo::{PdoConfigForm, PdoConfigGet, PdoConfigReq};

use super::handler::{Cx, Fetch, Handler, Next, fetched_or_call, fill};
use crate::engine::error::EngineError;
use crate::link::Link;
use crate::port::PortError;

/// A read of one PDO assignment object.
#[derive(Debug)]
pub(super) struct PdoConfig {
    slave: u8,
    /// 0x1C12 (RxPDO) or 0x1C13 (TxPDO).
    assign_index: u16,
}

impl PdoConfig {
    pub(super) fn new(slave: u8, assign_index: u16) -> Self {
        Self { slave, assign_index }
    }
}

impl Handler for PdoConfig {
    fn start<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError> {
        let (slave, assign_index) = (self.slave, self.assign_index);
        cx.read(&PdoConfigReq { slave, assign_index, form: PdoConfigForm::Manual })
    }

    fn fetch(&self) -> Option<Fetch> {
        Some(Fetch::PdoConfig)
    }

    fn ended<L: Link>(&mut self, cx: &mut Cx<'_, L>, failed: bool) -> Result<Next, PortError> {
        let (slave, assign_index) = (self.slave, self.assign_index);
        if failed {
            let what = format!("PDO assignment {assign_index:#06x} of slave {slave} could not be read");
            return Ok(Next::Done(Err(EngineError::Failed(what))));
        }
        // Relayed: the master reads it as PDO_CONFIG_GET's reply
        // (master/pdos.rs).
        let a = fetched_or_call(cx.port, cx.fetched, &PdoConfigGet)?;
        Ok(Next::Done(Ok(fill(cx.buffer, &[a.relayed()]))))
    }
}
