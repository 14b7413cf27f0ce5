//! Words and numbers as a user types and reads them: state names, data type
//! names, typed values, hex. One place, so every command spells them alike
//! (and the JSON schema can promise them).

use ecmxf_proto::v1 as pb;
use pb::value::Kind;
use serde::Serialize;

use crate::error::CliError;

/// EtherCAT state names, as the IgH `ethercat` tool prints them.
pub fn state_name(v: i32) -> &'static str {
    match pb::EcatState::try_from(v) {
        Ok(pb::EcatState::Init) => "INIT",
        Ok(pb::EcatState::PreOp) => "PREOP",
        Ok(pb::EcatState::Boot) => "BOOT",
        Ok(pb::EcatState::SafeOp) => "SAFEOP",
        Ok(pb::EcatState::Op) => "OP",
        Ok(pb::EcatState::Error) => "ERROR",
        _ => "UNKNOWN",
    }
}

/// A state a user asks for: `init`, `preop`/`pre-op`, `boot`,
/// `safeop`/`safe-op`, `op` (any case; IgH spellings accepted).
pub fn parse_state(s: &str) -> Option<pb::EcatState> {
    Some(match s.to_ascii_lowercase().replace(['-', '_'], "").as_str() {
        "init" | "1" => pb::EcatState::Init,
        "preop" | "2" => pb::EcatState::PreOp,
        "boot" | "3" => pb::EcatState::Boot,
        "safeop" | "4" => pb::EcatState::SafeOp,
        "op" | "8" => pb::EcatState::Op,
        _ => return None,
    })
}

/// A proto enum value's name without its type prefix
/// (`ENGINE_PHASE_RUNNING` -> `RUNNING`); `UNKNOWN` for UNSPECIFIED and for
/// numbers a newer daemon may send. The JSON schema promises these names, so
/// they come from the .proto, not from a second table here.
pub fn enum_name<E: TryFrom<i32>>(v: i32, name: fn(&E) -> &'static str, prefix: &str) -> &'static str {
    match E::try_from(v).map(|e| name(&e).strip_prefix(prefix)) {
        Ok(Some(n)) if n != "UNSPECIFIED" => n,
        _ => "UNKNOWN",
    }
}

/// Engine phase names.
pub fn phase_name(v: i32) -> &'static str {
    enum_name(v, pb::EnginePhase::as_str_name, "ENGINE_PHASE_")
}

/// CiA 402 drive state names.
pub fn drive_state_name(v: i32) -> &'static str {
    enum_name(v, pb::DriveState::as_str_name, "DRIVE_STATE_")
}

/// The data type names ecmxfctl accepts and prints (the IgH tool's).
pub const TYPE_NAMES: &[(&str, pb::DataType)] = &[
    ("bool", pb::DataType::Boolean),
    ("int8", pb::DataType::Integer8),
    ("int16", pb::DataType::Integer16),
    ("int32", pb::DataType::Integer32),
    ("int64", pb::DataType::Integer64),
    ("uint8", pb::DataType::Unsigned8),
    ("uint16", pb::DataType::Unsigned16),
    ("uint32", pb::DataType::Unsigned32),
    ("uint64", pb::DataType::Unsigned64),
    ("float", pb::DataType::Real32),
    ("double", pb::DataType::Real64),
    ("string", pb::DataType::VisibleString),
    ("octet_string", pb::DataType::OctetString),
];

/// A data type by its ecmxfctl name.
pub fn parse_type(s: &str) -> Result<pb::DataType, String> {
    TYPE_NAMES.iter().find(|(n, _)| *n == s).map(|(_, t)| *t).ok_or_else(|| {
        let names: Vec<&str> = TYPE_NAMES.iter().map(|(n, _)| *n).collect();
        format!("unknown type {s:?}; one of {}", names.join(", "))
    })
}

/// A data type's ecmxfctl name ("" when unknown).
pub fn type_name(v: i32) -> &'static str {
    TYPE_NAMES.iter().find(|(_, t)| *t as i32 == v).map_or("", |(n, _)| n)
}

/// An unsigned number in decimal or `0x` hex (underscores allowed).
pub fn parse_u64(s: &str) -> Option<u64> {
    let t = s.trim().replace('_', "");
    match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => u64::from_str_radix(h, 16).ok(),
        None => t.parse().ok(),
    }
}

/// A number for clap: decimal or `0x` hex, at most `max`.
pub fn parse_u32_max(s: &str, max: u64, what: &str) -> Result<u32, String> {
    match parse_u64(s) {
        Some(v) if v <= max => Ok(v as u32),
        Some(v) => Err(format!("{what} {v:#x} is larger than {max:#x}")),
        None => Err(format!("{what} {s:?} is not a number (decimal or 0x hex)")),
    }
}

/// clap parser for object indexes.
pub fn parse_index(s: &str) -> Result<u32, String> {
    parse_u32_max(s, 0xFFFF, "index")
}

/// clap parser for subindexes.
pub fn parse_subindex(s: &str) -> Result<u32, String> {
    parse_u32_max(s, 0xFF, "subindex")
}

