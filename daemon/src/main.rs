//! `ecmxfd`: runs the daemon ([`ecmxfd::run_with`]) on the configured chip
//! (or the simulator) until SIGINT/SIGTERM, then stops it safely. This file
//! only parses arguments, sets up logging and turns signals into the
//! library's shutdown and reloads.
#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};
use ecmxfd::config::{Config, LinkConfig};
use tracing::error;

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
    /// Write the ecmxfd(8) and ecmxfd.toml(5) manual pages into DIR (for
    /// packaging)
    #[command(hide = true)]
    Man {
        /// The folder to write ecmxfd.8 and ecmxfd.toml.5 into.
        dir: PathBuf,
    },
}

/// What ecmxfd(8) says beyond the options: how it runs, its signals,
/// files and exit statuses.
const MAN_MORE: &str = r#".SH DESCRIPTION
ecmxfd owns an ECM\-XF EtherCAT master chip on an SPI bus: one real\-time
thread runs the cyclic exchange and keeps the chip's PDO FIFO fed, and the
daemon serves the network over gRPC (the ecmxf.v1 API, on a Unix socket and
optionally TLS over TCP), a Prometheus endpoint, MQTT Sparkplug B, the
ETG.8200 mailbox gateway and OPC UA, as the configuration file says
(ecmxfd.toml, see the examples in /usr/share/doc/ecmxfd/examples).
.PP
ecmxfctl(1) is its command\-line client; ecmxfd.toml(5) documents every
key of the configuration file.
.SH SIGNALS
.TP
.B SIGTERM, SIGINT
Stop: the outputs are made safe as outputs.on_last_writer_gone says, the
network is left in a defined state, and the daemon exits within a second.
.TP
.B SIGHUP
Read the configuration file again and apply what can change while the bus
runs (roles, log level, Sparkplug). Started without \-\-config (\-\-sim in a
terminal), SIGHUP stops it, as for any foreground program.
.SH FILES
.TP
.I /etc/ecmxfd/ecmxfd.toml
The configuration (systemd unit: ecmxfd.service).
.TP
.I /run/ecmxfd/ecmxfd.sock
The API socket when run as root (else $XDG_RUNTIME_DIR/ecmxfd.sock or
/tmp/ecmxfd\-UID.sock); api.socket or \-\-socket set another.
.TP
.I /var/lib/ecmxfd
The state directory (systemd StateDirectory=): object dictionaries read
from devices (sdo\-info/), the OPC UA server's certificates (pki/).
.SH EXIT STATUS
0 after a stop by signal; 2 for a configuration mistake (as
\-\-check\-config reports it); another status when the network can never run
as configured or the chip cannot be reached (the message says which).
.SH SEE ALSO
ecmxfd.toml(5), ecmxfctl(1), ecmxf\-sim(1), systemd.service(5)
"#;

/// Writes ecmxfd(8) and ecmxfd.toml(5) into `dir`.
fn write_man_pages(dir: &std::path::Path) -> std::io::Result<[PathBuf; 2]> {
    use clap::CommandFactory;
    std::fs::create_dir_all(dir)?;
    let man = clap_mangen::Man::new(Cli::command()).section("8");
    let mut page = Vec::new();
    man.render_title(&mut page)?;
    man.render_name_section(&mut page)?;
    man.render_synopsis_section(&mut page)?;
    page.extend_from_slice(MAN_MORE.as_bytes());
    man.render_options_section(&mut page)?;
    man.render_subcommands_section(&mut page)?;
    man.render_version_section(&mut page)?;
    let path = dir.join("ecmxfd.8");
    std::fs::write(&path, page)?;
    let config = dir.join("ecmxfd.toml.5");
    std::fs::write(&config, ecmxfd::config::manual_page(env!("CARGO_PKG_VERSION")))?;
    Ok([path, config])
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(Command::Man { dir }) = &cli.command {
        return match write_man_pages(dir) {
            Ok(paths) => {
                for path in paths {
                    println!("{}", path.display());
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("ecmxfd: cannot write the manual pages into {}: {e}", dir.display());
                ExitCode::FAILURE
            }
        };
    }
    if let Some(path) = &cli.check_config {
        let status = ecmxfd::check_config(path, &mut std::io::stdout(), &mut std::io::stderr());
        return ExitCode::from(status);
    }
    let mut config = if cli.sim {
        let mut c = Config::simulator();
        c.link = LinkConfig::Sim { network: cli.network.clone() };
        // What a new user tries next: an OPC UA client on loopback.
        c.opcua = Some(ecmxfd::config::OpcuaConfig::loopback());
        // And a browser: the dashboard on loopback.
        c.web = Some(ecmxfd::config::WebConfig::loopback());
        c
    } else if let Some(path) = &cli.config {
        match Config::load(path) {
            Ok(c) => c,
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::from(ecmxfd::EXIT_CONFIG);
            }
        }
    } else {
        eprintln!("ecmxfd: give --config FILE, or --sim to run on the simulator");
        return ExitCode::from(2);
    };
    // A start refuses what --check-config refuses, with the same status.
    let source = cli.config.clone().unwrap_or_else(|| PathBuf::from("--sim"));
    if cli.command.is_none()
        && let Err((status, why)) = ecmxfd::preflight(&config, &source)
    {
        eprintln!("{why}");
        return ExitCode::from(status);
    }
    if let Some(socket) = cli.socket {
        config.api.socket = Some(socket);
    }
    if let Some(Command::Probe { force }) = cli.command {
        let source = cli.config.as_ref().map_or("--sim".to_string(), |p| p.display().to_string());
        return ExitCode::from(ecmxfd::probe::command(&config, &source, force));
    }
    if let Some(level) = &cli.log {
        if let Err(e) = tracing_subscriber::EnvFilter::builder().parse(level) {
            eprintln!("ecmxfd: --log {level:?} is not a log filter ({e}); e.g. \"info\" or \"info,ecmxfd=debug\"");
            return ExitCode::from(2);
        }
        config.log.level = level.clone();
    }
    let logging = ecmxfd::init_logging(&config.log.level);
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
    let status_every = (cli.status_every > 0).then(|| Duration::from_secs(cli.status_every));
    let result = rt.block_on(ecmxfd::run_until_signalled(config, cli.config.clone(), status_every, logging));
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
