//! The chip's internal CiA402 helper: 402_CONFIG_SET (26), 402_STATE_SET
//! (27), 402_STATE_GET (28), 402_CTL_SET (29), 402_CTL_GET (30),
//! 402_GET_STATUSWORD (74).
//!
//! With the helper enabled the chip writes controlword bits 0..3 (and bit7
//! when fault reset is on) inside the process image, walking the drive's
//! state machine; the host's own values for those bits are ignored (v049
//! notes under 26 and 29).

use crate::CommandCode;
use crate::bytes::{Reader, Writer, check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Reply, ReplyFields, Request, RequestFields, parameter_request};

/// A CiA402 drive state, as 402_STATE_SET/GET encode it: the statusword's
/// state bits (v049 402_STATE_SET table; v049 appendix).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Cia402State {
    /// 0x00 not ready to switch on.
    NotReadyToSwitchOn,
    /// 0x40 switch on disabled.
    SwitchOnDisabled,
    /// 0x21 ready to switch on.
    ReadyToSwitchOn,
    /// 0x23 switched on.
    SwitchedOn,
    /// 0x27 operation enabled.
    OperationEnabled,
    /// 0x07 quick stop active.
    QuickStopActive,
    /// 0x0F fault reaction active.
    FaultReactionActive,
    /// 0x08 fault.
    Fault,
    /// Any other value, kept.
    Other(u8),
}

impl Cia402State {
    /// From the state byte.
    pub const fn from_u8(v: u8) -> Self {
        match v {
            0x00 => Self::NotReadyToSwitchOn,
            0x40 => Self::SwitchOnDisabled,
            0x21 => Self::ReadyToSwitchOn,
            0x23 => Self::SwitchedOn,
            0x27 => Self::OperationEnabled,
            0x07 => Self::QuickStopActive,
            0x0F => Self::FaultReactionActive,
            0x08 => Self::Fault,
            other => Self::Other(other),
        }
    }

    /// To the state byte.
    pub const fn to_u8(self) -> u8 {
        match self {
            Self::NotReadyToSwitchOn => 0x00,
            Self::SwitchOnDisabled => 0x40,
            Self::ReadyToSwitchOn => 0x21,
            Self::SwitchedOn => 0x23,
            Self::OperationEnabled => 0x27,
            Self::QuickStopActive => 0x07,
            Self::FaultReactionActive => 0x0F,
            Self::Fault => 0x08,
            Self::Other(v) => v,
        }
    }

    /// Decodes a statusword (0x6041) with the CiA402 masks: bits 0..3 and 5..6
    /// (mask 0x6F), except that "not ready", "switch on disabled", "fault
    /// reaction" and "fault" ignore bit5 (mask 0x4F).
    pub const fn from_statusword(sw: u16) -> Self {
        let b = sw as u8;
        match b & 0x4F {
            0x00 => return Self::NotReadyToSwitchOn,
            0x40 => return Self::SwitchOnDisabled,
            0x0F => return Self::FaultReactionActive,
            0x08 => return Self::Fault,
            _ => {}
        }
        match b & 0x6F {
            0x21 => Self::ReadyToSwitchOn,
            0x23 => Self::SwitchedOn,
            0x27 => Self::OperationEnabled,
            0x07 => Self::QuickStopActive,
            other => Self::Other(other),
        }
    }
}

bitflags::bitflags! {
    /// The helper's control byte (402_CONFIG_SET data 2, 402_CTL_SET data 0,
    /// 402_CTL_GET return value).
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
    pub struct Cia402Control: u8 {
        /// bit3: one fault reset.
        const FAULT_RESET = 1 << 3;
        /// bit4: the helper drives the state machine.
        const ENABLE = 1 << 4;
        /// bit7: automatic, repeated fault reset.
        const AUTO_FAULT_RESET = 1 << 7;
    }
}

/// 402_CONFIG_SET (26): parameter = axis (0-based), data 0 controlword
/// offset, data 1 statusword offset (bytes in the process image), data 2
/// control byte, data 3 slave.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Cia402ConfigSet {
    /// Axis number.
    pub axis: u8,
    /// Byte offset of the controlword in the axis' slave's outputs.
    pub controlword_offset: u8,
    /// Byte offset of the statusword in the axis' slave's inputs.
    pub statusword_offset: u8,
    /// The helper's control byte.
    pub control: Cia402Control,
    /// Slave position.
    pub slave: u8,
}

