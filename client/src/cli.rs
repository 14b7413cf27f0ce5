//! The command line (clap). Names follow the IgH `ethercat` tool where its
//! users have habits (`master`, `slaves`, `states`, `upload`, `download`,
//! `sdos`, `pdos`, `reg_read` -> `reg read`, `foe_read` -> `foe read`);
//! `-p/--position` selects a slave by ring position as it does there.
//! Completions and the man page are generated from these definitions.

use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, Parser, Subcommand, ValueEnum};

use crate::values;

/// Diagnose and drive an EtherCAT network behind an ECM-XF master (ecmxfd).
///
/// ecmxfctl talks to the ecmxfd daemon over its gRPC API: its Unix socket by
/// default, or TCP with TLS (--connect). Every command prints a table, or
/// JSON with --json (schemas: `ecmxfctl json-schema`). Exit codes: 0 done,
/// 1 failed, 2 bad usage or argument, 3 daemon unreachable, 4 permission
/// denied, 5 timed out, 6 SDO abort, 7 wrong state, 8 diag found a problem.
#[derive(Debug, Parser)]
#[command(name = "ecmxfctl", version, max_term_width = 100)]
pub struct Cli {
    #[command(flatten)]
    pub connect: ConnectArgs,
    /// Print JSON instead of tables (one object; streams: one object per line).
    #[arg(long, global = true)]
    pub json: bool,
    /// Deadline for the whole command, e.g. 500ms, 3s, 1m [default: 5s,
    /// longer for what needs it: SII ranges and writes, FoE transfers,
    /// waiting for states]. Given, it is the deadline, whatever the command
    /// (following commands, `events` and `watch`, run until stopped).
    #[arg(long, global = true, value_parser = parse_duration, value_name = "DURATION")]
    pub timeout: Option<Duration>,
    #[command(subcommand)]
    pub command: Command,
}

/// Where the daemon is and who we are.
#[derive(Debug, Args)]
pub struct ConnectArgs {
    /// The daemon's Unix socket [default: $ECMXF_SOCKET, else your own
    /// daemon's ($XDG_RUNTIME_DIR/ecmxfd.sock or /tmp/ecmxfd-UID.sock; root:
    /// /run/ecmxfd/ecmxfd.sock) if it exists, else the system service's
    /// /run/ecmxfd/ecmxfd.sock].
    // The environment variables of --socket, --connect and --ca are read by
    // the methods below, not by clap: clap shows an argument given by its
    // variable in usage lines as if it had been typed.
    #[arg(long, global = true, value_name = "PATH")]
    pub socket: Option<PathBuf>,
    /// Connect over TCP with TLS instead: host:port or https://host:port
    /// [default: $ECMXF_CONNECT].
    #[arg(long, global = true, value_name = "URL", conflicts_with = "socket")]
    pub connect: Option<String>,
    /// Bearer token ([[api.token]] in the daemon's configuration).
    #[arg(long, global = true, env = "ECMXF_TOKEN", hide_env_values = true, value_name = "TOKEN")]
    pub token: Option<String>,
    /// Read the bearer token from a file.
    #[arg(long, global = true, value_name = "FILE", conflicts_with = "token")]
    pub token_file: Option<PathBuf>,
    /// CA certificate (PEM) that signed the daemon's TLS certificate
    /// [default: $ECMXF_CA, else the system's roots].
    #[arg(long, global = true, value_name = "FILE")]
    pub ca: Option<PathBuf>,
    /// Client certificate (PEM) for mutual TLS.
    #[arg(long, global = true, requires = "key", value_name = "FILE")]
    pub cert: Option<PathBuf>,
    /// The client certificate's private key (PEM).
    #[arg(long, global = true, requires = "cert", value_name = "FILE")]
    pub key: Option<PathBuf>,
    /// Server name to verify in the daemon's certificate [default: the host of --connect].
    #[arg(long, global = true, value_name = "NAME")]
    pub tls_domain: Option<String>,
}

