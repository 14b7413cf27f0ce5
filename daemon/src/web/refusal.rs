//! What a request could not do, as the dashboard answers it: an HTTP
//! status and a sentence naming what was wrong, `{"error": ...}`. The
//! engine's errors are mapped here, once for this front end.

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};

use crate::master::EngineError;

/// What a request could not do: an HTTP status and a sentence naming what
/// was wrong, sent as `{"error": ...}`.
#[derive(Debug)]
pub(crate) struct Refusal {
    pub(super) status: StatusCode,
    pub(super) why: String,
}

impl Refusal {
    pub(super) fn new(status: StatusCode, why: impl Into<String>) -> Self {
        Self { status, why: why.into() }
    }

    pub(super) fn bad(why: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, why)
    }

    pub(super) fn forbidden(why: impl Into<String>) -> Self {
        Self::new(StatusCode::FORBIDDEN, why)
    }

    pub(super) fn not_found(why: impl Into<String>) -> Self {
        Self::new(StatusCode::NOT_FOUND, why)
    }
}

impl From<EngineError> for Refusal {
    /// The engine's errors mapped once for this front end.
    fn from(e: EngineError) -> Self {
        let status = match &e {
            EngineError::Timeout => StatusCode::GATEWAY_TIMEOUT,
            EngineError::QueueFull => StatusCode::TOO_MANY_REQUESTS,
            EngineError::BadArgument { .. } => StatusCode::BAD_REQUEST,
            EngineError::SdoAbort { .. } => StatusCode::CONFLICT,
            EngineError::Unavailable(_) => StatusCode::SERVICE_UNAVAILABLE,
            _ => StatusCode::BAD_GATEWAY,
        };
        Self::new(status, e.to_string())
    }
}

impl IntoResponse for Refusal {
    fn into_response(self) -> Response {
        (self.status, axum::Json(serde_json::json!({ "error": self.why }))).into_response()
    }
}
