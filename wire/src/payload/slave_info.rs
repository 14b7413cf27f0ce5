//! Slave information: SLV_INFO_GET (15), SLV_CNT_GET (16).
//!
//! The manual lists info codes 0..=9; the vendor header adds 10..=13 (DC).
//! It does not give the widths of the answers, so decoding takes the width
//! from the data length (1..=4 bytes, little-endian) and encoding uses the
//! natural width of each item (ids 4 bytes, addresses 2, state 1, AL status
//! 2, sizes 2, DC times 4).

use crate::CommandCode;
use crate::bytes::{Writer, check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::flags::EcatState;
use crate::payload::{FromAnswer, ReplyFields, Request, RequestFields, bare_request, value_reply};

/// What SLV_INFO_GET asks for (command data 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SlaveInfoCode {
    /// 0: vendor id.
    VendorId,
    /// 1: product code.
    ProductCode,
    /// 2: revision number.
    Revision,
    /// 3: product name.
    Name,
    /// 4: configured station address.
    ConfiguredAddress,
    /// 5: station alias.
    Alias,
    /// 6: state (1 INIT, 2 PRE-OP, 4 SAFE-OP, 8 OP).
    State,
    /// 7: AL status code (0 = no error).
    AlStatus,
    /// 8: output (RxPDO) bytes.
    OutputBytes,
    /// 9: input (TxPDO) bytes.
    InputBytes,
    /// 10 (vendor header): has DC.
    HasDc,
    /// 11 (vendor header): DC cycle in ns.
    DcCycle,
    /// 12 (vendor header): DC shift in ns.
    DcShift,
    /// 13 (vendor header): DC active.
    DcActive,
}

impl SlaveInfoCode {
    /// All codes, in order.
    pub const ALL: [Self; 14] = [
        Self::VendorId,
        Self::ProductCode,
        Self::Revision,
        Self::Name,
        Self::ConfiguredAddress,
        Self::Alias,
        Self::State,
        Self::AlStatus,
        Self::OutputBytes,
        Self::InputBytes,
        Self::HasDc,
        Self::DcCycle,
        Self::DcShift,
        Self::DcActive,
    ];

    /// The code byte.
    pub fn to_u8(self) -> u8 {
        Self::ALL.iter().position(|&c| c == self).unwrap_or(0) as u8
    }

    /// From the code byte.
    pub fn from_u8(v: u8) -> Result<Self, PayloadError> {
        Self::ALL
            .get(usize::from(v))
            .copied()
            .ok_or(PayloadError::InvalidValue { field: "slave info code", value: v.into() })
    }
}

/// SLV_INFO_GET (15): parameter = slave, command data 0 = info code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SlaveInfoGet {
    /// Slave position 0..=127.
    pub slave: u8,
    /// What to read.
    pub item: SlaveInfoCode,
}

impl<'a> Request<'a> for SlaveInfoGet {
    const CODE: CommandCode = CommandCode::SlaveInfoGet;
    type Answer<'r> = SlaveInfo<'r>;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        check_range("slave", self.slave.into(), 0, 127)?;
        Ok(RequestFields { parameter: self.slave, param: [self.item.to_u8(), 0, 0, 0], ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        expect_range("slave", fields.parameter.into(), 0, 127)?;
        Ok(Self { slave: fields.parameter, item: SlaveInfoCode::from_u8(fields.param[0])? })
    }
}

/// One decoded item of slave information.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SlaveInfo<'a> {
    /// Vendor id.
    VendorId(u32),
    /// Product code.
    ProductCode(u32),
    /// Revision.
    Revision(u32),
    /// Name bytes, up to the first NUL (the slave's SII string, usually ASCII).
    Name(&'a [u8]),
    /// Configured station address.
    ConfiguredAddress(u16),
    /// Station alias.
    Alias(u16),
    /// State.
    State(EcatState),
    /// AL status code.
    AlStatus(u16),
    /// Output bytes.
    OutputBytes(u16),
    /// Input bytes.
    InputBytes(u16),
    /// Has DC.
    HasDc(bool),
    /// DC cycle, ns.
    DcCycle(u32),
    /// DC shift, ns.
    DcShift(i32),
    /// DC active.
    DcActive(bool),
}

fn le_int(field: &'static str, data: &[u8]) -> Result<u32, PayloadError> {
    if data.is_empty() {
        return Err(PayloadError::TooShort { field, needed: 1, available: 0 });
    }
    let mut b = [0u8; 4];
    let n = data.len().min(4);
    b[..n].copy_from_slice(&data[..n]);
    Ok(u32::from_le_bytes(b))
}

impl<'a> SlaveInfo<'a> {
    /// The item as one number, as the chip holds it: ids, sizes, addresses,
    /// the state byte, flags as 0/1, the DC shift as its 32 bits; `None`
    /// for the name. Callers that only show or compare a value need no
    /// match over every item.
    pub fn number(&self) -> Option<u32> {
        Some(match *self {
            Self::VendorId(v) | Self::ProductCode(v) | Self::Revision(v) | Self::DcCycle(v) => v,
            Self::ConfiguredAddress(v) | Self::Alias(v) | Self::AlStatus(v) => v.into(),
            Self::OutputBytes(v) | Self::InputBytes(v) => v.into(),
            Self::HasDc(v) | Self::DcActive(v) => v.into(),
            Self::DcShift(v) => v as u32,
            Self::State(s) => s.to_u8().into(),
            Self::Name(_) => return None,
        })
    }

