//! The CoE SDO Information service (ETG.1000.6 5.6.3): a slave describes
//! its own object dictionary. Three questions, each answered in one or
//! more messages:
//!
//! - Get OD List (opcode 1 -> 2): the indices of a list ([`ListType`]):
//!   all objects, those mappable into RxPDOs or TxPDOs, those stored for a
//!   device replacement, the start-up parameters; or (list type 0) how
//!   many each list holds.
//! - Get Object Description (3 -> 4): data type, highest subindex, object
//!   code (VAR 7, ARRAY 8, RECORD 9) and name of one object.
//! - Get Entry Description (5 -> 6): data type, bit length, access and
//!   mapping flags ([`ObjectAccess`]), optionally unit, default, minimum and
//!   maximum ([`ValueInfo`]), and the name of one subindex.
//!
//! An answer longer than the slave's send mailbox comes in fragments: each
//! message has the "incomplete" bit set but the last, and counts the
//! fragments still to come; the payloads, joined, are the answer
//! ([`InfoFragment`]). A question the slave cannot answer gets an SDO Info
//! error (opcode 7) with an SDO abort code.
//!
//! Every message: CoE header (service 8), then the four-byte info header:
//! byte 0 bits 0..6 opcode, bit 7 incomplete; byte 1 reserved; bytes 2..3
//! fragments left.

use crate::bytes::{Reader, Writer};
use crate::error::{EncodeError, PayloadError};
use crate::mbx::coe::{COE_HEADER_LEN, CoeHeader, CoeService};

/// CoE header and info header: the bytes before an info payload.
pub const INFO_OVERHEAD: usize = COE_HEADER_LEN + 4;

/// An SDO Information opcode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum InfoOpcode {
    /// 1: Get OD List request.
    OdListRequest,
    /// 2: Get OD List response.
    OdListResponse,
    /// 3: Get Object Description request.
    ObjectRequest,
    /// 4: Get Object Description response.
    ObjectResponse,
    /// 5: Get Entry Description request.
    EntryRequest,
    /// 6: Get Entry Description response.
    EntryResponse,
    /// 7: SDO Info error.
    Error,
    /// Any other.
    Other(u8),
}

impl InfoOpcode {
    /// The 7-bit code.
    pub fn code(self) -> u8 {
        match self {
            Self::OdListRequest => 1,
            Self::OdListResponse => 2,
            Self::ObjectRequest => 3,
            Self::ObjectResponse => 4,
            Self::EntryRequest => 5,
            Self::EntryResponse => 6,
            Self::Error => 7,
            Self::Other(c) => c & 0x7F,
        }
    }

    /// The opcode of a 7-bit code.
    pub fn from_code(code: u8) -> Self {
        match code & 0x7F {
            1 => Self::OdListRequest,
            2 => Self::OdListResponse,
            3 => Self::ObjectRequest,
            4 => Self::ObjectResponse,
            5 => Self::EntryRequest,
            6 => Self::EntryResponse,
            7 => Self::Error,
            c => Self::Other(c),
        }
    }
}

/// The four-byte info header.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct InfoHeader {
    /// What the message is.
    pub opcode: InfoOpcode,
    /// More fragments follow.
    pub incomplete: bool,
    /// How many.
    pub fragments_left: u16,
}

impl InfoHeader {
    /// A complete (single-message) header.
    pub fn whole(opcode: InfoOpcode) -> Self {
        Self { opcode, incomplete: false, fragments_left: 0 }
    }
}

/// Which list Get OD List asks for (ETG.1000.6 Table 43).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ListType {
    /// 0: the length of each of the lists below.
    Lengths,
    /// 1: every object.
    All,
    /// 2: objects mappable into an RxPDO.
    RxPdoMappable,
    /// 3: objects mappable into a TxPDO.
    TxPdoMappable,
    /// 4: objects stored for a device replacement.
    Backup,
    /// 5: start-up parameters.
    Settings,
}

impl ListType {
    /// The code.
    pub fn code(self) -> u16 {
        match self {
            Self::Lengths => 0,
            Self::All => 1,
            Self::RxPdoMappable => 2,
            Self::TxPdoMappable => 3,
            Self::Backup => 4,
            Self::Settings => 5,
        }
    }

