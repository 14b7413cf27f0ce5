//! The one place a request picks its handler: [`Kind`] holds the handler
//! of a request's kind and passes each call on to it.

use super::eeprom::Eeprom;
use super::foe::Foe;
use super::handler::{Cx, Fetch, Handler, Next};
use super::immediate::Once;
use super::pdo::PdoConfig;
use super::raw::Raw;
use super::request::SlotRequest;
use super::sdo::Sdo;
use super::state::State;
use crate::link::Link;
use crate::port::PortError;

/// The handler of a request's kind, with the steps it has taken.
#[derive(Debug)]
pub(super) enum Kind {
    Sdo(Sdo),
    Eeprom(Eeprom),
    State(State),
    PdoConfig(PdoConfig),
    Raw(Raw),
    Foe(Foe),
    Once(Once),
}

impl Kind {
    pub(super) fn of(request: &SlotRequest) -> Self {
        match *request {
            SlotRequest::SdoRead { slave, index, subindex, complete } => {
                Self::Sdo(Sdo::new(slave, index, subindex, complete, false))
            }
            SlotRequest::SdoWrite { slave, index, subindex, complete, .. } => {
                Self::Sdo(Sdo::new(slave, index, subindex, complete, true))
            }
            SlotRequest::EepromRead { slave, word } => Self::Eeprom(Eeprom::new(slave, word, None)),
            SlotRequest::EepromWrite { slave, word, value } => Self::Eeprom(Eeprom::new(slave, word, Some(value))),
            SlotRequest::SetState { target, state } => Self::State(State::new(target, Some(state))),
            SlotRequest::GetState { target } => Self::State(State::new(target, None)),
            SlotRequest::PdoConfigRead { slave, assign_index } => Self::PdoConfig(PdoConfig::new(slave, assign_index)),
            SlotRequest::Raw { head, .. } => Self::Raw(Raw::new(head)),
            SlotRequest::FoeWrite { slave, password, .. } => Self::Foe(Foe::new(slave, password, None)),
            SlotRequest::FoeRead { slave, password, max_len, .. } => {
                Self::Foe(Foe::new(slave, password, Some(max_len)))
            }
            SlotRequest::SlaveInfo { slave, item } => Self::Once(Once::SlaveInfo { slave, item }),
            SlotRequest::Immediate(command) => Self::Once(Once::Command(command)),
        }
    }
}

/// Each call goes to the kind's handler.
macro_rules! each {
    ($kind:expr, $h:ident => $call:expr) => {
        match $kind {
            Kind::Sdo($h) => $call,
            Kind::Eeprom($h) => $call,
            Kind::State($h) => $call,
            Kind::PdoConfig($h) => $call,
            Kind::Raw($h) => $call,
            Kind::Foe($h) => $call,
            Kind::Once($h) => $call,
        }
    };
}

impl Handler for Kind {
    fn start<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError> {
        each!(self, h => h.start(cx))
    }

    fn fetch(&self) -> Option<Fetch> {
        each!(self, h => h.fetch())
    }

    fn ended<L: Link>(&mut self, cx: &mut Cx<'_, L>, failed: bool) -> Result<Next, PortError> {
        each!(self, h => h.ended(cx, failed))
    }
}
