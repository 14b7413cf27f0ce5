//! Each slave's and each axis' methods (docs/opcua.md, "Methods"): what
//! an engineer does to one device from an OPC UA client, with the gRPC
//! API's roles and checks.
//!
//! - `SdoUpload(Index, SubIndex) -> (Value, Raw)`: the object read now,
//!   typed as the device or CiA 301 says (observer).
//! - `SdoDownload(Index, SubIndex, Value)`: a value of the object's type,
//!   refused before anything is sent when it is not one (operator).
//! - `RequestState(State)`: INIT, PREOP, SAFEOP, OP or BOOT, walked as
//!   the state machine allows (operator).
//! - An axis' `Enable`, `Disable`, `FaultReset` (through the chip's CiA 402
//!   helper, waiting for the drive to arrive) and `SetMode(Mode)` (0x6060
//!   under the session's output lease on the axis' slave, waiting for
//!   0x6061 to show it), each answering the drive's state (operator).
//!
//! Each call is queued on the master's door for the session (its own turn
//! on the chip's blocking slot) and bounded by [`CALL_WITHIN`].

use std::time::Duration;

use opcua::types::{ByteString, DataTypeId, StatusCode, Variant};

use opcua::server::node_manager::RequestContext;

use super::refusal::Refusal;
use super::values::{encode, kind, variant};
use super::writes::SessionLeases;
use crate::config::Role;
use crate::master::LeaseError;
use crate::master::axes::{AxisCommand, AxisError};
use crate::master::entry_writes::WriteError;
use crate::master::states::SlaveSelector;
use crate::master::value::{DataType, Value};
use crate::master::{Call, EcatState, EngineError, Master};

/// How long a call may take: a state walk to OP waits for the slaves.
const CALL_WITHIN: Duration = Duration::from_secs(10);

/// What a method acts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Target {
    /// The slave at this ring position.
    Slave(u8),
    /// This `[[axis]]`.
    Axis(u32),
}

/// A method of a slave or an axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Method {
    pub(super) target: Target,
    pub(super) kind: Kind,
}

/// What a method does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    SdoUpload,
    SdoDownload,
    RequestState,
    Enable,
    Disable,
    FaultReset,
    SetMode,
}

/// An argument: (name, type, description).
pub(super) type Argument = (&'static str, DataTypeId, &'static str);

impl Kind {
    /// A slave's methods.
    pub(super) const SLAVE: [Kind; 3] = [Kind::SdoUpload, Kind::SdoDownload, Kind::RequestState];
    /// An axis' methods.
    pub(super) const AXIS: [Kind; 4] = [Kind::Enable, Kind::Disable, Kind::FaultReset, Kind::SetMode];

    /// Every method, slave's and axis'.
    pub(super) fn all() -> impl Iterator<Item = Kind> {
        Self::SLAVE.into_iter().chain(Self::AXIS)
    }

    /// Its browse name.
    pub(super) fn name(self) -> &'static str {
        match self {
            Self::SdoUpload => "SdoUpload",
            Self::SdoDownload => "SdoDownload",
            Self::RequestState => "RequestState",
            Self::Enable => "Enable",
            Self::Disable => "Disable",
            Self::FaultReset => "FaultReset",
            Self::SetMode => "SetMode",
        }
    }

    /// What it does, for the node's description.
    pub(super) fn description(self) -> &'static str {
        match self {
            Self::SdoUpload => "Reads an object of the slave's dictionary now (CoE SDO upload)",
            Self::SdoDownload => "Writes an object of the slave's dictionary (CoE SDO download); operator",
            Self::RequestState => "Requests an EtherCAT state: INIT, PREOP, SAFEOP, OP or BOOT; operator",
            Self::Enable => "Walks the drive to OPERATION ENABLED (through a fault reset from FAULT); operator",
            Self::Disable => "Walks the drive to SWITCH ON DISABLED; operator",
            Self::FaultReset => "Resets the drive's fault, then SWITCH ON DISABLED; operator",
            Self::SetMode => "Sets the mode of operation (0x6060) and waits for the drive to show it; operator",
        }
    }

    /// The role it needs.
    pub(super) fn needs(self) -> Role {
        match self {
            Self::SdoUpload => Role::Observer,
            _ => Role::Operator,
        }
    }

    pub(super) fn inputs(self) -> &'static [Argument] {
        const INDEX: Argument = ("Index", DataTypeId::UInt16, "Object index, e.g. 0x6060");
        const SUBINDEX: Argument = ("SubIndex", DataTypeId::Byte, "Subindex");
        match self {
            Self::SdoUpload => &[INDEX, SUBINDEX],
            Self::SdoDownload => {
                &[INDEX, SUBINDEX, ("Value", DataTypeId::BaseDataType, "A value of the object's type")]
            }
            Self::RequestState => &[("State", DataTypeId::String, "INIT, PREOP, SAFEOP, OP or BOOT")],
            Self::SetMode => &[("Mode", DataTypeId::SByte, "Mode of operation: 8 CSP, 9 CSV, 10 CST, ...")],
            Self::Enable | Self::Disable | Self::FaultReset => &[],
        }
    }

    pub(super) fn outputs(self) -> &'static [Argument] {
        match self {
            Self::SdoUpload => &[
                ("Value", DataTypeId::BaseDataType, "The value, typed as the object"),
                ("Raw", DataTypeId::ByteString, "The object's bytes, little-endian"),
            ],
            Self::SdoDownload | Self::RequestState => &[],
            Self::Enable | Self::Disable | Self::FaultReset | Self::SetMode => {
                &[("State", DataTypeId::String, "The drive's CiA 402 state after the command")]
            }
        }
    }
}