    /// The list of a code.
    pub fn from_code(code: u16) -> Result<Self, PayloadError> {
        Ok(match code {
            0 => Self::Lengths,
            1 => Self::All,
            2 => Self::RxPdoMappable,
            3 => Self::TxPdoMappable,
            4 => Self::Backup,
            5 => Self::Settings,
            v => return Err(PayloadError::InvalidValue { field: "OD list type", value: v.into() }),
        })
    }
}

/// Which optional values Get Entry Description asks for and gets
/// (ETG.1000.6 Table 45, "ValueInfo").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct ValueInfo(pub u8);

impl ValueInfo {
    /// Bit 3: the unit type.
    pub const UNIT: u8 = 0x08;
    /// Bit 4: the default value.
    pub const DEFAULT: u8 = 0x10;
    /// Bit 5: the minimum value.
    pub const MINIMUM: u8 = 0x20;
    /// Bit 6: the maximum value.
    pub const MAXIMUM: u8 = 0x40;
    /// Everything.
    pub const ALL: Self = Self(Self::UNIT | Self::DEFAULT | Self::MINIMUM | Self::MAXIMUM);

    /// Whether `bit` is set.
    pub fn has(self, bit: u8) -> bool {
        self.0 & bit != 0
    }
}

/// An entry's access and mapping flags (ETG.1000.6 Table 46).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct ObjectAccess(pub u16);

impl ObjectAccess {
    /// Readable in PRE-OP.
    pub const READ_PREOP: u16 = 1 << 0;
    /// Readable in SAFE-OP.
    pub const READ_SAFEOP: u16 = 1 << 1;
    /// Readable in OP.
    pub const READ_OP: u16 = 1 << 2;
    /// Writable in PRE-OP.
    pub const WRITE_PREOP: u16 = 1 << 3;
    /// Writable in SAFE-OP.
    pub const WRITE_SAFEOP: u16 = 1 << 4;
    /// Writable in OP.
    pub const WRITE_OP: u16 = 1 << 5;
    /// Mappable into an RxPDO.
    pub const RXPDO: u16 = 1 << 6;
    /// Mappable into a TxPDO.
    pub const TXPDO: u16 = 1 << 7;
    /// Stored for a device replacement.
    pub const BACKUP: u16 = 1 << 8;
    /// A start-up parameter.
    pub const SETTINGS: u16 = 1 << 9;

    /// Whether `bit` is set.
    pub fn has(self, bit: u16) -> bool {
        self.0 & bit != 0
    }
}

/// A question to a slave.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum InfoRequest {
    /// Get OD List.
    OdList(ListType),
    /// Get Object Description.
    Object {
        /// Object index.
        index: u16,
    },
    /// Get Entry Description.
    Entry {
        /// Object index.
        index: u16,
        /// Subindex.
        subindex: u8,
        /// The optional values wanted.
        value_info: ValueInfo,
    },
}

fn write_header(w: &mut Writer<'_>, h: InfoHeader) -> Result<(), EncodeError> {
    w.bytes(&CoeHeader::of(CoeService::SdoInformation).to_bytes())?;
    w.u8(h.opcode.code() | if h.incomplete { 0x80 } else { 0 })?;
    w.u8(0)?;
    w.u16(h.fragments_left)
}

fn read_header<'a>(r: &mut Reader<'a>) -> Result<InfoHeader, PayloadError> {
    let coe = CoeHeader::decode(r.bytes("CoE header", COE_HEADER_LEN)?)?;
    if coe.service != CoeService::SdoInformation {
        return Err(PayloadError::InvalidValue { field: "CoE service", value: coe.service.code().into() });
    }
    let op = r.u8("SDO Info opcode")?;
    r.u8("SDO Info reserved")?;
    Ok(InfoHeader {
        opcode: InfoOpcode::from_code(op),
        incomplete: op & 0x80 != 0,
        fragments_left: r.u16("SDO Info fragments left")?,
    })
}

impl InfoRequest {
    /// The opcode its answer comes with (an error aside).
    pub fn answer_opcode(&self) -> InfoOpcode {
        match self {
            Self::OdList(_) => InfoOpcode::OdListResponse,
            Self::Object { .. } => InfoOpcode::ObjectResponse,
            Self::Entry { .. } => InfoOpcode::EntryResponse,
        }
    }

