//! Values between the process image and Sparkplug metrics: a CoE type's
//! Sparkplug datatype (spec 6.4.16), an entry's bits as a metric value,
//! a DCMD metric as an entry's bytes, and the deadband that decides
//! whether a value moved enough to publish.
//!
//! Signed integers narrower than 64 bits go in `int_value` as two's
//! complement of their own width (an Int8 -1 is 255), as the Eclipse Tahu
//! and pysparkplug hosts read them; commands are read the same way and
//! also sign-extended to 32 bits (as Tahu's Java host writes them).

pub(super) use crate::master::value::DataType;
use ecmxf_proto::sparkplug::DataType as SpType;
use ecmxf_proto::sparkplug::payload::metric::Value as MetricValue;

pub(super) use crate::master::value::Value;
use crate::master::value::ValueError;

/// A [`Value`] as a Sparkplug metric: its protobuf form and the deadband
/// test that decides whether it is published again.
pub(super) trait MetricValueExt {
    /// Whether `self` moved from `last` enough to be published: numbers by
    /// more than `deadband` (0: any change, and a NaN is a change), other
    /// values when they differ.
    fn moved_from(&self, last: &Value, deadband: f64) -> bool;
    /// The protobuf form, for a metric of `datatype`.
    fn to_metric(&self, datatype: SpType) -> MetricValue;
}

impl MetricValueExt for Value {
    fn moved_from(&self, last: &Value, deadband: f64) -> bool {
        match (self.as_f64(), last.as_f64()) {
            // A NaN on either side compares as moved.
            (Some(a), Some(b)) if deadband > 0.0 => {
                matches!((a - b).abs().partial_cmp(&deadband), Some(std::cmp::Ordering::Greater) | None)
            }
            _ => self != last,
        }
    }

    fn to_metric(&self, datatype: SpType) -> MetricValue {
        match self {
            Self::Bool(b) => MetricValue::BooleanValue(*b),
            Self::Int(v) => match datatype {
                SpType::Int8 => MetricValue::IntValue(u32::from(*v as i8 as u8)),
                SpType::Int16 => MetricValue::IntValue(u32::from(*v as i16 as u16)),
                SpType::Int32 => MetricValue::IntValue(*v as i32 as u32),
                _ => MetricValue::LongValue(*v as u64),
            },
            Self::UInt(v) => match datatype {
                SpType::UInt64 | SpType::Int64 => MetricValue::LongValue(*v),
                _ => MetricValue::IntValue(*v as u32),
            },
            Self::Real(v) => match datatype {
                SpType::Float => MetricValue::FloatValue(*v as f32),
                _ => MetricValue::DoubleValue(*v),
            },
            Self::Text(s) => MetricValue::StringValue(s.clone()),
            Self::Bytes(b) => MetricValue::BytesValue(b.clone()),
        }
    }
}

/// The Sparkplug datatype of a CoE type.
pub(super) fn datatype(t: DataType) -> SpType {
    match t {
        DataType::Bool => SpType::Boolean,
        DataType::Int8 => SpType::Int8,
        DataType::Int16 => SpType::Int16,
        DataType::Int32 => SpType::Int32,
        DataType::Int64 => SpType::Int64,
        DataType::UInt8 | DataType::Bits(_) => SpType::UInt8,
        DataType::UInt16 => SpType::UInt16,
        DataType::UInt32 => SpType::UInt32,
        DataType::UInt64 => SpType::UInt64,
        DataType::Real32 => SpType::Float,
        DataType::Real64 => SpType::Double,
        DataType::VisibleString(_) => SpType::String,
        DataType::OctetString(_) => SpType::Bytes,
    }
}

