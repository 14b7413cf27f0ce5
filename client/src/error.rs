//! What can go wrong, the one-line message a user reads, and the exit code
//! a script branches on (documented in docs/ecmxfctl.md, "Exit codes").

use std::path::PathBuf;

use schemars::JsonSchema;
use serde::Serialize;
use tonic::Code;

/// Exit codes. Stable: scripts depend on them.
pub mod exit {
    /// Done.
    pub const OK: u8 = 0;
    /// Something failed that has no code of its own (chip failure, file I/O).
    pub const FAILED: u8 = 1;
    /// The command line or a value in it is wrong (clap's own code, also used
    /// when the daemon refuses an argument: INVALID_ARGUMENT, NOT_FOUND).
    pub const USAGE: u8 = 2;
    /// The daemon cannot be reached, or its engine is not running (UNAVAILABLE).
    pub const UNREACHABLE: u8 = 3;
    /// The caller lacks the role, or has no identity (PERMISSION_DENIED,
    /// UNAUTHENTICATED).
    pub const DENIED: u8 = 4;
    /// The deadline passed (DEADLINE_EXCEEDED).
    pub const TIMEOUT: u8 = 5;
    /// The slave aborted the SDO transfer (ABORTED; the abort code is printed).
    pub const SDO_ABORT: u8 = 6;
    /// Not possible in the present state (FAILED_PRECONDITION), e.g. a drive
    /// that stays in FAULT.
    pub const WRONG_STATE: u8 = 7;
    /// `diag` found a problem (a slave not in the network's state, an AL
    /// status code, a configuration mismatch).
    pub const UNHEALTHY: u8 = 8;
}

/// Everything a command can fail with.
#[derive(Debug)]
pub enum CliError {
    /// No daemon at the address.
    Unreachable {
        /// The socket path or URL tried.
        target: String,
        /// Why (the OS's words).
        reason: String,
    },
    /// The daemon answered a call with an error.
    Rpc {
        /// What ecmxfctl was doing ("upload 0x6041:00 from slave 1").
        action: String,
        status: tonic::Status,
    },
    /// Bad input caught before anything was sent.
    Usage(String),
    /// A local file could not be read or written.
    File { path: PathBuf, error: std::io::Error },
    /// Writing to the terminal failed (a closed pipe ends quietly).
    Output(std::io::Error),
    /// `diag` found problems (listed in its output).
    Unhealthy(String),
}

impl CliError {
    /// A failed call, with what was being done.
    pub fn rpc(action: impl Into<String>) -> impl FnOnce(tonic::Status) -> Self {
        let action = action.into();
        move |status| {
            // tonic enforces the deadline locally too and then says
            // CANCELLED "Timeout expired": it is a deadline all the same.
            let status = if status.code() == Code::Cancelled && status.message().contains("Timeout expired") {
                tonic::Status::deadline_exceeded("no answer within the deadline (--timeout)")
            } else {
                status
            };
            Self::Rpc { action, status }
        }
    }

    /// A failed file operation on `path`.
    pub fn file(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |error| Self::File { path, error }
    }

    /// The exit code for this error.
    pub fn exit_code(&self) -> u8 {
        match self {
            Self::Unreachable { .. } => exit::UNREACHABLE,
            Self::Usage(_) => exit::USAGE,
            Self::File { .. } | Self::Output(_) => exit::FAILED,
            Self::Unhealthy(_) => exit::UNHEALTHY,
            Self::Rpc { status, .. } => match status.code() {
                Code::InvalidArgument | Code::NotFound | Code::OutOfRange | Code::AlreadyExists => exit::USAGE,
                Code::Unavailable => exit::UNREACHABLE,
                Code::PermissionDenied | Code::Unauthenticated => exit::DENIED,
                Code::DeadlineExceeded => exit::TIMEOUT,
                Code::Aborted => exit::SDO_ABORT,
                Code::FailedPrecondition => exit::WRONG_STATE,
                _ => exit::FAILED,
            },
        }
    }

    /// The gRPC code name (JSON error output), or what kind of local error.
    pub fn kind(&self) -> String {
        match self {
            Self::Unreachable { .. } => "UNREACHABLE".into(),
            Self::Usage(_) => "USAGE".into(),
            Self::File { .. } => "FILE".into(),
            Self::Output(_) => "OUTPUT".into(),
            Self::Unhealthy(_) => "UNHEALTHY".into(),
            Self::Rpc { status, .. } => code_name(status.code()).into(),
        }
    }

