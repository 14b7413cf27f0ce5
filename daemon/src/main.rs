//! `ecmxfd`: runs the engine on the configured chip (or the simulator) until
//! SIGINT/SIGTERM, then stops it safely.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use ecmxfd::config::{Config, LinkConfig};
use ecmxfd::engine::telemetry::Phase;
use ecmxfd::master::Master;
use tracing::{error, info};

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
    /// Log filter when RUST_LOG is not set, e.g. "info" or "ecmxfd=debug".
    #[arg(long, default_value = "info")]
    log: String,
    /// Serve the API on this Unix socket (overrides api.socket; default:
    /// $ECMXF_SOCKET, /run/ecmxfd/ecmxfd.sock for root, else
    /// $XDG_RUNTIME_DIR/ecmxfd.sock or /tmp/ecmxfd-UID.sock).
    #[arg(long, value_name = "PATH")]
    socket: Option<PathBuf>,
    /// Print the engine status every this many seconds (0: never).
    #[arg(long, default_value_t = 5)]
    status_every: u64,
}

fn init_logging(filter: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(filter));
    use std::io::IsTerminal;
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .init();
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

async fn run(config: Config, status_every: u64) -> Result<(), String> {
    let api = config.api.clone();
    let (master, _sim) = Master::from_config(config).map_err(|e| e.to_string())?;
    let master = std::sync::Arc::new(master);
    let (stop_api, api_stopped) = tokio::sync::watch::channel(());
    let mut server = tokio::spawn(ecmxfd::api::server::serve(std::sync::Arc::clone(&master), api, api_stopped));
    let mut sigterm =
        tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()).map_err(|e| e.to_string())?;
    let mut ticker = tokio::time::interval(Duration::from_secs(status_every.max(1)));
    ticker.tick().await;
    let mut announced = false;
    let mut poll = tokio::time::interval(Duration::from_millis(50));
    let mut events = master.events();
    let mut events_open = true;
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
                tokio::task::spawn_blocking(move || master.stop()).await.map_err(|e| e.to_string())?;
                return Err(why);
            }
            _ = tokio::signal::ctrl_c() => { info!("SIGINT"); break; }
            _ = sigterm.recv() => { info!("SIGTERM"); break; }
            _ = ticker.tick(), if status_every > 0 => info!("{}", status_line(&master)),
            _ = poll.tick() => {
                let phase = master.status().phase;
                if phase == Phase::Running && !announced {
                    announced = true;
                    let l = master.layout();
                    for (i, s) in l.slaves.iter().enumerate() {
                        info!(position = i, name = %s.name, vendor = format_args!("{:#010x}", s.vendor_id), product = format_args!("{:#010x}", s.product_code), revision = format_args!("{:#010x}", s.revision), outputs = s.rx_bytes, inputs = s.tx_bytes, "slave");
                    }
                    info!(state = %l.state, firmware = format_args!("{:#04x}", l.firmware), "ready");
                }
                if phase == Phase::Stopped {
                    return Err("the engine stopped (see the log above)".into());
                }
            }
        }
    }
    let _ = stop_api.send(());
    let _ = tokio::time::timeout(Duration::from_secs(2), server).await;
    tokio::task::spawn_blocking(move || master.stop()).await.map_err(|e| e.to_string())?;
    info!("stopped");
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_logging(&cli.log);
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
    match rt.block_on(run(config, cli.status_every)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            error!("{e}");
            ExitCode::FAILURE
        }
    }
}
