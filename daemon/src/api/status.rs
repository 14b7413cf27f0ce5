//! The one place engine errors become gRPC statuses. Every variant is
//! listed (no catch-all), so a new engine error cannot reach clients
//! unmapped.

use std::collections::HashMap;

use tonic::{Code, Status};
use tonic_types::{ErrorDetails, StatusExt};

use crate::master::EngineError;

/// The `google.rpc.ErrorInfo` domain of every error the daemon answers.
pub(crate) const DOMAIN: &str = "ecmxf";

/// The gRPC status for an engine error: its details are a full
/// `google.rpc.Status` (the same code and message, which grpc-go and
/// grpcurl take from there) with an `ErrorInfo` whose reason names the
/// kind of error and whose metadata carries its facts (the SDO abort code,
/// the argument at fault), so clients in any language read them without
/// parsing the message.
pub(crate) fn to_status(e: EngineError) -> Status {
    let message = e.to_string();
    let info = |reason: &str, metadata: &[(&str, &str)]| {
        let metadata: HashMap<String, String> =
            metadata.iter().map(|(k, v)| ((*k).to_owned(), (*v).to_owned())).collect();
        ErrorDetails::with_error_info(reason, DOMAIN, metadata)
    };
    let (code, details) = match &e {
        EngineError::BadArgument { field, reason } => {
            let mut d = info("BAD_ARGUMENT", &[("field", field)]);
            d.add_bad_request_violation(*field, reason.as_str());
            (Code::InvalidArgument, d)
        }
        EngineError::WrongState(_) => (Code::FailedPrecondition, info("WRONG_STATE", &[])),
        EngineError::SdoAbort { slave, index, subindex, code } => {
            let meaning = code.meaning().unwrap_or("unknown abort code");
            let abort = format!("{:#010x}", code.0);
            let slave = slave.to_string();
            let object = format!("{index:#06x}:{subindex:02x}");
            let metadata =
                [("abort_code", abort.as_str()), ("meaning", meaning), ("slave", &slave), ("object", &object)];
            (Code::Aborted, info("SDO_ABORT", &metadata))
        }
        // Said as the chip failing, as before these had types of their own.
        EngineError::Failed(_) | EngineError::BadAnswer { .. } | EngineError::NotUp { .. } => {
            (Code::Internal, info("CHIP_FAILED", &[]))
        }
        EngineError::Refused(_) => (Code::FailedPrecondition, info("REFUSED", &[])),
        EngineError::FoeRefused { slave, name, .. } => {
            (Code::FailedPrecondition, info("FOE_REFUSED", &[("slave", &slave.to_string()), ("file", name)]))
        }
        EngineError::Timeout => (Code::DeadlineExceeded, info("TIMEOUT", &[])),
        EngineError::QueueFull => (Code::ResourceExhausted, info("QUEUE_FULL", &[])),
        EngineError::Unavailable(_) => (Code::Unavailable, info("NOT_RUNNING", &[])),
        EngineError::BadDeviceData { slave, .. } => {
            (Code::FailedPrecondition, info("BAD_DEVICE_DATA", &[("slave", &slave.to_string())]))
        }
    };
    Status::with_error_details(code, message, details)
}

/// `status` with full details if it has none (reason: the code's
/// canonical name): for statuses made outside [`to_status`] — by the
/// services' own checks, the authentication interceptor, or tonic itself
/// (an unknown method, a request that does not decode). Applied to every
/// answer by [`super::error_details`].
pub(crate) fn with_details(status: &Status) -> Option<Status> {
    if status.code() == Code::Ok || !status.details().is_empty() {
        return None;
    }
    let details = ErrorDetails::with_error_info(ecmxf_proto::code_name(status.code()), DOMAIN, HashMap::new());
    Some(Status::with_error_details(status.code(), status.message(), details))
}

impl From<EngineError> for Status {
    fn from(e: EngineError) -> Self {
        to_status(e)
    }
}

