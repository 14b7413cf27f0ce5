//! EtherCAT states: STATE_SET (12), STATE_GET (13), STATE_CHECK (41).

use crate::CommandCode;
use crate::bytes::check_range;
use crate::error::{EncodeError, PayloadError};
use crate::flags::EcatState;
use crate::payload::{Reply, ReplyFields, Request, RequestFields};

/// Which slaves a state command addresses (its parameter): 0..=127, or 0xFF
/// for all.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SlaveSelector {
    /// One slave by position.
    One(u8),
    /// 0xFF: every slave.
    All,
}

impl SlaveSelector {
    /// The parameter byte.
    pub fn to_u8(self) -> Result<u8, EncodeError> {
        match self {
            Self::All => Ok(0xFF),
            Self::One(n) => check_range("slave", n.into(), 0, 127).map(|()| n),
        }
    }

    /// From the parameter byte.
    pub fn from_u8(v: u8) -> Result<Self, PayloadError> {
        match v {
            0xFF => Ok(Self::All),
            0..=127 => Ok(Self::One(v)),
            _ => Err(PayloadError::InvalidValue { field: "slave selector", value: v.into() }),
        }
    }
}

fn requestable(state: EcatState) -> Result<u8, EncodeError> {
    if state.is_requestable() {
        Ok(state.to_u8())
    } else {
        Err(EncodeError::FieldOutOfRange {
            field: "requested EtherCAT state",
            value: state.to_u8().into(),
            min: 1,
            max: 8,
        })
    }
}

fn read_requestable(v: u8) -> Result<EcatState, PayloadError> {
    let s = EcatState::from_u8(v);
    if s.is_requestable() {
        Ok(s)
    } else {
        Err(PayloadError::InvalidValue { field: "requested EtherCAT state", value: v.into() })
    }
}

macro_rules! state_command {
    ($(#[$doc:meta])* $name:ident => $code:ident) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub struct $name {
            /// Parameter: which slaves.
            pub target: SlaveSelector,
            /// Command data 0: INIT, PRE-OP, BOOT, SAFE-OP or OP.
            pub state: EcatState,
        }

        impl<'a> Request<'a> for $name {
            const CODE: CommandCode = CommandCode::$code;
            type Answer<'r> = crate::payload::Done;

            fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
                Ok(RequestFields {
                    parameter: self.target.to_u8()?,
                    param: [requestable(self.state)?, 0, 0, 0],
                    ..RequestFields::default()
                })
            }

            fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
                Ok(Self { target: SlaveSelector::from_u8(fields.parameter)?, state: read_requestable(fields.param[0])? })
            }
        }
    };
}

state_command! {
    /// STATE_SET (12): request a state (blocking).
    StateSet => StateSet
}

state_command! {
    /// STATE_CHECK (41): STATE_SET + STATE_UPDATE + STATE_GET in one blocking
    /// step.
    StateCheck => StateCheck
}

/// STATE_GET (13): the state the chip holds (refresh it first with
/// STATE_UPDATE, v049 note under 13).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct StateGet(pub SlaveSelector);

impl<'a> Request<'a> for StateGet {
    const CODE: CommandCode = CommandCode::StateGet;
    type Answer<'r> = StateReply;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        Ok(RequestFields::parameter(self.0.to_u8()?))
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        SlaveSelector::from_u8(fields.parameter).map(Self)
    }
}

/// STATE_GET's reply: the state in the return value.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct StateReply(pub EcatState);

impl<'a> Reply<'a> for StateReply {
    const CODE: CommandCode = CommandCode::StateGet;

    fn encode(&self, _data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        Ok(ReplyFields { value: self.0.to_u8(), data_len: 0 })
    }

    fn decode(fields: &ReplyFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self(EcatState::from_u8(fields.value)))
    }
}

/// "slave 3", "all slaves": as a user says it, in messages.
impl core::fmt::Display for SlaveSelector {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::One(n) => write!(f, "slave {n}"),
            Self::All => f.write_str("all slaves"),
        }
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    fn selector() -> impl Strategy<Value = SlaveSelector> {
        prop_oneof![Just(SlaveSelector::All), (0u8..=127).prop_map(SlaveSelector::One)]
    }

    fn state() -> impl Strategy<Value = EcatState> {
        prop_oneof![
            Just(EcatState::Init),
            Just(EcatState::PreOp),
            Just(EcatState::Boot),
            Just(EcatState::SafeOp),
            Just(EcatState::Op)
        ]
    }

    proptest! {
        #[test]
        fn state_commands_round_trip(t in selector(), s in state()) {
            request_round_trip(&StateSet { target: t, state: s });
            request_round_trip(&StateCheck { target: t, state: s });
            request_round_trip(&StateGet(t));
        }

        #[test]
        fn state_reply_keeps_any_byte(v: u8) {
            reply_round_trip(&StateReply(EcatState::from_u8(v)));
        }

        #[test]
        fn selector_bytes(v: u8) {
            match SlaveSelector::from_u8(v) {
                Ok(s) => prop_assert_eq!(s.to_u8().unwrap(), v),
                Err(_) => prop_assert!((128..=254).contains(&v)),
            }
        }
    }

    #[test]
    fn cannot_request_none_error_or_unknown_states() {
        for s in [EcatState::None, EcatState::Error, EcatState::Other(0x14)] {
            assert!(StateSet { target: SlaveSelector::All, state: s }.encode(&mut []).is_err());
        }
        let f = RequestFields { parameter: 0xFF, param: [0x10, 0, 0, 0], ..RequestFields::default() };
        assert!(matches!(
            StateSet::decode(&f, &[]),
            Err(PayloadError::InvalidValue { field: "requested EtherCAT state", value: 0x10 })
        ));
        assert!(StateSet { target: SlaveSelector::One(128), state: EcatState::Op }.encode(&mut []).is_err());
    }

    #[test]
    fn state_set_all_to_op_fields() {
        let (f, _) = request_round_trip(&StateSet { target: SlaveSelector::All, state: EcatState::Op });
        assert_eq!((f.parameter, f.param, f.data_len), (0xFF, [8, 0, 0, 0], 0));
    }
}
