//! Request bodies: JSON of at most [`BODY_LIMIT`] bytes that must arrive
//! within [`BODY_WITHIN`] (the header deadline does not cover a body: a
//! peer that sends half of one would hold its connection for ever), and
//! every way one can be wrong answered as the dashboard's other errors
//! are, `{"error": ...}` naming what was wrong.

use std::time::Duration;

use axum::Json;
use axum::extract::rejection::JsonRejection;
use axum::extract::{FromRequest, Request};
use axum::http::StatusCode;
use serde::de::DeserializeOwned;

use super::refusal::Refusal;

/// The largest body taken, bytes (the router's limit, `mod.rs`).
pub(super) const BODY_LIMIT: usize = 64 * 1024;
/// How long a body may take to arrive.
const BODY_WITHIN: Duration = Duration::from_secs(5);

/// A JSON body of type `T`.
pub(crate) struct JsonBody<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned> FromRequest<S> for JsonBody<T> {
    type Rejection = Refusal;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        match tokio::time::timeout(BODY_WITHIN, Json::<T>::from_request(req, state)).await {
            Ok(Ok(Json(v))) => Ok(Self(v)),
            Ok(Err(rejection)) => Err(refused(&rejection)),
            Err(_) => Err(Refusal::new(
                StatusCode::REQUEST_TIMEOUT,
                format!("the request's body did not arrive within {} s", BODY_WITHIN.as_secs()),
            )),
        }
    }
}

/// Why a body was not taken, said as the dashboard says errors.
fn refused(rejection: &JsonRejection) -> Refusal {
    let status = rejection.status();
    let why = match rejection {
        JsonRejection::MissingJsonContentType(_) => "send the body as JSON (Content-Type: application/json)".into(),
        _ if status == StatusCode::PAYLOAD_TOO_LARGE => format!("the body is over {} KiB", BODY_LIMIT / 1024),
        other => other.body_text(),
    };
    Refusal::new(status, why)
}
