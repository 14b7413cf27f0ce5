//! Commands answered in their own exchange, never occupying the blocking
//! slot's busy bit (v049 表三: not in the blocking list): the non-blocking
//! commands the API reaches (peripherals, the CiA402 helper, the emergency
//! history) and one item of slave information (ECAT_SLV_INFO_GET 15).
//! They take the slot's turn all the same, so clients share it fairly.

use ecmxf_wire::flags::ControlFlags;
use ecmxf_wire::payload::cia402::{Cia402GetStatusword, Cia402StateGet};
use ecmxf_wire::payload::emergency::CoeEmergencyGet;
use ecmxf_wire::payload::slave_info::{SlaveInfoCode, SlaveInfoGet};

use super::handler::{Cx, Handler, Next, fill, refused};
use super::request::Immediate;
use crate::engine::error::EngineError;
use crate::link::Link;
use crate::port::PortError;

/// One guarded call, its answer the result.
#[derive(Debug)]
pub(super) enum Once {
    /// A non-blocking command; the result is its return value byte
    /// followed by the answer's data.
    Command(Immediate),
    /// One item of a slave's information, relayed.
    SlaveInfo {
        /// Slave.
        slave: u8,
        /// Item.
        item: SlaveInfoCode,
    },
}

impl Handler for Once {
    fn start<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError> {
        let port = &mut *cx.port;
        match *self {
            Self::Command(command) => {
                let a = match &command {
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
                    return Ok(Next::Refused);
                }
                // Relayed as the chip gave it: the client reads the
                // peripheral's answer (api/peripherals.rs).
                Ok(Next::Done(Ok(fill(cx.buffer, &[&[a.header.return_value], a.relayed()]))))
            }
            Self::SlaveInfo { slave, item } => {
                let a = port.call(&SlaveInfoGet { slave, item })?;
                let refused = refused(&a);
                // Relayed: the master reads it by its item (master/transactions.rs).
                let data = fill(cx.buffer, &[a.relayed()]);
                if refused {
                    port.pending_control |= ControlFlags::CLEAR_COMMAND_ERROR;
                    let reason = "no such slave".into();
                    return Ok(Next::Done(Err(EngineError::BadArgument { field: "slave", reason })));
                }
                Ok(Next::Done(Ok(data)))
            }
        }
    }

    /// Never called: nothing of it waits on the chip.
    fn ended<L: Link>(&mut self, _: &mut Cx<'_, L>, _: bool) -> Result<Next, PortError> {
        Ok(Next::Done(Ok(Vec::new())))
    }
}
