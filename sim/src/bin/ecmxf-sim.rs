//! `ecmxf-sim`: serve the simulated ECM-XF chip on a Unix socket, control a
//! running one, run a program on emulated SPI and GPIO devices backed by
//! it, or check a network file.
#![forbid(unsafe_code)]

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use clap::{Parser, Subcommand};
use ecmxf_sim::config::NetworkFile;
use ecmxf_sim::server::{self, Server, SocketClient};
use ecmxf_sim::{Chip, ChipConfig, Network};

#[derive(Parser)]
#[command(name = "ecmxf-sim", version, about = "Simulated NEXTW ECM-XF EtherCAT master chip and network")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Serve the chip on a Unix socket in real time (framing: sim/README.md).
    Serve {
        /// Socket path.
        #[arg(long)]
        socket: PathBuf,
        /// Network file (TOML); the built-in demo network when absent.
        #[arg(long)]
        network: Option<PathBuf>,
        /// Seed for bit-flip fault injection.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Refuse (error bit7) a command whose declared data length is not
        /// the one v049 gives its layout; without it such a command runs
        /// and is counted (`ctl status`: length_mismatches).
        #[arg(long)]
        strict_lengths: bool,
        /// Microseconds the server polls for the next message, and yields
        /// instead of sleeping before a modelled moment: answers on time
        /// on a busy or virtual machine, for a core's worth of CPU. 0
        /// blocks and sleeps: the CPU is then the simulation's own work
        /// (scale benches), the answers later by a wake-up each.
        #[arg(long, default_value_t = 2000)]
        spin_us: u64,
    },
    /// Send a control command to a serving simulator (e.g. "unplug 2").
    Ctl {
        /// Socket path.
        #[arg(long)]
        socket: PathBuf,
        /// The command words; `help` lists them.
        #[arg(required = true, num_args = 1..)]
        command: Vec<String>,
    },
    /// Run a command on emulated /dev/spidev0.0 and /dev/gpiochip0 backed by
    /// this simulator, e.g. `ecmxf-sim hardware -- ecmxfd probe --config
    /// config/ecmxfd-rpi.toml`: the simulator is served on a socket and the
    /// command runs with the preload library (sim/hw-emu) in LD_PRELOAD.
    /// Faults: `ecmxf-sim ctl --socket SOCKET ...`, and the ECMXF_EMU_*
    /// variables (sim/hw-emu/README.md). Exits with the command's status.
    Hardware {
        /// Network file (TOML); the built-in demo network when absent.
        #[arg(long)]
        network: Option<PathBuf>,
        /// Socket path (default: one in the temporary folder, removed after).
        #[arg(long)]
        socket: Option<PathBuf>,
        /// The preload library (default: libecmxf_hw_emu.so next to this
        /// executable, or in its deps/ folder as `cargo test` leaves it).
        #[arg(long)]
        library: Option<PathBuf>,
        /// Seed for bit-flip fault injection.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// The command and its arguments.
        #[arg(required = true, num_args = 1.., last = true)]
        command: Vec<String>,
    },
    /// Validate a network file and list its slaves.
    Check {
        /// Network file.
        network: PathBuf,
    },
    /// Write the ecmxf-sim(1) manual page into DIR (for packaging).
    #[command(hide = true)]
    Man {
        /// The folder to write ecmxf-sim.1 into.
        dir: PathBuf,
    },
}

