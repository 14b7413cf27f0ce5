//! `ecmxfd`: runs the daemon ([`ecmxfd::run_with`]) on the configured chip
//! (or the simulator) until SIGINT/SIGTERM, then stops it safely. This file
//! only parses arguments, sets up logging and turns signals into the
//! library's shutdown and reloads.
#![forbid(unsafe_code)]

/// `println!` that never panics: a reader that went away (`ecmxfd
/// --check-config FILE | head`) ends the output, not the process with a
/// panic.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};
use ecmxfd::config::{Config, LinkConfig};
use ecmxfd::service::{Logging, Notifier};
use ecmxfd::{DaemonError, Options};
use tokio::signal::unix::SignalKind;
use tracing::{error, info, warn};

#[derive(Parser, Debug)]
#[command(name = "ecmxfd", version, about = "Daemon that owns a NEXTW ECM-XF EtherCAT master chip")]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Configuration file (TOML).
    #[arg(long, short, value_name = "FILE", conflicts_with = "sim", global = true)]
    config: Option<PathBuf>,
    /// Check a configuration file, print each mistake with its key and line, and exit.
    #[arg(long, value_name = "FILE")]
    check_config: Option<PathBuf>,
    /// Run on the in-process simulator (the demo network unless --network).
    #[arg(long, global = true)]
    sim: bool,
    /// Network file for --sim (see config/demo-network.toml).
    #[arg(long, value_name = "FILE", requires = "sim", global = true)]
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

#[derive(Subcommand, Debug)]
enum Command {
    /// Check a new board step by step, with the likely cause and fix of a failure
    ///
    /// Runs the link steps of bring-up one at a time against the chip of
    /// --config (or --sim): device opens, INT0 toggles, packet boundary,
    /// check word switch, firmware, slave count, state read. Prints a line
    /// per step, and the likely cause and fix under a failure; exits 1 when
    /// a step fails. Stop the daemon first: the probe re-initialises the
    /// network (slaves end in PRE-OP).
    Probe {
        /// Probe even though a daemon answers on the configuration's API
        /// socket (its exchange with the chip will be disturbed).
        #[arg(long)]
        force: bool,
    },
}

/// Turns SIGINT/SIGTERM into the daemon's shutdown and SIGHUP into a
/// reload of `config_path`, until the daemon ends.
async fn serve(
    config: Config,
    config_path: Option<PathBuf>,
    status_every: u64,
    logging: Logging,
) -> Result<(), DaemonError> {
    let signal = |k| tokio::signal::unix::signal(k).map_err(DaemonError::Signals);
    let mut sigterm = signal(SignalKind::terminate())?;
    let mut sighup = signal(SignalKind::hangup())?;
    let (reload_tx, reloads) = tokio::sync::mpsc::channel(1);
    let options = Options {
        status_every: (status_every > 0).then(|| Duration::from_secs(status_every)),
        notifier: Some(Notifier::from_env()),
        logging: Some(logging),
        reloads: Some(reloads),
    };
    let shutdown = async {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => info!("SIGINT"),
            _ = sigterm.recv() => info!("SIGTERM"),
        }
    };
    let reloader = async {
        while sighup.recv().await.is_some() {
            let Some(path) = &config_path else {
                warn!("SIGHUP: started without --config, nothing to reload");
                continue;
            };
            match Config::load(path) {
                Ok(c) => {
                    info!(file = %path.display(), "SIGHUP: configuration read again");
                    if reload_tx.send(c).await.is_err() {
                        return;
                    }
                }
                Err(e) => error!("SIGHUP: {e}; keeping the running configuration"),
            }
        }
    };
    tokio::select! {
        r = ecmxfd::run_with(config, options, shutdown) => r,
        () = reloader => std::future::pending().await,
    }
}

/// `ecmxfd probe`: 0 when every step passed, 1 when one failed, 2 when it
/// could not run.
fn probe(config: &Config, path: Option<&std::path::Path>, force: bool) -> ExitCode {
    if !force && let Some(why) = ecmxfd::probe::daemon_in_the_way(config) {
        eprintln!("ecmxfd probe: {why}");
        return ExitCode::from(2);
    }
    let source = path.map_or("--sim".to_string(), |p| p.display().to_string());
    out!("ecmxfd probe ({source})");
    match ecmxfd::probe::run(config, &mut std::io::stdout()) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        // The reader went away (`| head`): nothing left to tell.
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => ExitCode::from(2),
        Err(e) => {
            eprintln!("ecmxfd probe: {e}");
            ExitCode::from(2)
        }
    }
}

/// The link budget of a simulator configuration, from its network file
/// (or the demo network) with each slave's default mapping and the packet
/// time its SPI clock gives: what bring-up would refuse, said offline.
/// `None` where the frame sizes are known only from the slaves.
#[cfg(feature = "sim")]
fn offline_budget(
    c: &Config,
) -> Option<Result<ecmxfd::master::link_budget::LinkBudget, ecmxfd::master::link_budget::BudgetError>> {
    let LinkConfig::Sim { network } = &c.link else { return None };
    let (net, chip) = match network {
        None => (ecmxf_sim::Network::demo(), ecmxf_sim::ChipConfig::default()),
        Some(p) => {
            let f = ecmxf_sim::config::NetworkFile::load(p).ok()?;
            (f.build(p).ok()?, f.chip_config())
        }
    };
    let rx: usize = net.slaves.iter().map(|s| s.rx.bytes()).sum();
    let tx: usize = net.slaves.iter().map(|s| s.tx.bytes()).sum();
    let data_size = c.chip.data_size;
    let packet_ns = ecmxfd::master::link_budget::clocked_ns(data_size, chip.spi_hz) + chip.processing_ns;
    Some(ecmxfd::master::link_budget::check(data_size, rx, tx, packet_ns, u64::from(c.cycle.sync0_us) * 1000))
}