    /// The code this item answers.
    pub fn code(&self) -> SlaveInfoCode {
        match self {
            Self::VendorId(_) => SlaveInfoCode::VendorId,
            Self::ProductCode(_) => SlaveInfoCode::ProductCode,
            Self::Revision(_) => SlaveInfoCode::Revision,
            Self::Name(_) => SlaveInfoCode::Name,
            Self::ConfiguredAddress(_) => SlaveInfoCode::ConfiguredAddress,
            Self::Alias(_) => SlaveInfoCode::Alias,
            Self::State(_) => SlaveInfoCode::State,
            Self::AlStatus(_) => SlaveInfoCode::AlStatus,
            Self::OutputBytes(_) => SlaveInfoCode::OutputBytes,
            Self::InputBytes(_) => SlaveInfoCode::InputBytes,
            Self::HasDc(_) => SlaveInfoCode::HasDc,
            Self::DcCycle(_) => SlaveInfoCode::DcCycle,
            Self::DcShift(_) => SlaveInfoCode::DcShift,
            Self::DcActive(_) => SlaveInfoCode::DcActive,
        }
    }

    /// Reads the reply data for the item asked for (the reply alone does not
    /// say which item it is).
    pub fn decode(code: SlaveInfoCode, data: &'a [u8]) -> Result<Self, PayloadError> {
        let f = "slave info";
        Ok(match code {
            SlaveInfoCode::Name => Self::Name(data.split(|&b| b == 0).next().unwrap_or(&[])),
            SlaveInfoCode::VendorId => Self::VendorId(le_int(f, data)?),
            SlaveInfoCode::ProductCode => Self::ProductCode(le_int(f, data)?),
            SlaveInfoCode::Revision => Self::Revision(le_int(f, data)?),
            SlaveInfoCode::ConfiguredAddress => Self::ConfiguredAddress(le_int(f, data)? as u16),
            SlaveInfoCode::Alias => Self::Alias(le_int(f, data)? as u16),
            SlaveInfoCode::State => Self::State(EcatState::from_u8(le_int(f, data)? as u8)),
            SlaveInfoCode::AlStatus => Self::AlStatus(le_int(f, data)? as u16),
            SlaveInfoCode::OutputBytes => Self::OutputBytes(le_int(f, data)? as u16),
            SlaveInfoCode::InputBytes => Self::InputBytes(le_int(f, data)? as u16),
            SlaveInfoCode::HasDc => Self::HasDc(le_int(f, data)? != 0),
            SlaveInfoCode::DcCycle => Self::DcCycle(le_int(f, data)?),
            SlaveInfoCode::DcShift => Self::DcShift(le_int(f, data)? as i32),
            SlaveInfoCode::DcActive => Self::DcActive(le_int(f, data)? != 0),
        })
    }

    /// Writes the reply data (the chip's side).
    pub fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(data);
        match *self {
            Self::VendorId(v) | Self::ProductCode(v) | Self::Revision(v) | Self::DcCycle(v) => w.u32(v)?,
            Self::DcShift(v) => w.i32(v)?,
            Self::Name(n) => w.bytes(n)?,
            Self::ConfiguredAddress(v)
            | Self::Alias(v)
            | Self::AlStatus(v)
            | Self::OutputBytes(v)
            | Self::InputBytes(v) => w.u16(v)?,
            Self::State(s) => w.u8(s.to_u8())?,
            Self::HasDc(b) | Self::DcActive(b) => w.u8(u8::from(b))?,
        }
        Ok(ReplyFields { value: 0, data_len: w.len_u16() })
    }
}