/// Whether an error message a user reads shows Rust `{:?}` output (an
/// `Option`, a struct or enum dump, a path) instead of words: such text
/// says nothing to a user of grpcurl or Python. Quoted names (`"1.foo"`)
/// and durations (`100ms`) are words. Debug builds only: the tests read
/// what it finds.
#[cfg(any(debug_assertions, test))]
pub(crate) fn looks_like_debug(message: &str) -> bool {
    const MARKS: [&str; 9] = ["Some(", "None", "Ok(", "Err(", "::", " { ", "\\\"", "One(", "All)"];
    if MARKS.iter().any(|m| message.contains(m)) {
        return true;
    }
    // An enum variant with a payload: a capitalised word right before a
    // parenthesis, as in `Recovering(` or `SdoRead(`.
    message.match_indices('(').any(|(at, _)| {
        let before = &message[..at];
        let start = before.rfind(|c: char| !c.is_ascii_alphanumeric()).map_or(0, |i| i + 1);
        let name = &before[start..];
        name.chars().next().is_some_and(|c| c.is_ascii_uppercase()) && name.chars().any(|c| c.is_ascii_lowercase())
    })
}

/// Error messages seen that [`looks_like_debug`] (debug builds: the tests
/// read them back, [`debug_looking_messages`]; at most 16 are kept).
#[cfg(debug_assertions)]
static DEBUG_LOOKING: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());

/// Records `message` if it reads like Rust Debug output: every error the
/// API answers passes here (`error_details`), so the tests can require
/// that none did.
pub(crate) fn note_message(message: &str) {
    #[cfg(debug_assertions)]
    if looks_like_debug(message) {
        let mut seen = DEBUG_LOOKING.lock().unwrap_or_else(|e| e.into_inner());
        if seen.len() < 16 {
            seen.push(message.to_owned());
        }
    }
    #[cfg(not(debug_assertions))]
    let _ = message;
}

/// The error messages answered so far that read like Rust Debug output
/// (always empty in release builds).
pub fn debug_looking_messages() -> Vec<String> {
    #[cfg(debug_assertions)]
    return DEBUG_LOOKING.lock().unwrap_or_else(|e| e.into_inner()).clone();
    #[cfg(not(debug_assertions))]
    Vec::new()
}

/// How every server stream ends when the daemon stops: UNAVAILABLE with
/// the ErrorInfo reason STOPPING (proto/README.md).
pub(crate) fn stopping() -> Status {
    let details = ErrorDetails::with_error_info("STOPPING", DOMAIN, HashMap::new());
    Status::with_error_details(Code::Unavailable, "daemon stopping: the stream ends", details)
}

/// PERMISSION_DENIED ending the stream of `who`, whose access a reload of
/// the configuration took away.
pub(crate) fn access_revoked(who: &str) -> Status {
    let details = ErrorDetails::with_error_info("ACCESS_REVOKED", DOMAIN, HashMap::new());
    let message = format!("{who} lost its access (the configuration was reloaded): the stream ends");
    Status::with_error_details(Code::PermissionDenied, message, details)
}

/// INVALID_ARGUMENT naming `field`, for checks made in the API layer.
pub(crate) fn bad_argument(field: &'static str, reason: impl Into<String>) -> Status {
    to_status(EngineError::BadArgument { field, reason: reason.into() })
}

#[cfg(test)]
mod debug_text_tests {
    use super::looks_like_debug;