impl ConnectArgs {
    /// TCP: `--connect`, else `$ECMXF_CONNECT` unless `--socket` was given.
    pub fn tcp(&self) -> Option<String> {
        self.connect.clone().or_else(|| if self.socket.is_some() { None } else { env_value("ECMXF_CONNECT") })
    }

    /// The Unix socket: `--socket`, else as [`ecmxf_proto::client_socket_path`]
    /// finds it (`$ECMXF_SOCKET` first).
    pub fn socket_path(&self) -> PathBuf {
        self.socket.clone().unwrap_or_else(ecmxf_proto::client_socket_path)
    }

    /// `--ca`, else `$ECMXF_CA`.
    pub fn ca_file(&self) -> Option<PathBuf> {
        self.ca.clone().or_else(|| env_value("ECMXF_CA").map(PathBuf::from))
    }
}

fn env_value(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.is_empty())
}

/// A slave by ring position (0-based).
#[derive(Debug, Args, Clone, Copy)]
pub struct Position {
    /// Slave ring position (0-based).
    #[arg(short, long = "position", value_name = "POS")]
    pub position: u32,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// The master: chip firmware, cycle, FIFO, engine phase and counters.
    Master,
    /// Slaves on the ring: position, alias, state, AL status, identity.
    Slaves {
        /// Only this slave.
        #[arg(short, long = "position", value_name = "POS")]
        position: Option<u32>,
        /// Everything known about each slave (addresses, IO sizes, DC, expected identity).
        #[arg(short, long)]
        verbose: bool,
        /// Read identities afresh from the slaves first.
        #[arg(long)]
        scan: bool,
    },
    /// Show states, or request one: `states`, `states 1`, `states op`, `states 1 safeop`.
    States {
        /// A slave position, a state, or both (position first).
        #[arg(value_name = "SLAVE|STATE", num_args = 0..=2)]
        args: Vec<String>,
        /// The slave, as IgH's `ethercat states -p 1 SAFEOP` names it.
        #[arg(short, long = "position", value_name = "POS")]
        position: Option<u32>,
        /// Return once requested instead of waiting until reached.
        #[arg(long)]
        no_wait: bool,
    },
    /// Read an SDO: `upload -p 1 0x6041 0`.
    Upload(Upload),
    /// Write an SDO: `download -p 1 0x6060 0 8`.
    Download(Download),
    /// A slave's object dictionary: as the slave describes it (CoE SDO
    /// Information), else from its ESI, else probed.
    Sdos {
        #[command(flatten)]
        slave: Position,
        /// Only this source: the device itself, its ESI, or probing
        /// standard objects (default: the best there is).
        #[arg(long, value_enum)]
        source: Option<DictionarySource>,
    },
    /// The SII EEPROM: read, write (with backup and verify), dump, decode.
    #[command(subcommand)]
    Sii(SiiCommand),
    /// PDO assignment and mapping, and the process-image layout.
    Pdos {
        /// Only this slave.
        #[arg(short, long = "position", value_name = "POS")]
        position: Option<u32>,
    },
    /// Process data now: every input and output entry with its value.
    Data {
        /// Only these entries (names or variable names as `pdos` lists them).
        entries: Vec<String>,
        /// Only this variable (as `pdos` lists it: the ENI's name, or SLAVE.PDO.ENTRY), repeatable; the same as giving it as an entry.
        #[arg(short = 'v', long = "variable", value_name = "NAME")]
        variables: Vec<String>,
        /// The images as hex instead of entries.
        #[arg(long)]
        raw: bool,
    },
    /// Follow process data live: one line per sample.
    Watch(Watch),
    /// CiA 402 drives ([[axis]] in the daemon's configuration).
    #[command(subcommand)]
    Cia402(Cia402Command),
    /// The chip's GPIO lines 0..=19.
    #[command(subcommand)]
    Gpio(GpioCommand),
    /// One conversion of the chip's 12-bit ADC.
    Adc {
        /// Differential instead of single-ended input.
        #[arg(long)]
        differential: bool,
    },
    /// Set the chip's 12-bit DAC (0..=4095).
    Dac {
        #[arg(value_parser = clap::value_parser!(u32).range(0..=4095))]
        value: u32,
    },
    /// The chip's quadrature encoder input.
    Qei {
        #[arg(value_enum, default_value = "read")]
        action: QeiAction,
    },
    /// File access over EtherCAT (firmware updates): read or write a file.
    #[command(subcommand)]
    Foe(FoeCommand),
    /// ESC registers of a slave (admin).
    #[command(subcommand)]
    Reg(RegCommand),
    /// CoE emergency history, newest first.
    Emergencies {
        /// Records, 1..=8.
        #[arg(short = 'n', long, default_value = "8", value_parser = clap::value_parser!(u32).range(1..=8))]
        count: u32,
    },
    /// Follow the daemon's events (state changes, emergencies, errors) until Ctrl-C.
    Events {
        /// Stop after this many events.
        #[arg(short = 'n', long)]
        count: Option<u64>,
        /// Stop after this long, e.g. 10s.
        #[arg(long = "for", value_parser = parse_duration, value_name = "DURATION")]
        duration: Option<Duration>,
    },
    /// Which slave broke the working counter: counters, per-slave state and AL status.
    Diag,
    /// Bring the network up again and list the slaves found (admin; IgH `rescan`).
    Rescan,
    /// The network as Graphviz dot: `ecmxfctl graph | dot -Tsvg > ring.svg`.
    Graph,
    /// The network the daemon runs as a configuration ecmxfd takes unchanged (IgH `xml`): `ecmxfctl config > net.toml`, `--format eni > net.xml`.
    Config {
        /// `toml`: a whole ecmxfd configuration (link, cycle, [[slave]] with identities, DC and PDOs); `eni`: an ETG.2100 EtherCATConfig for `eni = FILE` (slaves, ProcessData, DC, cycle, ProcessImage).
        #[arg(long, value_enum, default_value = "toml")]
        format: ConfigFormat,
    },
    /// Station aliases in the slaves' SII; `--set N -p POS` writes one with its checksum (admin; IgH `alias`).
    Alias {
        /// Only this slave (required with --set).
        #[arg(short, long = "position", value_name = "POS")]
        position: Option<u32>,
        /// Write this alias (0..=65535).
        #[arg(long, value_name = "ALIAS")]
        set: Option<u16>,
    },
    /// Error counters per port of each slave's ESC (registers 0x0300..; admin; IgH `crc`).
    Crc {
        /// Only this slave.
        #[arg(short, long = "position", value_name = "POS")]
        position: Option<u32>,
        /// Clear the counters first.
        #[arg(long)]
        reset: bool,
    },
    /// PDO configuration as C arrays for IgH's ecrt.h (IgH `cstruct`): ec_pdo_entry_info_t, ec_pdo_info_t, ec_sync_info_t.
    Cstruct {
        /// Only this slave.
        #[arg(short, long = "position", value_name = "POS")]
        position: Option<u32>,
    },
    /// The process image as one domain (IgH `domains`): sizes, frames flowing, WKC errors, FIFO levels.
    Domains {
        /// Each slave's part of the image and the data now.
        #[arg(short, long)]
        verbose: bool,
    },
    /// The daemon's log filter (IgH `debug`): show it, or set it until the next reload: `debug 1`, `debug warn,ecmxfd::engine=debug` (admin).
    Debug {
        /// 0 (info), 1 (the daemon's debug), 2 (its trace), or a filter in tracing's syntax.
        level: Option<String>,
    },
    /// Versions: this tool, the daemon, the chip's firmware, the API.
    Version,
    /// Live view: slaves, states, FIFO, counters and a plot of process data.
    Top(Top),
    /// Shell completions: `ecmxfctl completions bash > /etc/bash_completion.d/ecmxfctl`.
    Completions {
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
    /// Write the man pages (ecmxfctl.1 and one per command) into a folder.
    Man {
        /// Folder to write into.
        #[arg(default_value = ".")]
        dir: PathBuf,
    },
    /// IgH's `ethercat eoe`, `soe`, `ip`: protocols the ECM-XF does not
    /// carry (it speaks CoE and FoE); said so, exit 2.
    #[command(name = "eoe", hide = true, aliases = ["soe", "ip"])]
    NotCarried {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        rest: Vec<String>,
    },
    /// IgH's `ethercat xml`: the slaves' descriptions are `config --format
    /// eni` here (an ETG.2100 file ecmxfd takes back); said so, exit 2.
    #[command(hide = true)]
    Xml {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        rest: Vec<String>,
    },
    /// The JSON schema of a command's --json output (all commands without one).
    JsonSchema {
        /// A command name (e.g. `slaves`, `cia402 status`).
        command: Vec<String>,
    },
}

#[derive(Debug, Args)]
pub struct Upload {
    #[command(flatten)]
    pub slave: Position,
    /// Object index, e.g. 0x6041 (or index:subindex, e.g. 0x1018:01).
    #[arg(value_parser = values::parse_index)]
    pub index: u32,
    /// Subindex.
    #[arg(value_parser = values::parse_subindex, default_value = "0")]
    pub subindex: u32,
    /// Decode as this type [default: the type the object dictionary says]
    /// (`-t` as IgH spells it; `-d` too).
    #[arg(short = 't', long = "type", short_alias = 'd', value_parser = values::parse_type, value_name = "TYPE")]
    pub data_type: Option<ecmxf_proto::v1::DataType>,
    /// CoE complete access: the whole object from the subindex on.
    #[arg(long)]
    pub complete_access: bool,
}

#[derive(Debug, Args)]
pub struct Download {
    #[command(flatten)]
    pub slave: Position,
    /// Object index, e.g. 0x6060 (or index:subindex, e.g. 0x6060:00).
    #[arg(value_parser = values::parse_index)]
    pub index: u32,
    /// Subindex.
    #[arg(value_parser = values::parse_subindex)]
    pub subindex: u32,
    /// The value: decimal or 0x hex; text for strings; hex bytes for
    /// octet_string and complete access.
    #[arg(allow_hyphen_values = true)]
    pub value: String,
    /// Encode as this type [default: the type the object dictionary says]
    /// (`-t` as IgH spells it; `-d` too).
    #[arg(short = 't', long = "type", short_alias = 'd', value_parser = values::parse_type, value_name = "TYPE")]
    pub data_type: Option<ecmxf_proto::v1::DataType>,
    /// CoE complete access (the value is hex bytes).
    #[arg(long)]
    pub complete_access: bool,
}

#[derive(Debug, Subcommand)]
pub enum SiiCommand {
    /// Read words: `sii read -p 0 --word 8 --count 4`.
    Read {
        #[command(flatten)]
        slave: Position,
        /// First word address.
        #[arg(long, default_value = "0", value_parser = values::parse_address)]
        word: u32,
        /// Words to read (1..=4096).
        #[arg(long, default_value = "64", value_parser = clap::value_parser!(u32).range(1..=4096))]
        count: u32,
    },
    /// Write a binary file (or hex) into the EEPROM, saving what it overwrites
    /// and verifying every word (admin).
    Write {
        #[command(flatten)]
        slave: Position,
        /// Binary file to write (`-` for standard input).
        #[arg(required_unless_present = "hex", conflicts_with = "hex")]
        file: Option<PathBuf>,
        /// Bytes as hex instead of a file.
        #[arg(long)]
        hex: Option<String>,
        /// First word address.
        #[arg(long, default_value = "0", value_parser = values::parse_address)]
        word: u32,
        /// Where to save the previous contents [default: sii-backup-<POS>-<UTC time, 20261128T195300Z>.bin].
        #[arg(long, value_name = "FILE")]
        backup: Option<PathBuf>,
    },
    /// The image as binary, from word 0 through its categories' end marker: to a file, or
    /// standard output when it is not a terminal.
    Dump {
        #[command(flatten)]
        slave: Position,
        /// Output file.
        #[arg(short, long, value_name = "FILE")]
        output: Option<PathBuf>,
    },
    /// The image decoded: identity, mailbox, strings, SyncManagers, PDOs.
    Decode {
        #[command(flatten)]
        slave: Position,
    },
}

#[derive(Debug, Args)]
pub struct Watch {
    /// Entries to show (input and output names or variable names as `pdos` lists them) [default: every input].
    pub entries: Vec<String>,
    /// A variable to show (as `pdos` lists it: the ENI's name, or SLAVE.PDO.ENTRY), repeatable; the same as giving it as an entry.
    #[arg(short = 'v', long = "variable", value_name = "NAME")]
    pub variables: Vec<String>,
    /// Time between lines, e.g. 100ms (inputs are sampled, not averaged).
    #[arg(short, long, default_value = "100ms", value_parser = parse_duration, value_name = "DURATION")]
    pub interval: Duration,
    /// Print a line only when a value changed.
    #[arg(long)]
    pub on_change: bool,
    /// Stop after this many lines.
    #[arg(short = 'n', long)]
    pub count: Option<u64>,
}

/// CiA 402 operation modes (0x6060).
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum Mode {
    /// Profile position (1).
    Pp,
    /// Profile velocity (3).
    Pv,
    /// Profile torque (4).
    Pt,
    /// Homing (6).
    Hm,
    /// Cyclic synchronous position (8).
    Csp,
    /// Cyclic synchronous velocity (9).
    Csv,
    /// Cyclic synchronous torque (10).
    Cst,
}

impl Mode {
    /// The 0x6060 value.
    pub fn code(self) -> i32 {
        match self {
            Self::Pp => 1,
            Self::Pv => 3,
            Self::Pt => 4,
            Self::Hm => 6,
            Self::Csp => 8,
            Self::Csv => 9,
            Self::Cst => 10,
        }
    }
}

/// An axis (0-based, [[axis]] order).
#[derive(Debug, Args, Clone, Copy)]
pub struct AxisArg {
    /// Axis number (0-based, as `cia402 status` lists them).
    #[arg(short, long, default_value = "0")]
    pub axis: u32,
}

/// Walking the drive state machine.
#[derive(Debug, Args, Clone, Copy)]
pub struct AxisCommandArgs {
    #[command(flatten)]
    pub axis: AxisArg,
    /// Return once requested instead of waiting until the drive is there.
    #[arg(long)]
    pub no_wait: bool,
}

#[derive(Debug, Subcommand)]
pub enum Cia402Command {
    /// Every axis (or one): drive state, statusword, mode, actual values, error code.
    Status {
        /// Only this axis.
        #[arg(short, long)]
        axis: Option<u32>,
    },
    /// To OPERATION ENABLED (resetting a fault first).
    Enable(AxisCommandArgs),
    /// To SWITCH ON DISABLED.
    Disable(AxisCommandArgs),
    /// Quick stop.
    Quickstop(AxisCommandArgs),
    /// Fault reset: FAULT to SWITCH ON DISABLED.
    Reset(AxisCommandArgs),
    /// Set the mode of operation (0x6060) and wait until the drive shows it.
    Mode {
        #[command(flatten)]
        axis: AxisArg,
        /// csp, csv, cst, pp, pv, pt, hm.
        #[arg(value_enum)]
        mode: Mode,
    },
    /// Set a target: `move --position 10000`, `--velocity`, `--torque`.
    Move(Move),
}

#[derive(Debug, Args)]
#[group(id = "target", required = true, multiple = false)]
pub struct Move {
    #[command(flatten)]
    pub axis: AxisArg,
    /// Target position (0x607A), increments.
    #[arg(long, allow_hyphen_values = true, group = "target")]
    pub position: Option<i64>,
    /// Target velocity (0x60FF), increments per second.
    #[arg(long, allow_hyphen_values = true, group = "target")]
    pub velocity: Option<i64>,
    /// Target torque (0x6071), per mille of rated torque.
    #[arg(long, allow_hyphen_values = true, group = "target")]
    pub torque: Option<i64>,
    /// Wait until the actual position is within this many increments of the
    /// target (position moves only).
    #[arg(long, value_name = "INCREMENTS")]
    pub wait_within: Option<u64>,
}

#[derive(Debug, Subcommand)]
pub enum GpioCommand {
    /// Levels and interrupt flags of every line.
    Get,
    /// Set output lines: `gpio set 3=1 4=0` (others keep their level).
    Set {
        /// LINE=LEVEL pairs, LINE 0..=19, LEVEL 0 or 1.
        #[arg(required = true, value_parser = parse_line_level)]
        lines: Vec<(u32, bool)>,
    },
    /// Configure lines: `gpio config 0-3 output --pull none`.
    Config {
        /// Lines: `5`, `0-3`, `1,4,7`.
        #[arg(value_parser = parse_lines)]
        lines: u32,
        #[arg(value_enum)]
        mode: GpioMode,
        #[arg(long, value_enum, default_value = "none")]
        pull: GpioPull,
    },
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum ConfigFormat {
    Toml,
    Eni,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum GpioMode {
    Input,
    Output,
    OpenDrain,
    QuasiBidirectional,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum GpioPull {
    None,
    Up,
    Down,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum QeiAction {
    /// Read the count.
    Read,
    /// Open in X4 free-counting mode and start.
    Start,
    /// Stop counting.
    Stop,
}

#[derive(Debug, Subcommand)]
pub enum FoeCommand {
    /// Read a file from a slave: `foe read -p 1 firmware.bin -o fw.bin`.
    Read {
        #[command(flatten)]
        slave: Position,
        /// File name on the slave.
        name: String,
        /// Where to save it [default: the name, in the current folder].
        #[arg(short, long, value_name = "FILE")]
        output: Option<PathBuf>,
        /// FoE password (decimal or 0x hex).
        #[arg(long, default_value = "0", value_parser = values::parse_u32)]
        password: u32,
        /// Largest file accepted, bytes.
        #[arg(long, default_value = "262143", value_parser = clap::value_parser!(u32).range(1..=262143))]
        max_bytes: u32,
    },
    /// Write a file to a slave: `foe write -p 1 fw.bin [--name firmware.bin]`.
    Write {
        #[command(flatten)]
        slave: Position,
        /// Local file.
        file: PathBuf,
        /// File name on the slave [default: the local file's name].
        #[arg(long)]
        name: Option<String>,
        /// FoE password (decimal or 0x hex).
        #[arg(long, default_value = "0", value_parser = values::parse_u32)]
        password: u32,
    },
}

#[derive(Debug, Subcommand)]
pub enum RegCommand {
    /// Read registers: `reg read -p 0 0x130 2` (AL status).
    Read {
        #[command(flatten)]
        slave: Position,
        /// Register address, e.g. 0x0130.
        #[arg(value_parser = values::parse_address)]
        address: u32,
        /// Bytes [default: the type's size, else 1].
        #[arg(value_parser = clap::value_parser!(u32).range(1..=1024))]
        length: Option<u32>,
        /// Decode as uint8/16/32/64 or int8/16/32/64.
        #[arg(short, long = "type", value_parser = values::parse_type, value_name = "TYPE")]
        data_type: Option<ecmxf_proto::v1::DataType>,
    },
    /// Write registers: `reg write -p 0 0x0120 --type uint16 2` or hex bytes.
    Write {
        #[command(flatten)]
        slave: Position,
        #[arg(value_parser = values::parse_address)]
        address: u32,
        /// Hex bytes, or a number with --type.
        #[arg(allow_hyphen_values = true)]
        value: String,
        /// Encode the value as this type (little-endian).
        #[arg(short, long = "type", value_parser = values::parse_type, value_name = "TYPE")]
        data_type: Option<ecmxf_proto::v1::DataType>,
    },
}

#[derive(Debug, Args)]
pub struct Top {
    /// Input entries to plot (e.g. 1.position_actual 1.velocity_actual) [default: the actual position and velocity of the first [[axis]], else of the first drive].
    #[arg(long = "plot", value_name = "ENTRY")]
    pub plot: Vec<String>,
    /// Refresh interval.
    #[arg(short, long, default_value = "250ms", value_parser = parse_duration, value_name = "DURATION")]
    pub interval: Duration,
    /// Print one frame of the view as text and exit (no terminal needed).
    #[arg(long)]
    pub once: bool,
    /// Width and height of the --once frame.
    #[arg(long, default_value = "100x30", value_parser = parse_size, value_name = "WxH")]
    pub size: (u16, u16),
}

/// "500ms", "3s", "1.5s", "2m", or plain seconds.
pub fn parse_duration(s: &str) -> Result<Duration, String> {
    let t = s.trim();
    let (num, scale) = if let Some(n) = t.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = t.strip_suffix("us") {
        (n, 1e-6)
    } else if let Some(n) = t.strip_suffix('s') {
        (n, 1.0)
    } else if let Some(n) = t.strip_suffix('m') {
        (n, 60.0)
    } else {
        (t, 1.0)
    };
    match num.trim().parse::<f64>() {
        Ok(v) if v >= 0.0 && v.is_finite() && v * scale < 1e9 => Ok(Duration::from_secs_f64(v * scale)),
        _ => Err(format!("{s:?} is not a duration (e.g. 500ms, 3s, 2m)")),
    }
}

/// "3=1" -> (3, true).
fn parse_line_level(s: &str) -> Result<(u32, bool), String> {
    let (l, v) = s.split_once('=').ok_or_else(|| format!("{s:?}: write LINE=LEVEL, e.g. 3=1"))?;
    let line: u32 = l.trim().parse().ok().filter(|l| *l < 20).ok_or_else(|| format!("{s:?}: line is 0..=19"))?;
    let level = match v.trim() {
        "1" | "high" | "on" => true,
        "0" | "low" | "off" => false,
        _ => return Err(format!("{s:?}: level is 0 or 1")),
    };
    Ok((line, level))
}

/// "0-3,7" -> bit mask.
fn parse_lines(s: &str) -> Result<u32, String> {
    let mut mask = 0u32;
    for part in s.split(',') {
        let line = |t: &str| {
            t.trim().parse::<u32>().ok().filter(|l| *l < 20).ok_or_else(|| format!("{s:?}: lines are 0..=19"))
        };
        let (a, b) = match part.split_once('-') {
            Some((a, b)) => (line(a)?, line(b)?),
            None => (line(part)?, line(part)?),
        };
        if a > b {
            return Err(format!("{s:?}: range {a}-{b} runs backwards"));
        }
        for l in a..=b {
            mask |= 1 << l;
        }
    }
    Ok(mask)
}

/// "100x30".
fn parse_size(s: &str) -> Result<(u16, u16), String> {
    let (w, h) = s.split_once('x').ok_or_else(|| format!("{s:?}: write WIDTHxHEIGHT, e.g. 100x30"))?;
    match (w.parse::<u16>(), h.parse::<u16>()) {
        (Ok(w), Ok(h)) if (20..=500).contains(&w) && (8..=200).contains(&h) => Ok((w, h)),
        _ => Err(format!("{s:?}: width 20..=500, height 8..=200")),
    }
}

/// The command line with an object given as `index:subindex` (`0x1018:01`,
/// as the daemon names objects) split into the two arguments `upload` and
/// `download` take. Only the first positional argument after those
/// commands is looked at; the subindex after the colon is hex when the
/// index is (`0x6000:0a`), else decimal.
pub fn split_object_address(args: Vec<std::ffi::OsString>) -> Vec<std::ffi::OsString> {
    let cli = <Cli as clap::CommandFactory>::command();
    // Options whose value is the next argument: the global ones, then
    // those of the command once it is known.
    let mut takes_value = value_options(&cli);
    let mut sdo_command = false;
    let mut out = Vec::with_capacity(args.len() + 1);
    let mut it = args.into_iter();
    out.extend(it.next()); // the program
    let mut skip_value = false;
    for a in it.by_ref() {
        let text = a.to_string_lossy().into_owned();
        out.push(a);
        if std::mem::take(&mut skip_value) {
            continue;
        }
        if text == "--" {
            break;
        }
        if takes_value.contains(&text) {
            skip_value = true;
            continue;
        }
        if text.starts_with('-') {
            continue;
        }
        if !sdo_command {
            match cli.find_subcommand(&text).filter(|_| text == "upload" || text == "download") {
                Some(command) => takes_value.extend(value_options(command)),
                None => break,
            }
            sdo_command = true;
            continue;
        }
        if let Some((index, sub)) = text.split_once(':').filter(|(i, s)| !i.is_empty() && !s.is_empty()) {
            let hex = index.starts_with("0x") || index.starts_with("0X");
            out.pop();
            out.push(index.into());
            out.push(if hex && !sub.starts_with("0x") { format!("0x{sub}") } else { sub.to_owned() }.into());
        }
        break;
    }
    out.extend(it);
    out
}

/// `--name` and `-n` of `command`'s options that take a value.
fn value_options(command: &clap::Command) -> Vec<String> {
    command
        .get_arguments()
        .filter(|a| !a.is_positional() && a.get_action().takes_values())
        .flat_map(|a| a.get_long().map(|l| format!("--{l}")).into_iter().chain(a.get_short().map(|c| format!("-{c}"))))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn small_parsers_accept_what_users_write_and_say_what_is_wrong() {
        assert_eq!(parse_duration("500ms").unwrap(), Duration::from_millis(500));
        assert_eq!(parse_duration("1.5s").unwrap(), Duration::from_millis(1500));
        assert_eq!(parse_duration("2m").unwrap(), Duration::from_secs(120));
        assert!(parse_duration("soon").unwrap_err().contains("soon"));
        assert_eq!(parse_lines("0-3,7").unwrap(), 0b1000_1111);
        assert!(parse_lines("3-1").unwrap_err().contains("backwards"));
        assert!(parse_lines("20").is_err());
        assert_eq!(parse_line_level("3=1").unwrap(), (3, true));
        assert!(parse_line_level("3").unwrap_err().contains("LINE=LEVEL"));
        assert_eq!(parse_size("80x24").unwrap(), (80, 24));
    }

    fn split(line: &str) -> String {
        let args = line.split(' ').map(std::ffi::OsString::from).collect();
        let out: Vec<String> = split_object_address(args).iter().map(|a| a.to_string_lossy().into_owned()).collect();
        out.join(" ")
    }

    #[test]
    fn an_object_as_index_colon_subindex_is_two_arguments() {
        assert_eq!(split("ecmxfctl upload -p 1 0x1018:01"), "ecmxfctl upload -p 1 0x1018 0x01");
        assert_eq!(
            split("ecmxfctl --socket /a:b upload 0x6000:0a -p 2"),
            "ecmxfctl --socket /a:b upload 0x6000 0x0a -p 2"
        );
        assert_eq!(split("ecmxfctl download -p 1 4120:2 7"), "ecmxfctl download -p 1 4120 2 7");
        assert_eq!(
            split("ecmxfctl --json download --type string -p 1 0x2000:00 a:b"),
            "ecmxfctl --json download --type string -p 1 0x2000 0x00 a:b"
        );
        // Only those commands, only their first positional argument.
        assert_eq!(split("ecmxfctl download -p 1 0x2000 0 a:b"), "ecmxfctl download -p 1 0x2000 0 a:b");
        assert_eq!(split("ecmxfctl reg read -p 0 0x130:2"), "ecmxfctl reg read -p 0 0x130:2");
        assert_eq!(split("ecmxfctl upload -- 0x1018:01"), "ecmxfctl upload -- 0x1018:01");
    }
}

/// Where `sdos` takes a dictionary from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DictionarySource {
    /// The slave's own description (CoE SDO Information).
    Device,
    /// The ESI file the configuration names for the slave.
    Esi,
    /// Standard objects probed with SDO uploads.
    Probe,
}
