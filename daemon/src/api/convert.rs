//! Conversions between engine/wire types and `ecmxf.v1` messages, and the
//! typed-value codec (CiA 301 data types, little-endian as on EtherCAT).

use ecmxf_proto::v1 as pb;
use ecmxf_wire::EcatState;
use tonic::Status;

use super::status::bad_argument;
use crate::master::Phase;

/// Wire state to API state.
pub fn state_to_pb(s: EcatState) -> pb::EcatState {
    match s {
        EcatState::Init => pb::EcatState::Init,
        EcatState::PreOp => pb::EcatState::PreOp,
        EcatState::Boot => pb::EcatState::Boot,
        EcatState::SafeOp => pb::EcatState::SafeOp,
        EcatState::Op => pb::EcatState::Op,
        EcatState::Error => pb::EcatState::Error,
        _ => pb::EcatState::Unspecified,
    }
}

/// API state (as sent: an i32) to a requestable wire state.
pub fn state_from_pb(v: i32, field: &'static str) -> Result<EcatState, Status> {
    match pb::EcatState::try_from(v) {
        Ok(pb::EcatState::Init) => Ok(EcatState::Init),
        Ok(pb::EcatState::PreOp) => Ok(EcatState::PreOp),
        Ok(pb::EcatState::Boot) => Ok(EcatState::Boot),
        Ok(pb::EcatState::SafeOp) => Ok(EcatState::SafeOp),
        Ok(pb::EcatState::Op) => Ok(EcatState::Op),
        _ => Err(bad_argument(field, format!("{v} is not a requestable state (INIT, PRE_OP, BOOT, SAFE_OP, OP)"))),
    }
}

/// Engine phase to API phase.
pub fn phase_to_pb(p: Phase) -> pb::EnginePhase {
    match p {
        Phase::Starting => pb::EnginePhase::Starting,
        Phase::BringUp => pb::EnginePhase::BringingUp,
        Phase::Running => pb::EnginePhase::Running,
        Phase::Recovering => pb::EnginePhase::Recovering,
        Phase::Stopping => pb::EnginePhase::Stopping,
        Phase::Stopped => pb::EnginePhase::Stopped,
    }
}

/// A slave position from a request (0..=127, the chip's addressing range).
pub fn slave(v: u32) -> Result<u8, Status> {
    u8::try_from(v).ok().filter(|s| *s < 128).ok_or_else(|| bad_argument("slave", format!("{v} is outside 0..=127")))
}

/// A slave position from a request that must name a slave on the ring
/// (`count` found): the chip would only answer "refused" for one that is
/// not there. Errors name `field`.
pub fn existing_slave(v: u32, count: usize, field: &'static str) -> Result<u8, Status> {
    let s = slave(v).map_err(|_| bad_argument(field, format!("{v} is outside 0..=127")))?;
    if usize::from(s) >= count {
        return Err(bad_argument(field, format!("slave {s} does not exist ({count} found)")));
    }
    Ok(s)
}

/// An object index from a request.
pub fn index(v: u32) -> Result<u16, Status> {
    u16::try_from(v).map_err(|_| bad_argument("index", format!("{v:#x} is outside 0..=0xFFFF")))
}

/// A subindex from a request.
pub fn subindex(v: u32) -> Result<u8, Status> {
    u8::try_from(v).map_err(|_| bad_argument("subindex", format!("{v:#x} is outside 0..=0xFF")))
}

pub use ecmxf_proto::value::{decode_value, type_size};

/// A type from a request field.
pub fn data_type(v: i32) -> Result<pb::DataType, Status> {
    pb::DataType::try_from(v).map_err(|_| bad_argument("data_type", format!("{v} is not a DataType")))
}

/// Encodes `value` as `t`: raw bytes exactly the type's size (any length
/// for a string or an unknown type), text only to a string type, numbers
/// within the type. Errors name `value` (or `data_type`) and say why.
pub fn encode_value(t: pb::DataType, value: &pb::Value) -> Result<Vec<u8>, Status> {
    encode(t, value).map_err(|(field, reason)| bad_argument(field, reason))
}

