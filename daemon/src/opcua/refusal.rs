//! Why a client's write or call was refused, as OPC UA says it.

use opcua::types::{DiagnosticInfo, StatusCode};

/// Why a write or a call was refused: its status code, what a person
/// reads (the operation's diagnostics, and the log), and for a call the
/// argument at fault.
#[derive(Debug)]
pub(crate) struct Refusal {
    pub(super) status: StatusCode,
    pub(super) why: String,
    pub(super) argument: Option<usize>,
}

impl Refusal {
    pub(super) fn new(status: StatusCode, why: impl Into<String>) -> Self {
        Self { status, why: why.into(), argument: None }
    }

    /// Not this user's to do (BadUserAccessDenied).
    pub(super) fn denied(why: impl Into<String>) -> Self {
        Self::new(StatusCode::BadUserAccessDenied, why)
    }

    /// Argument `n` of a call is wrong.
    pub(super) fn argument(n: usize, why: impl Into<String>) -> Self {
        Self { status: StatusCode::BadInvalidArgument, why: why.into(), argument: Some(n) }
    }

    /// What a client that asks for operation diagnostics reads.
    pub(super) fn diagnostic(&self) -> DiagnosticInfo {
        DiagnosticInfo { additional_info: Some(self.why.as_str().into()), ..Default::default() }
    }
}