/// Session clients' numbers on the blocking slot: the session id in the
/// high half, odd (see `engine::slot::client`), apart from API clients'.
pub(super) fn client(session_id: u32) -> u64 {
    (u64::from(session_id) << 32) | 0x0C0A_0001
}

/// Runs `method` with `args` for the session of `ctx`, whose user has
/// `role`.
pub(super) async fn run(
    master: &Master,
    leases: &SessionLeases,
    ctx: &RequestContext,
    method: Method,
    role: Option<Role>,
    args: &[Variant],
) -> Result<Vec<Variant>, Refusal> {
    let needs = method.kind.needs();
    if role < Some(needs) {
        return Err(Refusal::denied(format!(
            "{} needs the {needs} role; this session's user is {}",
            method.kind.name(),
            role.map_or("refused".to_string(), |r| r.to_string())
        )));
    }
    let call = Call::new(client(ctx.session_id), None).or_within(CALL_WITHIN);
    match method.target {
        Target::Slave(s) => slave_method(master, s, method.kind, call, args).await,
        Target::Axis(n) => {
            let axis = master.axis(n).map_err(axis_refusal)?;
            let command = match method.kind {
                Kind::Enable => AxisCommand::Enable,
                Kind::Disable => AxisCommand::Disable,
                Kind::FaultReset => AxisCommand::FaultReset,
                Kind::SetMode => {
                    let Some(Variant::SByte(mode)) = args.first() else {
                        return Err(Refusal::argument(0, format!("Mode: an SByte, not {}", kind(args.first()))));
                    };
                    let (lease, who) = leases.session_lease(ctx, axis.config.slave)?;
                    tracing::info!(axis = n, mode, who, "mode of operation set over OPC UA");
                    let s = master.set_axis_mode(&axis, *mode, &lease, &who, call).await.map_err(axis_refusal)?;
                    return Ok(vec![Variant::from(s.state.to_string())]);
                }
                _ => return Err(Refusal::new(StatusCode::BadMethodInvalid, "no such method of an axis")),
            };
            tracing::info!(axis = n, ?command, "axis command over OPC UA");
            let s = master.axis_command(&axis, command, true, call).await.map_err(axis_refusal)?;
            Ok(vec![Variant::from(s.state.to_string())])
        }
    }
}

async fn slave_method(
    master: &Master,
    s: u8,
    kind: Kind,
    call: Call,
    args: &[Variant],
) -> Result<Vec<Variant>, Refusal> {
    match kind {
        Kind::SdoUpload => {
            let (index, sub) = (index(args)?, subindex(args)?);
            let raw = master.sdo_read(s, index, sub, false, call).await.map_err(engine)?;
            let t = master.object_type(s, index, sub).await;
            let value = match t {
                Some(t) => variant(t, Value::decode(t, &raw)),
                None => Variant::from(ByteString::from(raw.clone())),
            };
            Ok(vec![value, Variant::from(ByteString::from(raw))])
        }
        Kind::SdoDownload => {
            let (index, sub) = (index(args)?, subindex(args)?);
            let given = args.get(2).ok_or_else(|| Refusal::argument(2, "Value: none given"))?;
            // Where the object's type is known the value must be one of
            // it: nothing else is sent. Unknown, a ByteString is sent as
            // it is, and a number as wide as the variant.
            let bytes = match master.object_type(s, index, sub).await {
                Some(t) => encode(t, t.bits().max(8), given).map_err(|why| {
                    let t = crate::master::value::type_name(t);
                    Refusal::argument(2, format!("Value: object {index:#06x}:{sub:02x} of slave {s} is {t}: {why}"))
                })?,
                None => untyped(given).map_err(|why| Refusal::argument(2, format!("Value: {why}")))?,
            };
            tracing::info!(slave = s, object = format_args!("{index:#06x}:{sub:02x}"), "SDO download over OPC UA");
            master.sdo_write(s, index, sub, false, bytes, call).await.map_err(engine)?;
            Ok(Vec::new())
        }
        Kind::RequestState => {
            let state = state(args)?;
            tracing::info!(slave = s, %state, "state requested over OPC UA");
            master.set_state(SlaveSelector::One(s), state, call).await.map_err(engine)?;
            Ok(Vec::new())
        }
        _ => Err(Refusal::new(StatusCode::BadMethodInvalid, "no such method of a slave")),
    }
}

