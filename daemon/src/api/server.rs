//! Serving: the Unix socket (created with the configured mode and group;
//! a stale socket file from a crash is replaced, a live one is an error),
//! optional TCP with TLS, health and reflection, and the background tasks
//! the services rely on (the newest inputs for CiA 402 values, gRPC health
//! from the bus state). Both listeners accept through
//! [`crate::admission`]: capped, each with a budget of its own, and a
//! handshake deadline; the TLS handshake runs there, under the deadline.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use tokio::net::{TcpListener, UnixListener};
use tokio::sync::{mpsc, watch};
use tokio_stream::StreamExt as _;
use tokio_stream::wrappers::ReceiverStream;
use tonic::server::NamedService;
use tonic::service::Routes;
use tonic::transport::Server;
use tonic_health::ServingStatus;
use tonic_health::server::HealthReporter;

use super::Context;
use super::admin::{FoeService, RegistersService};
use super::cia402::Cia402Service;
use super::diagnostics::DiagnosticsService;
use super::error_details::ErrorDetailsLayer;
use super::master::{MasterService, SlavesService, StateService};
use super::pdo::ProcessDataService;
use super::peripherals::PeripheralsService;
use super::sdo::SdoService;
use super::sii::SiiService;
use crate::admission::{self, Cap, Gate};
use crate::config::api::ApiConfig;
use crate::master::Master;

/// Why the API could not be served.
#[derive(Debug)]
pub enum ServeError {
    /// The socket could not be set up: where, and what went wrong.
    Socket(PathBuf, SocketProblem),
    /// A TLS file `api.tcp` needs is not configured (the key).
    TlsNotSet(&'static str),
    /// A TLS file could not be read: its key, path and the OS error.
    TlsFile {
        /// The configuration key, e.g. `tls_cert`.
        key: &'static str,
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A TLS file does not hold what its key needs (a certificate, a
    /// private key), or rustls refused them: the key and why.
    TlsContent(&'static str, String),
    /// The TCP port could not be bound.
    Bind(std::net::SocketAddr, std::io::Error),
    /// The reflection service could not be built.
    Reflection(tonic_reflection::server::Error),
    /// The server (or its TLS configuration) failed.
    Transport(tonic::transport::Error),
}

impl std::fmt::Display for ServeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Socket(p, why) => write!(f, "API socket {}: {why}", p.display()),
            Self::TlsNotSet(key) => write!(f, "API TLS: api.{key} is not set"),
            Self::TlsFile { key, path, source } => write!(f, "API TLS: api.{key} {}: {source}", path.display()),
            Self::TlsContent(key, why) => write!(f, "API TLS: api.{key}: {why}"),
            Self::Bind(addr, e) => write!(f, "api.tcp {addr}: cannot bind: {e}"),
            Self::Reflection(e) => write!(f, "API server: reflection: {e}"),
            Self::Transport(e) => write!(f, "API server: {e}"),
        }
    }
}

impl std::error::Error for ServeError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Socket(_, p) => p.source(),
            Self::TlsFile { source, .. } | Self::Bind(_, source) => Some(source),
            Self::Reflection(e) => Some(e),
            Self::Transport(e) => Some(e),
            Self::TlsNotSet(_) | Self::TlsContent(..) => None,
        }
    }
}

/// What went wrong setting up the API socket, with the OS's error where
/// there is one.
#[derive(Debug)]
pub enum SocketProblem {
    /// Its folder could not be created.
    CreateFolder(std::io::Error),
    /// Something that is not a socket is at the path (what it is).
    NotASocket(&'static str),
    /// Another daemon serves the socket.
    Served,
    /// A stale socket could not be removed.
    RemoveStale(std::io::Error),
    /// Binding failed.
    Bind(std::io::Error),
    /// `api.socket_mode` could not be applied.
    Mode(u32, std::io::Error),
    /// `api.socket_group` names no group.
    NoGroup(String),
    /// The socket could not be given to the group.
    Chown(String, nix::Error),
}

impl SocketProblem {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::CreateFolder(e) | Self::RemoveStale(e) | Self::Bind(e) | Self::Mode(_, e) => Some(e),
            Self::Chown(_, e) => Some(e),
            Self::NotASocket(_) | Self::Served | Self::NoGroup(_) => None,
        }
    }
}

