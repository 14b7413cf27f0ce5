//! The daemon's life, as a library: [`run`] starts the engine, the API and
//! the optional metrics endpoint from a [`Config`], serves until `shutdown`
//! completes, then brings the bus down safely. The binary (`main.rs`) only
//! parses arguments, sets up logging and turns signals into `shutdown` and
//! [`Options::reloads`]; tests and other programs embed the daemon the same
//! way (mini-redis' `server::run(listener, shutdown)` is the model).
//!
//! While it runs, everything it does on its own is driven by events: the
//! engine's snapshot [`watch`](crate::master::Master::watch_status) (the
//! first time the network runs, systemd's STATUS and READY, an engine that
//! stopped), the event stream (logged), reloads, and the watchdog and
//! status-line timers.

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{broadcast, mpsc};
use tracing::{info, warn};

use crate::api::Context;
use crate::api::server::ServeError;
use crate::config::Config;
use crate::master::{Failure, Master, Phase, Snapshot, StartError};
use crate::service::{Liveness, Logging, Notifier, ReloadPlan};

/// Why the daemon could not start, or ended without being asked to.
#[derive(Debug)]
pub enum DaemonError {
    /// The metrics endpoint could not listen (`metrics.listen`).
    Metrics {
        /// The address asked for.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The mailbox gateway could not listen (`gateway.listen`).
    Gateway(crate::gateway::GatewayError),
    /// The OPC UA server could not listen (`opcua.listen`).
    Opcua(crate::opcua::OpcuaError),
    /// The dashboard could not listen (`web.listen`).
    Web(crate::web::WebError),
    /// The Sparkplug node's TLS files or credentials did not load.
    Sparkplug(crate::sparkplug::SparkplugError),
    /// The engine could not start: the link, the simulator's network file.
    Start(StartError),
    /// The API server could not start or failed.
    Api(ServeError),
    /// The API server ended by itself.
    ApiEnded,
    /// A task of the daemon panicked or was cancelled: which, and how.
    Task(&'static str, tokio::task::JoinError),
    /// The engine stopped by itself (recovery disabled or given up); why it
    /// last failed, if it said.
    EngineStopped(Option<Failure>),
    /// The embedding program could not listen for signals (SIGTERM, SIGHUP).
    Signals(std::io::Error),
    /// The network can never run with this configuration (the link cannot
    /// carry its process data): why. Exit status [`EXIT_REFUSED`].
    NetworkRefused(Failure),
}

/// The exit status of a daemon whose configuration can never work: a
/// network the link budget refuses (EX_CONFIG of sysexits.h). The systemd
/// unit lists it in RestartPreventExitStatus=, so it is not restarted in a
/// loop; a configuration file that does not load exits 2, also listed.
pub const EXIT_REFUSED: u8 = 78;

impl DaemonError {
    /// The process exit status for this error, as `--check-config` gives
    /// it for the same finding: [`EXIT_REFUSED`] for a refused network,
    /// [`crate::EXIT_CONFIG`] for a file the configuration names that does
    /// not load (the simulator's network file, a TLS file), 1 otherwise.
    pub fn exit_status(&self) -> u8 {
        use crate::api::server::ServeError;
        match self {
            Self::NetworkRefused(_) => EXIT_REFUSED,
            Self::Start(StartError::Network(_)) | Self::Sparkplug(_) => crate::EXIT_CONFIG,
            Self::Api(ServeError::TlsNotSet(_) | ServeError::TlsFile { .. } | ServeError::TlsContent(..)) => {
                crate::EXIT_CONFIG
            }
            _ => 1,
        }
    }
}

impl std::fmt::Display for DaemonError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Metrics { addr, source } => write!(f, "metrics.listen {addr}: {source}"),
            Self::Gateway(e) => write!(f, "{e}"),
            Self::Opcua(e) => write!(f, "{e}"),
            Self::Web(e) => write!(f, "{e}"),
            Self::Sparkplug(e) => write!(f, "{e}"),
            Self::Start(e) => write!(f, "{e}"),
            Self::Api(e) => write!(f, "{e}"),
            Self::ApiEnded => f.write_str("the API server ended"),
            Self::Task(what, e) => write!(f, "{what} failed: {e}"),
            Self::EngineStopped(Some(why)) => write!(f, "the engine stopped: {why}"),
            Self::EngineStopped(None) => f.write_str("the engine stopped"),
            Self::Signals(e) => write!(f, "cannot listen for signals: {e}"),
            Self::NetworkRefused(why) => write!(
                f,
                "the network cannot run with this configuration, not retried (exit status {EXIT_REFUSED}): {why}"
            ),
        }
    }
}

