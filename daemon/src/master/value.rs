//! Typed values: the one encoder every front end writes through, with one
//! set of range and kind checks, and the decoder of an entry's bits.
//!
//! A front end turns its own wire value (a gRPC `Value`, a Sparkplug
//! metric, an OPC UA variant) into a [`Value`], then [`Value::encode`]s it
//! as the target's CoE type (CiA 301 data types, little-endian as EtherCAT
//! carries them) into the target's bits: a process-image entry's bit
//! length, or an object's size for an SDO. What does not fit is refused
//! with a [`ValueError`] naming the value and the type; nothing is cut,
//! padded with sign, or reinterpreted here.

use std::fmt;

pub(crate) use ecmxf_devices::od::DataType;

/// A value as the master writes and reads it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Value {
    /// A boolean: only to a BOOLEAN or a one-bit target (BIT1, or an
    /// entry mapped one bit wide); a number of any other width is given as
    /// a number.
    Bool(bool),
    /// A signed integer.
    Int(i64),
    /// An unsigned integer.
    UInt(u64),
    /// A real; REAL32 targets take it rounded to single precision.
    Real(f64),
    /// Text: only to string types.
    Text(String),
    /// The target's own bytes: exactly its size (a string's at most).
    Bytes(Vec<u8>),
}

/// Why a value cannot be written as a type.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ValueError {
    /// A number outside the type's range (`value` as given).
    OutOfRange {
        /// The value.
        value: String,
        /// The type's name.
        target: String,
    },
    /// A real given for an integer type.
    NotAnInteger {
        /// The value.
        value: String,
        /// The type's name.
        target: String,
    },
    /// A number given for a string type.
    NotAString {
        /// The value.
        value: String,
        /// The type's name.
        target: String,
    },
    /// Text given for a type that is not a string.
    TextForNumber {
        /// The value.
        value: String,
        /// The type's name.
        target: String,
    },
    /// A boolean given for a target wider than one bit.
    BoolForNumber {
        /// The value.
        value: bool,
        /// The type's name.
        target: String,
    },
    /// A type asked for that is not the target's own (another kind or
    /// size): written, the bytes would be read as another value.
    OtherType {
        /// The type asked for.
        asked: String,
        /// The target's type.
        target: String,
    },
    /// Raw bytes of another size than the type's.
    WrongSize {
        /// Bytes given.
        given: usize,
        /// The type's bytes.
        size: usize,
        /// The type's name.
        target: String,
    },
    /// A string or bytes longer than the target's room.
    TooLong {
        /// Bytes given.
        given: usize,
        /// The target's bytes.
        room: usize,
    },
    /// The target's bits cannot hold a number of its type (mapped wider
    /// than 64 bits, or zero bits).
    Unholdable {
        /// The target's bits.
        bits: u32,
        /// The type's name.
        target: String,
    },
}

impl fmt::Display for ValueError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::OutOfRange { value, target } => write!(f, "{value} does not fit {target}"),
            Self::NotAnInteger { value, target } => write!(f, "{value} is a real; {target} wants an integer"),
            Self::NotAString { value, target } => write!(f, "{value} is not a string or bytes ({target})"),
            Self::TextForNumber { value, target } => write!(f, "text {value} given for a {target} object"),
            Self::BoolForNumber { value, target } => {
                write!(f, "boolean {value} given for a {target} object; give it as a number")
            }
            Self::OtherType { asked, target } => write!(f, "{asked} asked for a {target} object"),
            Self::WrongSize { given, size, target } => {
                write!(f, "{given} raw bytes given for a {target} object, which has {size}")
            }
            Self::TooLong { given, room } => write!(f, "{given} bytes do not fit the {room}-byte entry"),
            Self::Unholdable { bits, target } => write!(f, "the entry's {bits} bits do not hold a {target}"),
        }
    }
}

impl std::error::Error for ValueError {}

/// A type's name as users write it (CiA 301): "UNSIGNED16". BITn is
/// named as the unsigned byte it travels in, as the API's types name it.
pub(crate) fn type_name(t: DataType) -> &'static str {
    match t {
        DataType::Bool => "BOOLEAN",
        DataType::Int8 => "INTEGER8",
        DataType::Int16 => "INTEGER16",
        DataType::Int32 => "INTEGER32",
        DataType::Int64 => "INTEGER64",
        DataType::UInt8 | DataType::Bits(_) => "UNSIGNED8",
        DataType::UInt16 => "UNSIGNED16",
        DataType::UInt32 => "UNSIGNED32",
        DataType::UInt64 => "UNSIGNED64",
        DataType::Real32 => "REAL32",
        DataType::Real64 => "REAL64",
        DataType::VisibleString(_) => "VISIBLE_STRING",
        DataType::OctetString(_) => "OCTET_STRING",
    }
}

