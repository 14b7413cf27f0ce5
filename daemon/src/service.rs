//! Life as a service: the systemd notification protocol (READY, STATUS,
//! WATCHDOG, RELOADING, STOPPING; sd_notify(3)) spoken directly on
//! `$NOTIFY_SOCKET` (no libsystemd), logging to journald under systemd and
//! to stderr otherwise with a filter SIGHUP can change, and what a reload
//! may apply while the bus runs.

use std::os::unix::net::UnixDatagram;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{EnvFilter, Registry, reload};

use crate::config::Config;
use crate::master::{Health, Phase, Snapshot};

/// The sender side of sd_notify; inert when not started by systemd.
#[derive(Debug)]
pub struct Notifier {
    socket: Option<(UnixDatagram, std::os::unix::net::SocketAddr)>,
}

impl Notifier {
    /// From `$NOTIFY_SOCKET` (a path, or `@name` for the abstract namespace).
    pub fn from_env() -> Self {
        let Some(path) = std::env::var_os("NOTIFY_SOCKET") else { return Self { socket: None } };
        let bytes = path.as_encoded_bytes();
        let addr = if let Some(name) = bytes.strip_prefix(b"@") {
            use std::os::linux::net::SocketAddrExt;
            std::os::unix::net::SocketAddr::from_abstract_name(name)
        } else {
            std::os::unix::net::SocketAddr::from_pathname(&path)
        };
        let socket = match (UnixDatagram::unbound(), addr) {
            (Ok(s), Ok(a)) => Some((s, a)),
            (Err(e), _) | (_, Err(e)) => {
                tracing::warn!(error = %e, socket = ?path, "NOTIFY_SOCKET unusable: systemd will not hear from ecmxfd");
                None
            }
        };
        Self { socket }
    }

    /// A notifier that sends nothing (not under systemd, or embedded).
    pub fn disabled() -> Self {
        Self { socket: None }
    }

    /// Whether a service manager listens.
    pub fn enabled(&self) -> bool {
        self.socket.is_some()
    }

    /// Sends `state` lines ("READY=1\nSTATUS=..."); failures are logged,
    /// never fatal.
    pub fn send(&self, state: &str) {
        if let Some((s, addr)) = &self.socket {
            if let Err(e) = s.send_to_addr(state.as_bytes(), addr) {
                tracing::debug!(error = %e, "sd_notify failed");
            }
        }
    }

    /// How often to ping the watchdog: half of `$WATCHDOG_USEC`, when it is
    /// meant for this process (`$WATCHDOG_PID` absent or ours).
    pub fn watchdog_interval() -> Option<Duration> {
        if let Some(pid) = std::env::var("WATCHDOG_PID").ok().and_then(|p| p.parse::<u32>().ok()) {
            if pid != std::process::id() {
                return None;
            }
        }
        let usec: u64 = std::env::var("WATCHDOG_USEC").ok()?.parse().ok()?;
        (usec > 0).then(|| Duration::from_micros(usec / 2))
    }
}

/// Proves the real-time loop alive to the watchdog: the engine's exchange
/// counter must have moved since the last ping. A stalled loop (stuck SPI
/// transfer, dead chip, deadlock) stops the pings and systemd restarts us.
#[derive(Debug, Default)]
pub(crate) struct Liveness {
    last_exchanges: Option<u64>,
}

impl Liveness {
    /// True when `exchanges` advanced since the previous call (the first
    /// call only records).
    pub(crate) fn advanced(&mut self, exchanges: u64) -> bool {
        let moved = self.last_exchanges.is_none_or(|l| exchanges > l);
        self.last_exchanges = Some(exchanges);
        moved
    }

    /// Whether to ping the watchdog now. Running, the real-time loop must
    /// exchange packets and process data must flow: a stall the engine
    /// did not turn into a recovery within a ping interval means it is
    /// wedged, and systemd should restart it. Bringing up or recovering,
    /// the engine is doing its job (its waits are bounded), so it is pinged.
    pub(crate) fn verdict(&mut self, s: &Snapshot, health: Health) -> Result<(), String> {
        let advanced = self.advanced(s.exchanges);
        match s.phase {
            Phase::Stopped => Err("the engine stopped".into()),
            Phase::Running if !advanced => Err("the real-time loop made no exchange since the last ping".into()),
            Phase::Running => match health {
                Health::Stalled { .. } => Err(health.to_string()),
                _ => Ok(()),
            },
            _ => Ok(()),
        }
    }
}

/// The log filter in force, replaceable on SIGHUP and through the API
/// (`Master.SetLogFilter`); clones control the same filter.
#[derive(Debug, Clone)]
pub struct Logging {
    handle: reload::Handle<EnvFilter, Registry>,
    from_env: bool,
    /// The filter's text as given (`RUST_LOG`'s, or the level set last).
    current: Arc<Mutex<String>>,
    /// Where logs go: "journald" or "stderr".
    pub sink: &'static str,
}

