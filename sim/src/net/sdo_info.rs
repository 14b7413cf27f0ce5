//! The SDO Information service as a slave answers it from its object
//! dictionary (ETG.1000.6 5.6.3; the wire format is `ecmxf_wire::mbx::
//! sdo_info`): the object lists, each object's description and each
//! entry's. What a device with `SdoInfo` in its ESI (bit 1 of the SII CoE
//! details) does; one without it answers the service with a mailbox error.

use ecmxf_wire::mbx::sdo_info::{
    EntryDescription, InfoOpcode, InfoRequest, ListType, ObjectAccess, ObjectDescription, OdList, ValueInfo,
};
use ecmxf_wire::payload::sdo::SdoAbortCode;

use super::od::{DataType, Entry, Mappable, Object, ObjectDictionary, ObjectKind, StateSet};

/// ETG.1000.6 object codes.
const VAR: u8 = 7;
const ARRAY: u8 = 8;
const RECORD: u8 = 9;

fn code_of(kind: ObjectKind) -> u8 {
    match kind {
        ObjectKind::Var => VAR,
        ObjectKind::Array => ARRAY,
        ObjectKind::Record => RECORD,
    }
}

/// The data type an object's description gives: its own for a VAR, its
/// elements' for an ARRAY; a RECORD has none of its own here (0), its
/// entries say theirs.
fn object_type(o: &Object) -> u16 {
    match o.kind {
        ObjectKind::Var => o.entries.get(&0).map_or(0, |e| e.dtype.code()),
        ObjectKind::Array => o.entries.get(&1).map_or(0, |e| e.dtype.code()),
        ObjectKind::Record => 0,
    }
}

/// An entry's access and mapping bits (ETG.1000.6 Table 46).
pub fn access_bits(e: &Entry) -> u16 {
    let states = |s: StateSet, preop, safeop, op| {
        (if s.preop { preop } else { 0 }) | (if s.safeop { safeop } else { 0 }) | (if s.op { op } else { 0 })
    };
    let mut bits = states(e.access.read, ObjectAccess::READ_PREOP, ObjectAccess::READ_SAFEOP, ObjectAccess::READ_OP)
        | states(e.access.write, ObjectAccess::WRITE_PREOP, ObjectAccess::WRITE_SAFEOP, ObjectAccess::WRITE_OP);
    if matches!(e.mappable, Mappable::Rx | Mappable::Both) {
        bits |= ObjectAccess::RXPDO;
    }
    if matches!(e.mappable, Mappable::Tx | Mappable::Both) {
        bits |= ObjectAccess::TXPDO;
    }
    bits
}

/// An entry's size in bits as SDO Info gives it: a string's is its length.
fn bit_length(e: &Entry) -> u16 {
    match e.dtype {
        DataType::VisibleString(_) | DataType::OctetString(_) => (e.value.len() * 8) as u16,
        t => t.bits() as u16,
    }
}

fn le(v: i64, n: usize) -> Vec<u8> {
    v.to_le_bytes()[..n.min(8)].to_vec()
}

