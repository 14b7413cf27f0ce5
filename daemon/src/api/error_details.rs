//! A tower layer under the whole API that gives every error answer a full
//! `google.rpc.Status` in `grpc-status-details-bin` (see
//! [`status::with_details`]). Engine errors
//! already carry theirs ([`to_status`](super::status::to_status)); this
//! covers the rest — the services' own checks, the authentication
//! interceptor and tonic itself — in one place, for unary answers (the
//! status in the headers) and streams (the status in the trailers) alike.

use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};

use http::HeaderMap;
use http_body::Frame;
use http_body_util::BodyExt;
use tonic::Status;
use tonic::body::Body;

use super::status;

/// Wraps a service in [`WithErrorDetails`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ErrorDetailsLayer;

impl<S> tower_layer::Layer<S> for ErrorDetailsLayer {
    type Service = WithErrorDetails<S>;

    fn layer(&self, inner: S) -> Self::Service {
        WithErrorDetails(inner)
    }
}

/// Completes the error status of every answer of the inner service.
#[derive(Clone, Debug)]
pub(crate) struct WithErrorDetails<S>(S);

impl<S, B> tower_service::Service<http::Request<B>> for WithErrorDetails<S>
where
    S: tower_service::Service<http::Request<B>, Response = http::Response<Body>>,
    S::Future: Send + 'static,
{
    type Response = http::Response<Body>;
    type Error = S::Error;
    type Future = Pin<Box<dyn Future<Output = Result<Self::Response, Self::Error>> + Send>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.0.poll_ready(cx)
    }

    fn call(&mut self, request: http::Request<B>) -> Self::Future {
        let answer = self.0.call(request);
        Box::pin(async move {
            let mut response = answer.await?;
            // A unary error comes "trailers-only": the status in the headers.
            complete(response.headers_mut());
            Ok(response.map(|body| {
                Body::new(body.map_frame(|frame| match frame.into_trailers() {
                    Ok(mut trailers) => {
                        complete(&mut trailers);
                        Frame::trailers(trailers)
                    }
                    Err(frame) => frame,
                }))
            }))
        })
    }
}

/// Adds details to the error status in `headers`, if there is one without.
fn complete(headers: &mut HeaderMap) {
    let failed = headers.get("grpc-status").is_some_and(|code| code.as_bytes() != b"0");
    if !failed {
        return;
    }
    if cfg!(debug_assertions) {
        if let Some(s) = Status::from_header_map(headers) {
            status::note_message(s.message());
        }
    }
    if headers.contains_key("grpc-status-details-bin") {
        return;
    }
    // No details header, so parsing cannot meet undecodable details.
    let Some(full) = Status::from_header_map(headers).as_ref().and_then(status::with_details) else { return };
    // The same code and message as before; only a message that cannot be
    // a header value could fail, and tonic already wrote that one.
    let _ = full.add_header(headers);
}

#[cfg(test)]
mod tests {
    use tonic_types::StatusExt;

    use super::*;

    #[test]
    fn an_error_without_details_gets_them_and_one_with_keeps_its_own() {
        let mut h = HeaderMap::new();
        Status::permission_denied("uid 5 (gid 5) has no access: 100%").add_header(&mut h).unwrap();
        complete(&mut h);
        let s = Status::from_header_map(&h).unwrap();
        assert_eq!(s.code(), tonic::Code::PermissionDenied);
        assert_eq!(s.message(), "uid 5 (gid 5) has no access: 100%");
        let info = s.get_details_error_info().expect("ErrorInfo added");
        assert_eq!(info.reason, "PERMISSION_DENIED");
        use prost::Message;
        let full = tonic_types::pb::Status::decode(s.details()).unwrap();
        assert_eq!((full.code, full.message.as_str()), (7, s.message()));

        let own = status::to_status(crate::master::EngineError::Timeout);
        let mut h = HeaderMap::new();
        own.add_header(&mut h).unwrap();
        complete(&mut h);
        assert_eq!(Status::from_header_map(&h).unwrap().get_details_error_info().unwrap().reason, "TIMEOUT");

        let mut ok = HeaderMap::new();
        ok.insert("grpc-status", http::HeaderValue::from_static("0"));
        complete(&mut ok);
        assert!(!ok.contains_key("grpc-status-details-bin"));
    }
}
