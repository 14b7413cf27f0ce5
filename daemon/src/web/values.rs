//! Process-data and SDO values as the dashboard's JSON carries them:
//! numbers as numbers, booleans as booleans, text as text, bytes as hex.

use serde_json::{Value, json};

use crate::master::image::{Entry, read_bits};
use crate::master::value::Value as Typed;

/// A decoded value as JSON: numbers as numbers, text as text, bytes as hex.
pub(super) fn value_json(v: Typed) -> Value {
    match v {
        Typed::Bool(b) => json!(b),
        Typed::Int(i) => json!(i),
        Typed::UInt(u) => json!(u),
        Typed::Real(f) => json!(f),
        Typed::Text(s) => json!(s),
        Typed::Bytes(b) => json!(hex::encode(b)),
    }
}

/// A JSON value as the master's value (its range is checked when it is
/// encoded for the target).
pub(super) fn typed(v: &Value) -> Result<Typed, String> {
    Ok(match v {
        Value::Bool(b) => Typed::Bool(*b),
        Value::Number(n) => match (n.as_u64(), n.as_i64(), n.as_f64()) {
            (Some(u), _, _) => Typed::UInt(u),
            (_, Some(i), _) => Typed::Int(i),
            (_, _, Some(f)) => Typed::Real(f),
            _ => return Err(format!("{n} is no number the daemon holds")),
        },
        Value::String(s) => Typed::Text(s.clone()),
        other => return Err(format!("{other} is not a number, a boolean or text")),
    })
}

/// An entry's value: an input from `inputs` (the newest frame; none yet:
/// null), an output from `outputs` (as front ends last wrote it; bytes no
/// one wrote go out as zeros).
pub(super) fn entry_value(e: &Entry, inputs: Option<&[u8]>, outputs: &[u8]) -> Value {
    let fits = |d: &[u8]| (e.bit_offset + e.bit_length).div_ceil(8) as usize <= d.len();
    let raw = match (e.output, inputs) {
        (true, _) if fits(outputs) => read_bits(outputs, e.bit_offset, e.bit_length),
        (true, _) => vec![0; e.bit_length.div_ceil(8) as usize],
        (false, Some(d)) if fits(d) => read_bits(d, e.bit_offset, e.bit_length),
        (false, _) => return Value::Null,
    };
    value_json(Typed::decode(e.data_type, &raw))
}