/// clap parser for 32-bit numbers.
pub fn parse_u32(s: &str) -> Result<u32, String> {
    parse_u32_max(s, u64::from(u32::MAX), "value")
}

/// clap parser for 16-bit register addresses.
pub fn parse_address(s: &str) -> Result<u32, String> {
    parse_u32_max(s, 0xFFFF, "address")
}

/// Bytes from hex text: "0102ab", "01 02 ab", "01:02:ab" or "0x0102ab".
pub fn parse_hex_bytes(s: &str) -> Result<Vec<u8>, String> {
    let t: String = s.trim().trim_start_matches("0x").chars().filter(|c| !matches!(c, ' ' | ':' | '_' | '-')).collect();
    if t.len() % 2 != 0 {
        return Err(format!("hex bytes {s:?} have an odd number of digits"));
    }
    (0..t.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&t[i..i + 2], 16).map_err(|_| format!("{s:?} is not hex bytes")))
        .collect()
}

/// Bytes as lowercase hex, no separators.
pub fn hex(b: &[u8]) -> String {
    use std::fmt::Write;
    b.iter().fold(String::with_capacity(2 * b.len()), |mut s, x| {
        let _ = write!(s, "{x:02x}");
        s
    })
}

/// Bytes as spaced hex ("01 02 ab"), for tables.
pub fn spaced_hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect::<Vec<_>>().join(" ")
}

/// What a user typed, as the typed value to send for `t` (UNSPECIFIED:
/// the daemon's known type decides; the text's shape picks the kind).
pub fn parse_value(text: &str, t: pb::DataType) -> Result<pb::Value, CliError> {
    use pb::DataType as T;
    let bad = |why: String| CliError::Usage(format!("value {text:?}: {why}"));
    let kind = match t {
        T::VisibleString => Kind::Text(text.to_owned()),
        T::OctetString => Kind::Raw(parse_hex_bytes(text).map_err(bad)?),
        T::Boolean => match text.to_ascii_lowercase().as_str() {
            "1" | "true" | "on" => Kind::Boolean(true),
            "0" | "false" | "off" => Kind::Boolean(false),
            _ => return Err(bad("a bool is 0/1, true/false or on/off".into())),
        },
        T::Real32 | T::Real64 => Kind::Real(text.trim().parse().map_err(|_| bad("not a number".into()))?),
        _ => {
            let t = text.trim();
            if let Some(neg) = t.strip_prefix('-') {
                let m = parse_u64(neg).ok_or_else(|| bad("not a number (decimal or 0x hex)".into()))?;
                let v = i64::try_from(m).ok().map(|m| -m).or((m == 1 << 63).then_some(i64::MIN));
                Kind::Integer(v.ok_or_else(|| bad("too small for 64 bits".into()))?)
            } else if let Some(u) = parse_u64(t) {
                Kind::Unsigned(u)
            } else if let Some(f) = t.parse::<f64>().ok().filter(|f| f.is_finite()) {
                Kind::Real(f)
            } else {
                return Err(bad("not a number (decimal or 0x hex); give --type for strings and bytes".into()));
            }
        }
    };
    Ok(pb::Value { kind: Some(kind) })
}

/// Decodes little-endian bytes as `t` with the daemon's own codec
/// ([`ecmxf_proto::value::decode_value`]), for types only a slave's ESI
/// knows and for registers. Short data and untyped bytes (octet strings)
/// are `None`: the caller shows the raw bytes.
pub fn decode_le(t: pb::DataType, raw: &[u8]) -> Option<pb::Value> {
    ecmxf_proto::value::decode_value(t, raw).ok().flatten().filter(|v| !matches!(v.kind, Some(Kind::Raw(_))))
}

/// A typed value as it appears in JSON output: the number, bool or text
/// itself; raw bytes as a hex string.
pub fn value_json(v: Option<&pb::Value>) -> serde_json::Value {
    match v.and_then(|v| v.kind.as_ref()) {
        Some(Kind::Boolean(b)) => (*b).into(),
        Some(Kind::Integer(i)) => (*i).into(),
        Some(Kind::Unsigned(u)) => (*u).into(),
        Some(Kind::Real(f)) => serde_json::Number::from_f64(*f).map_or(serde_json::Value::Null, Into::into),
        Some(Kind::Text(s)) => s.clone().into(),
        Some(Kind::Raw(b)) => hex(b).into(),
        None => serde_json::Value::Null,
    }
}

/// A typed value as a table shows it: decimal, with hex for unsigned
/// numbers (`6 (0x0006)` sized by `bytes`).
pub fn value_text(v: Option<&pb::Value>, bytes: usize) -> String {
    match v.and_then(|v| v.kind.as_ref()) {
        Some(Kind::Boolean(b)) => u8::from(*b).to_string(),
        Some(Kind::Integer(i)) => i.to_string(),
        Some(Kind::Unsigned(u)) => format!("{u} (0x{u:0w$x})", w = 2 * bytes.clamp(1, 8)),
        Some(Kind::Real(f)) => f.to_string(),
        Some(Kind::Text(s)) => format!("{s:?}"),
        Some(Kind::Raw(b)) => spaced_hex(b),
        None => "-".into(),
    }
}