/// A type's name as users write it: "UNSIGNED16", not "DATA_TYPE_UNSIGNED16".
pub fn type_name(t: pb::DataType) -> &'static str {
    t.as_str_name().trim_start_matches("DATA_TYPE_")
}

/// [`encode_value`] with the failing field and the reason apart, for
/// callers that put the target in the message (an output entry's name).
pub fn encode(t: pb::DataType, value: &pb::Value) -> Result<Vec<u8>, (&'static str, String)> {
    use pb::DataType as T;
    use pb::value::Kind;
    let kind = value.kind.as_ref().ok_or(("value", "no value given".to_string()))?;
    if let Kind::Raw(b) = kind {
        // Raw bytes are the object's own: exactly its size when the type
        // says one, never silently cut or padded.
        return match type_size(t) {
            Some(n) if b.len() != n => {
                Err(("value", format!("{} raw bytes given for a {} object, which has {n}", b.len(), type_name(t))))
            }
            _ => Ok(b.clone()),
        };
    }
    if let Kind::Text(s) = kind {
        return match t {
            T::VisibleString | T::OctetString => Ok(s.as_bytes().to_vec()),
            T::Unspecified => Err((
                "value",
                "text goes only to string objects, and this object's type is not known: \
                 give data_type VISIBLE_STRING, or a raw value"
                    .to_string(),
            )),
            _ => Err(("value", format!("text given for a {} object", type_name(t)))),
        };
    }
    let Some(size) = type_size(t) else {
        return Err(("data_type", "the object's type is not known: give data_type, or a raw value".to_string()));
    };
    let out_of_range = |v: String| ("value", format!("{v} does not fit {}", type_name(t)));
    let bytes: Vec<u8> = match (t, kind) {
        (T::Real32, Kind::Real(f)) => (*f as f32).to_le_bytes().to_vec(),
        (T::Real64, Kind::Real(f)) => f.to_le_bytes().to_vec(),
        (T::Real32 | T::Real64, Kind::Integer(i)) => return encode(t, &real(*i as f64)),
        (T::Real32 | T::Real64, Kind::Unsigned(u)) => return encode(t, &real(*u as f64)),
        (_, Kind::Real(f)) => {
            return Err(("value", format!("{f} is a real; {} wants an integer", type_name(t))));
        }
        (_, Kind::Boolean(v)) => {
            let mut b = vec![0u8; size];
            b[0] = u8::from(*v);
            b
        }
        (_, Kind::Integer(i)) => {
            let signed = matches!(t, T::Integer8 | T::Integer16 | T::Integer32 | T::Integer64);
            let bits = 8 * size as u32;
            let fits = if signed {
                bits == 64 || (*i >= -(1i64 << (bits - 1)) && *i < (1i64 << (bits - 1)))
            } else {
                *i >= 0 && (bits == 64 || *i < (1i64 << bits))
            };
            if !fits {
                return Err(out_of_range(i.to_string()));
            }
            i.to_le_bytes()[..size].to_vec()
        }
        (_, Kind::Unsigned(u)) => {
            let signed = matches!(t, T::Integer8 | T::Integer16 | T::Integer32 | T::Integer64);
            let bits = 8 * size as u32 - u32::from(signed);
            if bits < 64 && *u >= (1u64 << bits) {
                return Err(out_of_range(u.to_string()));
            }
            u.to_le_bytes()[..size].to_vec()
        }
        (_, Kind::Raw(_) | Kind::Text(_)) => unreachable!("handled above"),
    };
    Ok(bytes)
}

fn real(f: f64) -> pb::Value {
    pb::Value { kind: Some(pb::value::Kind::Real(f)) }
}