/// Starts logging: to journald when systemd connected our stderr to the
/// journal (`$JOURNAL_STREAM`) and journald answers, else to stderr. The
/// filter is `RUST_LOG` if set, else `level`.
pub fn init_logging(level: &str) -> Logging {
    let from_env = std::env::var_os("RUST_LOG").is_some();
    let current = if from_env { std::env::var("RUST_LOG").unwrap_or_default() } else { level.to_owned() };
    let filter = if from_env {
        EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"))
    } else {
        quiet_libraries(EnvFilter::try_new(level).unwrap_or_else(|_| EnvFilter::new("info")))
    };
    let (filter, handle) = reload::Layer::new(filter);
    let journald = if std::env::var_os("JOURNAL_STREAM").is_some() {
        // Fields as journal fields of their own (POSITION=1, not F_POSITION=1).
        tracing_journald::layer().ok().map(|l| l.with_syslog_identifier("ecmxfd".into()).with_field_prefix(None))
    } else {
        None
    };
    let sink = if journald.is_some() { "journald" } else { "stderr" };
    use std::io::IsTerminal;
    let stderr = journald.is_none().then(|| {
        tracing_subscriber::fmt::layer().with_writer(std::io::stderr).with_ansi(std::io::stderr().is_terminal())
    });
    let _ = tracing_subscriber::registry().with(filter).with(journald).with(stderr).try_init();
    Logging { handle, from_env, current: Arc::new(Mutex::new(current)), sink }
}

/// What libraries say at `info` is theirs, not the daemon's: the OPC UA
/// stack logs each connection it accepts (a peer could fill the journal),
/// so it says warnings and errors only; its certificate store and secure
/// channel, whose errors are about the certificate the unsecured endpoint
/// never uses, nothing.
/// `RUST_LOG` overrides all of it.
fn quiet_libraries(mut filter: EnvFilter) -> EnvFilter {
    for directive in [
        "opcua_server=warn",
        "opcua_core=warn",
        "opcua_crypto::certificate_store=off",
        "opcua_core::comms::secure_channel=off",
    ] {
        if let Ok(d) = directive.parse() {
            filter = filter.add_directive(d);
        }
    }
    filter
}

impl Logging {
    /// Applies a new filter from the configuration. `Ok(false)`: RUST_LOG
    /// is in force and wins.
    pub fn set_level(&self, level: &str) -> Result<bool, String> {
        if self.from_env {
            return Ok(false);
        }
        let f = quiet_libraries(EnvFilter::try_new(level).map_err(|e| e.to_string())?);
        self.handle.reload(f).map_err(|e| e.to_string())?;
        *self.current.lock().unwrap_or_else(|e| e.into_inner()) = level.to_owned();
        Ok(true)
    }
}

impl crate::api::LogFilter for Logging {
    fn current(&self) -> (String, bool) {
        (self.current.lock().unwrap_or_else(|e| e.into_inner()).clone(), self.from_env)
    }

    fn set(&self, filter: &str) -> Result<(), crate::api::LogFilterRefusal> {
        match self.set_level(filter) {
            Ok(true) => Ok(()),
            Ok(false) => Err(crate::api::LogFilterRefusal::FromEnv),
            Err(why) => Err(crate::api::LogFilterRefusal::Invalid(why)),
        }
    }
}

/// What a reload changed, split into what is applied while the bus runs
/// and what needs a restart.
#[derive(Debug, Default, PartialEq, Eq)]
pub(crate) struct ReloadPlan {
    /// `log.level` changed.
    pub log_level: bool,
    /// `[api]` roles, tokens, client certificates or default role changed.
    pub roles: bool,
    /// `[sparkplug]` changed: the node is restarted, the bus runs on.
    pub sparkplug: bool,
    /// Keys that changed but take a restart (or a re-initialisation that
    /// interrupts the bus), for the log.
    pub needs_restart: Vec<&'static str>,
}

