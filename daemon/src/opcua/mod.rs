//! The OPC UA server (docs/opcua.md): what SCADA, historians and HMIs
//! already speak. With `[opcua]` (and on loopback with `ecmxfd --sim`)
//! ecmxfd serves `opc.tcp://HOST:PORT/` with the master's state and
//! counters, one object per slave (identity as the DI companion
//! specification names it, EtherCAT state, AL status code) and one
//! variable per process-image entry ([`space`]); the daemon's events as
//! OPC UA events ([`events`]).
//!
//! A front end like the gRPC API, beside it: it reads the engine's
//! published snapshots (status, newest input frame, output shadow, the
//! laid-out image) when a client reads or a monitored item samples, so the
//! cyclic path never waits on it. The server is async-opcua's (a
//! maintained pure-Rust OPC UA stack, MPL-2.0; its cryptography is
//! RustCrypto, no C library to cross-compile); this module builds its
//! address space and keeps it matching the network: when bring-up finds
//! other slaves or the image is laid out again, the slaves' nodes are
//! replaced.
//!
//! Sessions have the daemon's roles ([`access`]): anonymous ones observe
//! unless the file says otherwise; operators write outputs under a lease
//! bound to their session ([`writes`]) and call the slaves' methods
//! ([`methods`]). The endpoints are Basic256Sha256 and
//! Aes128_Sha256_RsaOaep, signed and encrypted, with a certificate the
//! daemon makes at first start under `pki/` (and the `trusted/` and
//! `rejected/` folders OPC UA tools expect), and SecurityPolicy None for
//! anonymous sessions on loopback (on the network only if
//! `insecure_on_network` says so).

mod access;
mod dictionary;
mod events;
mod gate;
mod manager;
mod methods;
mod refusal;
mod space;
mod trust;
mod values;
mod writes;

use std::net::SocketAddr;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use opcua::crypto::SecurityPolicy;
use opcua::server::{ANONYMOUS_USER_TOKEN_ID, ServerBuilder, ServerEndpoint, ServerHandle, ServerUserToken};
use opcua::types::{BuildInfo, DateTime, MessageSecurityMode, NodeId, VariableId, Variant};
use tokio::net::TcpListener;
use tokio::sync::{broadcast, watch};
use tokio::task::JoinSet;
use tracing::{info, warn};

use crate::admission::{Cap, Gate};
use crate::config::OpcuaConfig;
use crate::master::device_dictionary::DeviceDictionary;
use crate::master::image::Image;
use crate::master::opcua_state::OpcuaState;
use crate::master::{Call, EventKind, Master, Phase, SlaveSummary};
use access::Access;
use manager::Plant;
use space::{AlStates, Ids, SlaveNodes};

/// The daemon's namespace.
pub const NAMESPACE_URI: &str = "urn:ecmxf:ecmxfd";

/// How long the server gets to close its sessions at shutdown.
const STOP_WITHIN: Duration = Duration::from_millis(500);

/// Why the server could not start.
#[derive(Debug)]
pub enum OpcuaError {
    /// `listen` could not be bound.
    Listen {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The server refused its own configuration.
    Server(String),
}

impl std::fmt::Display for OpcuaError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Listen { addr, source } => write!(f, "opcua.listen {addr}: {source}"),
            Self::Server(why) => write!(f, "opcua: {why}"),
        }
    }
}

impl std::error::Error for OpcuaError {}

/// The server's listeners: the public one, where [`gate`] admits
/// connections, and the server's own on loopback, where they are spliced.
#[derive(Debug)]
pub struct Listeners {
    public: TcpListener,
    inner: TcpListener,
}

/// Binds `[opcua]`'s address (before the bus starts, so a taken port is an
/// error at start, as for every listener) and the server's own.
pub async fn bind(config: &OpcuaConfig) -> Result<Listeners, OpcuaError> {
    let public =
        TcpListener::bind(config.listen).await.map_err(|source| OpcuaError::Listen { addr: config.listen, source })?;
    let loopback = SocketAddr::from(([127, 0, 0, 1], 0));
    let inner = TcpListener::bind(loopback).await.map_err(|source| OpcuaError::Listen { addr: loopback, source })?;
    Ok(Listeners { public, inner })
}