/// What ecmxf-sim(1) says beyond the commands' options: the network file
/// and the control commands (the same list `ctl help` prints).
fn man_more() -> String {
    let mut text = String::from(
        r#".SH DESCRIPTION
ecmxf\-sim simulates the NEXTW ECM\-XF EtherCAT master chip and the
EtherCAT network behind it, as the chip's manual describes them: the SPI
packets and their check words, the blocking\-command slot, the PDO FIFOs
fed per DC cycle, mailboxes (CoE with SDO Information, FoE), SII, the
slaves' state machines, CiA 402 drives and faults. ecmxfd(8) runs it
in its own process with \fBbackend = "sim"\fR (or \fB\-\-sim\fR), or
reaches one served by \fBecmxf\-sim serve\fR with \fBbackend =
"sim\-socket"\fR; \fBecmxf\-sim hardware\fR runs any program, the chip
vendor's driver included, on emulated /dev/spidev0.0 and /dev/gpiochip0.
.SH NETWORK FILE
TOML, strict (an unknown key is an error naming it and its line):
.PP
.nf
.RS
version = 1
[chip]                      # optional
processing_us = 30
firmware_version = 0x24
spi_hz = 20_000_000
[[slave]]                   # one per slave, in ring order
profile = "neuromeka\-core"  # a built\-in device, or:
# esi = "file.xml" (with product_code, revision), sii = "dump.bin",
# eni = "network.xml" with eni_slave = "Name" or a position from 1
alias = 1
min_cycle_us = 125          # a shorter SYNC0 is refused at SAFE\-OP
.RE
.fi
.PP
\fBecmxf\-sim check FILE\fR lists the slaves a file makes and what it
could not model as the file says.
.SH CONTROL COMMANDS
Sent to a serving simulator with \fBecmxf\-sim ctl \-\-socket SOCKET
WORDS...\fR; numbers are decimal or 0x hex.
.PP
.nf
"#,
    );
    for line in ecmxf_sim::control::HELP.lines() {
        let line = line.replace('\\', "\\e").replace('-', "\\-");
        text.push_str(&line);
        text.push('\n');
    }
    text.push_str(".fi\n.SH EXIT STATUS\n0 on success; 2 for a network file that does not load; 1 for any other failure; \
                   \\fBhardware\\fR exits with its command's status.\n.SH SEE ALSO\necmxfd(8), ecmxfd.toml(5), ecmxfctl(1)\n");
    text
}

/// Writes ecmxf-sim(1) into `dir`.
fn write_man_page(dir: &std::path::Path) -> std::io::Result<PathBuf> {
    use clap::CommandFactory;
    std::fs::create_dir_all(dir)?;
    let man = clap_mangen::Man::new(Cli::command()).section("1");
    let mut page = Vec::new();
    man.render_title(&mut page)?;
    man.render_name_section(&mut page)?;
    man.render_synopsis_section(&mut page)?;
    page.extend_from_slice(man_more().as_bytes());
    man.render_subcommands_section(&mut page)?;
    man.render_version_section(&mut page)?;
    let path = dir.join("ecmxf-sim.1");
    std::fs::write(&path, page)?;
    Ok(path)
}

/// Why a command failed, and so its exit code: a network file that does
/// not load is a usage error (2) for `serve` and `check` alike, as a bad
/// configuration is for `ecmxfd --check-config`; anything else is 1.
enum Failure {
    BadNetwork(String),
    Other(String),
    /// The command `hardware` ran exited with this status.
    Exit(u8),
}

/// The preload library beside this executable (`cargo build`) or in its
/// deps/ folder (`cargo test`).
fn find_library() -> Result<PathBuf, Failure> {
    let exe = std::env::current_exe().map_err(|e| format!("this executable's path: {e}"))?;
    let dir = exe.parent().map(PathBuf::from).unwrap_or_default();
    [dir.join("libecmxf_hw_emu.so"), dir.join("deps/libecmxf_hw_emu.so")].into_iter().find(|p| p.exists()).ok_or_else(
        || {
            Failure::Other(format!(
                "no libecmxf_hw_emu.so in {} (build it: `cargo build -p ecmxf-hw-emu`, or give --library)",
                dir.display()
            ))
        },
    )
}

impl From<String> for Failure {
    fn from(s: String) -> Self {
        Self::Other(s)
    }
}

fn load(network: Option<&PathBuf>) -> Result<(Network, ChipConfig), Failure> {
    match network {
        None => Ok((Network::demo(), ChipConfig::default())),
        Some(p) => {
            let f = NetworkFile::load(p).map_err(|e| Failure::BadNetwork(e.to_string()))?;
            Ok((f.build(p).map_err(|e| Failure::BadNetwork(e.to_string()))?, f.chip_config()))
        }
    }
}