    /// Writes the CoE body; returns its length.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let mut w = Writer::new(out);
        match *self {
            Self::OdList(list) => {
                write_header(&mut w, InfoHeader::whole(InfoOpcode::OdListRequest))?;
                w.u16(list.code())?;
            }
            Self::Object { index } => {
                write_header(&mut w, InfoHeader::whole(InfoOpcode::ObjectRequest))?;
                w.u16(index)?;
            }
            Self::Entry { index, subindex, value_info } => {
                write_header(&mut w, InfoHeader::whole(InfoOpcode::EntryRequest))?;
                w.u16(index)?;
                w.u8(subindex)?;
                w.u8(value_info.0)?;
            }
        }
        Ok(usize::from(w.len_u16()))
    }

    /// Reads a CoE body.
    pub fn decode(body: &[u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(body);
        let h = read_header(&mut r)?;
        match h.opcode {
            InfoOpcode::OdListRequest => Ok(Self::OdList(ListType::from_code(r.u16("OD list type")?)?)),
            InfoOpcode::ObjectRequest => Ok(Self::Object { index: r.u16("object index")? }),
            InfoOpcode::EntryRequest => Ok(Self::Entry {
                index: r.u16("object index")?,
                subindex: r.u8("subindex")?,
                value_info: ValueInfo(r.u8("value info")?),
            }),
            other => Err(PayloadError::InvalidValue { field: "SDO Info request opcode", value: other.code().into() }),
        }
    }
}

/// One message of an answer: its info header and its share of the payload.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct InfoFragment<'a> {
    /// The header.
    pub header: InfoHeader,
    /// This message's part of the answer.
    pub payload: &'a [u8],
}

impl<'a> InfoFragment<'a> {
    /// Reads a CoE body.
    pub fn decode(body: &'a [u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(body);
        let header = read_header(&mut r)?;
        Ok(Self { header, payload: r.rest() })
    }

    /// Writes a CoE body; returns its length.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let mut w = Writer::new(out);
        write_header(&mut w, self.header)?;
        w.bytes(self.payload)?;
        Ok(usize::from(w.len_u16()))
    }

    /// The SDO abort code of an SDO Info error (opcode 7).
    pub fn abort_code(&self) -> Option<u32> {
        (self.header.opcode == InfoOpcode::Error)
            .then(|| Reader::new(self.payload).u32("SDO Info abort code").ok())
            .flatten()
    }

    /// Splits a whole answer `payload` into the fragments a send mailbox of
    /// `mailbox_size` bytes carries, in order (a slave's side). Each part
    /// is an even number of bytes, so an OD list's indices are never cut.
    pub fn split(opcode: InfoOpcode, payload: &'a [u8], mailbox_size: usize) -> impl Iterator<Item = Self> + 'a {
        let room = (mailbox_size.saturating_sub(crate::mbx::HEADER_LEN + INFO_OVERHEAD) & !1).max(2);
        let count = payload.len().div_ceil(room).max(1);
        (0..count).map(move |k| {
            let part = payload.get(k * room..((k + 1) * room).min(payload.len())).unwrap_or(&[]);
            let left = (count - 1 - k) as u16;
            Self { header: InfoHeader { opcode, incomplete: left > 0, fragments_left: left }, payload: part }
        })
    }
}

/// A Get OD List answer, joined.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct OdList<'a> {
    /// The list.
    pub list: ListType,
    raw: &'a [u8],
}

impl<'a> OdList<'a> {
    /// Reads a joined payload.
    pub fn decode(payload: &'a [u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(payload);
        let list = ListType::from_code(r.u16("OD list type")?)?;
        let raw = r.rest();
        if raw.len() % 2 != 0 {
            return Err(PayloadError::InvalidValue { field: "OD list length", value: raw.len() as u32 });
        }
        Ok(Self { list, raw })
    }

    /// The indices (for [`ListType::Lengths`]: the five list lengths).
    pub fn indices(&self) -> impl Iterator<Item = u16> + 'a {
        self.raw.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]]))
    }

    /// Writes a payload: list type, then the indices.
    pub fn encode(
        list: ListType,
        indices: impl IntoIterator<Item = u16>,
        out: &mut [u8],
    ) -> Result<usize, EncodeError> {
        let mut w = Writer::new(out);
        w.u16(list.code())?;
        for i in indices {
            w.u16(i)?;
        }
        Ok(usize::from(w.len_u16()))
    }
}

/// A Get Object Description answer, joined.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ObjectDescription<'a> {
    /// Object index.
    pub index: u16,
    /// Data type (ETG.1000.6 Table 63/64 code) of the object or, for an
    /// array, of its elements.
    pub data_type: u16,
    /// Highest subindex.
    pub max_subindex: u8,
    /// 7 VAR, 8 ARRAY, 9 RECORD.
    pub object_code: u8,
    /// The name (usually ASCII).
    pub name: &'a [u8],
}