impl std::error::Error for DaemonError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Metrics { source, .. } => Some(source),
            Self::Gateway(e) => Some(e),
            Self::Opcua(e) => Some(e),
            Self::Web(e) => Some(e),
            Self::Sparkplug(e) => Some(e),
            Self::Start(e) => Some(e),
            Self::Api(e) => Some(e),
            Self::Signals(e) => Some(e),
            _ => None,
        }
    }
}

impl From<StartError> for DaemonError {
    fn from(e: StartError) -> Self {
        Self::Start(e)
    }
}

/// How the daemon is embedded; [`Options::default`] is a daemon that
/// nobody reloads and that logs no status lines.
#[derive(Debug, Default)]
pub struct Options {
    /// Log a status line this often (`None`: never).
    pub status_every: Option<Duration>,
    /// The service manager to notify (inert when not under systemd).
    pub notifier: Option<Notifier>,
    /// The log filter, for reloads of `log.level`.
    pub logging: Option<Logging>,
    /// Configurations read again (SIGHUP): what can change while the bus
    /// runs is applied, the rest is named in the log.
    pub reloads: Option<mpsc::Receiver<Config>>,
}

/// How long open streams (events, inputs) get to end by themselves at
/// shutdown before their connections are cut.
const STREAM_GRACE: Duration = Duration::from_millis(200);

/// Runs the daemon until `shutdown` completes (or a fatal error): the
/// engine, the API, the optional metrics endpoint. Then the bus goes down
/// first (axes disabled, slaves to INIT within a second) while the API
/// stops taking calls.
pub async fn run(config: Config, shutdown: impl Future<Output = ()>) -> Result<(), DaemonError> {
    run_with(config, Options::default(), shutdown).await
}

