//! Serving: the Unix socket (created with the configured mode and group;
//! a stale socket file from a crash is replaced, a live one is an error),
//! optional TCP with TLS, health and reflection, and the background tasks
//! the services rely on (the newest inputs for CiA 402 values, gRPC health
//! from the bus state).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use tokio::net::UnixListener;
use tokio::sync::watch;
use tokio_stream::wrappers::UnixListenerStream;
use tonic::server::NamedService;
use tonic::service::Routes;
use tonic::transport::{Certificate, Identity, Server, ServerTlsConfig};
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
            Self::Reflection(e) => write!(f, "API server: reflection: {e}"),
            Self::Transport(e) => write!(f, "API server: {e}"),
        }
    }
}

impl std::error::Error for ServeError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Socket(_, p) => p.source(),
            Self::TlsFile { source, .. } => Some(source),
            Self::Reflection(e) => Some(e),
            Self::Transport(e) => Some(e),
            Self::TlsNotSet(_) => None,
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
        .build_v1()
        .map_err(ServeError::Reflection)?;
    let v1alpha = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(pb::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
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

fn tls(config: &ApiConfig) -> Result<ServerTlsConfig, ServeError> {
    let read = |p: &Option<PathBuf>, what: &'static str| -> Result<Vec<u8>, ServeError> {
        let p = p.as_ref().ok_or(ServeError::TlsNotSet(what))?;
        std::fs::read(p).map_err(|source| ServeError::TlsFile { key: what, path: p.clone(), source })
    };
    let mut tls = ServerTlsConfig::new()
        .identity(Identity::from_pem(read(&config.tls_cert, "tls_cert")?, read(&config.tls_key, "tls_key")?));
    if config.client_ca.is_some() {
        tls =
            tls.client_ca_root(Certificate::from_pem(read(&config.client_ca, "client_ca")?)).client_auth_optional(true);
    }
    Ok(tls)
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

    let mut stop = shutdown.clone();
    let unix = Server::builder().layer(ErrorDetailsLayer).add_routes(routes.clone()).serve_with_incoming_shutdown(
        UnixListenerStream::new(listener),
        async move {
            let _ = stop.changed().await;
        },
    );
    let result = if let Some(addr) = config.tcp {
        let tcp = Server::builder()
            .tls_config(tls(&config)?)
            .map_err(ServeError::Transport)?
            .layer(ErrorDetailsLayer)
            .add_routes(routes)
            .serve_with_shutdown(addr, async move {
                let _ = shutdown.changed().await;
            });
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
