//! `ecmxfd`: runs the engine on the configured chip (or the simulator) until
//! SIGINT/SIGTERM, then stops it safely.
#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use ecmxfd::config::{Config, LinkConfig};
use ecmxfd::engine::telemetry::Phase;
use ecmxfd::master::Master;
use std::sync::Arc;

use ecmxfd::api::Context;
use ecmxfd::service::{Liveness, Logging, Notifier, ReloadPlan};
use tracing::{error, info, warn};

#[derive(Parser, Debug)]
#[command(name = "ecmxfd", version, about = "Daemon that owns a NEXTW ECM-XF EtherCAT master chip")]
struct Cli {
    /// Configuration file (TOML).
    #[arg(long, short, value_name = "FILE", conflicts_with = "sim")]
    config: Option<PathBuf>,
    /// Check a configuration file, print each mistake with its key and line, and exit.
    #[arg(long, value_name = "FILE")]
    check_config: Option<PathBuf>,
    /// Run on the in-process simulator (the demo network unless --network).
    #[arg(long)]
    sim: bool,
    /// Network file for --sim (see config/demo-network.toml).
    #[arg(long, value_name = "FILE", requires = "sim")]
    network: Option<PathBuf>,
    /// Log filter when RUST_LOG is not set, e.g. "info" or "ecmxfd=debug"
    /// [default: log.level of the configuration, "info"].
    #[arg(long)]
    log: Option<String>,
    /// Serve the API on this Unix socket (overrides api.socket; default:
    /// $ECMXF_SOCKET, /run/ecmxfd/ecmxfd.sock for root, else
    /// $XDG_RUNTIME_DIR/ecmxfd.sock or /tmp/ecmxfd-UID.sock).
    #[arg(long, value_name = "PATH")]
    socket: Option<PathBuf>,
    /// Print the engine status every this many seconds (0: never).
    #[arg(long, default_value_t = 5)]
    status_every: u64,
}

fn status_line(m: &Master) -> String {
    let s = m.status();
    format!(
        "phase={:?} state={} crc_errors={} wkc_errors={} rx_fifo={} exchanges={} corrupt={} not_ready={} transactions={} inputs={} outputs={} fifo_alarms={} recoveries={} max_fifo_gap_us={}",
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
        Phase::Recovering => format!("recovering: {}", m.last_error().unwrap_or_default()),
        p => format!("{p:?}"),
    }
}

/// How long open streams (events, inputs) get to end by themselves at
/// shutdown before their connections are cut.
const STREAM_GRACE: Duration = Duration::from_millis(200);

/// Runs until SIGINT/SIGTERM (or a fatal error): the engine, the API, the
/// optional metrics endpoint, systemd notifications and SIGHUP reloads.
async fn run(config: Config, config_path: Option<PathBuf>, status_every: u64, logging: Logging) -> Result<(), String> {
    let notifier = Notifier::from_env();
    let api = config.api.clone();
    let metrics_listener = match config.metrics.listen {
        Some(addr) => Some(ecmxfd::metrics::bind(addr).await?),
        None => None,
    };
    let mut running = config.clone();
    let (master, _sim) = Master::from_config(config).map_err(|e| e.to_string())?;
    let master = Arc::new(master);
    let ctx = Context::new(Arc::clone(&master), &api, nix::unistd::getuid().as_raw());
    let (stop_api, api_stopped) = tokio::sync::watch::channel(());
    if let Some(l) = metrics_listener {
        tokio::spawn(ecmxfd::metrics::serve(Arc::clone(&ctx), l, api_stopped.clone()));
    }
    let mut server = tokio::spawn(ecmxfd::api::server::serve(Arc::clone(&ctx), api, api_stopped));
    let signal = |k| tokio::signal::unix::signal(k).map_err(|e| e.to_string());
    let mut sigterm = signal(tokio::signal::unix::SignalKind::terminate())?;
    let mut sighup = signal(tokio::signal::unix::SignalKind::hangup())?;
    let mut ticker = tokio::time::interval(Duration::from_secs(status_every.max(1)));
    ticker.tick().await;
    let watchdog_every = Notifier::watchdog_interval();
    let mut watchdog = tokio::time::interval(watchdog_every.unwrap_or(Duration::from_secs(3600)));
    let mut liveness = Liveness::default();
    let mut announced = false;
    let mut ready = false;
    let mut status_sent = String::new();
    let mut status_key = None;
    let mut poll = tokio::time::interval(Duration::from_millis(50));
    let mut events = master.events();
    let mut events_open = true;
    info!(logs = logging.sink, systemd = notifier.enabled(), watchdog = ?watchdog_every, "service");
    loop {
        tokio::select! {
            e = events.recv(), if events_open => match e {
                Ok(e) => info!(t_ms = e.time_ns / 1_000_000, "event: {:?}", e.kind),
                Err(tokio::sync::broadcast::error::RecvError::Lagged(n)) => info!("{n} events not logged"),
                Err(tokio::sync::broadcast::error::RecvError::Closed) => events_open = false,
            },
            r = &mut server => {
                let why = match r {
                    Ok(Ok(())) => "the API server ended".to_string(),
                    Ok(Err(e)) => e.to_string(),
                    Err(e) => format!("the API server failed: {e}"),
                };
                notifier.send(&format!("STOPPING=1\nSTATUS=failed: {why}"));
                tokio::task::spawn_blocking(move || master.stop()).await.map_err(|e| e.to_string())?;
                return Err(why);
            }
            _ = tokio::signal::ctrl_c() => { info!("SIGINT"); break; }
            _ = sigterm.recv() => { info!("SIGTERM"); break; }
            _ = sighup.recv() => {
                notifier.send("RELOADING=1");
                reload(config_path.as_deref(), &mut running, &ctx, &logging);
                notifier.send(&format!("READY=1\nSTATUS={}", service_status(&master)));
            }
            _ = watchdog.tick(), if watchdog_every.is_some() => {
                let s = master.status();
                match liveness.verdict(&s, master.health()) {
                    Ok(()) => notifier.send("WATCHDOG=1"),
                    Err(why) => warn!(phase = ?s.phase, exchanges = s.exchanges, "{why}: not pinging the watchdog"),
                }
            }
            _ = ticker.tick(), if status_every > 0 => info!("{}", status_line(&master)),
            _ = poll.tick() => {
                let s = master.status();
                if s.phase == Phase::Running && !announced {
                    announced = true;
                    let l = master.layout();
                    for (i, s) in l.slaves.iter().enumerate() {
                        info!(position = i, name = %s.name, vendor = format_args!("{:#010x}", s.vendor_id), product = format_args!("{:#010x}", s.product_code), revision = format_args!("{:#010x}", s.revision), outputs = s.rx_bytes, inputs = s.tx_bytes, "slave");
                    }
                    info!(state = %l.state, firmware = format_args!("{:#04x}", l.firmware), "ready");
                }
                // The status line is rebuilt (layout and config cloned) only
                // when what it shows may have changed, and only for systemd.
                let key = (s.phase, s.ecat_state, s.config_generation, s.recoveries);
                if notifier.enabled() && status_key != Some(key) {
                    status_key = Some(key);
                    let status = service_status(&master);
                    if status != status_sent {
                        notifier.send(&format!("STATUS={status}"));
                        status_sent = status;
                    }
                }
                // READY only once bring-up reached the configured state and
                // process data flows.
                if !ready && master.health().is_healthy() {
                    ready = true;
                    notifier.send(&format!("READY=1\nSTATUS={status_sent}"));
                }
                if s.phase == Phase::Stopped {
                    notifier.send("STOPPING=1\nSTATUS=the engine stopped");
                    return Err("the engine stopped (see the log above)".into());
                }
            }
        }
    }
    // The bus first and at once: axes disabled and slaves in INIT within a
    // second, whatever clients are attached. The API stops taking calls
    // meanwhile; streams still open after a short grace are cut.
    notifier.send("STOPPING=1\nSTATUS=stopping: bringing the network down");
    let started = std::time::Instant::now();
    let bus = tokio::task::spawn_blocking({
        let master = Arc::clone(&master);
        move || master.stop()
    });
    let _ = stop_api.send(());
    if tokio::time::timeout(STREAM_GRACE, &mut server).await.is_err() {
        server.abort();
    }
    bus.await.map_err(|e| e.to_string())?;
    info!(took_ms = started.elapsed().as_millis() as u64, "stopped");
    Ok(())
}

