//! `ecmxf-proto`: the `ecmxf.v1` gRPC API — the `.proto` files in
//! `proto/ecmxf/v1/` (the contract, usable from any language) and the Rust
//! client and server code generated from them at build time with protox
//! (no system `protoc` needed).
#![forbid(unsafe_code)]
#![allow(missing_docs, missing_debug_implementations, clippy::all)]

/// The `ecmxf.v1` package: messages, `*_client` and `*_server` modules.
pub mod v1 {
    tonic::include_proto!("ecmxf.v1");
    include!(concat!(env!("OUT_DIR"), "/server/ecmxf.v1.rs"));

    /// The encoded `FileDescriptorSet` of every file, for gRPC reflection.
    pub const FILE_DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/ecmxf_descriptor.bin"));
}

/// The encoded `FileDescriptorSet` of `google/rpc/status.proto` and
/// `google/rpc/error_details.proto` (the messages of every error's
/// `grpc-status-details-bin`), for gRPC reflection: a client decodes error
/// details by asking the daemon alone.
pub const ERROR_MODEL_DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/error_model_descriptor.bin"));

/// The Sparkplug B payload (`sparkplug/sparkplug_b.proto`, Eclipse
/// Sparkplug 3.0 section 6.4): what the daemon's MQTT edge node publishes.
pub mod sparkplug {
    include!(concat!(env!("OUT_DIR"), "/org.eclipse.tahu.protobuf.rs"));
}

#[warn(clippy::all)]
pub mod codec;
#[warn(clippy::all)]
pub mod value;

/// gRPC's canonical name for a code ("PERMISSION_DENIED"): the reason of
/// the daemon's generic error details and `ecmxfctl --json`'s error kind.
pub fn code_name(c: tonic::Code) -> &'static str {
    match c {
        tonic::Code::Ok => "OK",
        tonic::Code::Cancelled => "CANCELLED",
        tonic::Code::Unknown => "UNKNOWN",
        tonic::Code::InvalidArgument => "INVALID_ARGUMENT",
        tonic::Code::DeadlineExceeded => "DEADLINE_EXCEEDED",
        tonic::Code::NotFound => "NOT_FOUND",
        tonic::Code::AlreadyExists => "ALREADY_EXISTS",
        tonic::Code::PermissionDenied => "PERMISSION_DENIED",
        tonic::Code::ResourceExhausted => "RESOURCE_EXHAUSTED",
        tonic::Code::FailedPrecondition => "FAILED_PRECONDITION",
        tonic::Code::Aborted => "ABORTED",
        tonic::Code::OutOfRange => "OUT_OF_RANGE",
        tonic::Code::Unimplemented => "UNIMPLEMENTED",
        tonic::Code::Internal => "INTERNAL",
        tonic::Code::Unavailable => "UNAVAILABLE",
        tonic::Code::DataLoss => "DATA_LOSS",
        tonic::Code::Unauthenticated => "UNAUTHENTICATED",
    }
}

/// Where `ecmxfd` listens and `ecmxfctl` connects when not told otherwise:
/// `$ECMXF_SOCKET` if set; for root `/run/ecmxfd/ecmxfd.sock` (the systemd
/// unit's RuntimeDirectory); for other users `$XDG_RUNTIME_DIR/ecmxfd.sock`,
/// or `/tmp/ecmxfd-<uid>.sock` without one.
pub fn default_socket_path() -> std::path::PathBuf {
    if let Some(p) = std::env::var_os("ECMXF_SOCKET") {
        return p.into();
    }
    let uid = current_uid();
    if uid == 0 {
        return SYSTEM_SOCKET.into();
    }
    match std::env::var_os("XDG_RUNTIME_DIR") {
        Some(d) if !d.is_empty() => std::path::Path::new(&d).join("ecmxfd.sock"),
        _ => format!("/tmp/ecmxfd-{uid}.sock").into(),
    }
}

/// The socket path a client tries when not told: `$ECMXF_SOCKET`; else
/// [`default_socket_path`] if a daemon of this user listens there; else the
/// system daemon's `/run/ecmxfd/ecmxfd.sock` if it exists (the packaged
/// service, reachable by members of its group); else
/// [`default_socket_path`] (for the error message).
pub fn client_socket_path() -> std::path::PathBuf {
    let own = default_socket_path();
    if std::env::var_os("ECMXF_SOCKET").is_some() || own.exists() {
        return own;
    }
    let system = std::path::PathBuf::from(SYSTEM_SOCKET);
    if system.exists() { system } else { own }
}

/// Where the packaged service listens (systemd RuntimeDirectory).
pub const SYSTEM_SOCKET: &str = "/run/ecmxfd/ecmxfd.sock";

fn current_uid() -> u32 {
    // The owner of /proc/self is the process's real uid; no libc needed.
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self").map(|m| m.uid()).unwrap_or(u32::MAX)
}

/// A channel to a daemon's Unix socket (gRPC over HTTP/2 on the socket;
/// the URI is a placeholder the connector ignores).
pub async fn connect_unix(
    path: impl Into<std::path::PathBuf>,
) -> Result<tonic::transport::Channel, tonic::transport::Error> {
    let path: std::path::PathBuf = path.into();
    tonic::transport::Endpoint::from_static("http://ecmxfd.sock")
        .connect_with_connector(tower::service_fn(move |_: tonic::transport::Uri| {
            let path = path.clone();
            async move {
                Ok::<_, std::io::Error>(hyper_util::rt::TokioIo::new(tokio::net::UnixStream::connect(path).await?))
            }
        }))
        .await
}