fn run(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        Command::Serve { socket, network, seed, strict_lengths, spin_us } => {
            let (net, mut config) = load(network.as_ref())?;
            config.strict_lengths |= strict_lengths;
            let slaves = net.slaves.len();
            let mut chip = Chip::new(net, config);
            chip.faults.seed(seed);
            let listener = server::bind(&socket).map_err(|e| format!("{}: {e}", socket.display()))?;
            let lengths = if chip.config.strict_lengths { "strict (v049 only)" } else { "as the chip takes them" };
            eprintln!("ecmxf-sim: {slaves} slaves, serving on {}, data lengths {lengths}", socket.display());
            let stop = Arc::new(AtomicBool::new(false));
            let server = Server::new(chip).with_spin(Duration::from_micros(spin_us));
            Ok(Arc::new(server).serve(listener, stop).map_err(|e| e.to_string())?)
        }
        Command::Hardware { network, socket, library, seed, command } => {
            let (net, config) = load(network.as_ref())?;
            let mut chip = Chip::new(net, config);
            chip.faults.seed(seed);
            let library = library.map_or_else(find_library, Ok)?;
            let temporary = socket.is_none();
            let socket = socket.unwrap_or_else(|| {
                std::env::temp_dir().join(format!("ecmxf-sim-hardware-{}.sock", std::process::id()))
            });
            let listener = server::bind(&socket).map_err(|e| format!("{}: {e}", socket.display()))?;
            let stop = Arc::new(AtomicBool::new(false));
            let serving = {
                let stop = Arc::clone(&stop);
                let server = Arc::new(Server::new(chip));
                std::thread::spawn(move || server.serve(listener, stop))
            };
            eprintln!(
                "ecmxf-sim: serving on {} for {} with {} preloaded (devices: sim/hw-emu/README.md)",
                socket.display(),
                command[0],
                library.display()
            );
            let preload = match std::env::var_os("LD_PRELOAD") {
                Some(other) if !other.is_empty() => {
                    let mut all = library.clone().into_os_string();
                    all.push(":");
                    all.push(other);
                    all
                }
                _ => library.clone().into_os_string(),
            };
            let status = std::process::Command::new(&command[0])
                .args(&command[1..])
                .env("LD_PRELOAD", preload)
                .env("ECMXF_SIM_SOCKET", &socket)
                .status()
                .map_err(|e| format!("{}: {e}", command[0]));
            stop.store(true, std::sync::atomic::Ordering::Relaxed);
            let _ = serving.join();
            if temporary {
                let _ = std::fs::remove_file(&socket);
            }
            let status = status?;
            match status.code() {
                Some(0) => Ok(()),
                Some(code) => Err(Failure::Exit(u8::try_from(code).unwrap_or(1))),
                None => Err(format!("{} ended by a signal ({status})", command[0]).into()),
            }
        }
        Command::Ctl { socket, command } => {
            let mut c = SocketClient::connect(&socket).map_err(|e| format!("{}: {e}", socket.display()))?;
            match c.control(&command.join(" ")).map_err(|e| e.to_string())? {
                Ok(text) => {
                    println!("{text}");
                    Ok(())
                }
                Err(text) => Err(text.into()),
            }
        }
        Command::Man { dir } => {
            let path = write_man_page(&dir)
                .map_err(|e| format!("cannot write the manual page into {}: {e}", dir.display()))?;
            println!("{}", path.display());
            Ok(())
        }
        Command::Check { network } => {
            let (net, _) = load(Some(&network))?;
            // A closed pipe (`| head -1`) ends the listing, not in a panic.
            let mut out = std::io::stdout().lock();
            for (i, s) in net.slaves.iter().enumerate() {
                let sii = s.sii();
                let line = format!(
                    "{i}: {:<24} vendor {:#010x} product {:#010x} revision {:#010x} outputs {} B inputs {} B",
                    s.name,
                    sii.vendor_id,
                    sii.product_code,
                    sii.revision,
                    s.rx.bytes(),
                    s.tx.bytes()
                );
                if writeln!(out, "{line}").is_err() {
                    return Ok(());
                }
                for note in &s.notes {
                    if writeln!(out, "   {note}").is_err() {
                        return Ok(());
                    }
                }
                for ((index, sub), why) in &s.od.beyond_file {
                    let what = why.says();
                    let note = format!("   {index:#06x}:{sub:02x}, {what}");
                    if writeln!(out, "{note}").is_err() {
                        return Ok(());
                    }
                }
            }
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::BadNetwork(e)) => {
            eprintln!("ecmxf-sim: {e}");
            ExitCode::from(2)
        }
        Err(Failure::Other(e)) => {
            eprintln!("ecmxf-sim: {e}");
            ExitCode::FAILURE
        }
        Err(Failure::Exit(code)) => ExitCode::from(code),
    }
}