/// The natural type of an entry of `bits` bits with no better knowledge.
/// The API's type for a device's CoE type. BITn travels as UNSIGNED8 (its
/// bit length says how many bits the image has).
pub fn pb_type(t: ecmxf_devices::od::DataType) -> pb::DataType {
    use ecmxf_devices::od::DataType as D;
    use pb::DataType as T;
    match t {
        D::Bool => T::Boolean,
        D::Int8 => T::Integer8,
        D::Int16 => T::Integer16,
        D::Int32 => T::Integer32,
        D::Int64 => T::Integer64,
        D::UInt8 | D::Bits(_) => T::Unsigned8,
        D::UInt16 => T::Unsigned16,
        D::UInt32 => T::Unsigned32,
        D::UInt64 => T::Unsigned64,
        D::Real32 => T::Real32,
        D::Real64 => T::Real64,
        D::VisibleString(_) => T::VisibleString,
        D::OctetString(_) => T::OctetString,
    }
}

/// A type of `bits` bits when nothing better is known.
pub fn type_for_bits(bits: u32, signed: bool) -> pb::DataType {
    use pb::DataType as T;
    match (bits, signed) {
        (1, _) => T::Boolean,
        (8, false) => T::Unsigned8,
        (16, false) => T::Unsigned16,
        (32, false) => T::Unsigned32,
        (64, false) => T::Unsigned64,
        (8, true) => T::Integer8,
        (16, true) => T::Integer16,
        (32, true) => T::Integer32,
        (64, true) => T::Integer64,
        _ => T::OctetString,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pb::DataType as T;
    use pb::value::Kind;

    fn v(k: Kind) -> pb::Value {
        pb::Value { kind: Some(k) }
    }

    #[test]
    fn every_fixed_type_round_trips_at_its_limits() {
        let cases = [
            (T::Boolean, Kind::Boolean(true)),
            (T::Integer8, Kind::Integer(-128)),
            (T::Integer8, Kind::Integer(127)),
            (T::Integer16, Kind::Integer(-32768)),
            (T::Integer32, Kind::Integer(i32::MIN.into())),
            (T::Integer64, Kind::Integer(i64::MIN)),
            (T::Unsigned8, Kind::Unsigned(255)),
            (T::Unsigned16, Kind::Unsigned(65535)),
            (T::Unsigned32, Kind::Unsigned(u32::MAX.into())),
            (T::Unsigned64, Kind::Unsigned(u64::MAX)),
            (T::Real32, Kind::Real(1.5)),
            (T::Real64, Kind::Real(-2.25)),
            (T::VisibleString, Kind::Text("abc".into())),
            (T::OctetString, Kind::Raw(vec![1, 2, 3])),
        ];
        for (t, k) in cases {
            let bytes = encode_value(t, &v(k.clone())).unwrap();
            assert_eq!(Some(bytes.len()), type_size(t).or(Some(bytes.len())));
            assert_eq!(decode_value(t, &bytes).unwrap(), Some(v(k)), "{t:?}");
        }
    }

    #[test]
    fn out_of_range_values_are_refused_naming_the_type() {
        for (t, k) in [
            (T::Integer8, Kind::Integer(128)),
            (T::Unsigned8, Kind::Integer(-1)),
            (T::Unsigned16, Kind::Unsigned(65536)),
            (T::Integer16, Kind::Unsigned(32768)),
            (T::Unsigned32, Kind::Real(1.0)),
            (T::Unsigned32, Kind::Text("x".into())),
        ] {
            let e = encode_value(t, &v(k)).unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument);
            assert!(e.message().contains("value"), "{}", e.message());
        }
        assert!(encode_value(T::Unspecified, &v(Kind::Integer(1))).unwrap_err().message().contains("data_type"));
    }

    #[test]
    fn short_data_is_an_error_naming_sizes() {
        assert!(decode_value(T::Unsigned32, &[1, 2]).unwrap_err().contains("2 bytes"));
        assert_eq!(decode_value(T::Integer16, &[0xFF, 0xFF]).unwrap(), Some(v(Kind::Integer(-1))));
    }
}