/// The value bits of an integer type in a target of `bits` bits, and
/// whether it is signed; `None` for reals and strings.
fn integer_width(t: DataType, bits: u32) -> Option<(u32, bool)> {
    let signed = matches!(t, DataType::Int8 | DataType::Int16 | DataType::Int32 | DataType::Int64);
    match t {
        DataType::Bool => Some((1, false)),
        DataType::Bits(n) => Some((u32::from(n).min(bits), false)),
        DataType::Real32 | DataType::Real64 | DataType::VisibleString(_) | DataType::OctetString(_) => None,
        _ => Some((t.bits().min(bits), signed)),
    }
}

/// What a type is, for telling whether one stands for another: strings
/// of either kind are bytes of the value's length.
#[derive(PartialEq, Eq)]
enum Kind {
    Bool,
    Signed(u32),
    Unsigned(u32),
    Real(u32),
    String,
}

fn kind(t: DataType) -> Kind {
    match t {
        DataType::Bool => Kind::Bool,
        DataType::Int8 | DataType::Int16 | DataType::Int32 | DataType::Int64 => Kind::Signed(t.bits()),
        // BITn travels as the unsigned byte the API names it.
        DataType::Bits(_) => Kind::Unsigned(8),
        DataType::UInt8 | DataType::UInt16 | DataType::UInt32 | DataType::UInt64 => Kind::Unsigned(t.bits()),
        DataType::Real32 | DataType::Real64 => Kind::Real(t.bits()),
        DataType::VisibleString(_) | DataType::OctetString(_) => Kind::String,
    }
}

/// The type to write a target of type `target` as, when the caller named
/// `asked`: the target's own, if `asked` is of its kind and size (a
/// string's length is the value's), else refused. An object's type, once
/// known, decides its bytes: INTEGER32 asked for a UNSIGNED16 object would
/// send 4 bytes the slave refuses or, worse, takes.
pub(crate) fn as_type(asked: DataType, target: DataType) -> Result<DataType, ValueError> {
    match (kind(asked) == kind(target), target) {
        (false, _) => Err(ValueError::OtherType { asked: type_name(asked).into(), target: type_name(target).into() }),
        (true, DataType::VisibleString(_) | DataType::OctetString(_)) => Ok(asked),
        (true, _) => Ok(target),
    }
}

impl Value {
    /// The value as the bytes of a target of type `t` and `bits` bits
    /// (little-endian, `bits` rounded up to bytes), or why it is not one.
    pub(crate) fn encode(&self, t: DataType, bits: u32) -> Result<Vec<u8>, ValueError> {
        let size = bits.div_ceil(8) as usize;
        let target = || type_name(t).to_string();
        if let DataType::VisibleString(_) | DataType::OctetString(_) = t {
            let data = match self {
                Self::Text(s) => s.as_bytes(),
                Self::Bytes(b) => b.as_slice(),
                _ => return Err(ValueError::NotAString { value: self.shown(), target: target() }),
            };
            if data.len() > size {
                return Err(ValueError::TooLong { given: data.len(), room: size });
            }
            let mut out = data.to_vec();
            out.resize(size, 0);
            return Ok(out);
        }
        if size == 0 || size > 8 {
            return Err(ValueError::Unholdable { bits, target: target() });
        }
        // A number: a whole one exactly, or a real.
        let number: Result<i128, f64> = match self {
            Self::Text(_) => return Err(ValueError::TextForNumber { value: self.shown(), target: target() }),
            Self::Bytes(b) if b.len() != size => {
                return Err(ValueError::WrongSize { given: b.len(), size, target: target() });
            }
            Self::Bytes(b) => return Ok(b.clone()),
            Self::Bool(b) => Ok(i128::from(*b)),
            Self::Int(i) => Ok(i128::from(*i)),
            Self::UInt(u) => Ok(i128::from(*u)),
            Self::Real(f) => Err(*f),
        };
        // A boolean is a bit: in a wider target it would be a number the
        // caller did not give (true to a UNSIGNED32 writes 1).
        let one_bit = integer_width(t, bits).is_some_and(|(width, _)| width == 1);
        if let (Self::Bool(value), false) = (self, one_bit) {
            return Err(ValueError::BoolForNumber { value: *value, target: target() });
        }
        let Some((width, signed)) = integer_width(t, bits) else {
            // A real type.
            let f = number.map_or_else(|f| f, |i| i as f64);
            let mut out = match t {
                DataType::Real32 => (f as f32).to_le_bytes().to_vec(),
                _ => f.to_le_bytes().to_vec(),
            };
            out.resize(size, 0);
            return Ok(out);
        };
        let wide = number.map_err(|f| ValueError::NotAnInteger { value: f.to_string(), target: target() })?;
        let (low, high) = if signed { (-(1i128 << (width - 1)), 1i128 << (width - 1)) } else { (0, 1i128 << width) };
        if wide < low || wide >= high {
            return Err(ValueError::OutOfRange { value: self.shown(), target: target() });
        }
        Ok((wide as i64).to_le_bytes()[..size].to_vec())
    }