/// Serves OPC UA on `listeners` until `stopped` changes (or its sender is
/// dropped).
pub async fn serve(master: Arc<Master>, config: OpcuaConfig, listeners: Listeners, mut stopped: watch::Receiver<()>) {
    // The first start makes the server's RSA key pair: seconds on a slow
    // core, never on the runtime's threads.
    let pki = config.pki_dir.clone().unwrap_or_else(|| pki_dir(&master));
    let built = {
        let (config, master, pki) = (config.clone(), Arc::clone(&master), pki.clone());
        tokio::task::spawn_blocking(move || build(&config, pki, master))
    };
    let (server, handle) = match built.await {
        Ok(Ok(built)) => built,
        Ok(Err(e)) => {
            warn!("opcua: {e}");
            return;
        }
        Err(e) => {
            warn!("opcua: the server could not be built: {e}");
            return;
        }
    };
    let Ok(inner) = listeners.inner.local_addr() else { return };
    let mut running = tokio::spawn(server.run_with(listeners.inner));
    let gate = Gate::new(
        "opcua.listen",
        Cap { limit: config.max_connections as usize, key: "opcua.max_connections" },
        Some(Cap { limit: config.max_connections_per_peer as usize, key: "opcua.max_connections_per_peer" }),
    );
    let hello = Duration::from_secs(config.hello_timeout_s.into());
    let inside = gate::Inside {
        server: inner,
        trusted: Arc::new(pki.join("trusted")),
        info: Arc::clone(handle.info()),
        public_port: listeners.public.local_addr().map_or(config.listen.port(), |a| a.port()),
    };
    let door = tokio::spawn(gate::admit_loop(listeners.public, gate, hello, inside, stopped.clone()));
    info!(listen = %config.listen, "opcua: serving opc.tcp://{}/", config.listen);
    let keeper = tokio::spawn(keep_matching(Arc::clone(&master), handle.clone(), config.dictionaries));
    let leases = tokio::spawn(keep_sessions(master.lease_ttl(), handle.clone(), Arc::clone(master.opcua_state())));
    tokio::select! {
        _ = stopped.changed() => {}
        r = &mut running => {
            match r {
                Ok(Ok(())) => warn!("opcua: the server ended"),
                Ok(Err(e)) => warn!("opcua: the server ended: {e}"),
                Err(e) => warn!("opcua: the server ended: {e}"),
            }
            keeper.abort();
            leases.abort();
            door.abort();
            return;
        }
    }
    keeper.abort();
    leases.abort();
    door.abort();
    handle.cancel();
    if tokio::time::timeout(STOP_WITHIN, &mut running).await.is_err() {
        warn!("opcua: the server did not close its sessions within {} ms; cut", STOP_WITHIN.as_millis());
        running.abort();
    }
}

/// Where the server keeps certificates (`trusted/`, `rejected/`, as OPC UA
/// tools expect): `pki/` under the state directory, else under the
/// system's temporary directory (the daemon keeps nothing there).
fn pki_dir(master: &Master) -> std::path::PathBuf {
    let state = master.config().state_dir.clone().or_else(|| std::env::var_os("STATE_DIRECTORY").map(Into::into));
    state.map_or_else(|| std::env::temp_dir().join(format!("ecmxfd-{}-pki", nix::unistd::getuid())), |d| d.join("pki"))
}