/// A command's value as the bytes of an entry of type `t` and `bits`
/// bits (little-endian), or why it cannot be one. The metric is read as
/// Sparkplug hosts write it (below); the range checks are the master's
/// ([`Value::encode`]).
pub(super) fn encode(t: DataType, bits: u32, v: &MetricValue) -> Result<Vec<u8>, String> {
    metric_value(t, v)?.encode(t, bits).map_err(|e| match e {
        ValueError::OutOfRange { value, .. } => {
            let width = match t {
                DataType::Bits(n) => u32::from(n),
                DataType::Bool => 1,
                _ => t.bits().min(bits),
            };
            let kind = if matches!(t, DataType::Int8 | DataType::Int16 | DataType::Int32 | DataType::Int64) {
                "signed"
            } else {
                "unsigned"
            };
            format!("{value} does not fit a {width}-bit {kind} entry")
        }
        e => e.to_string(),
    })
}

/// A metric's value as the master's [`Value`] for a target of type `t`.
/// Integers are read as Sparkplug hosts write them: signed ones narrower
/// than 64 bits as two's complement of their own width (an Int8 -1 is 255,
/// as Tahu and pysparkplug write it) or sign-extended to 32 bits (Tahu's
/// Java `int_value`); a whole float is an integer. A boolean stays one:
/// the master's encoder takes it only for a bit ([`Value::encode`]).
fn metric_value(t: DataType, v: &MetricValue) -> Result<Value, String> {
    if let MetricValue::BooleanValue(b) = v {
        return Ok(Value::Bool(*b));
    }
    let int = |v: &MetricValue| -> Result<i128, String> {
        match v {
            MetricValue::IntValue(u) => Ok(i128::from(*u)),
            MetricValue::LongValue(u) => Ok(i128::from(*u)),
            MetricValue::FloatValue(f) if f.fract() == 0.0 => Ok(*f as i128),
            MetricValue::DoubleValue(f) if f.fract() == 0.0 => Ok(*f as i128),
            other => Err(format!("{} is not an integer", shown(other))),
        }
    };
    let signed = |width: u32| -> Result<Value, String> {
        let raw = int(v)?;
        let span = 1i128 << width;
        let value = if raw >= span / 2 && raw < span {
            raw - span
        } else if width < 32 && (1 << 31..1 << 32).contains(&raw) {
            raw - (1 << 32)
        } else if width == 64 && raw >= 1 << 63 {
            raw - (1 << 64)
        } else {
            raw
        };
        i64::try_from(value).map(Value::Int).map_err(|_| format!("{raw} does not fit a {width}-bit signed entry"))
    };
    let unsigned = || -> Result<Value, String> {
        let raw = int(v)?;
        u64::try_from(raw).map(Value::UInt).map_err(|_| format!("{raw} does not fit an unsigned entry"))
    };
    match t {
        DataType::Bool => unsigned(),
        DataType::Int8 => signed(8),
        DataType::Int16 => signed(16),
        DataType::Int32 => signed(32),
        DataType::Int64 => signed(64),
        DataType::Bits(_) | DataType::UInt8 | DataType::UInt16 | DataType::UInt32 | DataType::UInt64 => unsigned(),
        DataType::Real32 | DataType::Real64 => match v {
            MetricValue::FloatValue(f) => Ok(Value::Real(f64::from(*f))),
            MetricValue::DoubleValue(f) => Ok(Value::Real(*f)),
            other => Ok(Value::Int(i64::try_from(int(other)?).map_err(|_| "out of range".to_string())?)),
        },
        DataType::VisibleString(_) | DataType::OctetString(_) => match v {
            MetricValue::StringValue(s) => Ok(Value::Text(s.clone())),
            MetricValue::BytesValue(b) => Ok(Value::Bytes(b.clone())),
            other => Err(format!("{} is not a string or bytes", shown(other))),
        },
    }
}