impl<'a> ObjectDescription<'a> {
    /// Reads a joined payload.
    pub fn decode(payload: &'a [u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(payload);
        Ok(Self {
            index: r.u16("object index")?,
            data_type: r.u16("data type")?,
            max_subindex: r.u8("max subindex")?,
            object_code: r.u8("object code")?,
            name: r.rest(),
        })
    }

    /// Writes a payload.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let mut w = Writer::new(out);
        w.u16(self.index)?;
        w.u16(self.data_type)?;
        w.u8(self.max_subindex)?;
        w.u8(self.object_code)?;
        w.bytes(self.name)?;
        Ok(usize::from(w.len_u16()))
    }
}

/// A Get Entry Description answer, joined.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct EntryDescription<'a> {
    /// Object index.
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// Which optional values follow.
    pub value_info: ValueInfo,
    /// Data type code.
    pub data_type: u16,
    /// Size in bits.
    pub bit_length: u16,
    /// Access and mapping.
    pub access: ObjectAccess,
    /// Unit type (ETG.1004), when asked for and given.
    pub unit: Option<u32>,
    /// Default value, `ceil(bit_length / 8)` bytes.
    pub default: Option<&'a [u8]>,
    /// Minimum value.
    pub minimum: Option<&'a [u8]>,
    /// Maximum value.
    pub maximum: Option<&'a [u8]>,
    /// The name.
    pub name: &'a [u8],
}

impl<'a> EntryDescription<'a> {
    /// Reads a joined payload.
    pub fn decode(payload: &'a [u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(payload);
        let index = r.u16("object index")?;
        let subindex = r.u8("subindex")?;
        let value_info = ValueInfo(r.u8("value info")?);
        let data_type = r.u16("data type")?;
        let bit_length = r.u16("bit length")?;
        let access = ObjectAccess(r.u16("object access")?);
        let unit = if value_info.has(ValueInfo::UNIT) { Some(r.u32("unit type")?) } else { None };
        let n = usize::from(bit_length).div_ceil(8);
        let mut value = |bit, field| if value_info.has(bit) { r.bytes(field, n).map(Some) } else { Ok(None) };
        let default = value(ValueInfo::DEFAULT, "default value")?;
        let minimum = value(ValueInfo::MINIMUM, "minimum value")?;
        let maximum = value(ValueInfo::MAXIMUM, "maximum value")?;
        Ok(Self {
            index,
            subindex,
            value_info,
            data_type,
            bit_length,
            access,
            unit,
            default,
            minimum,
            maximum,
            name: r.rest(),
        })
    }