/// The simulator's network file, loaded and built as the daemon will
/// (its ESI and SII files with it): a mistake named by `link.network`.
/// With it known, each `[[axis]]` must find its slave's controlword
/// (0x6040, or an axis's at +0x800 x n) at its output offset and the
/// statusword (0x6041) at its input offset: the chip's CiA 402 helper
/// drives those bytes.
#[cfg(feature = "sim")]
fn check_network(c: &Config, path: &std::path::Path) -> Result<(), ecmxfd::config::ConfigError> {
    let LinkConfig::Sim { network } = &c.link else { return Ok(()) };
    let bad = |key: String, message: String| ecmxfd::config::ConfigError::Invalid { file: path.into(), key, message };
    let net = match network {
        None => ecmxf_sim::Network::demo(),
        Some(p) => {
            let f = ecmxf_sim::config::NetworkFile::load(p).map_err(|e| bad("link.network".into(), e.to_string()))?;
            f.build(p).map_err(|e| bad("link.network".into(), e.to_string()))?
        }
    };
    let maps = |entries: &[ecmxf_sim::net::pdo_map::MappedEntry], base: u16, byte: u8| {
        entries.iter().any(|e| {
            (0..8u16).any(|k| e.index == base + 0x800 * k) && e.subindex == 0 && e.bit_offset == u32::from(byte) * 8
        })
    };
    for (i, a) in c.axes.iter().enumerate() {
        let Some(s) = net.slaves.get(usize::from(a.slave)) else {
            let why = format!("slave {} is not in the simulated network of {}", a.slave, net.slaves.len());
            return Err(bad(format!("axis[{i}].slave"), why));
        };
        if !maps(&s.rx.entries, 0x6040, a.controlword_offset) {
            let why = format!(
                "slave {} ({}) maps no controlword (0x6040) at output byte {}",
                a.slave, s.name, a.controlword_offset
            );
            return Err(bad(format!("axis[{i}].controlword_offset"), why));
        }
        if !maps(&s.tx.entries, 0x6041, a.statusword_offset) {
            let why = format!(
                "slave {} ({}) maps no statusword (0x6041) at input byte {}",
                a.slave, s.name, a.statusword_offset
            );
            return Err(bad(format!("axis[{i}].statusword_offset"), why));
        }
    }
    Ok(())
}

#[cfg(not(feature = "sim"))]
fn check_network(_: &Config, _: &std::path::Path) -> Result<(), ecmxfd::config::ConfigError> {
    Ok(())
}

#[cfg(not(feature = "sim"))]
fn offline_budget(
    _: &Config,
) -> Option<Result<ecmxfd::master::link_budget::LinkBudget, ecmxfd::master::link_budget::BudgetError>> {
    None
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(path) = &cli.check_config {
        return match Config::load(path).and_then(|c| {
            let notes = c.check_files(path)?;
            // The Sparkplug node's certificates and credentials load as at start.
            if let Some(s) = &c.sparkplug {
                ecmxfd::sparkplug::prepare(s).map_err(|e| ecmxfd::config::ConfigError::Invalid {
                    file: path.into(),
                    key: "sparkplug".into(),
                    message: e.to_string(),
                })?;
            }
            check_network(&c, path)?;
            Ok((c, notes))
        }) {
            Ok((c, notes)) => {
                for n in &notes {
                    out!("note: {n}");
                }
                let link = match &c.link {
                    LinkConfig::Sim { .. } => "in-process simulator".to_string(),
                    LinkConfig::SimSocket { socket } => format!("simulator socket {}", socket.display()),
                    LinkConfig::Spidev { device, .. } => format!("{}", device.display()),
                };
                let latency = match c.cycle.output_latency_us {
                    Some(us) => format!(", output latency budget {us} us"),
                    None => String::new(),
                };
                let budget = offline_budget(&c);
                if let Some(Err(e)) = &budget {
                    eprintln!("{}: the network cannot run: link budget: {e}", path.display());
                    return ExitCode::from(ecmxfd::lifecycle::EXIT_REFUSED);
                }
                out!(
                    "{}: ok ({link}, {} expected slaves, {} us cycle{latency})",
                    path.display(),
                    c.slaves.len(),
                    c.cycle.sync0_us
                );
                match budget {
                    Some(Ok(b)) => {
                        out!(
                            "link budget: the process data needs {:.0}% of the SPI link ({} cycle(s) of frames a \
                             packet, {:.0} exchanges/s at least)",
                            b.load() * 100.0,
                            b.frames_per_packet,
                            b.min_exchanges_per_s()
                        );
                        ExitCode::SUCCESS
                    }
                    _ => {
                        out!("link budget: checked at bring-up (the frame sizes come from the slaves)");
                        ExitCode::SUCCESS
                    }
                }
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
    if let Some(Command::Probe { force }) = cli.command {
        return probe(&config, cli.config.as_deref(), force);
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
    let result = rt.block_on(serve(config, cli.config.clone(), cli.status_every, logging));
    // Connections cut at shutdown are not waited for.
    rt.shutdown_timeout(Duration::from_millis(100));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            error!("{e}");
            ExitCode::from(e.exit_status())
        }
    }
}