/// The answer says nothing of which item it is: the request does.
impl<'r> FromAnswer<'r, SlaveInfoGet> for SlaveInfo<'r> {
    fn from_answer(request: &SlaveInfoGet, _fields: &ReplyFields, data: &'r [u8]) -> Result<Self, PayloadError> {
        Self::decode(request.item, data)
    }
}

bare_request! {
    /// SLV_CNT_GET (16): the number of slaves found.
    SlaveCountGet => SlaveCountGet -> SlaveCount;
}

value_reply! {
    /// SLV_CNT_GET's reply: the count in the return value.
    SlaveCount => SlaveCountGet;
}

/// What the item is, in words ("product code"), for messages.
impl core::fmt::Display for SlaveInfoCode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::VendorId => "vendor id",
            Self::ProductCode => "product code",
            Self::Revision => "revision",
            Self::Name => "name",
            Self::ConfiguredAddress => "configured address",
            Self::Alias => "alias",
            Self::State => "state",
            Self::AlStatus => "AL status code",
            Self::OutputBytes => "output bytes",
            Self::InputBytes => "input bytes",
            Self::HasDc => "DC support",
            Self::DcCycle => "DC cycle",
            Self::DcShift => "DC shift",
            Self::DcActive => "DC activation",
        })
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    fn info() -> impl Strategy<Value = (SlaveInfoCode, u32)> {
        (0usize..14, any::<u32>()).prop_map(|(i, v)| (SlaveInfoCode::ALL[i], v))
    }

    fn make(code: SlaveInfoCode, v: u32, name: &[u8]) -> SlaveInfo<'_> {
        match code {
            SlaveInfoCode::VendorId => SlaveInfo::VendorId(v),
            SlaveInfoCode::ProductCode => SlaveInfo::ProductCode(v),
            SlaveInfoCode::Revision => SlaveInfo::Revision(v),
            SlaveInfoCode::Name => SlaveInfo::Name(name),
            SlaveInfoCode::ConfiguredAddress => SlaveInfo::ConfiguredAddress(v as u16),
            SlaveInfoCode::Alias => SlaveInfo::Alias(v as u16),
            SlaveInfoCode::State => SlaveInfo::State(EcatState::from_u8(v as u8)),
            SlaveInfoCode::AlStatus => SlaveInfo::AlStatus(v as u16),
            SlaveInfoCode::OutputBytes => SlaveInfo::OutputBytes(v as u16),
            SlaveInfoCode::InputBytes => SlaveInfo::InputBytes(v as u16),
            SlaveInfoCode::HasDc => SlaveInfo::HasDc(v & 1 == 1),
            SlaveInfoCode::DcCycle => SlaveInfo::DcCycle(v),
            SlaveInfoCode::DcShift => SlaveInfo::DcShift(v as i32),
            SlaveInfoCode::DcActive => SlaveInfo::DcActive(v & 1 == 1),
        }
    }

    proptest! {
        #[test]
        fn every_info_item_round_trips((code, v) in info(), name in "[ -~]{0,64}", slave in 0u8..=127) {
            let item = make(code, v, name.as_bytes());
            prop_assert_eq!(item.code(), code);
            let mut data = [0u8; 112];
            let f = item.encode(&mut data).unwrap();
            prop_assert_eq!(SlaveInfo::decode(code, &data[..f.data_len as usize]).unwrap(), item);
            if code != SlaveInfoCode::Name {
                let bytes = item.number().unwrap().to_le_bytes();
                prop_assert_eq!(SlaveInfo::decode(code, &bytes).unwrap(), item);
            }
            request_round_trip(&SlaveInfoGet { slave, item: code });
        }

        #[test]
        fn slave_count_round_trips(n: u8) {
            reply_round_trip(&SlaveCount(n));
        }
    }

    #[test]
    fn narrow_and_padded_answers() {
        assert_eq!(SlaveInfo::decode(SlaveInfoCode::VendorId, &[0x9A]).unwrap(), SlaveInfo::VendorId(0x9A));
        assert_eq!(SlaveInfo::decode(SlaveInfoCode::AlStatus, &[0x1B, 0, 0, 0]).unwrap(), SlaveInfo::AlStatus(0x1B));
        assert_eq!(SlaveInfo::decode(SlaveInfoCode::Name, b"EK1100\0\0junk").unwrap(), SlaveInfo::Name(b"EK1100"));
        assert!(SlaveInfo::decode(SlaveInfoCode::Revision, &[]).is_err());
        assert!(SlaveInfoCode::from_u8(14).is_err());
        for (i, c) in SlaveInfoCode::ALL.iter().enumerate() {
            assert_eq!(c.to_u8() as usize, i);
        }
    }
}