    /// Writes a payload; `value_info` is made to say what is there.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let mut info = 0;
        for (present, bit) in [
            (self.unit.is_some(), ValueInfo::UNIT),
            (self.default.is_some(), ValueInfo::DEFAULT),
            (self.minimum.is_some(), ValueInfo::MINIMUM),
            (self.maximum.is_some(), ValueInfo::MAXIMUM),
        ] {
            if present {
                info |= bit;
            }
        }
        let n = usize::from(self.bit_length).div_ceil(8);
        let mut w = Writer::new(out);
        w.u16(self.index)?;
        w.u8(self.subindex)?;
        w.u8(info)?;
        w.u16(self.data_type)?;
        w.u16(self.bit_length)?;
        w.u16(self.access.0)?;
        if let Some(u) = self.unit {
            w.u32(u)?;
        }
        for v in [self.default, self.minimum, self.maximum].into_iter().flatten() {
            // Each value is exactly the entry's size: cut or zero-padded.
            let take = v.len().min(n);
            w.bytes(&v[..take])?;
            for _ in take..n {
                w.u8(0)?;
            }
        }
        w.bytes(self.name)?;
        Ok(usize::from(w.len_u16()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::vec::Vec;

    proptest! {
        #[test]
        fn requests_round_trip(kind in 0u8..3, list in 0u16..6, index: u16, subindex: u8, info: u8) {
            let r = match kind {
                0 => InfoRequest::OdList(ListType::from_code(list).unwrap()),
                1 => InfoRequest::Object { index },
                _ => InfoRequest::Entry { index, subindex, value_info: ValueInfo(info) },
            };
            let mut b = [0u8; 16];
            let n = r.encode(&mut b).unwrap();
            prop_assert_eq!(InfoRequest::decode(&b[..n]).unwrap(), r);
        }

        /// Split and joined again, any payload is itself, in fragments
        /// that fit the mailbox, counted down, incomplete but the last.
        #[test]
        fn fragments_join_to_the_payload(payload in proptest::collection::vec(any::<u8>(), 0..600), size in 16usize..300) {
            let parts: Vec<_> = InfoFragment::split(InfoOpcode::OdListResponse, &payload, size).collect();
            let mut joined = Vec::new();
            for (k, p) in parts.iter().enumerate() {
                let mut b = [0u8; 512];
                let n = p.encode(&mut b).unwrap();
                prop_assert!(n + crate::mbx::HEADER_LEN <= size.max(crate::mbx::HEADER_LEN + INFO_OVERHEAD + 2));
                let back = InfoFragment::decode(&b[..n]).unwrap();
                prop_assert_eq!(back.header.fragments_left as usize, parts.len() - 1 - k);
                prop_assert_eq!(back.header.incomplete, k + 1 < parts.len());
                joined.extend_from_slice(back.payload);
            }
            prop_assert_eq!(joined, payload);
        }

        #[test]
        fn entry_descriptions_round_trip(index: u16, subindex: u8, data_type: u16, bits in 1u16..65, access: u16,
                                         unit: Option<u32>, d in any::<Option<[u8; 8]>>(), name in "[ -~]{0,40}") {
            let n = usize::from(bits).div_ceil(8);
            let value = d.map(|v| v[..n].to_vec());
            let e = EntryDescription {
                index, subindex, value_info: ValueInfo(0), data_type, bit_length: bits, access: ObjectAccess(access),
                unit, default: value.as_deref(), minimum: value.as_deref(), maximum: None, name: name.as_bytes(),
            };
            let mut b = [0u8; 128];
            let len = e.encode(&mut b).unwrap();
            let back = EntryDescription::decode(&b[..len]).unwrap();
            prop_assert_eq!((back.index, back.subindex, back.data_type, back.bit_length), (index, subindex, data_type, bits));
            prop_assert_eq!((back.access, back.unit, back.default, back.minimum), (e.access, unit, e.default, e.minimum));
            prop_assert_eq!((back.maximum, back.name), (None, name.as_bytes()));
        }

        #[test]
        fn decoding_arbitrary_bytes_never_panics(data in proptest::collection::vec(any::<u8>(), 0..40)) {
            let _ = InfoRequest::decode(&data);
            if let Ok(f) = InfoFragment::decode(&data) {
                let _ = f.abort_code();
            }
            let _ = OdList::decode(&data);
            let _ = ObjectDescription::decode(&data);
            let _ = EntryDescription::decode(&data);
        }
    }

    #[test]
    fn golden_get_od_list_and_its_answer() {
        // Get OD List, all objects: CoE 0x8000, opcode 1, list type 1.
        let mut b = [0u8; 16];
        let n = InfoRequest::OdList(ListType::All).encode(&mut b).unwrap();
        assert_eq!(&b[..n], &[0x00, 0x80, 0x01, 0x00, 0x00, 0x00, 0x01, 0x00]);
        let mut payload = [0u8; 16];
        let n = OdList::encode(ListType::All, [0x1000, 0x1018], &mut payload).unwrap();
        let list = OdList::decode(&payload[..n]).unwrap();
        assert_eq!(list.list, ListType::All);
        assert_eq!(list.indices().collect::<Vec<_>>(), [0x1000, 0x1018]);
    }

    #[test]
    fn an_object_description_round_trips() {
        let o =
            ObjectDescription { index: 0x1018, data_type: 0x0023, max_subindex: 4, object_code: 9, name: b"Identity" };
        let mut b = [0u8; 32];
        let n = o.encode(&mut b).unwrap();
        assert_eq!(&b[..6], &[0x18, 0x10, 0x23, 0x00, 4, 9]);
        assert_eq!(ObjectDescription::decode(&b[..n]).unwrap(), o);
    }

    #[test]
    fn an_info_error_carries_an_abort_code() {
        let payload = 0x0602_0000u32.to_le_bytes();
        let f = InfoFragment { header: InfoHeader::whole(InfoOpcode::Error), payload: &payload };
        let mut b = [0u8; 16];
        let n = f.encode(&mut b).unwrap();
        assert_eq!(InfoFragment::decode(&b[..n]).unwrap().abort_code(), Some(0x0602_0000));
    }
}