    /// The value of a target of type `t` from its bits (`raw`:
    /// little-endian, its bytes rounded up, as
    /// [`super::image::read_bits`] gives them). Short data reads as
    /// zero-extended.
    pub(crate) fn decode(t: DataType, raw: &[u8]) -> Self {
        let mut le = [0u8; 8];
        let n = raw.len().min(8);
        le[..n].copy_from_slice(&raw[..n]);
        let u = u64::from_le_bytes(le);
        match t {
            DataType::Bool => Self::Bool(u & 1 == 1),
            DataType::Int8 => Self::Int(i64::from(u as u8 as i8)),
            DataType::Int16 => Self::Int(i64::from(u as u16 as i16)),
            DataType::Int32 => Self::Int(i64::from(u as u32 as i32)),
            DataType::Int64 => Self::Int(u as i64),
            DataType::UInt8 | DataType::Bits(_) | DataType::UInt16 | DataType::UInt32 | DataType::UInt64 => {
                Self::UInt(u)
            }
            DataType::Real32 => Self::Real(f64::from(f32::from_bits(u as u32))),
            DataType::Real64 => Self::Real(f64::from_bits(u)),
            DataType::VisibleString(_) => {
                let end = raw.iter().position(|&b| b == 0).unwrap_or(raw.len());
                Self::Text(String::from_utf8_lossy(&raw[..end]).into_owned())
            }
            DataType::OctetString(_) => Self::Bytes(raw.to_vec()),
        }
    }

    /// The value as a signed integer, where it is one (a whole real or a
    /// boolean counts; an unsigned one above `i64::MAX` does not).
    pub(crate) fn as_i64(&self) -> Option<i64> {
        match self {
            Self::Bool(b) => Some(i64::from(*b)),
            Self::Int(i) => Some(*i),
            Self::UInt(u) => i64::try_from(*u).ok(),
            Self::Real(f) if f.fract() == 0.0 && f.abs() < 9.2e18 => Some(*f as i64),
            _ => None,
        }
    }

    /// The value as a number, for deadbands (`None`: not a number).
    pub(crate) fn as_f64(&self) -> Option<f64> {
        match self {
            Self::Int(v) => Some(*v as f64),
            Self::UInt(v) => Some(*v as f64),
            Self::Real(v) => Some(*v),
            _ => None,
        }
    }