/// The answer to `request`: its opcode and whole payload (to be split into
/// fragments by the caller), or the abort code of an SDO Info error.
pub fn answer(od: &ObjectDictionary, request: InfoRequest) -> Result<(InfoOpcode, Vec<u8>), SdoAbortCode> {
    let mut out = vec![0u8; 64 * 1024];
    let n = match request {
        InfoRequest::OdList(list) => {
            let mappable = |rx: bool| {
                od.objects().filter(move |(_, o)| o.entries.values().any(|e| e.mappable.allows(rx))).map(|(i, _)| i)
            };
            let indices: Vec<u16> = match list {
                ListType::Lengths => vec![
                    od.objects().count() as u16,
                    mappable(true).count() as u16,
                    mappable(false).count() as u16,
                    0,
                    0,
                ],
                ListType::All => od.objects().map(|(i, _)| i).collect(),
                ListType::RxPdoMappable => mappable(true).collect(),
                ListType::TxPdoMappable => mappable(false).collect(),
                ListType::Backup | ListType::Settings => Vec::new(),
            };
            OdList::encode(list, indices, &mut out).map_err(|_| SdoAbortCode::GENERAL)?
        }
        InfoRequest::Object { index } => {
            let o = od.object(index).ok_or(SdoAbortCode::OBJECT_MISSING)?;
            let description = ObjectDescription {
                index,
                data_type: object_type(o),
                max_subindex: o.entries.keys().copied().max().unwrap_or(0),
                object_code: code_of(o.kind),
                name: o.name.as_bytes(),
            };
            description.encode(&mut out).map_err(|_| SdoAbortCode::GENERAL)?
        }
        InfoRequest::Entry { index, subindex, value_info } => {
            let o = od.object(index).ok_or(SdoAbortCode::OBJECT_MISSING)?;
            let e = o.entries.get(&subindex).ok_or(SdoAbortCode::SUBINDEX_MISSING)?;
            let n = e.dtype.bytes();
            let range = e.range.filter(|_| e.dtype.is_fixed_size());
            let minimum = range.filter(|_| value_info.has(ValueInfo::MINIMUM)).map(|(lo, _)| le(lo, n));
            let maximum = range.filter(|_| value_info.has(ValueInfo::MAXIMUM)).map(|(_, hi)| le(hi, n));
            let default = value_info.has(ValueInfo::DEFAULT).then(|| e.value.clone());
            let description = EntryDescription {
                index,
                subindex,
                value_info,
                data_type: e.dtype.code(),
                bit_length: bit_length(e),
                access: ObjectAccess(access_bits(e)),
                unit: None,
                default: default.as_deref(),
                minimum: minimum.as_deref(),
                maximum: maximum.as_deref(),
                name: e.name.as_bytes(),
            };
            description.encode(&mut out).map_err(|_| SdoAbortCode::GENERAL)?
        }
    };
    out.truncate(n);
    Ok((request.answer_opcode(), out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net::od::Access;

    fn od() -> ObjectDictionary {
        let mut od = ObjectDictionary::new();
        od.insert(0x1000, Object::var("Device type", Entry::new("Device type", DataType::UInt32, Access::RO)));
        od.insert(
            0x6040,
            Object::var(
                "Controlword",
                Entry::new("Controlword", DataType::UInt16, Access::RW).mappable(Mappable::Rx).range(0, 0xFF),
            ),
        );
        od
    }

    #[test]
    fn lists_descriptions_and_errors() {
        let od = od();
        let (op, p) = answer(&od, InfoRequest::OdList(ListType::All)).unwrap();
        assert_eq!(op, InfoOpcode::OdListResponse);
        assert_eq!(OdList::decode(&p).unwrap().indices().collect::<Vec<_>>(), [0x1000, 0x6040]);
        let (_, p) = answer(&od, InfoRequest::OdList(ListType::RxPdoMappable)).unwrap();
        assert_eq!(OdList::decode(&p).unwrap().indices().collect::<Vec<_>>(), [0x6040]);
        let (_, p) = answer(&od, InfoRequest::Object { index: 0x6040 }).unwrap();
        let o = ObjectDescription::decode(&p).unwrap();
        assert_eq!((o.data_type, o.object_code, o.name), (0x0006, VAR, &b"Controlword"[..]));
        let ask = InfoRequest::Entry { index: 0x6040, subindex: 0, value_info: ValueInfo::ALL };
        let (_, p) = answer(&od, ask).unwrap();
        let e = EntryDescription::decode(&p).unwrap();
        assert_eq!((e.bit_length, e.minimum, e.maximum), (16, Some(&[0u8, 0][..]), Some(&[0xFFu8, 0][..])));
        assert!(e.access.has(ObjectAccess::RXPDO) && e.access.has(ObjectAccess::WRITE_OP));
        assert_eq!(answer(&od, InfoRequest::Object { index: 0x2000 }), Err(SdoAbortCode::OBJECT_MISSING));
        let missing = InfoRequest::Entry { index: 0x6040, subindex: 3, value_info: ValueInfo(0) };
        assert_eq!(answer(&od, missing), Err(SdoAbortCode::SUBINDEX_MISSING));
    }
}
