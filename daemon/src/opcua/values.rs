//! The master's values as OPC UA variants: each CoE type as the OPC UA
//! built-in type of the same width and sign (OPC 10000-6 5.1.2), and the
//! engine's clock as an OPC UA DateTime.

use opcua::types::{DataTypeId, DateTime, Variant};

use crate::master::value::{DataType, Value};

/// The OPC UA data type of an entry of CoE type `t`. BITn (1..=8 bits) is
/// a Byte, as the value decoder reads it (an unsigned number).
pub(super) fn data_type_id(t: DataType) -> DataTypeId {
    match t {
        DataType::Bool => DataTypeId::Boolean,
        DataType::Int8 => DataTypeId::SByte,
        DataType::Int16 => DataTypeId::Int16,
        DataType::Int32 => DataTypeId::Int32,
        DataType::Int64 => DataTypeId::Int64,
        DataType::UInt8 => DataTypeId::Byte,
        DataType::UInt16 => DataTypeId::UInt16,
        DataType::UInt32 => DataTypeId::UInt32,
        DataType::UInt64 => DataTypeId::UInt64,
        DataType::Bits(_) => DataTypeId::Byte,
        DataType::Real32 => DataTypeId::Float,
        DataType::Real64 => DataTypeId::Double,
        DataType::VisibleString(_) => DataTypeId::String,
        DataType::OctetString(_) => DataTypeId::ByteString,
    }
}

/// `value` (decoded as type `t`) as a variant of [`data_type_id`]`(t)`.
pub(super) fn variant(t: DataType, value: Value) -> Variant {
    // The decoder gives each type its own kind of value; a number is
    // narrowed to the type it was decoded from, so it always fits.
    match (data_type_id(t), value) {
        (_, Value::Bool(b)) => Variant::from(b),
        (DataTypeId::SByte, Value::Int(i)) => Variant::from(i as i8),
        (DataTypeId::Int16, Value::Int(i)) => Variant::from(i as i16),
        (DataTypeId::Int32, Value::Int(i)) => Variant::from(i as i32),
        (_, Value::Int(i)) => Variant::from(i),
        (DataTypeId::Byte, Value::UInt(u)) => Variant::from(u as u8),
        (DataTypeId::UInt16, Value::UInt(u)) => Variant::from(u as u16),
        (DataTypeId::UInt32, Value::UInt(u)) => Variant::from(u as u32),
        (_, Value::UInt(u)) => Variant::from(u),
        (DataTypeId::Float, Value::Real(f)) => Variant::from(f as f32),
        (_, Value::Real(f)) => Variant::from(f),
        (_, Value::Text(s)) => Variant::from(s),
        (_, Value::Bytes(b)) => Variant::from(opcua::types::ByteString::from(b)),
    }
}

/// A written variant as the master's [`Value`]: a number as a number (its
/// range is checked when it is encoded for its target), a boolean as a
/// bit, text as text, a ByteString as the target's own bytes.
pub(super) fn value_of(v: &Variant) -> Result<Value, String> {
    Ok(match v {
        Variant::Boolean(b) => Value::Bool(*b),
        Variant::SByte(i) => Value::Int(i64::from(*i)),
        Variant::Int16(i) => Value::Int(i64::from(*i)),
        Variant::Int32(i) => Value::Int(i64::from(*i)),
        Variant::Int64(i) => Value::Int(*i),
        Variant::Byte(u) => Value::UInt(u64::from(*u)),
        Variant::UInt16(u) => Value::UInt(u64::from(*u)),
        Variant::UInt32(u) => Value::UInt(u64::from(*u)),
        Variant::UInt64(u) => Value::UInt(*u),
        Variant::Float(f) => Value::Real(f64::from(*f)),
        Variant::Double(f) => Value::Real(*f),
        Variant::String(s) => Value::Text(s.as_ref().to_string()),
        Variant::ByteString(b) => Value::Bytes(b.value.clone().unwrap_or_default()),
        Variant::Empty => return Err("no value given".into()),
        other => return Err(format!("a value of {} is no value of an EtherCAT object", kind(Some(other)))),
    })
}

/// What a client gave, in words: "Int32", "array of Byte", "nothing".
pub(super) fn kind(v: Option<&Variant>) -> String {
    match v.and_then(|v| v.scalar_type_id().map(|t| (v.is_array(), t))) {
        None => "nothing".into(),
        Some((true, t)) => format!("array of {t}"),
        Some((false, t)) => t.to_string(),
    }
}

/// `v` as the bytes of a target of CoE type `t` and `bits` bits, or why
/// it is not one (the master's checks: [`Value::encode`]).
pub(super) fn encode(t: DataType, bits: u32, v: &Variant) -> Result<Vec<u8>, String> {
    value_of(v)?.encode(t, bits).map_err(|e| e.to_string())
}

/// 100 ns ticks from 1601-01-01 (OPC 10000-6 5.2.2.5) to 1970-01-01.
const UNIX_EPOCH_TICKS: i64 = 116_444_736_000_000_000;

/// The wall-clock time of an engine-clock instant: `wall_now_ns` (ns since
/// the Unix epoch, now) less how long ago it was on the engine's clock.
pub(super) fn wall_time(engine_ns: u64, engine_now_ns: u64, wall_now_ns: u64) -> DateTime {
    let unix_ns = wall_now_ns.saturating_sub(engine_now_ns.saturating_sub(engine_ns));
    DateTime::from(UNIX_EPOCH_TICKS + (unix_ns / 100) as i64)
}

/// Now, ns since the Unix epoch.
pub(super) fn wall_now_ns() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_coe_type_is_the_opc_ua_type_of_its_width_and_sign() {
        let v = |t, raw: &[u8]| variant(t, Value::decode(t, raw));
        assert_eq!(v(DataType::Int8, &[0xFF]), Variant::SByte(-1));
        assert_eq!(v(DataType::Int16, &[0xFE, 0xFF]), Variant::Int16(-2));
        assert_eq!(v(DataType::Int32, &[0xFD, 0xFF, 0xFF, 0xFF]), Variant::Int32(-3));
        assert_eq!(v(DataType::UInt8, &[0xFF]), Variant::Byte(255));
        assert_eq!(v(DataType::UInt16, &[0x34, 0x12]), Variant::UInt16(0x1234));
        assert_eq!(v(DataType::UInt32, &[1, 0, 0, 0x80]), Variant::UInt32(0x8000_0001));
        assert_eq!(v(DataType::Bits(3), &[0x05]), Variant::Byte(5));
        assert_eq!(v(DataType::Bool, &[0x01]), Variant::Boolean(true));
        assert_eq!(v(DataType::Real32, &1.5f32.to_le_bytes()), Variant::Float(1.5));
    }

    #[test]
    fn what_a_client_gave_is_said_in_words() {
        assert_eq!(kind(Some(&Variant::from(5i32))), "Int32");
        assert_eq!(kind(Some(&Variant::from(5u16))), "UInt16");
        assert_eq!(kind(None), "nothing");
        assert_eq!(kind(Some(&Variant::Empty)), "nothing");
    }

    #[test]
    fn an_engine_instant_is_its_wall_time() {
        // 2 ms ago on the engine's clock, at a wall time of 1 s past 1970.
        let t = wall_time(8_000_000, 10_000_000, 1_000_000_000);
        assert_eq!(t.ticks(), UNIX_EPOCH_TICKS + 998_000_000 / 100);
    }
}