impl std::fmt::Display for SocketProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::CreateFolder(e) => write!(f, "cannot create its folder: {e}"),
            Self::NotASocket(what) => {
                write!(f, "something that is not a socket is there ({what}); remove it or give another api.socket")
            }
            Self::Served => f.write_str("another daemon is serving it (stop it, or give another api.socket)"),
            Self::RemoveStale(e) => write!(f, "cannot remove the stale socket: {e}"),
            Self::Bind(e) => write!(f, "cannot bind: {e}"),
            Self::Mode(mode, e) => write!(f, "cannot set mode {mode:#o}: {e}"),
            Self::NoGroup(group) => write!(f, "api.socket_group {group:?} does not exist"),
            Self::Chown(group, e) => write!(f, "cannot give it to group {group}: {e}"),
        }
    }
}

/// Every service name, for health.
const SERVICES: [&str; 12] = [
    "",
    <pb::master_server::MasterServer<MasterService> as NamedService>::NAME,
    <pb::slaves_server::SlavesServer<SlavesService> as NamedService>::NAME,
    <pb::state_server::StateServer<StateService> as NamedService>::NAME,
    <pb::sdo_server::SdoServer<SdoService> as NamedService>::NAME,
    <pb::sii_server::SiiServer<SiiService> as NamedService>::NAME,
    <pb::process_data_server::ProcessDataServer<ProcessDataService> as NamedService>::NAME,
    <pb::cia402_server::Cia402Server<Cia402Service> as NamedService>::NAME,
    <pb::peripherals_server::PeripheralsServer<PeripheralsService> as NamedService>::NAME,
    <pb::foe_server::FoeServer<FoeService> as NamedService>::NAME,
    <pb::registers_server::RegistersServer<RegistersService> as NamedService>::NAME,
    <pb::diagnostics_server::DiagnosticsServer<DiagnosticsService> as NamedService>::NAME,
];

/// The largest request body the daemon decodes: the largest legitimate
/// one is a whole FoE file (the chip stages at most `FOE_MAX_FILE`, 256
/// KiB) or an SII image (at most 64 KiB), plus room for the message around
/// it. A larger body is refused with OUT_OF_RANGE before it is read whole
/// (proto/README.md lists it).
pub(crate) const MAX_REQUEST_BYTES: usize = crate::master::transactions::FOE_MAX_FILE + 64 * 1024;