impl<'a> Request<'a> for Cia402ConfigSet {
    const CODE: CommandCode = CommandCode::Cia402ConfigSet;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        check_range("slave", self.slave.into(), 0, 127)?;
        Ok(RequestFields {
            parameter: self.axis,
            param: [self.controlword_offset, self.statusword_offset, self.control.bits(), self.slave],
            ..RequestFields::default()
        })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        let [cw, sw, control, slave] = fields.param;
        expect_range("slave", slave.into(), 0, 127)?;
        Ok(Self {
            axis: fields.parameter,
            controlword_offset: cw,
            statusword_offset: sw,
            control: Cia402Control::from_bits_retain(control),
            slave,
        })
    }
}

/// 402_STATE_SET (27): drive an axis to a state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Cia402StateSet {
    /// Axis number.
    pub axis: u8,
    /// Target state.
    pub state: Cia402State,
}

impl<'a> Request<'a> for Cia402StateSet {
    const CODE: CommandCode = CommandCode::Cia402StateSet;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        Ok(RequestFields { parameter: self.axis, param: [self.state.to_u8(), 0, 0, 0], ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self { axis: fields.parameter, state: Cia402State::from_u8(fields.param[0]) })
    }
}

parameter_request! {
    /// 402_STATE_GET (28): an axis' state (parameter = axis).
    Cia402StateGet => Cia402StateGet -> Cia402StateReply;
    /// 402_CTL_GET (30): an axis' helper control byte (parameter = axis).
    Cia402CtlGet => Cia402CtlGet -> Cia402CtlReply;
    /// 402_GET_STATUSWORD (74): an axis' statusword (parameter = axis).
    Cia402GetStatusword => Cia402GetStatusword -> StatuswordReply;
}

/// 402_STATE_GET's reply: the state in the return value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Cia402StateReply(pub Cia402State);

impl<'a> Reply<'a> for Cia402StateReply {
    const CODE: CommandCode = CommandCode::Cia402StateGet;

    fn encode(&self, _data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        Ok(ReplyFields { value: self.0.to_u8(), data_len: 0 })
    }

    fn decode(fields: &ReplyFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self(Cia402State::from_u8(fields.value)))
    }
}

/// 402_CTL_SET (29): parameter = axis, data 0 control byte, data 1 fixed 0x5A,
/// data 2 number of axes, data 3 slave.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Cia402CtlSet {
    /// Axis number.
    pub axis: u8,
    /// Control byte.
    pub control: Cia402Control,
    /// Total axes.
    pub axis_count: u8,
    /// Slave position.
    pub slave: u8,
}

/// 402_CTL_SET's fixed command data 1.
pub const CTL_SET_MAGIC: u8 = 0x5A;

impl<'a> Request<'a> for Cia402CtlSet {
    const CODE: CommandCode = CommandCode::Cia402CtlSet;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        check_range("slave", self.slave.into(), 0, 127)?;
        Ok(RequestFields {
            parameter: self.axis,
            param: [self.control.bits(), CTL_SET_MAGIC, self.axis_count, self.slave],
            ..RequestFields::default()
        })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        let [control, magic, axis_count, slave] = fields.param;
        if magic != CTL_SET_MAGIC {
            return Err(PayloadError::InvalidValue { field: "402_CTL_SET fixed 0x5A", value: magic.into() });
        }
        expect_range("slave", slave.into(), 0, 127)?;
        Ok(Self { axis: fields.parameter, control: Cia402Control::from_bits_retain(control), axis_count, slave })
    }
}

/// 402_CTL_GET's reply: the control byte in the return value.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Cia402CtlReply(pub Cia402Control);

impl<'a> Reply<'a> for Cia402CtlReply {
    const CODE: CommandCode = CommandCode::Cia402CtlGet;

    fn encode(&self, _data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        Ok(ReplyFields { value: self.0.bits(), data_len: 0 })
    }

    fn decode(fields: &ReplyFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self(Cia402Control::from_bits_retain(fields.value)))
    }
}

/// 402_GET_STATUSWORD's reply: 2 bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct StatuswordReply(pub u16);