    /// The value as messages show it.
    pub(crate) fn shown(&self) -> String {
        match self {
            Self::Bool(b) => b.to_string(),
            Self::Int(i) => i.to_string(),
            Self::UInt(u) => u.to_string(),
            Self::Real(f) => f.to_string(),
            Self::Text(s) => format!("{s:?}"),
            Self::Bytes(b) => format!("{} bytes", b.len()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_are_checked_against_their_type_and_bits() {
        assert_eq!(Value::Int(-128).encode(DataType::Int8, 8).unwrap(), vec![0x80]);
        assert_eq!(Value::UInt(65535).encode(DataType::UInt16, 16).unwrap(), vec![0xFF, 0xFF]);
        assert_eq!(Value::Int(i64::MIN).encode(DataType::Int64, 64).unwrap(), i64::MIN.to_le_bytes());
        assert_eq!(Value::UInt(u64::MAX).encode(DataType::UInt64, 64).unwrap(), u64::MAX.to_le_bytes());
        let e = Value::UInt(256).encode(DataType::UInt8, 8).unwrap_err();
        assert_eq!(e.to_string(), "256 does not fit UNSIGNED8");
        assert!(Value::Int(-1).encode(DataType::UInt32, 32).is_err());
        assert!(Value::Int(128).encode(DataType::Int8, 8).is_err());
        assert!(Value::UInt(1 << 63).encode(DataType::Int64, 64).is_err());
        assert!(Value::UInt(4).encode(DataType::Bits(2), 2).is_err());
        assert!(Value::UInt(2).encode(DataType::Bool, 1).is_err());
    }

    #[test]
    fn a_boolean_goes_only_to_one_bit() {
        assert_eq!(Value::Bool(true).encode(DataType::Bool, 1).unwrap(), vec![1]);
        assert_eq!(Value::Bool(true).encode(DataType::Bits(1), 1).unwrap(), vec![1]);
        // An unsigned entry mapped one bit wide is a bit.
        assert_eq!(Value::Bool(true).encode(DataType::UInt8, 1).unwrap(), vec![1]);
        let e = Value::Bool(true).encode(DataType::UInt32, 32).unwrap_err();
        assert_eq!(e.to_string(), "boolean true given for a UNSIGNED32 object; give it as a number");
        for t in [DataType::UInt16, DataType::Int8, DataType::Bits(2), DataType::Real32, DataType::Real64] {
            assert!(matches!(Value::Bool(false).encode(t, t.bits()), Err(ValueError::BoolForNumber { .. })), "{t:?}");
        }
        assert!(Value::Bool(true).encode(DataType::VisibleString(4), 32).is_err());
    }

    #[test]
    fn an_asked_type_stands_for_the_target_only_of_its_kind_and_size() {
        assert_eq!(as_type(DataType::UInt32, DataType::UInt32), Ok(DataType::UInt32));
        // BITn is named UNSIGNED8 by the API; its own width then checks.
        assert_eq!(as_type(DataType::UInt8, DataType::Bits(2)), Ok(DataType::Bits(2)));
        // A string's length is the value's; either string kind writes bytes.
        assert_eq!(as_type(DataType::OctetString(3), DataType::VisibleString(0)), Ok(DataType::OctetString(3)));
        for (asked, target) in [
            (DataType::UInt64, DataType::UInt16),
            (DataType::Int16, DataType::UInt16),
            (DataType::UInt32, DataType::Int32),
            (DataType::Real32, DataType::UInt32),
            (DataType::UInt32, DataType::Real32),
            (DataType::Bool, DataType::UInt8),
            (DataType::UInt8, DataType::Bool),
            (DataType::VisibleString(2), DataType::UInt16),
            (DataType::UInt16, DataType::VisibleString(0)),
        ] {
            assert!(matches!(as_type(asked, target), Err(ValueError::OtherType { .. })), "{asked:?} for {target:?}");
        }
        let e = as_type(DataType::UInt64, DataType::UInt16).unwrap_err();
        assert_eq!(e.to_string(), "UNSIGNED64 asked for a UNSIGNED16 object");
    }

    #[test]
    fn reals_text_and_bytes_go_only_where_they_fit() {
        assert_eq!(Value::Real(1.5).encode(DataType::Real32, 32).unwrap(), 1.5f32.to_le_bytes());
        assert_eq!(Value::Int(2).encode(DataType::Real64, 64).unwrap(), 2.0f64.to_le_bytes());
        let e = Value::Real(1.0).encode(DataType::UInt32, 32).unwrap_err();
        assert_eq!(e.to_string(), "1 is a real; UNSIGNED32 wants an integer");
        let e = Value::Text("ab".into()).encode(DataType::UInt16, 16).unwrap_err();
        assert_eq!(e.to_string(), "text \"ab\" given for a UNSIGNED16 object");
        let e = Value::Bytes(vec![1, 2, 3]).encode(DataType::UInt16, 16).unwrap_err();
        assert_eq!(e.to_string(), "3 raw bytes given for a UNSIGNED16 object, which has 2");
        assert_eq!(Value::Text("ab".into()).encode(DataType::VisibleString(4), 32).unwrap(), b"ab\0\0");
        assert!(Value::Bytes(vec![1, 2, 3]).encode(DataType::OctetString(2), 16).is_err());
        assert!(Value::Int(1).encode(DataType::UInt32, 72).is_err());
    }

    #[test]
    fn decoded_values_encode_back_to_their_bytes() {
        for (t, raw) in [
            (DataType::Int8, vec![0xFF]),
            (DataType::Int16, vec![0xD4, 0xFE]),
            (DataType::UInt32, vec![1, 2, 3, 4]),
            (DataType::Real32, 1.5f32.to_le_bytes().to_vec()),
            (DataType::Bool, vec![1]),
        ] {
            let v = Value::decode(t, &raw);
            assert_eq!(v.encode(t, t.bits()).unwrap(), raw, "{t:?}");
        }
        assert_eq!(Value::decode(DataType::VisibleString(4), b"ab\0\0"), Value::Text("ab".into()));
    }
}