fn routes(
    ctx: &Arc<Context>,
    health: tonic_health::pb::health_server::HealthServer<impl tonic_health::pb::health_server::Health>,
) -> Result<Routes, ServeError> {
    let v1 = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(pb::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(ecmxf_proto::ERROR_MODEL_DESCRIPTOR_SET)
        .build_v1()
        .map_err(ServeError::Reflection)?;
    let v1alpha = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(pb::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(ecmxf_proto::ERROR_MODEL_DESCRIPTOR_SET)
        .build_v1alpha()
        .map_err(ServeError::Reflection)?;
    let c = || Arc::clone(ctx);
    Ok(Routes::new(health)
        .add_service(v1)
        .add_service(v1alpha)
        .add_service(
            pb::master_server::MasterServer::new(MasterService(c())).max_decoding_message_size(MAX_REQUEST_BYTES),
        )
        .add_service(
            pb::slaves_server::SlavesServer::new(SlavesService(c())).max_decoding_message_size(MAX_REQUEST_BYTES),
        )
        .add_service(pb::state_server::StateServer::new(StateService(c())).max_decoding_message_size(MAX_REQUEST_BYTES))
        .add_service(pb::sdo_server::SdoServer::new(SdoService(c())).max_decoding_message_size(MAX_REQUEST_BYTES))
        .add_service(pb::sii_server::SiiServer::new(SiiService(c())).max_decoding_message_size(MAX_REQUEST_BYTES))
        .add_service(
            pb::process_data_server::ProcessDataServer::new(ProcessDataService(c()))
                .max_decoding_message_size(MAX_REQUEST_BYTES),
        )
        .add_service(
            pb::cia402_server::Cia402Server::new(Cia402Service(c())).max_decoding_message_size(MAX_REQUEST_BYTES),
        )
        .add_service(
            pb::peripherals_server::PeripheralsServer::new(PeripheralsService(c()))
                .max_decoding_message_size(MAX_REQUEST_BYTES),
        )
        .add_service(pb::foe_server::FoeServer::new(FoeService(c())).max_decoding_message_size(MAX_REQUEST_BYTES))
        .add_service(
            pb::registers_server::RegistersServer::new(RegistersService(c()))
                .max_decoding_message_size(MAX_REQUEST_BYTES),
        )
        .add_service(
            pb::diagnostics_server::DiagnosticsServer::new(DiagnosticsService(c()))
                .max_decoding_message_size(MAX_REQUEST_BYTES),
        ))
}

/// Binds the Unix socket: parent folder created if missing, a stale file
/// replaced, mode and group applied.
fn bind_socket(path: &Path, config: &ApiConfig) -> Result<UnixListener, ServeError> {
    use SocketProblem as P;
    let err = |problem: SocketProblem| ServeError::Socket(path.to_owned(), problem);
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| err(P::CreateFolder(e)))?;
    }
    // Only a socket nobody serves may be replaced: anything else at that
    // path (a regular file, a folder, a typo pointing at a config) stays.
    if let Ok(meta) = std::fs::symlink_metadata(path) {
        use std::os::unix::fs::FileTypeExt;
        if !meta.file_type().is_socket() {
            return Err(err(P::NotASocket(describe(&meta.file_type()))));
        }
        if std::os::unix::net::UnixStream::connect(path).is_ok() {
            return Err(err(P::Served));
        }
        std::fs::remove_file(path).map_err(|e| err(P::RemoveStale(e)))?;
    }
    let listener = UnixListener::bind(path).map_err(|e| err(P::Bind(e)))?;
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(config.socket_mode))
        .map_err(|e| err(P::Mode(config.socket_mode, e)))?;
    if let Some(group) = &config.socket_group {
        let gid = match group.parse::<u32>() {
            Ok(g) => nix::unistd::Gid::from_raw(g),
            Err(_) => match nix::unistd::Group::from_name(group) {
                Ok(Some(g)) => g.gid,
                _ => return Err(err(P::NoGroup(group.clone()))),
            },
        };
        nix::unistd::chown(path, None, Some(gid)).map_err(|e| err(P::Chown(group.clone(), e)))?;
    }
    Ok(listener)
}

fn describe(t: &std::fs::FileType) -> &'static str {
    if t.is_dir() {
        "a folder"
    } else if t.is_symlink() {
        "a symbolic link"
    } else if t.is_file() {
        "a regular file"
    } else {
        "a special file"
    }
}