    /// A hint for what to do next, if there is an obvious one.
    pub fn hint(&self) -> Option<&'static str> {
        match self {
            Self::Unreachable { .. } => Some(
                "is ecmxfd running? Start it (`systemctl start ecmxfd`, or `ecmxfd --sim` to try the simulator), \
                 or say where it listens with --socket / $ECMXF_SOCKET, or --connect for TCP",
            ),
            Self::Rpc { status, .. } => match status.code() {
                Code::PermissionDenied => Some(
                    "ask the daemon's administrator for the role ([[api.user]], [[api.group]], [[api.token]] in \
                     ecmxfd.toml), or pass a token with --token / $ECMXF_TOKEN",
                ),
                Code::Unauthenticated => Some("TCP connections need --token, or --cert and --key"),
                Code::Unavailable => Some("the daemon runs but its engine does not: see `ecmxfctl master`"),
                _ => None,
            },
            _ => None,
        }
    }

    /// The daemon ended a stream because it is stopping (UNAVAILABLE,
    /// ErrorInfo reason STOPPING): a following command (`events`, `data
    /// watch`) ends with exit 0 and says so, instead of failing.
    pub fn is_stopping(status: &tonic::Status) -> bool {
        use tonic_types::StatusExt;
        status.code() == Code::Unavailable && status.get_details_error_info().is_some_and(|i| i.reason == "STOPPING")
    }

    /// Extra detail from the daemon's google.rpc.ErrorInfo (SDO abort code,
    /// the argument at fault), as `key=value` pairs.
    pub fn details(&self) -> Vec<(String, String)> {
        use tonic_types::StatusExt;
        let Self::Rpc { status, .. } = self else { return Vec::new() };
        let Some(info) = status.get_details_error_info() else { return Vec::new() };
        let mut v: Vec<(String, String)> = info.metadata.into_iter().collect();
        v.sort();
        v
    }
}

pub use ecmxf_proto::code_name;

impl std::fmt::Display for CliError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Unreachable { target, reason } => write!(f, "cannot reach ecmxfd at {target}: {reason}"),
            Self::Rpc { action, status } => {
                let what = match status.code() {
                    Code::PermissionDenied => "permission denied: ",
                    Code::Unauthenticated => "not authenticated: ",
                    Code::DeadlineExceeded => "timed out: ",
                    _ => "",
                };
                write!(f, "{action}: {what}{}", status.message())
            }
            Self::Usage(m) | Self::Unhealthy(m) => f.write_str(m),
            Self::File { path, error } => write!(f, "{}: {error}", path.display()),
            Self::Output(e) => write!(f, "writing output: {e}"),
        }
    }
}

impl std::error::Error for CliError {}

impl From<std::io::Error> for CliError {
    fn from(e: std::io::Error) -> Self {
        Self::Output(e)
    }
}

/// What `--json` prints on standard error when a command fails.
#[derive(Debug, Serialize, JsonSchema)]
pub struct ErrorReport {
    pub error: ErrorBody,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct ErrorBody {
    /// gRPC code name (PERMISSION_DENIED, ABORTED, ...) or a local kind:
    /// UNREACHABLE, USAGE, FILE, OUTPUT, UNHEALTHY.
    pub kind: String,
    /// The message ecmxfctl prints without --json.
    pub message: String,
    /// The process's exit code.
    pub exit_code: u8,
    /// The daemon's error details (e.g. abort_code, meaning, field).
    pub details: std::collections::BTreeMap<String, String>,
    /// What to try next, if there is an obvious step.
    pub hint: Option<String>,
}

impl ErrorReport {
    /// The report for `e`.
    pub fn of(e: &CliError) -> Self {
        Self {
            error: ErrorBody {
                kind: e.kind(),
                message: e.to_string(),
                exit_code: e.exit_code(),
                details: e.details().into_iter().collect(),
                hint: e.hint().map(str::to_owned),
            },
        }
    }

    /// The report for a command line clap refused: `message` (what was
    /// wrong) and the usage line as the hint.
    pub fn usage(message: String, usage: Option<&str>) -> Self {
        let e = CliError::Usage(message);
        let mut r = Self::of(&e);
        r.error.hint = Some(match usage {
            Some(u) => format!("{u} (more: --help)"),
            None => "see --help".into(),
        });
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_status_code_has_a_documented_exit_code() {
        let rpc = |c| CliError::Rpc { action: "x".into(), status: tonic::Status::new(c, "m") };
        for (c, want) in [
            (Code::InvalidArgument, exit::USAGE),
            (Code::NotFound, exit::USAGE),
            (Code::Unavailable, exit::UNREACHABLE),
            (Code::PermissionDenied, exit::DENIED),
            (Code::Unauthenticated, exit::DENIED),
            (Code::DeadlineExceeded, exit::TIMEOUT),
            (Code::Aborted, exit::SDO_ABORT),
            (Code::FailedPrecondition, exit::WRONG_STATE),
            (Code::Internal, exit::FAILED),
            (Code::Cancelled, exit::FAILED),
        ] {
            assert_eq!(rpc(c).exit_code(), want, "{c:?}");
        }
        assert_eq!(rpc(Code::PermissionDenied).kind(), "PERMISSION_DENIED");
        let e = rpc(Code::PermissionDenied);
        assert!(e.to_string().starts_with("x: permission denied: m"), "{e}");
        assert!(e.hint().unwrap().contains("--token"));
    }
}
