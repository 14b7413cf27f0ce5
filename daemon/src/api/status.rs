//! The one place engine errors become gRPC statuses. Every variant is
//! listed (no catch-all), so a new engine error cannot reach clients
//! unmapped.

use tonic::{Code, Status};

use crate::engine::error::EngineError;

/// The gRPC status for an engine error.
pub fn to_status(e: EngineError) -> Status {
    let message = e.to_string();
    match e {
        EngineError::BadArgument { field, .. } => {
            Status::with_details(Code::InvalidArgument, message, error_info("BAD_ARGUMENT", &[("field", field)]))
        }
        EngineError::WrongState(_) => Status::failed_precondition(message),
        EngineError::SdoAbort { slave, index, subindex, code } => {
            let meaning = code.meaning().unwrap_or("unknown abort code");
            let abort = format!("{:#010x}", code.0);
            let slave = slave.to_string();
            let object = format!("{index:#06x}:{subindex:02x}");
            let details = error_info(
                "SDO_ABORT",
                &[("abort_code", &abort), ("meaning", meaning), ("slave", &slave), ("object", &object)],
            );
            Status::with_details(Code::Aborted, message, details)
        }
        EngineError::Failed(_) => Status::internal(message),
        EngineError::Refused(_) => Status::failed_precondition(message),
        EngineError::Timeout => Status::deadline_exceeded(message),
        EngineError::QueueFull => Status::resource_exhausted(message),
        EngineError::Unavailable(_) => Status::unavailable(message),
        EngineError::BadDeviceData(_) => Status::failed_precondition(message),
    }
}

/// A `google.rpc.ErrorInfo` (domain "ecmxf") encoded for status details,
/// so clients in any language read the reason and fields without parsing
/// the message.
fn error_info(reason: &str, metadata: &[(&str, &str)]) -> bytes::Bytes {
    use prost::Message;
    #[derive(Clone, PartialEq, prost::Message)]
    struct ErrorInfo {
        #[prost(string, tag = "1")]
        reason: String,
        #[prost(string, tag = "2")]
        domain: String,
        #[prost(map = "string, string", tag = "3")]
        metadata: std::collections::HashMap<String, String>,
    }
    #[derive(Clone, PartialEq, prost::Message)]
    struct Any {
        #[prost(string, tag = "1")]
        type_url: String,
        #[prost(bytes = "vec", tag = "2")]
        value: Vec<u8>,
    }
    #[derive(Clone, PartialEq, prost::Message)]
    struct RpcStatus {
        #[prost(int32, tag = "1")]
        code: i32,
        #[prost(string, tag = "2")]
        message: String,
        #[prost(message, repeated, tag = "3")]
        details: Vec<Any>,
    }
    let info = ErrorInfo {
        reason: reason.into(),
        domain: "ecmxf".into(),
        metadata: metadata.iter().map(|(k, v)| ((*k).into(), (*v).into())).collect(),
    };
    let any = Any { type_url: "type.googleapis.com/google.rpc.ErrorInfo".into(), value: info.encode_to_vec() };
    // The details of a gRPC status are a serialized google.rpc.Status.
    RpcStatus { code: 0, message: String::new(), details: vec![any] }.encode_to_vec().into()
}

impl From<EngineError> for Status {
    fn from(e: EngineError) -> Self {
        to_status(e)
    }
}

/// INVALID_ARGUMENT naming `field`, for checks made in the API layer.
pub fn bad_argument(field: &'static str, reason: impl Into<String>) -> Status {
    to_status(EngineError::BadArgument { field, reason: reason.into() })
}

#[cfg(test)]
mod tests {
    use ecmxf_wire::payload::sdo::SdoAbortCode;

    use super::*;

    #[test]
    fn every_engine_error_maps_to_its_code() {
        let cases = [
            (EngineError::BadArgument { field: "index", reason: "x".into() }, Code::InvalidArgument),
            (EngineError::WrongState(crate::engine::error::WrongState::NoInputs), Code::FailedPrecondition),
            (
                EngineError::SdoAbort { slave: 1, index: 0x6060, subindex: 0, code: SdoAbortCode(0x0602_0000) },
                Code::Aborted,
            ),
            (EngineError::Failed("x".into()), Code::Internal),
            (EngineError::Refused("x".into()), Code::FailedPrecondition),
            (EngineError::Timeout, Code::DeadlineExceeded),
            (EngineError::QueueFull, Code::ResourceExhausted),
            (EngineError::Unavailable(crate::engine::error::NotRunning::Stopped), Code::Unavailable),
            (EngineError::BadDeviceData("x".into()), Code::FailedPrecondition),
        ];
        for (e, code) in cases {
            assert_eq!(to_status(e.clone()).code(), code, "{e}");
        }
    }

    #[test]
    fn sdo_abort_details_carry_code_and_meaning() {
        let s =
            to_status(EngineError::SdoAbort { slave: 2, index: 0x1234, subindex: 5, code: SdoAbortCode(0x0602_0000) });
        let d = String::from_utf8_lossy(s.details()).into_owned();
        assert!(d.contains("0x06020000") && d.contains("does not exist"), "{d}");
        assert!(s.message().contains("0x1234:05"), "{}", s.message());
    }
}
