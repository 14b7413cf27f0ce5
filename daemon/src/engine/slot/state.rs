//! The slaves' EtherCAT states. A change runs exactly once (guarded,
//! v049 ECAT_STATE_CHECK 41). A read refreshes the chip's view
//! (ECAT_STATE_UPDATE 57, a read sent once) and then asks for it
//! (ECAT_STATE_GET 13).

use ecmxf_wire::EcatState;
use ecmxf_wire::flags::ControlFlags;
use ecmxf_wire::payload::ecat_init::StateUpdate;
use ecmxf_wire::payload::state::{SlaveSelector, StateCheck, StateGet, StateReply};

use super::handler::{Cx, Handler, Next, fill, refused};
use crate::engine::error::{EngineError, WrongState};
use crate::link::Link;
use crate::port::PortError;

/// A state change or a state read.
#[derive(Debug)]
pub(super) struct State {
    target: SlaveSelector,
    /// The state asked for; `None` for a read.
    set: Option<EcatState>,
}

impl State {
    /// A read of `target`'s state, or with `set` a change to it.
    pub(super) fn new(target: SlaveSelector, set: Option<EcatState>) -> Self {
        Self { target, set }
    }
}

impl Handler for State {
    fn start<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError> {
        match self.set {
            Some(state) => cx.start(&StateCheck { target: self.target, state }),
            None => cx.read(&StateUpdate),
        }
    }

    fn ended<L: Link>(&mut self, cx: &mut Cx<'_, L>, failed: bool) -> Result<Next, PortError> {
        let target = self.target;
        Ok(Next::Done(match (self.set, failed) {
            (Some(state), true) => Err(EngineError::WrongState(WrongState::Refused(state))),
            (Some(_), false) => Ok(Vec::new()),
            (None, true) => Err(EngineError::Failed("the slaves' states could not be refreshed".into())),
            (None, false) => {
                let req = StateGet(target);
                let a = cx.port.call(&req)?;
                match a.answer_to(&req) {
                    Ok(StateReply(state)) if !refused(&a) => Ok(fill(cx.buffer, &[&[state.to_u8()]])),
                    _ => {
                        cx.port.pending_control |= ControlFlags::CLEAR_COMMAND_ERROR;
                        Err(EngineError::BadArgument { field: "slave", reason: format!("no such slave: {target}") })
                    }
                }
            }
        }))
    }
}