/// SIGHUP: reads the configuration file again and applies what can change
/// while the bus runs (log filter, API roles and tokens); names what needs
/// a restart. A file with mistakes changes nothing.
fn reload(path: Option<&std::path::Path>, running: &mut Config, ctx: &Context, logging: &Logging) {
    let Some(path) = path else {
        warn!("SIGHUP: started without --config, nothing to reload");
        return;
    };
    let new = match Config::load(path) {
        Ok(c) => c,
        Err(e) => {
            error!("SIGHUP: {e}; keeping the running configuration");
            return;
        }
    };
    let plan = ReloadPlan::between(running, &new);
    if plan.log_level {
        match logging.set_level(&new.log.level) {
            Ok(true) => info!(level = %new.log.level, "SIGHUP: log.level applied"),
            Ok(false) => warn!("SIGHUP: log.level not applied: RUST_LOG is set and wins"),
            Err(e) => warn!("SIGHUP: log.level not applied: {e}"),
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
    if !plan.log_level && !plan.roles && plan.needs_restart.is_empty() {
        info!("SIGHUP: {} unchanged", path.display());
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(path) = &cli.check_config {
        return match Config::load(path) {
            Ok(c) => {
                let link = match &c.link {
                    LinkConfig::Sim { .. } => "in-process simulator".to_string(),
                    LinkConfig::SimSocket { socket } => format!("simulator socket {}", socket.display()),
                    LinkConfig::Spidev { device, .. } => format!("{}", device.display()),
                };
                println!(
                    "{}: ok ({link}, {} expected slaves, {} us cycle)",
                    path.display(),
                    c.slaves.len(),
                    c.cycle.sync0_us
                );
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("{e}");
                ExitCode::from(2)
            }
        };
    }
    let mut config = if cli.sim {
        let mut c = Config::simulator();
        c.link = LinkConfig::Sim { network: cli.network.clone() };
        c
    } else if let Some(path) = &cli.config {
        match Config::load(path) {
            Ok(c) => c,
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::from(2);
            }
        }
    } else {
        eprintln!("ecmxfd: give --config FILE, or --sim to run on the simulator");
        return ExitCode::from(2);
    };
    if let Some(socket) = cli.socket {
        config.api.socket = Some(socket);
    }
    if let Some(level) = &cli.log {
        if let Err(e) = tracing_subscriber::EnvFilter::builder().parse(level) {
            eprintln!("ecmxfd: --log {level:?} is not a log filter ({e}); e.g. \"info\" or \"info,ecmxfd=debug\"");
            return ExitCode::from(2);
        }
        config.log.level = level.clone();
    }
    let logging = ecmxfd::service::init_logging(&config.log.level);
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_stack_size(8 << 20)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("ecmxfd: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let result = rt.block_on(run(config, cli.config.clone(), cli.status_every, logging));
    // Connections cut at shutdown are not waited for.
    rt.shutdown_timeout(Duration::from_millis(100));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            error!("{e}");
            ExitCode::FAILURE
        }
    }
}