/// Serde helper: a hex string field documented as such in the schema.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema, PartialEq, Eq)]
#[serde(transparent)]
pub struct Hex(
    /// Lowercase hex digits, two per byte, no separators.
    #[schemars(regex(pattern = r"^([0-9a-f]{2})*$"))]
    pub String,
);

impl Hex {
    /// Bytes as hex.
    pub fn of(b: &[u8]) -> Self {
        Self(hex(b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_parse_in_decimal_and_hex() {
        assert_eq!(parse_u64("0x6041"), Some(0x6041));
        assert_eq!(parse_u64("24641"), Some(24641));
        assert_eq!(parse_u64("1_000"), Some(1000));
        assert_eq!(parse_u64("0xg"), None);
        assert!(parse_index("0x10000").unwrap_err().contains("larger"));
        assert!(parse_subindex("x").unwrap_err().contains("not a number"));
    }

    #[test]
    fn values_take_the_kind_the_text_and_type_say() {
        let k = |s: &str, t| parse_value(s, t).unwrap().kind.unwrap();
        assert_eq!(k("0x06", pb::DataType::Unspecified), Kind::Unsigned(6));
        assert_eq!(k("-5", pb::DataType::Integer16), Kind::Integer(-5));
        assert_eq!(k("-0x8000000000000000", pb::DataType::Integer64), Kind::Integer(i64::MIN));
        assert_eq!(k("1.5", pb::DataType::Unspecified), Kind::Real(1.5));
        assert_eq!(k("2", pb::DataType::Real32), Kind::Real(2.0));
        assert_eq!(k("on", pb::DataType::Boolean), Kind::Boolean(true));
        assert_eq!(k("ab 01", pb::DataType::OctetString), Kind::Raw(vec![0xab, 1]));
        assert_eq!(k("hi", pb::DataType::VisibleString), Kind::Text("hi".into()));
        let e = parse_value("hello", pb::DataType::Unspecified).unwrap_err().to_string();
        assert!(e.contains("\"hello\"") && e.contains("--type"), "{e}");
        assert!(parse_value("maybe", pb::DataType::Boolean).is_err());
        assert!(parse_value("abc", pb::DataType::OctetString).unwrap_err().to_string().contains("odd"));
    }

    #[test]
    fn type_and_state_names_round_trip() {
        for (n, t) in TYPE_NAMES {
            assert_eq!(parse_type(n).unwrap(), *t);
            assert_eq!(type_name(*t as i32), *n);
        }
        assert!(parse_type("u16").unwrap_err().contains("uint16"));
        for s in ["init", "PREOP", "pre-op", "boot", "safe_op", "op"] {
            let st = parse_state(s).unwrap();
            assert_eq!(parse_state(state_name(st as i32)), Some(st));
        }
        assert_eq!(parse_state("run"), None);
    }

    #[test]
    fn enum_names_drop_the_prefix_and_hide_unspecified() {
        assert_eq!(phase_name(pb::EnginePhase::BringingUp as i32), "BRINGING_UP");
        assert_eq!(drive_state_name(pb::DriveState::OperationEnabled as i32), "OPERATION_ENABLED");
        assert_eq!(phase_name(0), "UNKNOWN");
        assert_eq!(drive_state_name(99), "UNKNOWN");
    }

    #[test]
    fn values_print_for_tables_and_json() {
        let v = |k| Some(pb::Value { kind: Some(k) });
        assert_eq!(value_text(v(Kind::Unsigned(6)).as_ref(), 2), "6 (0x0006)");
        assert_eq!(value_text(v(Kind::Raw(vec![1, 0xab])).as_ref(), 2), "01 ab");
        assert_eq!(value_json(v(Kind::Integer(-3)).as_ref()), serde_json::json!(-3));
        assert_eq!(value_json(v(Kind::Raw(vec![1, 0xab])).as_ref()), serde_json::json!("01ab"));
        assert_eq!(value_json(None), serde_json::Value::Null);
        assert_eq!(parse_hex_bytes("01:02:ab").unwrap(), vec![1, 2, 0xab]);
    }

    #[test]
    fn local_decoding_matches_cia301_little_endian() {
        let k = |t, b: &[u8]| decode_le(t, b).and_then(|v| v.kind);
        assert_eq!(k(pb::DataType::Integer16, &[0xfe, 0xff]), Some(Kind::Integer(-2)));
        assert_eq!(k(pb::DataType::Unsigned32, &[1, 2, 3, 4]), Some(Kind::Unsigned(0x0403_0201)));
        assert_eq!(k(pb::DataType::Integer8, &[0x80]), Some(Kind::Integer(-128)));
        assert_eq!(k(pb::DataType::Real32, &1.5f32.to_le_bytes()), Some(Kind::Real(1.5)));
        assert_eq!(k(pb::DataType::VisibleString, b"ab\0"), Some(Kind::Text("ab".into())));
        assert_eq!(k(pb::DataType::Unsigned32, &[1]), None, "short data is not guessed");
    }
}
