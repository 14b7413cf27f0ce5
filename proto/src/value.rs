//! Typed values on the wire: CiA 301 data types, little-endian as EtherCAT
//! carries them. Shared by the daemon (SDO uploads, process-image entries)
//! and clients (types only a slave's ESI knows, ESC registers), so both read
//! bytes the same way.

use crate::v1 as pb;

/// Size in bytes of a fixed-size type, `None` for strings and unknown.
pub fn type_size(t: pb::DataType) -> Option<usize> {
    use pb::DataType as T;
    Some(match t {
        T::Boolean | T::Integer8 | T::Unsigned8 => 1,
        T::Integer16 | T::Unsigned16 => 2,
        T::Integer32 | T::Unsigned32 | T::Real32 => 4,
        T::Integer64 | T::Unsigned64 | T::Real64 => 8,
        T::VisibleString | T::OctetString | T::Unspecified => return None,
    })
}

/// Decodes bytes (little-endian) as `t`. Short data is an error naming the
/// sizes; longer data is decoded from its start (complete access).
pub fn decode_value(t: pb::DataType, raw: &[u8]) -> Result<Option<pb::Value>, String> {
    use pb::DataType as T;
    use pb::value::Kind;
    if let Some(n) = type_size(t) {
        if raw.len() < n {
            return Err(format!("{} bytes received for a {}-byte {}", raw.len(), n, t.as_str_name()));
        }
    }
    let mut b = [0u8; 8];
    let n = raw.len().min(8);
    b[..n].copy_from_slice(&raw[..n]);
    let signed = |bytes: usize| {
        let v = u64::from_le_bytes(b);
        let shift = 64 - 8 * bytes as u32;
        ((v << shift) as i64) >> shift
    };
    let unsigned = |bytes: usize| {
        let v = u64::from_le_bytes(b);
        if bytes == 8 { v } else { v & ((1u64 << (8 * bytes)) - 1) }
    };
    let kind = match t {
        T::Unspecified => return Ok(None),
        T::Boolean => Kind::Boolean(b[0] != 0),
        T::Integer8 => Kind::Integer(signed(1)),
        T::Integer16 => Kind::Integer(signed(2)),
        T::Integer32 => Kind::Integer(signed(4)),
        T::Integer64 => Kind::Integer(signed(8)),
        T::Unsigned8 => Kind::Unsigned(unsigned(1)),
        T::Unsigned16 => Kind::Unsigned(unsigned(2)),
        T::Unsigned32 => Kind::Unsigned(unsigned(4)),
        T::Unsigned64 => Kind::Unsigned(unsigned(8)),
        T::Real32 => Kind::Real(f32::from_le_bytes([b[0], b[1], b[2], b[3]]).into()),
        T::Real64 => Kind::Real(f64::from_le_bytes(b)),
        T::VisibleString => {
            let end = raw.iter().position(|&c| c == 0).unwrap_or(raw.len());
            Kind::Text(String::from_utf8_lossy(&raw[..end]).into_owned())
        }
        T::OctetString => Kind::Raw(raw.to_vec()),
    };
    Ok(Some(pb::Value { kind: Some(kind) }))
}