    #[test]
    fn debug_output_is_told_from_words() {
        for debug in [
            "no such slave: One(9)",
            "SdoRead { slave: 1, index: 4096 }",
            "value Some(3)",
            "ecmxfd::engine::Phase",
            "the network is not running: Recovering(WkcStreak(50ms))",
        ] {
            assert!(looks_like_debug(debug), "{debug}");
        }
        // What the API answers is recorded for the tests to read back.
        super::note_message("value Some(7) refused");
        super::note_message("no entry \"2.foo\"");
        let seen = super::debug_looking_messages();
        assert!(seen.iter().any(|m| m == "value Some(7) refused"), "{seen:?}");
        assert!(!seen.iter().any(|m| m.contains("2.foo")), "{seen:?}");
        for words in [
            "no entry \"1.foo\" (see GetLayout for the names)",
            "chip not ready (INT0) within 100ms",
            "SDO 0x2fff:00 on slave 1 aborted: 0x06020000 (object does not exist in the object dictionary)",
            "axis 0 is SWITCH ON DISABLED, not OPERATION ENABLED, at the deadline",
            "bad value: 204800 raw bytes given for a UNSIGNED8 object, which has 1",
        ] {
            assert!(!looks_like_debug(words), "{words}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::master::SdoAbortCode;

    #[test]
    fn every_engine_error_maps_to_its_code() {
        let cases = [
            (EngineError::BadArgument { field: "index", reason: "x".into() }, Code::InvalidArgument),
            (EngineError::WrongState(crate::master::WrongState::NoInputs), Code::FailedPrecondition),
            (
                EngineError::SdoAbort { slave: 1, index: 0x6060, subindex: 0, code: SdoAbortCode(0x0602_0000) },
                Code::Aborted,
            ),
            (EngineError::Failed("x".into()), Code::Internal),
            (EngineError::Refused("x".into()), Code::FailedPrecondition),
            (EngineError::Timeout, Code::DeadlineExceeded),
            (EngineError::QueueFull, Code::ResourceExhausted),
            (EngineError::Unavailable(crate::master::NotRunning::Stopped), Code::Unavailable),
            (
                EngineError::BadDeviceData {
                    slave: 1,
                    error: ecmxf_devices::sii::SiiError::CategoryOverrun { kind: 10, offset: 0x80 },
                },
                Code::FailedPrecondition,
            ),
        ];
        for (e, code) in cases {
            assert_eq!(to_status(e.clone()).code(), code, "{e}");
        }
    }

    /// The details decode as a google.rpc.Status equal to the status
    /// itself (what grpc-go reads), plus the ErrorInfo.
    fn full(s: &Status) -> tonic_types::pb::Status {
        use prost::Message;
        let details = tonic_types::pb::Status::decode(s.details()).expect("details are a google.rpc.Status");
        assert_eq!(details.code, s.code() as i32, "{s:?}");
        assert_eq!(details.message, s.message(), "{s:?}");
        details
    }

    #[test]
    fn sdo_abort_details_carry_code_and_meaning() {
        let s =
            to_status(EngineError::SdoAbort { slave: 2, index: 0x1234, subindex: 5, code: SdoAbortCode(0x0602_0000) });
        full(&s);
        let info = s.get_details_error_info().expect("ErrorInfo");
        assert_eq!((info.reason.as_str(), info.domain.as_str()), ("SDO_ABORT", DOMAIN));
        assert_eq!(info.metadata["abort_code"], "0x06020000");
        assert!(info.metadata["meaning"].contains("does not exist"), "{info:?}");
        assert_eq!(info.metadata["object"], "0x1234:05");
        assert!(s.message().contains("0x1234:05"), "{}", s.message());
    }

    #[test]
    fn every_error_carries_a_full_status() {
        let e = to_status(EngineError::BadArgument { field: "slave", reason: "no slave 99".into() });
        full(&e);
        let bad = e.get_details_bad_request().expect("BadRequest");
        assert_eq!(bad.field_violations[0].field, "slave");
        assert_eq!(bad.field_violations[0].description, "no slave 99");
        for e in [EngineError::Timeout, EngineError::QueueFull, EngineError::Failed("x".into())] {
            full(&to_status(e));
        }
        let plain = Status::permission_denied("uid 5 has no access");
        let s = with_details(&plain).expect("completed");
        full(&s);
        assert_eq!(s.get_details_error_info().unwrap().reason, "PERMISSION_DENIED");
        assert!(with_details(&s).is_none(), "details already there are kept");
        assert!(with_details(&Status::ok("")).is_none());
    }
}