fn build(
    config: &OpcuaConfig,
    pki: std::path::PathBuf,
    master: Arc<Master>,
) -> Result<(opcua::server::Server, ServerHandle), OpcuaError> {
    let ip = config.listen.ip();
    let host = if ip.is_unspecified() { hostname() } else { ip.to_string() };
    let access = Arc::new(Access::new(config));
    let mut secure_users = Vec::new();
    if access.takes_anonymous() {
        secure_users.push(ANONYMOUS_USER_TOKEN_ID.to_string());
    }
    secure_users.push(access::NAMED_USERS.to_string());
    let mut builder = ServerBuilder::new()
        .application_name("ecmxfd")
        .application_uri(format!("urn:ecmxf:ecmxfd:{}", hostname()))
        .product_uri("urn:ecmxf:ecmxfd")
        .build_info(BuildInfo {
            product_uri: "urn:ecmxf:ecmxfd".into(),
            manufacturer_name: "ecmxf".into(),
            product_name: "ecmxfd EtherCAT master".into(),
            software_version: env!("CARGO_PKG_VERSION").into(),
            build_number: env!("CARGO_PKG_VERSION").into(),
            build_date: DateTime::now(),
        })
        .host(host.clone())
        .port(config.listen.port())
        .hello_timeout(config.hello_timeout_s)
        .max_sessions(config.max_sessions as usize)
        // The server's subscription tick: a sample waits at most this for
        // its publishing slot (at the default 100 ms a value could reach a
        // client 200 ms after its frame; 20 ms of ticks cost nothing seen
        // in ecmxfd-bench).
        .subscription_poll_interval_ms(20)
        // Its session and subscription counts (the Server object's
        // diagnostics; the metrics read the session count).
        .diagnostics_enabled(true)
        // The server's certificate: made at first start (RSA 2048, for
        // the application URI, the host name and addresses), kept under
        // pki/own and pki/private. A client's certificate is trusted once
        // it is in pki/trusted; an unknown one is copied to pki/rejected
        // and refused.
        .create_sample_keypair(true)
        .pki_dir(pki)
        .trust_client_certs(false)
        .check_cert_time(true)
        .discovery_urls(vec![format!("opc.tcp://{host}:{}/", config.listen.port())])
        .with_authenticator(Arc::clone(&access) as Arc<dyn opcua::server::authenticator::AuthManager>)
        // Who named users are is `access`'s to say; the stack wants the id
        // the endpoints list to exist.
        .add_user_token(access::NAMED_USERS, ServerUserToken::user_pass("named users", "-"))
        .add_endpoint(
            "basic256sha256",
            ServerEndpoint::new(
                "/",
                SecurityPolicy::Basic256Sha256,
                MessageSecurityMode::SignAndEncrypt,
                &secure_users,
            ),
        )
        .add_endpoint(
            "aes128_sha256_rsaoaep",
            ServerEndpoint::new(
                "/",
                SecurityPolicy::Aes128Sha256RsaOaep,
                MessageSecurityMode::SignAndEncrypt,
                &secure_users,
            ),
        )
        .with_node_manager(manager::plant(NAMESPACE_URI, master, Arc::clone(&access)));
    // Without security: anonymous sessions only (a password would travel
    // in clear), on loopback unless the file asks for the network.
    if config.serves_without_security() {
        builder = builder.add_endpoint("none", ServerEndpoint::new_none("/", &[ANONYMOUS_USER_TOKEN_ID.to_string()]));
    }
    let limits = &mut builder.limits_mut().subscriptions;
    limits.max_monitored_items_per_sub = 10_000;
    limits.min_sampling_interval_ms = manager::SAMPLING_FLOOR_MS;
    // A client that asks for faster publishing (an alarm view at 50 ms)
    // gets it, down to the subscription tick; the library's floor is
    // 100 ms.
    limits.min_publishing_interval_ms = 20.0;
    builder.build().map_err(OpcuaError::Server)
}

/// Keeps the leases of live sessions alive and releases those of ended
/// ones, four times per lease time-to-live; counts the sessions open for
/// the metrics as it goes.
async fn keep_sessions(ttl: Duration, handle: ServerHandle, counters: Arc<OpcuaState>) {
    let Some(nm) = handle.node_managers().get_of_type::<Plant>() else { return };
    counters.enabled.store(true, Relaxed);
    let open = VariableId::Server_ServerDiagnostics_ServerDiagnosticsSummary_CurrentSessionCount;
    let mut every = tokio::time::interval(ttl / 4);
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        every.tick().await;
        if nm.inner().leases().any() {
            nm.inner().leases().keep();
        }
        if let Some(Variant::UInt32(n)) = handle.info().diagnostics.get(open).and_then(|v| v.value) {
            counters.sessions.store(u64::from(n), Relaxed);
        }
    }
}