impl ReloadPlan {
    /// Compares the running configuration with the reloaded one.
    pub(crate) fn between(old: &Config, new: &Config) -> Self {
        let mut p =
            Self { log_level: old.log != new.log, sparkplug: old.sparkplug != new.sparkplug, ..Self::default() };
        let (a, b) = (&old.api, &new.api);
        p.roles = a.users != b.users
            || a.groups != b.groups
            || a.tokens != b.tokens
            || a.client_certs != b.client_certs
            || a.default_role != b.default_role;
        let mut restart = |changed: bool, key: &'static str| {
            if changed {
                p.needs_restart.push(key);
            }
        };
        restart(old.link != new.link, "[link]");
        restart(old.chip != new.chip, "[chip]");
        restart(old.realtime != new.realtime, "[realtime]");
        restart(old.cycle != new.cycle, "[cycle]");
        restart(old.slaves != new.slaves, "[[slave]]");
        restart(old.axes != new.axes, "[[axis]]");
        restart(old.recovery != new.recovery, "[recovery]");
        restart(old.outputs != new.outputs, "[outputs]");
        restart(old.metrics != new.metrics, "[metrics]");
        restart(old.gateway != new.gateway, "[gateway]");
        restart(old.opcua != new.opcua, "[opcua]");
        restart(old.web != new.web, "[web]");
        restart(
            a.socket != b.socket || a.socket_mode != b.socket_mode || a.socket_group != b.socket_group,
            "api.socket*",
        );
        restart(
            a.tcp != b.tcp || a.tls_cert != b.tls_cert || a.tls_key != b.tls_key || a.client_ca != b.client_ca,
            "api.tcp/tls",
        );
        restart(a.lease_ttl_ms != b.lease_ttl_ms, "api.lease_ttl_ms");
        // The listeners' caps and deadlines are fixed when they start.
        restart(
            a.handshake_timeout_ms != b.handshake_timeout_ms
                || a.keepalive_s != b.keepalive_s
                || a.max_connections != b.max_connections
                || a.max_connections_per_peer != b.max_connections_per_peer
                || a.max_socket_connections != b.max_socket_connections,
            "api connection caps",
        );
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_watchdog_is_fed_only_while_exchanges_advance() {
        let mut l = Liveness::default();
        assert!(l.advanced(10), "the first look only records");
        assert!(l.advanced(11));
        assert!(!l.advanced(11), "a stalled loop stops the pings");
        assert!(l.advanced(500));
    }

    #[test]
    fn the_watchdog_wants_flowing_process_data_while_running() {
        let mut l = Liveness::default();
        let mut s = Snapshot { phase: Phase::Running, ..Snapshot::default() };
        assert!(l.verdict(&s, Health::Healthy).is_ok());
        s.exchanges += 1;
        let stalled = Health::Stalled { age: Duration::from_millis(900), limit: Duration::from_millis(50) };
        assert!(l.verdict(&s, stalled).unwrap_err().contains("stalled"));
        s.exchanges += 1;
        assert!(l.verdict(&s, Health::Healthy).is_ok());
        assert!(l.verdict(&s, Health::Healthy).unwrap_err().contains("no exchange"), "a loop that stopped");
        s.phase = Phase::Recovering;
        assert!(l.verdict(&s, Health::NotRunning(Phase::Recovering)).is_ok(), "recovering is the engine's job");
        s.phase = Phase::Stopped;
        assert!(l.verdict(&s, Health::NotRunning(Phase::Stopped)).is_err());
    }

    #[test]
    fn a_reload_applies_roles_and_log_level_and_names_the_rest() {
        let old = Config::simulator();
        let mut new = old.clone();
        assert_eq!(ReloadPlan::between(&old, &new), ReloadPlan::default());
        new.log.level = "debug".into();
        new.api.default_role = crate::config::api::RoleName::None;
        new.cycle.sync0_us = 500;
        new.api.lease_ttl_ms = 10;
        let p = ReloadPlan::between(&old, &new);
        assert!(p.log_level && p.roles);
        assert_eq!(p.needs_restart, vec!["[cycle]", "api.lease_ttl_ms"]);
        // A Sparkplug node is restarted on its own (the bus runs on); a
        // mailbox gateway's address needs the daemon restarted.
        let mut new = old.clone();
        new.sparkplug = Some(toml::from_str("broker = \"mqtt://b\"\ngroup_id = \"g\"").unwrap());
        new.gateway = Some(toml::from_str("listen = \"127.0.0.1:34980\"").unwrap());
        let p = ReloadPlan::between(&old, &new);
        assert!(p.sparkplug);
        assert_eq!(p.needs_restart, vec!["[gateway]"]);
        let mut new = old.clone();
        new.api.max_connections_per_peer = 4;
        assert_eq!(ReloadPlan::between(&old, &new).needs_restart, vec!["api connection caps"]);
    }

    #[test]
    fn notifications_reach_the_socket_and_the_abstract_namespace() {
        let dir = std::env::temp_dir().join(format!("ecmxfd-notify-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let path = dir.join("notify.sock");
        let _ = std::fs::remove_file(&path);
        let listener = UnixDatagram::bind(&path).unwrap();
        let n = Notifier {
            socket: Some((
                UnixDatagram::unbound().unwrap(),
                std::os::unix::net::SocketAddr::from_pathname(&path).unwrap(),
            )),
        };
        assert!(n.enabled());
        n.send("READY=1\nSTATUS=OP");
        let mut buf = [0u8; 64];
        let len = listener.recv(&mut buf).unwrap();
        assert_eq!(&buf[..len], b"READY=1\nSTATUS=OP");
        let _ = std::fs::remove_dir_all(&dir);
        // Outside systemd nothing is sent and nothing fails.
        Notifier { socket: None }.send("READY=1");
    }
}
