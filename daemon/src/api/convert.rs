//! Conversions between engine/wire types and `ecmxf.v1` messages, and the
//! typed-value codec (CiA 301 data types, little-endian as on EtherCAT).

use crate::master::EcatState;
use ecmxf_proto::v1 as pb;
use tonic::Status;

use super::status::bad_argument;
use crate::master::Phase;
use crate::master::value::{DataType, Value, as_type};

/// Wire state to API state.
pub(crate) fn state_to_pb(s: EcatState) -> pb::EcatState {
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
pub(crate) fn state_from_pb(v: i32, field: &'static str) -> Result<EcatState, Status> {
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
pub(crate) fn phase_to_pb(p: Phase) -> pb::EnginePhase {
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
pub(crate) fn slave(v: u32) -> Result<u8, Status> {
    u8::try_from(v).ok().filter(|s| *s < 128).ok_or_else(|| bad_argument("slave", format!("{v} is outside 0..=127")))
}

/// A slave position from a request that must name a slave on the ring
/// (see [`crate::master::Master::check_slave`]: UNAVAILABLE while the
/// network is coming up). Errors name `field`.
pub(crate) fn existing_slave(master: &crate::master::Master, v: u32, field: &'static str) -> Result<u8, Status> {
    let s = slave(v).map_err(|_| bad_argument(field, format!("{v} is outside 0..=127")))?;
    master.check_slave(s, field).map_err(super::status::to_status)?;
    Ok(s)
}

/// An object index from a request.
pub(crate) fn index(v: u32) -> Result<u16, Status> {
    u16::try_from(v).map_err(|_| bad_argument("index", format!("{v:#x} is outside 0..=0xFFFF")))
}

/// A subindex from a request.
pub(crate) fn subindex(v: u32) -> Result<u8, Status> {
    u8::try_from(v).map_err(|_| bad_argument("subindex", format!("{v:#x} is outside 0..=0xFF")))
}

pub(crate) use ecmxf_proto::value::{decode_value, type_size};

/// A type from a request field.
pub(crate) fn data_type(v: i32) -> Result<pb::DataType, Status> {
    pb::DataType::try_from(v).map_err(|_| bad_argument("data_type", format!("{v} is not a DataType")))
}

/// Encodes `value` as `t`: raw bytes exactly the type's size (any length
/// for a string or an unknown type), text only to a string type, numbers
/// within the type. Errors name `value` (or `data_type`) and say why.
pub(crate) fn encode_value(t: pb::DataType, value: &pb::Value) -> Result<Vec<u8>, Status> {
    encode(t, value).map_err(|(field, reason)| bad_argument(field, reason))
}

/// A request's value as the master's [`Value`].
pub(crate) fn domain_value(kind: &pb::value::Kind) -> Value {
    use pb::value::Kind;
    match kind {
        Kind::Boolean(b) => Value::Bool(*b),
        Kind::Integer(i) => Value::Int(*i),
        Kind::Unsigned(u) => Value::UInt(*u),
        Kind::Real(f) => Value::Real(*f),
        Kind::Text(s) => Value::Text(s.clone()),
        Kind::Raw(b) => Value::Bytes(b.clone()),
    }
}

/// The master's type for an API type (`None`: not known). A string's
/// length is the value's own: an SDO writes what it is given.
fn domain_type(t: pb::DataType, value: &pb::value::Kind) -> Option<DataType> {
    use pb::DataType as T;
    use pb::value::Kind;
    let len = match value {
        Kind::Text(s) => s.len(),
        Kind::Raw(b) => b.len(),
        _ => 0,
    };
    let len = u16::try_from(len).unwrap_or(u16::MAX);
    Some(match t {
        T::Unspecified => return None,
        T::Boolean => DataType::Bool,
        T::Integer8 => DataType::Int8,
        T::Integer16 => DataType::Int16,
        T::Integer32 => DataType::Int32,
        T::Integer64 => DataType::Int64,
        T::Unsigned8 => DataType::UInt8,
        T::Unsigned16 => DataType::UInt16,
        T::Unsigned32 => DataType::UInt32,
        T::Unsigned64 => DataType::UInt64,
        T::Real32 => DataType::Real32,
        T::Real64 => DataType::Real64,
        T::VisibleString => DataType::VisibleString(len),
        T::OctetString => DataType::OctetString(len),
    })
}

/// [`encode_value`] with the failing field and the reason apart, for
/// callers that put the target in the message (an output entry's name).
/// Raw bytes for an object of unknown type go as they are; everything
/// else is the master's encoding ([`Value::encode`]).
pub(crate) fn encode(t: pb::DataType, value: &pb::Value) -> Result<Vec<u8>, (&'static str, String)> {
    use pb::value::Kind;
    let kind = value.kind.as_ref().ok_or(("value", "no value given".to_string()))?;
    match (domain_type(t, kind), kind) {
        (None, Kind::Raw(b)) => Ok(b.clone()),
        (None, Kind::Text(_)) => Err((
            "value",
            "text goes only to string objects, and this object's type is not known: \
             give data_type VISIBLE_STRING, or a raw value"
                .to_string(),
        )),
        (None, _) => Err(("data_type", "the object's type is not known: give data_type, or a raw value".to_string())),
        (Some(d), _) => domain_value(kind).encode(d, d.bits()).map_err(|e| ("value", e.to_string())),
    }
}

/// [`encode`] for an object whose type the daemon knows (`known`, see
/// `Master::object_type`): the value is written as that type, whatever
/// type the request names; a request naming another kind or size
/// (`data_type`) is refused rather than sent for the slave to abort, or
/// worse, take as another value ([`as_type`]). A string's length is the
/// value's: an SDO writes what it is given.
pub(crate) fn encode_known(
    asked: pb::DataType,
    known: DataType,
    value: &pb::Value,
) -> Result<Vec<u8>, (&'static str, String)> {
    let kind = value.kind.as_ref().ok_or(("value", "no value given".to_string()))?;
    let own = domain_type(pb_type(known), kind).filter(|t| !t.is_fixed_size()).unwrap_or(known);
    let t = match domain_type(asked, kind) {
        None => own,
        Some(a) => as_type(a, own).map_err(|e| ("data_type", e.to_string()))?,
    };
    domain_value(kind).encode(t, t.bits()).map_err(|e| ("value", e.to_string()))
}

/// A value for an output entry as its bytes: the entry's own type and bit
/// length ([`Value::encode`]).
pub(crate) fn encode_entry(
    e: &crate::master::image::Entry,
    value: &pb::Value,
) -> Result<Vec<u8>, (&'static str, String)> {
    let kind = value.kind.as_ref().ok_or(("value", "no value given".to_string()))?;
    domain_value(kind).encode(e.data_type, e.bit_length).map_err(|e| ("value", e.to_string()))
}

/// The API's type for a device's CoE type. BITn travels as UNSIGNED8 (its
/// bit length says how many bits the image has).
pub(crate) fn pb_type(t: ecmxf_devices::od::DataType) -> pb::DataType {
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
    fn a_known_type_decides_and_another_asked_is_refused() {
        use crate::master::value::DataType as D;
        let known = |asked, known, k| encode_known(asked, known, &v(k));
        assert_eq!(known(T::Unspecified, D::UInt32, Kind::Unsigned(7)).unwrap(), vec![7, 0, 0, 0]);
        assert_eq!(known(T::Unspecified, D::UInt16, Kind::Integer(5)).unwrap(), vec![5, 0]);
        assert_eq!(known(T::Unsigned16, D::UInt16, Kind::Integer(5)).unwrap(), vec![5, 0]);
        assert_eq!(known(T::Unspecified, D::VisibleString(0), Kind::Text("abc".into())).unwrap(), b"abc");
        assert_eq!(known(T::Unspecified, D::Bits(2), Kind::Unsigned(3)).unwrap(), vec![3]);
        for (asked, t, k, field) in [
            (T::Unspecified, D::UInt32, Kind::Boolean(true), "value"),
            (T::Unspecified, D::Int32, Kind::Real(1.5), "value"),
            (T::Unspecified, D::UInt16, Kind::Text("5".into()), "value"),
            (T::Unspecified, D::UInt16, Kind::Unsigned(70000), "value"),
            (T::Unspecified, D::UInt32, Kind::Integer(-1), "value"),
            (T::Unspecified, D::UInt32, Kind::Raw(vec![1, 2]), "value"),
            (T::Unspecified, D::Bits(2), Kind::Unsigned(4), "value"),
            (T::Unsigned64, D::UInt16, Kind::Unsigned(5), "data_type"),
            (T::Integer16, D::UInt16, Kind::Integer(5), "data_type"),
            (T::Boolean, D::UInt8, Kind::Boolean(true), "data_type"),
            (T::VisibleString, D::UInt32, Kind::Text("x".into()), "data_type"),
        ] {
            let e = known(asked, t, k.clone()).unwrap_err();
            assert_eq!(e.0, field, "{asked:?} {t:?} {k:?}: {}", e.1);
        }
    }

    #[test]
    fn short_data_is_an_error_naming_sizes() {
        assert!(decode_value(T::Unsigned32, &[1, 2]).unwrap_err().contains("2 bytes"));
        assert_eq!(decode_value(T::Integer16, &[0xFF, 0xFF]).unwrap(), Some(v(Kind::Integer(-1))));
    }
}