fn hostname() -> String {
    nix::unistd::gethostname().ok().and_then(|h| h.into_string().ok()).unwrap_or_else(|| "localhost".into())
}

/// Keeps the address space matching the network: the master's nodes once,
/// each slave's again whenever the slaves or their image change; the AL
/// states slaves report, for their State variables; each slave's
/// dictionary once the daemon has it (read in the background, as the
/// daemon's own work, when `opcua.dictionaries` asks for it).
async fn keep_matching(master: Arc<Master>, handle: ServerHandle, dictionaries: bool) {
    let Some(nm) = handle.node_managers().get_of_type::<Plant>() else { return };
    let Some(ns) = handle.get_namespace_index(NAMESPACE_URI) else { return };
    let ids = Ids::new(ns);
    let al: Arc<AlStates> = Arc::new(Mutex::new(Default::default()));
    space::add_master(&nm, &ids, &master);
    let mut images = master.watch_images();
    let mut status = master.watch_status();
    let mut events = master.events();
    // The slaves and the image the nodes show (the image held, so a new
    // one is never taken for it).
    let mut shown: Option<(Vec<SlaveSummary>, Option<Arc<Image>>)> = None;
    let mut added: Vec<NodeId> = Vec::new();
    // Dictionaries read for the nodes shown: (slave, its dictionary).
    let mut reads: JoinSet<Option<(u8, Arc<DeviceDictionary>)>> = JoinSet::new();
    loop {
        let slaves = master.layout().slaves;
        let image = master.current_image().and_then(Result::ok);
        let same = shown.as_ref().is_some_and(|(s, i)| {
            *s == slaves
                && match (i, &image) {
                    (Some(a), Some(b)) => Arc::ptr_eq(a, b),
                    (None, None) => true,
                    _ => false,
                }
        });
        if !same {
            // Under one lock: a client never finds a slave's nodes gone
            // while they are made again.
            let mut tree = nm.address_space().write();
            space::remove(&nm, &mut tree, &added);
            added.clear();
            // Reads for the slaves shown before answer for nodes gone.
            reads.abort_all();
            for (p, summary) in slaves.iter().enumerate().take(256) {
                let slave = SlaveNodes { position: p as u8, summary, image: image.as_ref() };
                added.extend(space::add_slave(&nm, &mut tree, &ids, &master, &al, &slave));
                if dictionaries {
                    let master = Arc::clone(&master);
                    reads.spawn(async move {
                        let p = p as u8;
                        master.device_dictionary(p, Call::daemon()).await.ok().map(|d| (p, d))
                    });
                }
            }
            added.extend(space::add_axes(&nm, &mut tree, &ids, &master, &slaves));
            drop(tree);
            shown = Some((slaves, image));
        }
        let seen = status.borrow_and_update().key();
        tokio::select! {
            r = images.changed() => if r.is_err() { return },
            r = status.wait_for(|s| s.key() != seen) => if r.is_err() { return },
            read = reads.join_next(), if !reads.is_empty() => {
                // A read for nodes since replaced was aborted; one the
                // device could not answer leaves no folder.
                if let Some(Ok(Some((p, d)))) = read {
                    added.extend(space::add_dictionary(&nm, &ids, p, &d.to_od()));
                }
            }
            e = events.recv() => match e {
                Ok(e) => {
                    track_al(&al, &e.kind);
                    events::notify(handle.subscriptions(), &ids, &master, &e);
                }
                Err(broadcast::error::RecvError::Lagged(_)) => {}
                Err(broadcast::error::RecvError::Closed) => return,
            },
        }
    }
}

/// What a slave reported of its AL state, since the network last came up.
fn track_al(al: &AlStates, kind: &EventKind) {
    let mut al = al.lock().unwrap_or_else(|e| e.into_inner());
    match kind {
        EventKind::AlStatus { slave, state, code } => {
            al.insert(*slave, (*state, *code));
        }
        EventKind::Phase(Phase::Running) => al.clear(),
        _ => {}
    }
}