/// An axis operation's error as a method's result.
fn axis_refusal(e: AxisError) -> Refusal {
    let status = match &e {
        AxisError::NotConfigured { .. } => StatusCode::BadNodeIdUnknown,
        AxisError::Engine(inner) => return engine(inner.clone()),
        AxisError::Write(WriteError::Lease(LeaseError::Held { .. })) => StatusCode::BadUserAccessDenied,
        AxisError::Value { .. } => StatusCode::BadInvalidArgument,
        _ => StatusCode::BadInvalidState,
    };
    Refusal::new(status, e.to_string())
}

fn index(args: &[Variant]) -> Result<u16, Refusal> {
    match args.first() {
        Some(Variant::UInt16(i)) => Ok(*i),
        other => Err(Refusal::argument(0, format!("Index: a UInt16, not {}", kind(other)))),
    }
}

fn subindex(args: &[Variant]) -> Result<u8, Refusal> {
    match args.get(1) {
        Some(Variant::Byte(s)) => Ok(*s),
        other => Err(Refusal::argument(1, format!("SubIndex: a Byte, not {}", kind(other)))),
    }
}

fn state(args: &[Variant]) -> Result<EcatState, Refusal> {
    let Some(Variant::String(s)) = args.first() else {
        return Err(Refusal::argument(0, "State: a String (INIT, PREOP, SAFEOP, OP or BOOT)"));
    };
    let name = s.as_ref().to_ascii_uppercase().replace(['-', '_'], "");
    Ok(match name.as_str() {
        "INIT" => EcatState::Init,
        "PREOP" => EcatState::PreOp,
        "SAFEOP" => EcatState::SafeOp,
        "OP" => EcatState::Op,
        "BOOT" => EcatState::Boot,
        _ => return Err(Refusal::argument(0, format!("State: {s} is none of INIT, PREOP, SAFEOP, OP, BOOT"))),
    })
}

/// A value for an object of unknown type: its bytes as the variant's own
/// type holds them.
fn untyped(v: &Variant) -> Result<Vec<u8>, String> {
    let t = match v {
        Variant::Boolean(_) => DataType::Bool,
        Variant::SByte(_) => DataType::Int8,
        Variant::Int16(_) => DataType::Int16,
        Variant::Int32(_) => DataType::Int32,
        Variant::Int64(_) => DataType::Int64,
        Variant::Byte(_) => DataType::UInt8,
        Variant::UInt16(_) => DataType::UInt16,
        Variant::UInt32(_) => DataType::UInt32,
        Variant::UInt64(_) => DataType::UInt64,
        Variant::Float(_) => DataType::Real32,
        Variant::Double(_) => DataType::Real64,
        Variant::ByteString(b) => return Ok(b.value.clone().unwrap_or_default()),
        other => {
            return Err(format!(
                "the object's type is unknown; give a number or a ByteString, not {}",
                kind(Some(other))
            ));
        }
    };
    encode(t, t.bits().max(1), v)
}

/// An engine error as a method's result.
fn engine(e: EngineError) -> Refusal {
    let status = match &e {
        EngineError::Timeout => StatusCode::BadTimeout,
        EngineError::QueueFull => StatusCode::BadTooManyOperations,
        EngineError::BadArgument { .. } => StatusCode::BadInvalidArgument,
        // The device refused (the abort code and its text are in the
        // diagnostics).
        EngineError::SdoAbort { .. } => StatusCode::BadRequestNotAllowed,
        _ => StatusCode::BadInvalidState,
    };
    Refusal::new(status, e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_are_read_as_engineers_write_them() {
        for (given, want) in [("op", EcatState::Op), ("Pre-Op", EcatState::PreOp), ("SAFE_OP", EcatState::SafeOp)] {
            assert_eq!(state(&[Variant::from(given)]).unwrap(), want);
        }
        let e = state(&[Variant::from("RUN")]).unwrap_err();
        assert_eq!(e.status, StatusCode::BadInvalidArgument);
        assert!(e.why.contains("RUN"), "{}", e.why);
    }

    #[test]
    fn an_untyped_value_is_as_wide_as_its_variant() {
        assert_eq!(untyped(&Variant::from(0x1234u16)).unwrap(), vec![0x34, 0x12]);
        assert_eq!(untyped(&Variant::from(-1i32)).unwrap(), vec![0xFF; 4]);
        assert!(untyped(&Variant::from("x")).is_err());
    }

    #[test]
    fn session_clients_are_odd_and_apart() {
        assert_eq!(client(1) % 2, 1);
        assert_ne!(client(1), client(2));
    }
}