impl<'a> Reply<'a> for StatuswordReply {
    const CODE: CommandCode = CommandCode::Cia402GetStatusword;

    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(data);
        w.u16(self.0)?;
        Ok(ReplyFields { value: 0, data_len: w.len_u16() })
    }

    fn decode(_fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self(Reader::new(data).u16("statusword")?))
    }
}

/// The state's CiA 402 name ("OPERATION ENABLED"), for messages.
impl core::fmt::Display for Cia402State {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let name = match self {
            Self::NotReadyToSwitchOn => "NOT READY TO SWITCH ON",
            Self::SwitchOnDisabled => "SWITCH ON DISABLED",
            Self::ReadyToSwitchOn => "READY TO SWITCH ON",
            Self::SwitchedOn => "SWITCHED ON",
            Self::OperationEnabled => "OPERATION ENABLED",
            Self::QuickStopActive => "QUICK STOP ACTIVE",
            Self::FaultReactionActive => "FAULT REACTION ACTIVE",
            Self::Fault => "FAULT",
            Self::Other(v) => return write!(f, "state {v:#04x}"),
        };
        f.write_str(name)
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn helper_requests_round_trip(axis: u8, cw: u8, sw: u8, control: u8, slave in 0u8..=127, count: u8, state: u8) {
            let control = Cia402Control::from_bits_retain(control);
            request_round_trip(&Cia402ConfigSet { axis, controlword_offset: cw, statusword_offset: sw, control, slave });
            request_round_trip(&Cia402CtlSet { axis, control, axis_count: count, slave });
            request_round_trip(&Cia402StateSet { axis, state: Cia402State::from_u8(state) });
            request_round_trip(&Cia402StateGet(axis));
            request_round_trip(&Cia402CtlGet(axis));
            request_round_trip(&Cia402GetStatusword(axis));
        }

        #[test]
        fn helper_replies_round_trip(v: u8, sw: u16) {
            reply_round_trip(&Cia402StateReply(Cia402State::from_u8(v)));
            reply_round_trip(&Cia402CtlReply(Cia402Control::from_bits_retain(v)));
            reply_round_trip(&StatuswordReply(sw));
        }

        #[test]
        fn state_byte_round_trips(v: u8) {
            prop_assert_eq!(Cia402State::from_u8(v).to_u8(), v);
        }
    }

    #[test]
    fn statusword_decoding_matches_the_appendix_table() {
        use Cia402State::*;
        let table = [
            (0x0000, NotReadyToSwitchOn),
            (0x0040, SwitchOnDisabled),
            (0x0021, ReadyToSwitchOn),
            (0x0023, SwitchedOn),
            (0x0027, OperationEnabled),
            (0x0007, QuickStopActive),
            (0x000F, FaultReactionActive),
            (0x0008, Fault),
        ];
        for (sw, state) in table {
            assert_eq!(Cia402State::from_statusword(sw), state, "{sw:#06x}");
            // The state byte is the statusword's state bits.
            assert_eq!(state.to_u8() as u16, sw);
            // Bits outside 0..3, 5..6 do not matter (voltage enabled, remote,
            // target reached, ...).
            assert_eq!(Cia402State::from_statusword(sw | 0xFF90), state, "{sw:#06x} with high bits");
        }
        // Fault and switch-on-disabled ignore the quick-stop bit.
        assert_eq!(Cia402State::from_statusword(0x0028), Fault);
        assert_eq!(Cia402State::from_statusword(0x0060), SwitchOnDisabled);
        // Ready/switched on/enabled with quick stop bit clear mean quick stop
        // only for 0x07.
        assert_eq!(Cia402State::from_statusword(0x0001), Other(0x01));
    }

    #[test]
    fn ctl_set_checks_magic() {
        let f = RequestFields { param: [0x10, 0x00, 1, 0], ..RequestFields::default() };
        assert_eq!(
            Cia402CtlSet::decode(&f, &[]),
            Err(PayloadError::InvalidValue { field: "402_CTL_SET fixed 0x5A", value: 0 })
        );
        let (f, _) =
            request_round_trip(&Cia402CtlSet { axis: 2, control: Cia402Control::ENABLE, axis_count: 3, slave: 1 });
        assert_eq!(f.param, [0x10, 0x5A, 3, 1]);
    }
}