/// [`run`], embedded as `options` say (systemd, reloads, status lines).
pub async fn run_with(config: Config, options: Options, shutdown: impl Future<Output = ()>) -> Result<(), DaemonError> {
    let notifier = options.notifier.unwrap_or_else(Notifier::disabled);
    let api = config.api.clone();
    // Every listener's connections at their caps, plus what the daemon
    // opens besides: the limit must cover the sum, or a full listener
    // fails accepts (and starves the others) instead of refusing cleanly.
    let connections = u64::from(api.max_socket_connections)
        + api.tcp.map_or(0, |_| u64::from(api.max_connections))
        + config.metrics.listen.map_or(0, |_| crate::metrics::MAX_CONNECTIONS as u64)
        // An OPC UA connection holds three: the peer's, and both ends of
        // its splice to the server on loopback.
        + config.opcua.as_ref().map_or(0, |o| 3 * u64::from(o.max_connections))
        + config.web.as_ref().map_or(0, |w| u64::from(w.max_connections));
    crate::admission::ensure_fd_budget(connections + crate::admission::FD_RESERVE);
    let metrics_listener = match config.metrics.listen {
        Some(addr) => Some(crate::metrics::bind(addr).await.map_err(|source| DaemonError::Metrics { addr, source })?),
        None => None,
    };
    let gateway = match &config.gateway {
        Some(g) => Some((g.clone(), crate::gateway::bind(g).await.map_err(DaemonError::Gateway)?)),
        None => None,
    };
    let opcua = match &config.opcua {
        Some(o) => match crate::opcua::bind(o).await {
            Ok(l) => Some((o.clone(), l)),
            // `ecmxfd --sim`'s own server on loopback is a convenience: a
            // port another daemon holds does not stop this one.
            Err(e) if o.best_effort => {
                warn!("{e}: serving no OPC UA");
                None
            }
            Err(e) => return Err(DaemonError::Opcua(e)),
        },
        None => None,
    };
    let web = match &config.web {
        Some(w) => match crate::web::bind(w).await {
            Ok(l) => Some((w.clone(), l)),
            // `ecmxfd --sim`'s own dashboard on loopback is a convenience:
            // a port another program holds does not stop this daemon.
            Err(e) if w.best_effort => {
                warn!("{e}: serving no dashboard");
                None
            }
            Err(e) => return Err(DaemonError::Web(e)),
        },
        None => None,
    };
    let sparkplug = match &config.sparkplug {
        Some(s) => Some(crate::sparkplug::prepare(s).map_err(DaemonError::Sparkplug)?),
        None => None,
    };
    let mut running = config.clone();
    let (master, _sim) = Master::from_config(config)?;
    let master = Arc::new(master);
    let ctx = Context::new(Arc::clone(&master), &api, nix::unistd::getuid().as_raw());
    let layout_builder = tokio::spawn({
        let ctx = Arc::clone(&ctx);
        async move { Arc::clone(&ctx.master).keep_image_built().await }
    });
    let setups_reader = tokio::spawn(Arc::clone(&master).keep_slave_setups_read());
    let (stop_api, api_stopped) = tokio::sync::watch::channel(());
    // Front ends beside the API, each ending when the API stops; joined at
    // shutdown.
    let mut front_ends = tokio::task::JoinSet::new();
    if let Some(l) = metrics_listener {
        let sources =
            crate::metrics::Sources { master: Arc::clone(&master), sdo_latency: Arc::clone(&ctx.sdo_latency) };
        front_ends.spawn(crate::metrics::serve(sources, l, api_stopped.clone()));
    }
    if let Some((g, socket)) = gateway {
        front_ends.spawn(crate::gateway::serve(Arc::clone(&master), g, socket, api_stopped.clone()));
    }
    if let Some((o, listener)) = opcua {
        front_ends.spawn(crate::opcua::serve(Arc::clone(&master), o, listener, api_stopped.clone()));
    }
    if let Some((w, listener)) = web {
        let (tokens, certificates) = (api.tokens.clone(), api.client_certs.clone());
        front_ends.spawn(crate::web::serve(
            Arc::clone(&master),
            w,
            tokens,
            certificates,
            listener,
            api_stopped.clone(),
        ));
    }
    let mut sparkplug_node = crate::sparkplug::Runner::new(Arc::clone(&master));
    if let Some(prepared) = sparkplug {
        sparkplug_node.start(prepared);
    }
    let mut server = tokio::spawn(crate::api::server::serve(Arc::clone(&ctx), api, api_stopped));
    let status_every = options.status_every;
    let mut ticker = tokio::time::interval(status_every.unwrap_or(Duration::from_secs(3600)));
    ticker.tick().await;
    let watchdog_every = Notifier::watchdog_interval();
    let mut watchdog = tokio::time::interval(watchdog_every.unwrap_or(Duration::from_secs(3600)));
    let mut liveness = Liveness::default();
    let mut announcer = Announcer::default();
    let mut changes = master.watch_status();
    let mut events = master.events();
    let mut events_open = true;
    let mut event_log = crate::master::EventLog::default();
    let mut reloads = options.reloads;
    let logging = options.logging;
    if let Some(l) = &logging {
        let _ = ctx.log_filter.set(Arc::new(l.clone()));
    }
    info!(logs = logging.as_ref().map_or("(embedded)", |l| l.sink), systemd = notifier.enabled(), watchdog = ?watchdog_every, "service");
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            e = events.recv(), if events_open => match e {
                Ok(e) => event_log.log(&e, std::time::Instant::now()),
                Err(broadcast::error::RecvError::Lagged(n)) => info!("{n} events not logged"),
                Err(broadcast::error::RecvError::Closed) => events_open = false,
            },
            r = &mut server => {
                let why = match r {
                    Ok(Ok(())) => DaemonError::ApiEnded,
                    Ok(Err(e)) => DaemonError::Api(e),
                    Err(e) => DaemonError::Task("the API server", e),
                };
                notifier.send(&format!("STOPPING=1\nSTATUS=failed: {why}"));
                layout_builder.abort();
                setups_reader.abort();
                let m = Arc::clone(&master);
                tokio::task::spawn_blocking(move || m.stop()).await.map_err(|e| DaemonError::Task("stopping the engine", e))?;
                return Err(why);
            }
            () = &mut shutdown => break,
            Some(new) = async { reloads.as_mut()?.recv().await }, if reloads.is_some() => {
                notifier.send("RELOADING=1");
                reload(&mut running, new, &ctx, logging.as_ref(), &mut sparkplug_node).await;
                notifier.send(&format!("READY=1\nSTATUS={}", service_status(&master)));
            }
            _ = watchdog.tick(), if watchdog_every.is_some() => {
                let s = master.status();
                match liveness.verdict(&s, master.health()) {
                    Ok(()) => notifier.send("WATCHDOG=1"),
                    Err(why) => warn!(phase = ?s.phase, exchanges = s.exchanges, "{why}: not pinging the watchdog"),
                }
            }
            _ = ticker.tick(), if status_every.is_some() => info!("{}", status_line(&master.status())),
            () = async { tokio::time::sleep_until(event_log.spell_ends().unwrap_or_else(std::time::Instant::now).into()).await }, if event_log.spell_ends().is_some() => {
                event_log.end_spell();
            }
            r = changes.changed() => {
                if r.is_err() {
                    continue;
                }
                let s = *changes.borrow_and_update();
                announcer.snapshot(&s, &master, &notifier)?;
            }
        }
    }
    event_log.end_spell();
    // The bus first and at once: axes disabled and slaves in INIT within a
    // second, whatever clients are attached. The API stops taking calls
    // meanwhile; streams still open after a short grace are cut.
    notifier.send("STOPPING=1\nSTATUS=stopping: bringing the network down");
    let started = std::time::Instant::now();
    let bus = tokio::task::spawn_blocking({
        let master = Arc::clone(&master);
        move || master.stop()
    });
    ctx.stop_streams();
    let _ = stop_api.send(());
    // NDEATH while the bus goes down (at most a second or so).
    sparkplug_node.stop().await;
    layout_builder.abort();
    setups_reader.abort();
    if tokio::time::timeout(STREAM_GRACE, &mut server).await.is_err() {
        server.abort();
        let _ = server.await;
    }
    // Every task the daemon started ends before it returns: the front ends
    // saw the API stop; whatever is still busy after the grace is cut.
    if tokio::time::timeout(STREAM_GRACE, async { while front_ends.join_next().await.is_some() {} }).await.is_err() {
        front_ends.shutdown().await;
    }
    let _ = layout_builder.await;
    let _ = setups_reader.await;
    bus.await.map_err(|e| DaemonError::Task("stopping the engine", e))?;
    info!(took_ms = started.elapsed().as_millis() as u64, "stopped");
    Ok(())
}

