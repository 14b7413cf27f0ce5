//! `reg read|write`: ESC registers of one slave by ring position (Registers
//! service, APRD/APWR; admin role), as `ethercat reg_read` / `reg_write`.

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::cli::RegCommand;
use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Out, Report};
use crate::values::{Hex, decode_le, parse_hex_bytes, parse_value, spaced_hex, type_name, value_json};

/// `ecmxfctl reg read|write --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct RegReport {
    pub slave: u32,
    pub address: u32,
    /// Bytes read (read) or written (write), as hex.
    pub data: Hex,
    /// Working counter of the datagram (1: the slave answered).
    pub working_counter: u32,
    /// With --type: the type and decoded value (read), else "" and null.
    pub data_type: String,
    pub value: serde_json::Value,
}

impl Report for RegReport {
    fn text(&self) -> String {
        let bytes = parse_hex_bytes(&self.data.0).unwrap_or_default();
        let mut s = format!("{:#06x}: {}", self.address, spaced_hex(&bytes));
        if !self.value.is_null() {
            s.push_str(&format!("  ({} {})", self.data_type, self.value));
        }
        if self.working_counter == 0 {
            s.push_str("  [working counter 0: no slave answered]");
        }
        s
    }
}

/// A register type's size in bytes.
fn size_of(t: pb::DataType) -> Option<u32> {
    ecmxf_proto::value::type_size(t).map(|n| n as u32)
}

/// Little-endian bytes of an integer `value` for type `t`.
fn encode(text: &str, t: pb::DataType) -> Result<Vec<u8>, CliError> {
    use pb::value::Kind;
    let n = size_of(t)
        .ok_or_else(|| CliError::Usage(format!("--type {}: registers take integer types", type_name(t as i32))))?;
    let bytes = match parse_value(text, t)?.kind {
        Some(Kind::Unsigned(u)) if n == 8 || u < 1 << (8 * n) => u.to_le_bytes(),
        Some(Kind::Integer(i)) if n == 8 || (i >= -(1 << (8 * n - 1)) && i < 1 << (8 * n - 1)) => i.to_le_bytes(),
        Some(Kind::Boolean(b)) => u64::from(b).to_le_bytes(),
        _ => return Err(CliError::Usage(format!("value {text:?} does not fit {}", type_name(t as i32)))),
    };
    Ok(bytes[..n as usize].to_vec())
}

fn decode(b: &[u8], t: pb::DataType) -> serde_json::Value {
    value_json(decode_le(t, b).as_ref())
}

/// Runs a `reg` subcommand.
pub async fn run(api: &Api, out: Out, cmd: &RegCommand) -> Result<(), CliError> {
    match cmd {
        RegCommand::Read { slave, address, length, data_type } => {
            let slave = slave.position;
            let length = length.or(data_type.and_then(size_of)).unwrap_or(1);
            let req = pb::ReadRegistersRequest { slave, address: *address, length };
            let r = api.registers().read_registers(api.req(req)).await;
            let r = r.map_err(CliError::rpc(format!("read register {address:#06x} of slave {slave}")))?.into_inner();
            out.report(&RegReport {
                slave,
                address: *address,
                value: data_type.map_or(serde_json::Value::Null, |t| decode(&r.data, t)),
                data_type: data_type.map_or("", |t| type_name(t as i32)).into(),
                data: Hex::of(&r.data),
                working_counter: r.working_counter,
            })?;
        }
        RegCommand::Write { slave, address, value, data_type } => {
            let slave = slave.position;
            let data = match data_type {
                Some(t) => encode(value, *t)?,
                None => {
                    parse_hex_bytes(value).map_err(|e| CliError::Usage(format!("{e} (or give --type for a number)")))?
                }
            };
            if data.is_empty() {
                return Err(CliError::Usage("reg write: no bytes given".into()));
            }
            let req = pb::WriteRegistersRequest { slave, address: *address, data: data.clone() };
            let r = api.registers().write_registers(api.req(req)).await;
            let r = r.map_err(CliError::rpc(format!("write register {address:#06x} of slave {slave}")))?.into_inner();
            out.report(&RegReport {
                slave,
                address: *address,
                data: Hex::of(&data),
                working_counter: r.working_counter,
                data_type: data_type.map_or("", |t| type_name(t as i32)).into(),
                value: serde_json::Value::Null,
            })?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn register_values_encode_little_endian_and_refuse_overflow() {
        assert_eq!(encode("0x0102", pb::DataType::Unsigned16).unwrap(), vec![2, 1]);
        assert_eq!(encode("-1", pb::DataType::Integer8).unwrap(), vec![0xff]);
        assert!(encode("256", pb::DataType::Unsigned8).unwrap_err().to_string().contains("does not fit"));
        assert!(encode("1", pb::DataType::VisibleString).is_err());
        assert_eq!(decode(&[0xfe, 0xff], pb::DataType::Integer16), serde_json::json!(-2));
        assert_eq!(decode(&[8, 0], pb::DataType::Unsigned16), serde_json::json!(8));
        assert_eq!(decode(&[8], pb::DataType::Unsigned16), serde_json::Value::Null);
    }
}