fn shown(v: &MetricValue) -> String {
    match v {
        MetricValue::IntValue(u) => u.to_string(),
        MetricValue::LongValue(u) => u.to_string(),
        MetricValue::FloatValue(f) => f.to_string(),
        MetricValue::DoubleValue(f) => f.to_string(),
        MetricValue::BooleanValue(b) => b.to_string(),
        MetricValue::StringValue(s) => format!("{s:?}"),
        MetricValue::BytesValue(b) => format!("{} bytes", b.len()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_round_trip_through_metrics_at_every_width() {
        let cases: &[(DataType, u32, i64)] = &[
            (DataType::Int8, 8, -1),
            (DataType::Int8, 8, -128),
            (DataType::Int8, 8, 127),
            (DataType::Int16, 16, -300),
            (DataType::Int32, 32, i64::from(i32::MIN)),
            (DataType::Int64, 64, i64::MIN),
            (DataType::Int64, 64, -5),
        ];
        for &(t, bits, v) in cases {
            let raw = v.to_le_bytes()[..bits.div_ceil(8) as usize].to_vec();
            let value = Value::decode(t, &raw);
            assert_eq!(value, Value::Int(v), "{t:?}");
            let metric = value.to_metric(datatype(t));
            assert_eq!(encode(t, bits, &metric).unwrap(), raw, "{t:?} {v}");
        }
        // An Int8 -1 is 255 in int_value, as Tahu and pysparkplug read it.
        assert_eq!(Value::Int(-1).to_metric(SpType::Int8), MetricValue::IntValue(255));
        // Tahu's Java host sign-extends to 32 bits: also -1.
        assert_eq!(encode(DataType::Int8, 8, &MetricValue::IntValue(u32::MAX)).unwrap(), vec![0xFF]);
        assert_eq!(encode(DataType::UInt16, 16, &MetricValue::IntValue(65535)).unwrap(), vec![0xFF, 0xFF]);
        assert!(encode(DataType::UInt16, 16, &MetricValue::IntValue(65536)).unwrap_err().contains("does not fit"));
        assert!(encode(DataType::Int8, 8, &MetricValue::IntValue(300)).unwrap_err().contains("does not fit"));
        assert!(
            encode(DataType::UInt8, 8, &MetricValue::StringValue("x".into())).unwrap_err().contains("not an integer")
        );
    }

    #[test]
    fn bits_booleans_floats_and_strings() {
        assert_eq!(Value::decode(DataType::Bool, &[1]), Value::Bool(true));
        assert_eq!(encode(DataType::Bool, 1, &MetricValue::BooleanValue(true)).unwrap(), vec![1]);
        assert_eq!(encode(DataType::Bool, 1, &MetricValue::IntValue(1)).unwrap(), vec![1]);
        assert!(encode(DataType::Bool, 1, &MetricValue::IntValue(2)).is_err());
        assert!(encode(DataType::Bits(2), 2, &MetricValue::IntValue(4)).is_err());
        // A boolean is a bit, not a number: refused for a wider entry.
        assert_eq!(encode(DataType::Bits(1), 1, &MetricValue::BooleanValue(true)).unwrap(), vec![1]);
        assert!(encode(DataType::UInt16, 16, &MetricValue::BooleanValue(true)).unwrap_err().contains("boolean true"));
        assert_eq!(Value::decode(DataType::Real32, &1.5f32.to_le_bytes()), Value::Real(1.5));
        assert_eq!(encode(DataType::Real32, 32, &MetricValue::DoubleValue(1.5)).unwrap(), 1.5f32.to_le_bytes());
        assert_eq!(Value::decode(DataType::VisibleString(4), b"ab\0\0"), Value::Text("ab".into()));
        assert_eq!(encode(DataType::VisibleString(4), 32, &MetricValue::StringValue("ab".into())).unwrap(), b"ab\0\0");
        assert!(encode(DataType::OctetString(2), 16, &MetricValue::BytesValue(vec![1, 2, 3])).is_err());
    }

    #[test]
    fn deadband_decides_what_moved() {
        assert!(!Value::UInt(5).moved_from(&Value::UInt(5), 0.0));
        assert!(Value::UInt(6).moved_from(&Value::UInt(5), 0.0));
        assert!(!Value::Int(7).moved_from(&Value::Int(5), 2.0));
        assert!(Value::Int(8).moved_from(&Value::Int(5), 2.0));
        assert!(Value::Real(f64::NAN).moved_from(&Value::Real(1.0), 2.0));
        assert!(Value::Text("b".into()).moved_from(&Value::Text("a".into()), 5.0));
        assert!(!Value::Bool(true).moved_from(&Value::Bool(true), 0.0));
    }
}