/// What the daemon says about the engine's snapshots: the network the
/// first time it runs, systemd's STATUS when it changes, READY once.
#[derive(Debug, Default)]
struct Announcer {
    announced: bool,
    ready: bool,
    status_sent: String,
    status_key: Option<(Phase, ecmxf_wire::EcatState, u64, u64)>,
}

impl Announcer {
    fn snapshot(&mut self, s: &Snapshot, master: &Master, notifier: &Notifier) -> Result<(), DaemonError> {
        if s.phase == Phase::Running && !self.announced {
            self.announced = true;
            let l = master.layout();
            for (i, s) in l.slaves.iter().enumerate() {
                info!(position = i, name = %s.name, vendor = format_args!("{:#010x}", s.vendor_id), product = format_args!("{:#010x}", s.product_code), revision = format_args!("{:#010x}", s.revision), outputs = s.rx_bytes, inputs = s.tx_bytes, "slave");
            }
            info!(state = %l.state, firmware = format_args!("{:#04x}", l.firmware), "ready");
        }
        // The status line is rebuilt (layout and config cloned) only when
        // what it shows may have changed, and only for systemd.
        if notifier.enabled() && self.status_key != Some(s.key()) {
            self.status_key = Some(s.key());
            let status = service_status(master);
            if status != self.status_sent {
                notifier.send(&format!("STATUS={status}"));
                self.status_sent = status;
            }
        }
        // READY only once bring-up reached the configured state and
        // process data flows.
        if !self.ready && master.health_of(s, master.now_ns()).is_healthy() {
            self.ready = true;
            notifier.send(&format!("READY=1\nSTATUS={}", self.status_sent));
        }
        if s.phase == Phase::Stopped {
            if let Some(why) = master.last_error().filter(|f| master.refused() && f.is_permanent()) {
                notifier.send(&format!("STOPPING=1\nSTATUS=refused: {why}"));
                return Err(DaemonError::NetworkRefused(why));
            }
            notifier.send("STOPPING=1\nSTATUS=the engine stopped");
            return Err(DaemonError::EngineStopped(master.last_error()));
        }
        Ok(())
    }
}