/// The TLS acceptor of `api.tcp`: the server's chain and key, client
/// certificates verified against `api.client_ca` when set but optional (a
/// caller may bring a token instead; daemon/src/api/auth.rs decides), and
/// HTTP/2 by ALPN (gRPC needs it).
fn tls(config: &ApiConfig) -> Result<tokio_rustls::TlsAcceptor, ServeError> {
    let read = |p: &Option<PathBuf>, what: &'static str| -> Result<Vec<u8>, ServeError> {
        let p = p.as_ref().ok_or(ServeError::TlsNotSet(what))?;
        std::fs::read(p).map_err(|source| ServeError::TlsFile { key: what, path: p.clone(), source })
    };
    let certs = |pem: &[u8], what: &'static str| -> Result<Vec<CertificateDer<'static>>, ServeError> {
        let certs = CertificateDer::pem_slice_iter(pem)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| ServeError::TlsContent(what, format!("not PEM certificates: {e}")))?;
        if certs.is_empty() {
            return Err(ServeError::TlsContent(what, "no PEM certificate in the file".into()));
        }
        Ok(certs)
    };
    let chain = certs(&read(&config.tls_cert, "tls_cert")?, "tls_cert")?;
    let key = PrivateKeyDer::from_pem_slice(&read(&config.tls_key, "tls_key")?)
        .map_err(|e| ServeError::TlsContent("tls_key", format!("no PEM private key: {e}")))?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let builder = rustls::ServerConfig::builder_with_provider(Arc::clone(&provider))
        .with_safe_default_protocol_versions()
        .map_err(|e| ServeError::TlsContent("tls_cert", e.to_string()))?;
    let builder = if config.client_ca.is_some() {
        let mut roots = rustls::RootCertStore::empty();
        for ca in certs(&read(&config.client_ca, "client_ca")?, "client_ca")? {
            roots.add(ca).map_err(|e| ServeError::TlsContent("client_ca", e.to_string()))?;
        }
        let verifier = rustls::server::WebPkiClientVerifier::builder_with_provider(Arc::new(roots), provider)
            .allow_unauthenticated()
            .build()
            .map_err(|e| ServeError::TlsContent("client_ca", e.to_string()))?;
        builder.with_client_cert_verifier(verifier)
    } else {
        builder.with_no_client_auth()
    };
    let mut tls = builder.with_single_cert(chain, key).map_err(|e| ServeError::TlsContent("tls_key", e.to_string()))?;
    tls.alpn_protocols = vec![b"h2".to_vec()];
    Ok(tokio_rustls::TlsAcceptor::from(Arc::new(tls)))
}

/// Health follows the bus: SERVING while the engine runs, the network is in
/// the configured target state and process data flows ([`Master::health`]),
/// NOT_SERVING otherwise (bringing up, recovering, a slave dropped out of
/// OP, no input frame for longer than the limit). Judged again on every
/// snapshot the engine announces (a phase or state change at once) and at
/// the moment the newest input frame passes its limit, so a stall shows on
/// time even when a wedged engine announces nothing.
async fn track_health(master: Arc<Master>, reporter: HealthReporter) {
    let mut changes = master.watch_status();
    let mut last = None;
    loop {
        let s = *changes.borrow_and_update();
        let now = master.now_ns();
        let serving = master.health_of(&s, now).is_healthy();
        if last != Some(serving) {
            last = Some(serving);
            let status = if serving { ServingStatus::Serving } else { ServingStatus::NotServing };
            for name in SERVICES {
                reporter.set_service_status(name, status).await;
            }
        }
        // Only a new snapshot can end a stall; a fresh frame gets stale.
        let stale_in = s.input_age(now).and_then(|(age, limit)| (age <= limit).then(|| limit - age));
        let changed = match stale_in {
            Some(d) => tokio::time::timeout(d + Duration::from_millis(1), changes.changed()).await.unwrap_or(Ok(())),
            None => changes.changed().await,
        };
        if changed.is_err() {
            return;
        }
    }
}