/// The status line logged every `status_every`.
fn status_line(s: &Snapshot) -> String {
    format!(
        "phase={:?} state={} crc_errors={} wkc_errors={} rx_fifo={} exchanges={} corrupt={} not_ready={} transactions={} inputs={} outputs={} fifo_alarms={} ring_overflows={} recoveries={} max_fifo_gap_us={}",
        s.phase,
        s.ecat_state,
        s.crc_errors,
        s.wkc_errors,
        s.rx_fifo,
        s.exchanges,
        s.corrupt,
        s.not_ready,
        s.transactions,
        s.input_frames,
        s.output_frames,
        s.fifo_alarms,
        s.ring_overflows,
        s.recoveries,
        s.max_fifo_gap_us
    )
}

/// The one-line state systemd shows (`systemctl status`): phase, state,
/// slaves, cycle.
fn service_status(m: &Master) -> String {
    let s = m.status();
    let l = m.layout();
    match s.phase {
        Phase::Running => {
            format!("{}: {} slaves, cycle {} us", s.ecat_state, l.slaves.len(), m.config().cycle.sync0_us)
        }
        Phase::Recovering => format!("recovering: {}", m.last_error().map(|f| f.to_string()).unwrap_or_default()),
        p => format!("{p:?}"),
    }
}

/// A configuration read again (SIGHUP): applies what can change while the
/// bus runs (log filter, API roles and tokens) and names what needs a
/// restart.
async fn reload(
    running: &mut Config,
    new: Config,
    ctx: &Context,
    logging: Option<&Logging>,
    sparkplug: &mut crate::sparkplug::Runner,
) {
    let plan = ReloadPlan::between(running, &new);
    if plan.sparkplug {
        match sparkplug.replace(new.sparkplug.as_ref()).await {
            Ok(()) => {
                running.sparkplug = new.sparkplug.clone();
                info!("SIGHUP: [sparkplug] applied (the node restarted; the bus ran on)");
            }
            Err(e) => warn!("SIGHUP: [sparkplug] not applied, the node runs as before: {e}"),
        }
    }
    if plan.log_level {
        match logging.map(|l| l.set_level(&new.log.level)) {
            Some(Ok(true)) => info!(level = %new.log.level, "SIGHUP: log.level applied"),
            Some(Ok(false)) => warn!("SIGHUP: log.level not applied: RUST_LOG is set and wins"),
            Some(Err(e)) => warn!("SIGHUP: log.level not applied: {e}"),
            None => warn!("SIGHUP: log.level not applied: the embedding program owns logging"),
        }
        running.log = new.log.clone();
    }
    if plan.roles {
        ctx.reload_roles(&new.api);
        running.api.users = new.api.users.clone();
        running.api.groups = new.api.groups.clone();
        running.api.tokens = new.api.tokens.clone();
        running.api.client_certs = new.api.client_certs.clone();
        running.api.default_role = new.api.default_role;
        info!("SIGHUP: api roles, tokens and client certificates applied");
    }
    if !plan.needs_restart.is_empty() {
        warn!(
            changed = %plan.needs_restart.join(", "),
            "SIGHUP: not applied while the bus runs; restart the service to apply"
        );
    }
    if !plan.log_level && !plan.roles && !plan.sparkplug && plan.needs_restart.is_empty() {
        info!("SIGHUP: configuration unchanged");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_what_failed() {
        let e = DaemonError::Metrics {
            addr: "127.0.0.1:9".parse().unwrap(),
            source: std::io::Error::from(std::io::ErrorKind::AddrInUse),
        };
        assert!(e.to_string().starts_with("metrics.listen 127.0.0.1:9: "), "{e}");
        assert_eq!(
            DaemonError::EngineStopped(Some(Failure::Recovery(crate::master::RecoverCause::ChipReset))).to_string(),
            "the engine stopped: recovery: chip reset (status back to power-up values)"
        );
    }
}