/// Serves the API until `shutdown` changes; removes the socket file after.
pub(crate) async fn serve(
    ctx: Arc<Context>,
    config: ApiConfig,
    mut shutdown: watch::Receiver<()>,
) -> Result<(), ServeError> {
    let (reporter, health) = tonic_health::server::health_reporter();
    for name in SERVICES {
        reporter.set_service_status(name, ServingStatus::NotServing).await;
    }
    let routes = routes(&ctx, health)?;
    let path = config.socket_path();
    let listener = bind_socket(&path, &config)?;
    tracing::info!(socket = %path.display(), mode = format_args!("{:#o}", config.socket_mode), "API listening");

    let mut tasks = tokio::task::JoinSet::new();
    tasks.spawn(track_health(Arc::clone(&ctx.master), reporter));
    let sweeper = Arc::clone(&ctx);
    tasks.spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_millis(50));
        loop {
            tick.tick().await;
            sweeper.master.sweep_leases();
        }
    });

    let deadline = Duration::from_millis(config.handshake_timeout_ms.into());
    let keepalive = Duration::from_secs(config.keepalive_s.into());
    // HTTP/2 PINGs find peers that vanished without a FIN (a cable pulled,
    // a host powered off) and close their connections.
    let server = || {
        Server::builder()
            .http2_keepalive_interval(Some(keepalive))
            .http2_keepalive_timeout(Some(keepalive))
            .layer(ErrorDetailsLayer)
    };
    let unix_gate = Gate::new(
        "api.socket",
        Cap { limit: config.max_socket_connections as usize, key: "api.max_socket_connections" },
        None,
    );
    let (unix_tx, unix_rx) = mpsc::channel(16);
    tasks.spawn(admission::admit_loop(listener, unix_gate, deadline, |io| async move { Ok(io) }, unix_tx));
    let mut stop = shutdown.clone();
    // Socket paths as `:authority` (grpcio, grpc-java) made `localhost`:
    // api/authority.rs.
    let unix = server().add_routes(routes.clone()).serve_with_incoming_shutdown(
        ReceiverStream::new(unix_rx).map(|conn| Ok::<_, std::io::Error>(super::authority::AuthorityFix::new(conn))),
        async move {
            let _ = stop.changed().await;
        },
    );
    let result = if let Some(addr) = config.tcp {
        let acceptor = tls(&config)?;
        let listener = TcpListener::bind(addr).await.map_err(|e| ServeError::Bind(addr, e))?;
        let gate = Gate::new(
            "api.tcp",
            Cap { limit: config.max_connections as usize, key: "api.max_connections" },
            Some(Cap { limit: config.max_connections_per_peer as usize, key: "api.max_connections_per_peer" }),
        );
        let (tcp_tx, tcp_rx) = mpsc::channel(16);
        let handshake = move |io: tokio::net::TcpStream| {
            let acceptor = acceptor.clone();
            async move {
                let _ = io.set_nodelay(true);
                // TCP keepalive closes what HTTP/2 PINGs cannot reach: a
                // connection whose peer went away before its first frame.
                let probes = socket2::TcpKeepalive::new().with_time(keepalive).with_interval(keepalive);
                let _ = socket2::SockRef::from(&io).set_tcp_keepalive(&probes);
                acceptor.accept(io).await
            }
        };
        tasks.spawn(admission::admit_loop(listener, gate, deadline, handshake, tcp_tx));
        let tcp = server().add_routes(routes).serve_with_incoming_shutdown(
            ReceiverStream::new(tcp_rx).map(Ok::<_, std::io::Error>),
            async move {
                let _ = shutdown.changed().await;
            },
        );
        tracing::info!(%addr, "API listening on TCP (TLS)");
        tokio::try_join!(unix, tcp).map(|_| ())
    } else {
        unix.await
    };
    tasks.abort_all();
    let _ = std::fs::remove_file(&path);
    result.map_err(ServeError::Transport)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ecmxfd-sock-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[tokio::test]
    async fn only_a_stale_socket_is_replaced() {
        let d = dir("rule");
        let config = ApiConfig::default();
        let file = d.join("ecmxfd.sock");
        std::fs::write(&file, "precious").unwrap();
        let e = bind_socket(&file, &config).unwrap_err().to_string();
        assert!(e.contains(&file.display().to_string()) && e.contains("a regular file"), "{e}");
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "precious", "left as it was");

        let stale = d.join("stale.sock");
        drop(std::os::unix::net::UnixListener::bind(&stale).unwrap());
        assert!(stale.exists(), "a socket nobody serves");
        bind_socket(&stale, &config).expect("a stale socket is replaced");

        let served = d.join("served.sock");
        let _live = std::os::unix::net::UnixListener::bind(&served).unwrap();
        let e = bind_socket(&served, &config).unwrap_err().to_string();
        assert!(e.contains("another daemon"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }
}
