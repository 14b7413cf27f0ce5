//! The daemon's configuration file (TOML). A `version` key, unknown keys
//! rejected, and every mistake reported with the key that holds it (and, for
//! syntax, the line), so `ecmxfd --check-config FILE` tells an engineer what
//! to fix before the daemon touches a bus.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};

pub mod api;
mod eni;
mod files;
mod manual;
pub mod opcua;
#[cfg(feature = "sim")]
pub(crate) mod sim_network;
mod slave_frames;
pub mod sparkplug;
pub mod web;

pub use api::{ApiConfig, Role};
pub use opcua::OpcuaConfig;
pub use sparkplug::SparkplugConfig;
pub use web::WebConfig;

/// A configuration mistake: unreadable file, TOML syntax or schema (naming
/// key and line), or a value not allowed (naming the dotted key). The same
/// type as the simulator's network files, which follow the same rules.
pub use ecmxf_devices::config_file::ConfigError;

/// The file format version this build reads.
pub const VERSION: u32 = 1;

/// The DC cycle range, us: at least 125 us (v049 簡介; docs/protocol.md §17),
/// at most what SYNC0's 32-bit nanosecond register holds (ECAT_INIT's
/// cycle field, v049 命令 1).
pub const SYNC0_US: std::ops::RangeInclusive<u32> = 125..=(u32::MAX / 1000);

/// CPUs the affinity mask can name (the kernel's `CPU_SETSIZE`).
pub const MAX_CPUS: usize = 1024;

/// ecmxfd.toml(5), in roff: every key of [`Config`] with its type,
/// default and documentation (`config/manual.rs`).
pub fn manual_page(version: &str) -> String {
    manual::render(&schemars::schema_for!(Config), version)
}

/// Every key ecmxfd.toml(5) documents, dotted (`cycle.sync0_us`).
pub fn documented_keys() -> Vec<String> {
    manual::keys(&schemars::schema_for!(Config))
}

/// The whole file.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Format version, 1.
    pub version: u32,
    /// How the chip is reached.
    pub link: LinkConfig,
    /// Link settings the daemon gives the chip.
    #[serde(default)]
    pub chip: ChipSettings,
    /// Real-time thread.
    #[serde(default)]
    pub realtime: RealtimeConfig,
    /// Cyclic exchange.
    #[serde(default)]
    pub cycle: CycleConfig,
    /// An ENI file (ETG.2100) describing the network: its slaves and their
    /// CoE init commands become the `[[slave]]` list, or are merged into
    /// the one given (config/eni.rs).
    #[serde(default)]
    pub eni: Option<PathBuf>,
    /// The output and input frame sizes the ENI describes, bytes, when it
    /// describes every slave's (config/eni.rs, `eni_frames`): the offline
    /// link budget. Not a TOML key.
    #[serde(skip)]
    pub eni_frames: Option<(usize, usize)>,
    /// The expected network, in ring order (empty: accept what is found).
    #[serde(default, rename = "slave")]
    pub slaves: Vec<SlaveConfig>,
    /// Axes driven by the chip's CiA402 helper.
    #[serde(default, rename = "axis")]
    pub axes: Vec<AxisConfig>,
    /// Automatic recovery.
    #[serde(default)]
    pub recovery: RecoveryConfig,
    /// What happens to the outputs when their writers go.
    #[serde(default)]
    pub outputs: OutputsConfig,
    /// The gRPC API: socket, TCP/TLS, roles.
    #[serde(default)]
    pub api: ApiConfig,
    /// Logging.
    #[serde(default)]
    pub log: LogConfig,
    /// The Prometheus endpoint.
    #[serde(default)]
    pub metrics: MetricsConfig,
    /// The ETG.8200 mailbox gateway for engineering tools; absent: off.
    #[serde(default)]
    pub gateway: Option<GatewayConfig>,
    /// The MQTT Sparkplug B edge node; absent: off.
    #[serde(default)]
    pub sparkplug: Option<SparkplugConfig>,
    /// The OPC UA server; absent: off.
    #[serde(default)]
    pub opcua: Option<OpcuaConfig>,
    /// The web dashboard; absent: off.
    #[serde(default)]
    pub web: Option<WebConfig>,
    /// Where the daemon keeps what it learned across restarts (object
    /// dictionaries read from devices). Unset: systemd's
    /// `$STATE_DIRECTORY` (the unit's `StateDirectory=`), else nothing is
    /// kept on disk.
    #[serde(default)]
    pub state_dir: Option<PathBuf>,
}

/// `[log]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct LogConfig {
    /// A `tracing` filter: "info", "warn", "info,ecmxfd::engine=debug".
    /// `RUST_LOG` wins over it; SIGHUP applies a new one.
    pub level: String,
}

impl Default for LogConfig {
    fn default() -> Self {
        Self { level: "info".into() }
    }
}

/// `[metrics]`.
#[derive(Clone, Debug, Default, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct MetricsConfig {
    /// Serve Prometheus metrics at http://ADDRESS/metrics; absent: off.
    pub listen: Option<std::net::SocketAddr>,
}

/// `[gateway]`: the ETG.8200 mailbox gateway (daemon/src/gateway).
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GatewayConfig {
    /// UDP address to serve, e.g. "0.0.0.0:34980" (0x88A4, the port tools
    /// use).
    pub listen: std::net::SocketAddr,
    /// Clients allowed: addresses ("10.0.0.7") or networks ("10.0.0.0/24",
    /// "fd00::/8"). Empty: this host only.
    #[serde(default)]
    #[schemars(with = "Vec<String>")]
    pub allow: Vec<AllowedClients>,
}

/// One `gateway.allow` entry: an address and how many leading bits of it
/// a client must share.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AllowedClients {
    /// The address.
    pub address: std::net::IpAddr,
    /// Leading bits that must match.
    pub prefix: u8,
}

impl<'de> Deserialize<'de> for AllowedClients {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        let (addr, prefix) = text.split_once('/').map_or((text.as_str(), None), |(a, p)| (a, Some(p)));
        let address: std::net::IpAddr = addr
            .trim()
            .parse()
            .map_err(|_| serde::de::Error::custom(format!("{text:?} is not an address or address/prefix")))?;
        let max = if address.is_ipv4() { 32 } else { 128 };
        let prefix = match prefix {
            None => max,
            Some(p) => p
                .trim()
                .parse::<u8>()
                .ok()
                .filter(|p| *p <= max)
                .ok_or_else(|| serde::de::Error::custom(format!("{text:?}: the prefix must be 0..={max}")))?,
        };
        Ok(Self { address, prefix })
    }
}

impl AllowedClients {
    /// Whether `ip` is in it.
    pub fn contains(&self, ip: std::net::IpAddr) -> bool {
        use std::net::IpAddr::{V4, V6};
        let (a, b, bits): (u128, u128, u32) = match (self.address, ip) {
            (V4(a), V4(b)) => (u32::from(a).into(), u32::from(b).into(), 32),
            (V6(a), V6(b)) => (u128::from(a), u128::from(b), 128),
            (V4(a), V6(b)) => match b.to_ipv4_mapped() {
                Some(b) => (u32::from(a).into(), u32::from(b).into(), 32),
                None => return false,
            },
            (V6(_), V4(_)) => return false,
        };
        let keep = u32::from(self.prefix).min(bits);
        keep == 0 || (a ^ b) >> (bits - keep) == 0
    }
}

impl GatewayConfig {
    /// Whether a client at `ip` may use the gateway.
    pub fn allows(&self, ip: std::net::IpAddr) -> bool {
        if self.allow.is_empty() {
            return ip.is_loopback()
                || matches!(ip, std::net::IpAddr::V6(v6) if v6.to_ipv4_mapped().is_some_and(|v4| v4.is_loopback()));
        }
        self.allow.iter().any(|a| a.contains(ip))
    }
}

/// `[outputs]`.
#[derive(Clone, Debug, Default, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct OutputsConfig {
    /// What the daemon does when the last client that wrote outputs goes
    /// away (disconnects, crashes) while the network runs; also what the
    /// outputs are when the network comes back after a fault (hold-last and
    /// quick-stop: the image the lease holders last wrote; zero: zeros).
    /// Whatever it is, configured axes come up disabled after a fault.
    pub on_last_writer_gone: WriterGoneAction,
}

/// `outputs.on_last_writer_gone`.
#[derive(Clone, Copy, Debug, Default, Deserialize, schemars::JsonSchema, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum WriterGoneAction {
    /// Keep sending the last outputs written (what the chip itself does
    /// when its RxFIFO runs dry).
    #[default]
    HoldLast,
    /// Set every output byte to zero.
    Zero,
    /// Quick-stop every `[[axis]]` through the chip's CiA402 helper, and
    /// keep the other outputs as they are.
    QuickStop,
}

impl WriterGoneAction {
    /// As written in the configuration file (`hold-last`, `zero`,
    /// `quick-stop`).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::HoldLast => "hold-last",
            Self::Zero => "zero",
            Self::QuickStop => "quick-stop",
        }
    }
}

/// `[link]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(try_from = "RawLink")]
pub enum LinkConfig {
    /// The in-process simulator.
    Sim {
        /// Network file (the demo network when absent).
        network: Option<PathBuf>,
    },
    /// A simulator served on a Unix socket (`ecmxf-sim serve`).
    SimSocket {
        /// Socket path.
        socket: PathBuf,
    },
    /// Real hardware.
    Spidev {
        /// SPI device.
        device: PathBuf,
        /// SPI clock, Hz.
        spi_hz: u32,
        /// GPIO chip of INT0/INT1.
        gpio_chip: Option<PathBuf>,
        /// INT0 line offset (ready); absent = not wired, fixed idle time.
        int0_line: Option<u32>,
        /// INT1 line offset (events).
        int1_line: Option<u32>,
        /// Kernel debounce on INT1, us (INT0's busy pulse, tens of us, would
        /// vanish under it: it is never debounced).
        debounce_us: Option<u32>,
        /// Idle time after a transfer without INT0, us (vendor: 150-200).
        idle_us: u32,
    },
}

impl LinkConfig {
    /// The `[link]` table as TOML lines, paths as resolved: what
    /// `ecmxfctl config` copies into a configuration written from the live
    /// network (MasterInfo.link_toml).
    pub fn to_toml(&self) -> String {
        use ecmxf_devices::config_file::toml_path as path;
        let mut out = String::new();
        let mut line = |k: &str, v: String| out.push_str(&format!("{k} = {v}\n"));
        match self {
            Self::Sim { network } => {
                line("backend", "\"sim\"".into());
                if let Some(n) = network {
                    line("network", path(n));
                }
            }
            Self::SimSocket { socket } => {
                line("backend", "\"sim-socket\"".into());
                line("socket", path(socket));
            }
            Self::Spidev { device, spi_hz, gpio_chip, int0_line, int1_line, debounce_us, idle_us } => {
                line("backend", "\"spidev\"".into());
                line("device", path(device));
                line("spi_hz", spi_hz.to_string());
                if let Some(c) = gpio_chip {
                    line("gpio_chip", path(c));
                }
                for (k, v) in [("int0_line", int0_line), ("int1_line", int1_line), ("debounce_us", debounce_us)] {
                    if let Some(v) = v {
                        line(k, v.to_string());
                    }
                }
                line("idle_us", idle_us.to_string());
            }
        }
        out
    }
}

/// `[link]` as written: one flat table, so a value of the wrong type is
/// reported at its own line (an internally tagged enum buffers the table
/// and toml can then only point at `[link]`); which keys go with which
/// backend is checked in [`LinkConfig::try_from`].
#[derive(Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
struct RawLink {
    /// How the chip is reached: "spidev" (the chip on an SPI bus), "sim"
    /// (the simulator in the daemon's process) or "sim-socket" (a
    /// simulator served by `ecmxf-sim serve`).
    backend: String,
    /// sim: the simulated network's file (ecmxf-sim(1)); absent: the demo
    /// network.
    network: Option<PathBuf>,
    /// sim-socket: the socket `ecmxf-sim serve` listens on.
    socket: Option<PathBuf>,
    /// spidev: the SPI device, e.g. "/dev/spidev0.0".
    device: Option<PathBuf>,
    /// spidev: the SPI clock, Hz (default 20000000; the chip takes up to
    /// 50 MHz where the wiring allows).
    spi_hz: Option<u32>,
    /// spidev: the GPIO chip of INT0 and INT1, e.g. "/dev/gpiochip0".
    gpio_chip: Option<PathBuf>,
    /// spidev: INT0's line offset (the chip's ready signal); absent: not
    /// wired, the daemon waits `idle_us` after each transfer instead.
    int0_line: Option<u32>,
    /// spidev: INT1's line offset (the chip's event signal).
    int1_line: Option<u32>,
    /// spidev: the kernel's debounce on INT1, us (INT0's busy pulse, tens
    /// of us, would vanish under it: it is never debounced).
    debounce_us: Option<u32>,
    /// spidev: the time after a transfer without INT0, us (default 200;
    /// the vendor's driver waits 150-200).
    idle_us: Option<u32>,
}

impl TryFrom<RawLink> for LinkConfig {
    type Error = String;

    fn try_from(r: RawLink) -> Result<Self, String> {
        let only = |backend: &str, allowed: &[&str]| -> Result<(), String> {
            let given = [
                ("network", r.network.is_some()),
                ("socket", r.socket.is_some()),
                ("device", r.device.is_some()),
                ("spi_hz", r.spi_hz.is_some()),
                ("gpio_chip", r.gpio_chip.is_some()),
                ("int0_line", r.int0_line.is_some()),
                ("int1_line", r.int1_line.is_some()),
                ("debounce_us", r.debounce_us.is_some()),
                ("idle_us", r.idle_us.is_some()),
            ];
            match given.iter().find(|(k, set)| *set && !allowed.contains(k)) {
                Some((k, _)) => Err(format!("link.{k} does not go with backend = \"{backend}\"")),
                None => Ok(()),
            }
        };
        match r.backend.as_str() {
            "sim" => {
                only("sim", &["network"])?;
                Ok(Self::Sim { network: r.network })
            }
            "sim-socket" => {
                only("sim-socket", &["socket"])?;
                let socket = r.socket.ok_or("link.socket is needed with backend = \"sim-socket\"")?;
                Ok(Self::SimSocket { socket })
            }
            "spidev" => {
                only("spidev", &["device", "spi_hz", "gpio_chip", "int0_line", "int1_line", "debounce_us", "idle_us"])?;
                let device = r.device.ok_or("link.device is needed with backend = \"spidev\"")?;
                Ok(Self::Spidev {
                    device,
                    spi_hz: r.spi_hz.unwrap_or(20_000_000),
                    gpio_chip: r.gpio_chip,
                    int0_line: r.int0_line,
                    int1_line: r.int1_line,
                    debounce_us: r.debounce_us,
                    idle_us: r.idle_us.unwrap_or(200),
                })
            }
            other => Err(format!("link.backend {other:?} is not one of sim, sim-socket, spidev")),
        }
    }
}

/// `[chip]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ChipSettings {
    /// SPI data-section size to switch to (32..=1408).
    pub data_size: usize,
    /// Use CRC-32 check words (strongly advised: the fixed word protects
    /// nothing).
    pub crc32: bool,
    /// INT0 polarity to program (command 58).
    pub int0_active_high: bool,
    /// INT1 polarity to program.
    pub int1_active_high: bool,
    /// How long to wait for INT0, ms.
    pub ready_timeout_ms: u64,
}

impl Default for ChipSettings {
    fn default() -> Self {
        Self { data_size: 512, crc32: true, int0_active_high: true, int1_active_high: false, ready_timeout_ms: 100 }
    }
}

/// `[realtime]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct RealtimeConfig {
    /// SCHED_FIFO priority 1..=99; 0 = normal scheduling.
    pub priority: u8,
    /// CPU to pin the thread to.
    pub cpu: Option<usize>,
    /// mlockall the process.
    pub lock_memory: bool,
    /// Waits shorter than this many us are spent yielding instead of
    /// sleeping: a short sleep can overshoot by milliseconds without
    /// PREEMPT_RT (or on a virtual machine), and the FIFO margin is made of
    /// such times. At most half of each wait is spun, so the thread sleeps
    /// between exchanges and the kernel's real-time throttling never stops
    /// it. 0: always sleep (idle core, RT kernel).
    pub spin_us: u32,
    /// The host stall an output latency budget must outlast, us: a
    /// budget whose RxFIFO margin does not cover the link's refill and
    /// this is refused (`cycle.output_latency_us`). 1000 by default: what a
    /// stock kernel with SCHED_FIFO and memory locked held here (a 3 ms
    /// budget at a 1 ms cycle, which the link alone allows, ran dry in a
    /// minute). Lower it on a PREEMPT_RT kernel with an isolated
    /// core, once measured (`ecmxf-latency-bench --rt`).
    pub host_stall_us: u32,
}

impl RealtimeConfig {
    /// `host_stall_us`, ns: what the output latency floor adds for the host.
    pub fn host_stall_ns(&self) -> u64 {
        u64::from(self.host_stall_us) * 1000
    }
}

impl Default for RealtimeConfig {
    fn default() -> Self {
        Self { priority: 80, cpu: None, lock_memory: true, spin_us: 2000, host_stall_us: 1000 }
    }
}

/// `[cycle]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct CycleConfig {
    /// SYNC0 cycle, us (>= 125).
    pub sync0_us: u32,
    /// DC AssignActivate (0 = DC off, free-run 1 ms).
    pub dc_assign_activate: u16,
    /// SYNC0 shift, ns.
    pub shift_ns: i32,
    /// RxFIFO depth, frames.
    pub fifo_rx_depth: u8,
    /// TxFIFO depth, frames.
    pub fifo_tx_depth: u8,
    /// Keep at least this many output frames queued in the chip.
    pub fifo_low: u8,
    /// And at most this many.
    pub fifo_high: u8,
    /// Consecutive WKC errors that stop exchange (255 = never).
    pub wkc_error_limit: u8,
    /// State to bring the network to: "preop", "safeop" or "op".
    pub target_state: TargetState,
    /// The output latency budget, us: how long a client's write may take
    /// to reach the wire (the frame the chip plays). The engine keeps the
    /// RxFIFO at the shallowest level that meets it (never deeper than
    /// midway between `fifo_low` and `fifo_high`), trading margin against
    /// host stalls for latency: a stall longer than the budget empties the
    /// FIFO (counted, with an event). 250..=1000000 and at least two DC
    /// cycles, and no less than the link and host hold: a refill must land
    /// within half the budget's frames after a transaction's packet, the
    /// emergency question and a FIFO call (four packets) and
    /// `realtime.host_stall_us`, so a budget under 2 x ceil((4 packets +
    /// host stall) / cycle) + 1 cycles is refused (`--check-config` names
    /// the smallest: 4125 us at 125 us with 512-byte packets at 20 MHz and
    /// the default 1 ms of host stall); unset: the FIFO is kept midway
    /// between its marks.
    pub output_latency_us: Option<u32>,
    /// How the answer to a FIFO call is fetched (docs/protocol.md §7):
    /// "pipelined" (the default) lets the next exchange bring it, one
    /// exchange per call, and resends the call to fetch it when no exchange
    /// came within 2 ms; "guarded" resends every call at once, two
    /// exchanges per call. A corrupt answer fetched by another packet loses
    /// its input frames (counted, numbered as a gap), so after any link
    /// error pipelined calls go guarded for a second.
    pub fifo_reads: FifoReads,
}

/// `cycle.fifo_reads`: how the answer to a FIFO call is fetched.
#[derive(Clone, Copy, Debug, Default, Deserialize, schemars::JsonSchema, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum FifoReads {
    /// Every call resent at once until its answer arrives intact.
    Guarded,
    /// The answer rides on the next exchange; guarded after a link error.
    #[default]
    Pipelined,
}

impl CycleConfig {
    /// The `[cycle]` table as TOML lines, every key set: what `ecmxfctl
    /// config` copies into a configuration written from the live network
    /// (MasterInfo.cycle_toml), so it runs with the same cycle and FIFOs.
    /// Serialized by the same serde names the parser reads, so a key added
    /// to the table is written too.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    /// The DC cycle the chip plays frames at (1 ms free-run without DC).
    pub fn dc_cycle(&self) -> std::time::Duration {
        let us = if self.dc_assign_activate != 0 { self.sync0_us } else { 1000 };
        std::time::Duration::from_micros(u64::from(us))
    }

    /// The output latency budget, if one is set.
    pub fn output_latency(&self) -> Option<std::time::Duration> {
        self.output_latency_us.map(|us| std::time::Duration::from_micros(u64::from(us)))
    }

    /// `target_state` as a state.
    pub fn target(&self) -> ecmxf_wire::EcatState {
        self.target_state.state()
    }
}

/// `cycle.target_state`: the state bring-up drives the network to. A
/// closed set, so a typo is refused by the parser with the key and line.
#[derive(Clone, Copy, Debug, Default, Deserialize, schemars::JsonSchema, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum TargetState {
    /// PRE-OP: mailboxes only, no process data.
    #[serde(rename = "preop")]
    PreOp,
    /// SAFE-OP: inputs flow, outputs held safe.
    #[serde(rename = "safeop")]
    SafeOp,
    /// OP: process data both ways.
    #[default]
    Op,
}

impl TargetState {
    /// The EtherCAT state.
    pub fn state(self) -> ecmxf_wire::EcatState {
        match self {
            Self::PreOp => ecmxf_wire::EcatState::PreOp,
            Self::SafeOp => ecmxf_wire::EcatState::SafeOp,
            Self::Op => ecmxf_wire::EcatState::Op,
        }
    }
}

impl Default for CycleConfig {
    fn default() -> Self {
        Self {
            sync0_us: 1000,
            dc_assign_activate: 0x0300,
            shift_ns: 0,
            fifo_rx_depth: 32,
            fifo_tx_depth: 32,
            fifo_low: 8,
            fifo_high: 20,
            wkc_error_limit: 255,
            target_state: TargetState::Op,
            output_latency_us: None,
            fifo_reads: FifoReads::default(),
        }
    }
}

/// One expected slave (`[[slave]]`).
#[derive(Clone, Debug, Default, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SlaveConfig {
    /// A label for logs and the API.
    pub name: Option<String>,
    /// Vendor id the slave must have.
    pub vendor_id: Option<u32>,
    /// Product code it must have.
    pub product_code: Option<u32>,
    /// Revision it must have.
    pub revision: Option<u32>,
    /// RxPDO assignment to configure (PDO_CONFIG_SET for up to 3 PDOs of 8
    /// entries, over CoE beyond).
    #[serde(default)]
    pub rx_pdos: Vec<PdoConfig>,
    /// TxPDO assignment to configure.
    #[serde(default)]
    pub tx_pdos: Vec<PdoConfig>,
    /// SDOs written in PRE-OP, in order (like ENI init commands).
    #[serde(default, rename = "sdo")]
    pub sdos: Vec<StartupSdo>,
    /// This slave's DC AssignActivate word when it differs from
    /// `cycle.dc_assign_activate` (0: no DC for this slave, e.g. an IO
    /// coupler in a network of DC drives). Applied with DCSYNC (cmd 50)
    /// and ECAT_INIT_DC (cmd 3).
    pub dc_assign_activate: Option<u16>,
    /// This slave's SYNC0 shift in ns when it differs from `cycle.shift_ns`.
    pub dc_shift_ns: Option<i32>,
    /// The slave's ESI file: its object dictionary is what the API lists
    /// (`Sdo.ListObjects`) instead of probing standard objects; its
    /// device's CoE init commands are written at their transitions, before
    /// the `[[slave.sdo]]` entries (config/eni.rs), unless an ENI is given.
    #[serde(default)]
    pub esi: Option<PathBuf>,
    /// Whether the ESI device's CoE init commands are written (default
    /// true).
    #[serde(default = "yes")]
    pub esi_init_cmds: bool,
    /// Objects (indexes) whose ESI init commands are not written.
    #[serde(default)]
    pub esi_init_cmds_skip: Vec<u16>,
    /// When the entry's ESI file has several devices the entry's identity
    /// keys do not narrow to one: each candidate with its init commands,
    /// the one the slave's scanned identity names chosen at bring-up
    /// (config/eni.rs, `esi_device_sdos` in engine/bringup). Not a TOML key.
    #[serde(skip)]
    pub esi_choices: Vec<EsiChoice>,
    /// The ENI's process-image variables of this slave, placed from the
    /// start of its data (config/eni.rs): the names the image's entries
    /// take, and the offsets the layout must match. Not a TOML key.
    #[serde(skip)]
    pub variables: Vec<SlaveVariable>,
    /// The ENI's register init commands a host may replay (the watchdog
    /// registers; config/eni.rs says which and why), written by raw
    /// datagram at their transitions before the start-up SDOs. Not a TOML
    /// key.
    #[serde(skip)]
    pub registers: Vec<StartupRegister>,
}

/// One device of a `[[slave]] esi` file the slave may turn out to be, and
/// the start-up SDOs its CoE init commands make.
#[derive(Clone, Debug, PartialEq)]
pub struct EsiChoice {
    /// Its name in the file (`Type` text, then `Name`).
    pub name: String,
    /// The file's vendor id.
    pub vendor_id: u32,
    /// `Type/@ProductCode`.
    pub product_code: u32,
    /// `Type/@RevisionNo`.
    pub revision: u32,
    /// Its init commands as start-up SDOs, those `esi_init_cmds_skip`
    /// names left out.
    pub sdos: Vec<StartupSdo>,
}

/// An ESC register write at a transition (an ENI register init command).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StartupRegister {
    /// When.
    pub transition: InitTransition,
    /// Register.
    pub ado: u16,
    /// Bytes written.
    pub data: Vec<u8>,
    /// Where it came from, for errors (`ENI line 2157:5, "set watchdog divider"`).
    pub origin: String,
}

/// A named variable of one slave's process data, as a configuration tool
/// laid it out (ENI `ProcessImage/*/Variable`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SlaveVariable {
    /// `WheelRearLeft.Inputs.Status word`.
    pub name: String,
    /// In the outputs (else the inputs).
    pub output: bool,
    /// Bits from the start of the slave's outputs or inputs.
    pub bit: u32,
    /// Size in bits.
    pub bits: u32,
    /// Its type as the ENI names it, when it does and the type is of
    /// that size (`INT` for the IMU's 16-bit values, which the slave's
    /// CoE mapping alone would call unsigned).
    pub data_type: Option<ecmxf_devices::od::DataType>,
    /// Where it is in the ENI.
    pub at: ecmxf_devices::TextPos,
}

fn yes() -> bool {
    true
}

/// One PDO of an assignment.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PdoConfig {
    /// Mapping object (0x16xx / 0x1Axx).
    pub index: u16,
    /// Entries as `[index, subindex, bits]`.
    pub entries: Vec<[u32; 3]>,
}

/// A start-up SDO download.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StartupSdo {
    /// Object index.
    pub index: u16,
    /// Subindex.
    #[serde(default)]
    pub subindex: u8,
    /// Integer value, written in `size` bytes little-endian.
    pub value: Option<i64>,
    /// Size of `value` in bytes (1, 2, 4, 8).
    pub size: Option<u8>,
    /// Raw bytes instead of `value`.
    pub bytes: Option<Vec<u8>>,
    /// Complete access.
    #[serde(default)]
    pub complete_access: bool,
    /// The transition it is written at: `ip` (INIT to PRE-OP: right after
    /// PRE-OP is reached), `ps` (before SAFE-OP; the default) or `so` (in
    /// SAFE-OP, before OP), as ENI init commands say.
    #[serde(default)]
    pub transition: InitTransition,
    /// How long the slave may take, ms (default 1000).
    pub timeout_ms: Option<u32>,
    /// Where it came from, for errors: `ENI line 1170:9 "download pdo
    /// 0x1C13:01 index"`, `ESI ... init command`; "" for a `[[slave.sdo]]`
    /// entry. Not a TOML key.
    #[serde(skip)]
    pub origin: String,
}

/// When a start-up SDO is written (ETG.2100 transitions a master replays
/// CoE init commands at).
#[derive(Clone, Copy, Debug, Default, Deserialize, schemars::JsonSchema, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum InitTransition {
    /// INIT to PRE-OP (once the mailbox works: in PRE-OP).
    Ip,
    /// PRE-OP to SAFE-OP.
    #[default]
    Ps,
    /// SAFE-OP to OP.
    So,
}

impl InitTransition {
    /// ETG.2100's two letters for it.
    pub fn letters(self) -> &'static str {
        match self {
            Self::Ip => "IP",
            Self::Ps => "PS",
            Self::So => "SO",
        }
    }
}

impl StartupSdo {
    /// The bytes to write.
    pub fn payload(&self) -> Vec<u8> {
        match (&self.bytes, self.value) {
            (Some(b), _) => b.clone(),
            (None, Some(v)) => v.to_le_bytes()[..usize::from(self.size.unwrap_or(4)).min(8)].to_vec(),
            (None, None) => Vec::new(),
        }
    }
}

/// One axis of the chip's CiA402 helper (`[[axis]]`).
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AxisConfig {
    /// Slave position.
    pub slave: u8,
    /// Controlword byte offset in the slave's outputs.
    #[serde(default)]
    pub controlword_offset: u8,
    /// Statusword byte offset in the slave's inputs.
    #[serde(default)]
    pub statusword_offset: u8,
    /// Reset faults automatically.
    #[serde(default)]
    pub auto_fault_reset: bool,
}

/// `[recovery]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct RecoveryConfig {
    /// Bring the network back to the target state after faults.
    pub enabled: bool,
    /// First back-off, ms.
    pub backoff_ms: u64,
    /// Longest back-off, ms.
    pub max_backoff_ms: u64,
}

impl Default for RecoveryConfig {
    fn default() -> Self {
        Self { enabled: true, backoff_ms: 200, max_backoff_ms: 10_000 }
    }
}

impl Config {
    /// Where the slaves the configuration expects come from, with their
    /// number, for messages: "the ENI machine.xml lists 7" reads better
    /// than "[[slave]] entries" to someone who never wrote one.
    pub(crate) fn expected_slaves(&self) -> String {
        let n = self.slaves.len();
        match &self.eni {
            Some(eni) => format!("the ENI {} lists {n}", eni.display()),
            None => format!("the configuration lists {n} ([[slave]] entries)"),
        }
    }

    /// The configuration `--sim` runs: the in-process simulator with the demo
    /// network, 125 us cycle, normal scheduling (the simulator needs no
    /// real-time priority and a trial run should not lock memory).
    pub fn simulator() -> Self {
        Self {
            version: VERSION,
            link: LinkConfig::Sim { network: None },
            // The simulated chip is a thread of this host: a host stall (a
            // VM can stop a thread for 100 ms and more) is not a chip fault,
            // so wait longer for "ready" before calling it one.
            chip: ChipSettings { ready_timeout_ms: 1000, ..ChipSettings::default() },
            eni: None,
            eni_frames: None,
            // No spinning: the in-process simulator already keeps a core
            // busy, and on a small machine a yielding engine thread takes
            // the CPU the API needs (ecmxf-api-bench on 2 cores: stream p99
            // 7 ms with 2000 us of spin, 0.6 ms without; the deep RxFIFO
            // below absorbs the longer sleeps).
            realtime: RealtimeConfig {
                priority: 0,
                cpu: None,
                lock_memory: false,
                spin_us: 0,
                ..RealtimeConfig::default()
            },
            // Without real-time priority, and on a virtual machine, a thread
            // can stall for 25 ms: keep about 17 ms of outputs queued (the
            // budget below) and room for 12 ms of inputs, so a stall runs
            // neither FIFO dry nor over (a 40-frame TxFIFO, 5 ms, lost a few
            // input frames a minute under ecmxfd-pi-bench's CPU quota). The
            // two share the 16 KiB FIFO memory (192 + 96 frames of the demo's
            // 53 bytes); bring-up fits the depths to larger frames.
            cycle: CycleConfig {
                sync0_us: 125,
                fifo_rx_depth: 192,
                fifo_tx_depth: 96,
                fifo_low: 96,
                fifo_high: 184,
                // As config/ecmxfd-sim.toml: deep enough for a VM's stalls.
                output_latency_us: Some(20_000),
                ..CycleConfig::default()
            },
            slaves: Vec::new(),
            axes: Vec::new(),
            recovery: RecoveryConfig::default(),
            outputs: OutputsConfig::default(),
            api: ApiConfig::default(),
            log: LogConfig::default(),
            metrics: MetricsConfig::default(),
            state_dir: None,
            gateway: None,
            sparkplug: None,
            opcua: None,
            web: None,
        }
    }

    /// Parses and validates `text`, read from `path`. Relative paths in it
    /// are taken relative to the file's folder.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let mut c: Self = toml::from_str(text).map_err(|e| ConfigError::Toml(path.into(), e.to_string()))?;
        c.validate(path).map_err(|e| e.at_line(text))?;
        let base = path.parent().unwrap_or(Path::new(""));
        let resolve = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        match &mut c.link {
            LinkConfig::Sim { network: Some(p) } => resolve(p),
            LinkConfig::SimSocket { socket } => resolve(socket),
            _ => {}
        }
        c.api.resolve_paths(base);
        if let Some(p) = c.opcua.as_mut().and_then(|o| o.pki_dir.as_mut()) {
            resolve(p);
        }
        if let Some(w) = c.web.as_mut() {
            w.resolve_paths(base);
        }
        for s in &mut c.slaves {
            if let Some(p) = &mut s.esi {
                resolve(p);
            }
        }
        if c.eni.is_none() {
            c.apply_esi_init_cmds().map_err(|(key, message)| ConfigError::Invalid {
                file: path.into(),
                key,
                message,
            })?;
        }
        if let Some(p) = &mut c.eni {
            resolve(p);
            let eni = ecmxf_devices::eni::Eni::load(p).map_err(|e| ConfigError::Invalid {
                file: path.into(),
                key: "eni".into(),
                message: format!("{}: {e}", p.display()),
            })?;
            // The ENI's DC cycle applies where the file does not set one.
            let sync0_given = toml::from_str::<toml::Table>(text)
                .ok()
                .and_then(|t| t.get("cycle")?.as_table()?.get("sync0_us").cloned())
                .is_some();
            c.apply_eni(&eni, sync0_given).map_err(|(key, message)| ConfigError::Invalid {
                file: path.into(),
                key,
                message,
            })?;
            c.validate(path)?;
        }
        Ok(c)
    }

    /// Reads, parses and validates a file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = ConfigError::read(path)?;
        Self::parse(&text, path)
    }

    /// Checks values serde cannot.
    pub fn validate(&self, path: &Path) -> Result<(), ConfigError> {
        let bad =
            |key: &str, message: String| Err(ConfigError::Invalid { file: path.into(), key: key.into(), message });
        if let Err(e) = tracing_subscriber::EnvFilter::builder().parse(&self.log.level) {
            return bad(
                "log.level",
                format!("{:?} is not a log filter ({e}); e.g. \"info\" or \"info,ecmxfd=debug\"", self.log.level),
            );
        }
        if self.version != VERSION {
            return bad("version", format!("version {} is not supported (this build reads {VERSION})", self.version));
        }
        if !(32..=1408).contains(&self.chip.data_size) {
            return bad("chip.data_size", format!("{} is outside 32..=1408", self.chip.data_size));
        }
        if !(1..=60_000).contains(&self.chip.ready_timeout_ms) {
            return bad("chip.ready_timeout_ms", format!("{} ms is outside 1..=60000", self.chip.ready_timeout_ms));
        }
        if self.realtime.priority > 99 {
            return bad("realtime.priority", format!("{} is outside 0..=99", self.realtime.priority));
        }
        if let Some(cpu) = self.realtime.cpu {
            if cpu >= MAX_CPUS {
                return bad("realtime.cpu", format!("CPU {cpu} is outside 0..{MAX_CPUS} (the kernel's CPU set)"));
            }
        }
        if self.realtime.spin_us > 100_000 {
            return bad("realtime.spin_us", format!("{} us is outside 0..=100000", self.realtime.spin_us));
        }
        if self.realtime.host_stall_us > 100_000 {
            return bad("realtime.host_stall_us", format!("{} us is outside 0..=100000", self.realtime.host_stall_us));
        }
        if !SYNC0_US.contains(&self.cycle.sync0_us) {
            return bad(
                "cycle.sync0_us",
                format!(
                    "{} us is outside the chip's {}..={} us (SYNC0 is a 32-bit nanosecond register)",
                    self.cycle.sync0_us,
                    SYNC0_US.start(),
                    SYNC0_US.end()
                ),
            );
        }
        let c = &self.cycle;
        let cycle_ns = i64::from(c.sync0_us) * 1000;
        for (key, shift) in std::iter::once(("cycle.shift_ns".to_string(), Some(c.shift_ns)))
            .chain(self.slaves.iter().enumerate().map(|(i, s)| (format!("slave[{i}].dc_shift_ns"), s.dc_shift_ns)))
        {
            if let Some(shift) = shift {
                if i64::from(shift).abs() >= cycle_ns {
                    return bad(&key, format!("{shift} ns is not within one cycle (+-{cycle_ns} ns)"));
                }
            }
        }
        if c.fifo_tx_depth == 0 {
            return bad("cycle.fifo_tx_depth", "0 frames: the TxFIFO needs at least 1".into());
        }
        if c.wkc_error_limit == 0 {
            return bad("cycle.wkc_error_limit", "0 is outside 1..=255 (255: never stop)".into());
        }
        let r = &self.recovery;
        if !(1..=60_000).contains(&r.backoff_ms) {
            return bad("recovery.backoff_ms", format!("{} ms is outside 1..=60000", r.backoff_ms));
        }
        if r.max_backoff_ms < r.backoff_ms || r.max_backoff_ms > 600_000 {
            return bad(
                "recovery.max_backoff_ms",
                format!("{} ms is outside backoff_ms..=600000 ({}..=600000)", r.max_backoff_ms, r.backoff_ms),
            );
        }
        if self.slaves.len() > ecmxf_wire::limits::MAX_SLAVES {
            return bad(
                "slave",
                format!("{} slaves; the chip takes at most {}", self.slaves.len(), ecmxf_wire::limits::MAX_SLAVES),
            );
        }
        if let LinkConfig::Spidev { spi_hz, idle_us, debounce_us, int0_line, int1_line, .. } = &self.link {
            if let (Some(int0), Some(int1)) = (int0_line, int1_line)
                && int0 == int1
            {
                // The kernel grants a line to one request: the second would
                // fail with EBUSY, which reads as "another program holds it".
                return bad(
                    "link.int1_line",
                    format!("line {int1} is link.int0_line too: INT0 and INT1 are two pins, each on its own line"),
                );
            }
            let range = ecmxf_wire::limits::SPI_HZ;
            if !range.contains(&u64::from(*spi_hz)) {
                return bad(
                    "link.spi_hz",
                    format!("{spi_hz} Hz is outside the chip's {}..={} Hz", range.start(), range.end()),
                );
            }
            if *idle_us > 1_000_000 {
                return bad("link.idle_us", format!("{idle_us} us is outside 100..=1000000"));
            }
            if debounce_us.is_some_and(|d| d > 100_000) {
                return bad("link.debounce_us", format!("{} us is outside 0..=100000", debounce_us.unwrap_or(0)));
            }
        }
        if c.fifo_low >= c.fifo_high || c.fifo_high > c.fifo_rx_depth {
            return bad(
                "cycle.fifo_high",
                format!(
                    "need fifo_low < fifo_high <= fifo_rx_depth, got {} < {} <= {}",
                    c.fifo_low, c.fifo_high, c.fifo_rx_depth
                ),
            );
        }
        if let Some(budget) = c.output_latency_us {
            let two_cycles = 2 * c.dc_cycle().as_micros() as u32;
            if !(250..=1_000_000).contains(&budget) || budget < two_cycles {
                return bad(
                    "cycle.output_latency_us",
                    format!(
                        "{budget} us is outside 250..=1000000 or shorter than two DC cycles ({two_cycles} us): \
                         the chip plays one frame per cycle"
                    ),
                );
            }
        }
        if self.outputs.on_last_writer_gone == WriterGoneAction::QuickStop && self.axes.is_empty() {
            return bad(
                "outputs.on_last_writer_gone",
                "quick-stop acts on [[axis]] entries, and none is configured".into(),
            );
        }
        self.api.validate(path)?;
        // The certificates `[[api.client_cert]]` names are verified against
        // the API's CA, or the dashboard's.
        let verified = self.api.client_ca.is_some() || self.web.as_ref().is_some_and(|w| w.client_ca.is_some());
        if !self.api.client_certs.is_empty() && !verified {
            return bad(
                "api.client_cert",
                "client certificates need api.client_ca (or web.client_ca) to verify them".into(),
            );
        }
        if let Some(s) = &self.sparkplug {
            s.validate(path)?;
        }
        if let Some(o) = &self.opcua {
            o.validate(path)?;
        }
        if let Some(w) = &self.web {
            w.validate(path)?;
        }
        if let LinkConfig::Spidev { int0_line: None, idle_us, .. } = &self.link {
            if *idle_us < 100 {
                return bad(
                    "link.idle_us",
                    format!("{idle_us} us without INT0 is shorter than the chip's processing time"),
                );
            }
        }
        for (i, s) in self.slaves.iter().enumerate() {
            for (dir, pdos) in [("rx_pdos", &s.rx_pdos), ("tx_pdos", &s.tx_pdos)] {
                // Subindex 0 counts them in a byte; beyond 3 PDOs of 8
                // entries bring-up writes them over CoE (engine/bringup/pdos.rs).
                if pdos.len() > 254 {
                    return bad(&format!("slave[{i}].{dir}"), format!("{} PDOs; an assignment holds 254", pdos.len()));
                }
                if let Some(twice) = pdos
                    .iter()
                    .enumerate()
                    .find_map(|(k, p)| pdos[..k].iter().any(|q| q.index == p.index).then_some(p.index))
                {
                    return bad(&format!("slave[{i}].{dir}"), format!("PDO {twice:#06x} is assigned twice"));
                }
                for (k, p) in pdos.iter().enumerate() {
                    if p.entries.len() > 254 {
                        return bad(
                            &format!("slave[{i}].{dir}[{k}].entries"),
                            format!("{} entries; a PDO holds 254", p.entries.len()),
                        );
                    }
                    for e in &p.entries {
                        if e[0] > 0xFFFF || e[1] > 0xFF || e[2] > 0xFF {
                            return bad(
                                &format!("slave[{i}].{dir}[{k}].entries"),
                                format!("{e:?} is not [index u16, subindex u8, bits u8]"),
                            );
                        }
                    }
                }
            }
            for (k, sdo) in s.sdos.iter().enumerate() {
                let key = format!("slave[{i}].sdo[{k}]");
                match (&sdo.bytes, sdo.value, sdo.size) {
                    (Some(_), Some(_), _) => return bad(&key, "give value or bytes, not both".into()),
                    (None, None, _) => return bad(&key, "needs value (with size) or bytes".into()),
                    (None, Some(_), Some(n)) if ![1, 2, 4, 8].contains(&n) => {
                        return bad(&format!("{key}.size"), format!("{n} is not 1, 2, 4 or 8"));
                    }
                    _ => {}
                }
            }
        }
        for (i, a) in self.axes.iter().enumerate() {
            if !self.slaves.is_empty() && usize::from(a.slave) >= self.slaves.len() {
                return bad(
                    &format!("axis[{i}].slave"),
                    format!("slave {} is not in the expected network of {}", a.slave, self.slaves.len()),
                );
            }
        }
        Ok(())
    }

    /// The INT0 wait timeout.
    pub fn ready_timeout(&self) -> Duration {
        Duration::from_millis(self.chip.ready_timeout_ms)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn every_key_of_the_manual_page_is_documented() {
        let missing = manual::undocumented(&schemars::schema_for!(Config));
        assert!(missing.is_empty(), "keys without documentation: {missing:?}");
    }

    #[test]
    fn the_manual_page_has_the_files_tables_and_keys() {
        let page = manual_page("0");
        for want in [".SH [link]", ".SH [cycle]", ".SS [[slave.sdo]]", ".SH [[axis]]", ".B sync0_us", ".B backend"] {
            assert!(page.contains(want), "no {want:?} in the page");
        }
        let keys = documented_keys();
        for want in ["version", "link.backend", "cycle.sync0_us", "slave.sdo.index", "api.token.name", "web.listen"] {
            assert!(keys.iter().any(|k| k == want), "{want} not among {keys:?}");
        }
    }

    use super::*;

    fn parse(t: &str) -> Result<Config, ConfigError> {
        Config::parse(t, Path::new("ecmxfd.toml"))
    }

    const MINIMAL: &str = "version = 1\n[link]\nbackend = \"sim\"\n";

    #[test]
    fn sparkplug_takes_one_broker_or_a_list_and_names_the_key_it_refuses() {
        let c = parse(&format!("{MINIMAL}[sparkplug]\nbroker = \"mqtt://b\"\ngroup_id = \"plant\"\n")).unwrap();
        let s = c.sparkplug.unwrap();
        assert_eq!((s.broker.len(), s.data_period_ms, s.commands), (1, 100, api::RoleName::None));
        let t = format!(
            "{MINIMAL}[sparkplug]\nbroker = [\"mqtt://a:1884\", \"mqtt://b\"]\ngroup_id = \"g\"\nnode_id = \"n\"\ncommands = \"operator\"\n"
        );
        let s = parse(&t).unwrap().sparkplug.unwrap();
        assert_eq!((s.broker[0].port, s.broker[1].port, s.node_id()), (1884, 1883, "n".to_string()));
        for (body, key, words) in [
            ("broker = \"http://b\"\ngroup_id = \"g\"", "line 5", "mqtt:// or mqtts://"),
            ("broker = \"mqtt://b\"\ngroup_id = \"a/b\"", "sparkplug.group_id", "cannot be a topic level"),
            (
                "broker = \"mqtt://b\"\ngroup_id = \"g\"\nnode_id = \"#\"",
                "sparkplug.node_id",
                "cannot be a topic level",
            ),
            ("broker = \"mqtt://b\"\ngroup_id = \"g\"\ndata_period_ms = 1", "sparkplug.data_period_ms", "10..=3600000"),
            (
                "broker = \"mqtt://b\"\ngroup_id = \"g\"\ndata_deadband = -1.0",
                "sparkplug.data_deadband",
                "not a deadband",
            ),
            (
                "broker = \"mqtt://b\"\ngroup_id = \"g\"\nca_file = \"/etc/hosts\"",
                "sparkplug.ca_file",
                "no broker is mqtts",
            ),
            (
                "broker = \"mqtts://b\"\ngroup_id = \"g\"\nca_file = \"/nonexistent.pem\"",
                "sparkplug.ca_file",
                "not a readable file",
            ),
            (
                "broker = \"mqtt://b\"\ngroup_id = \"g\"\ncredentials_file = \"/nonexistent\"",
                "sparkplug.credentials_file",
                "/nonexistent",
            ),
            (
                "broker = \"mqtt://b\"\ngroup_id = \"g\"\ncommands = \"root\"",
                "line 7",
                "`root`, expected one of `none`",
            ),
        ] {
            let e = parse(&format!("{MINIMAL}[sparkplug]\n{body}\n")).unwrap_err().to_string();
            assert!(e.contains(key) && e.contains(words), "{body}: {e}");
        }
    }

    #[test]
    fn the_gateway_allows_the_clients_it_names_and_else_this_host() {
        let c = parse(&format!("{MINIMAL}[gateway]\nlisten = \"0.0.0.0:34980\"\n")).unwrap();
        let g = c.gateway.unwrap();
        assert!(g.allows("127.0.0.1".parse().unwrap()) && g.allows("::1".parse().unwrap()));
        assert!(!g.allows("10.0.0.7".parse().unwrap()), "only this host without an allow list");
        let t = format!(
            "{MINIMAL}[gateway]\nlisten = \"[::]:34980\"\nallow = [\"10.1.0.0/16\", \"192.168.3.4\", \"fd00::/8\"]\n"
        );
        let g = parse(&t).unwrap().gateway.unwrap();
        for (ip, ok) in [
            ("10.1.200.3", true),
            ("10.2.0.1", false),
            ("192.168.3.4", true),
            ("192.168.3.5", false),
            ("::ffff:10.1.0.9", true),
            ("fd12::1", true),
            ("fe80::1", false),
            ("127.0.0.1", false),
        ] {
            assert_eq!(g.allows(ip.parse().unwrap()), ok, "{ip}");
        }
        let e = parse(&format!("{MINIMAL}[gateway]\nlisten = \"0.0.0.0:1\"\nallow = [\"10.0.0.0/40\"]\n"));
        assert!(e.unwrap_err().to_string().contains("prefix must be 0..=32"));
        let e = parse(&format!("{MINIMAL}[gateway]\nlisten = \"0.0.0.0:1\"\nallow = [\"plant\"]\n"));
        assert!(e.unwrap_err().to_string().contains("not an address"));
    }

    #[test]
    fn link_values_of_the_wrong_type_are_named_at_their_line() {
        let spi = "version = 1\n[link]\nbackend = \"spidev\"\ndevice = \"/dev/x\"\nspi_hz = \"fast\"\n";
        let e = parse(spi).unwrap_err().to_string();
        assert!(e.contains("line 5") && e.contains("fast"), "{e}");
        let e = parse("version = 1\n[link]\nbackend = \"sim\"\ndevice = \"/dev/x\"\n").unwrap_err().to_string();
        assert!(e.contains("link.device") && e.contains("\"sim\""), "{e}");
        let e = parse("version = 1\n[link]\nbackend = \"sim-socket\"\n").unwrap_err().to_string();
        assert!(e.contains("link.socket is needed"), "{e}");
        let e = parse("version = 1\n[link]\nbackend = \"usb\"\n").unwrap_err().to_string();
        assert!(e.contains("\"usb\"") && e.contains("spidev"), "{e}");
        let e = parse("version = 1\n[link]\nbackend = \"sim\"\nspeed = 3\n").unwrap_err().to_string();
        assert!(e.contains("speed") && e.contains("line 4"), "{e}");
    }

    #[test]
    fn int0_and_int1_on_one_line_is_refused() {
        let spi = "version = 1\n[link]\nbackend = \"spidev\"\ndevice = \"/dev/spidev0.0\"\ngpio_chip = \"/dev/gpiochip0\"\n\
                   int0_line = 24\nint1_line = 24\n";
        let e = parse(spi).unwrap_err().to_string();
        assert!(e.contains("link.int1_line") && e.contains("line 24 is link.int0_line too"), "{e}");
    }

    #[test]
    fn every_mistake_names_its_line() {
        let e = parse(&format!("{MINIMAL}[cycle]\nfifo_rx_depth = 10\n\nsync0_us = 50\n")).unwrap_err().to_string();
        assert!(e.contains("line 7") && e.contains("cycle.sync0_us"), "{e}");
        let spi = "version = 1\n[link]\nbackend = \"spidev\"\ndevice = \"/dev/spidev0.0\"\nspi_hz = 0\n";
        let e = parse(spi).unwrap_err().to_string();
        assert!(e.contains("line 5") && e.contains("link.spi_hz") && e.contains("96000000"), "{e}");
    }

    #[test]
    fn the_link_table_written_back_reads_the_same() {
        for link in [
            "backend = \"sim\"\n",
            "backend = \"sim\"\nnetwork = \"/tmp/a b/net.toml\"\n",
            "backend = \"sim-socket\"\nsocket = \"/run/sim.sock\"\n",
            "backend = \"spidev\"\ndevice = \"/dev/spidev0.0\"\nspi_hz = 24000000\ngpio_chip = \"/dev/gpiochip0\"\n\
             int0_line = 25\nint1_line = 24\ndebounce_us = 5\nidle_us = 150\n",
        ] {
            let c = parse(&format!("version = 1\n[link]\n{link}")).unwrap();
            assert_eq!(c.link.to_toml(), link);
            assert_eq!(parse(&format!("version = 1\n[link]\n{}", c.link.to_toml())).unwrap().link, c.link);
        }
        let c = Config::simulator();
        let back = parse(&format!("{MINIMAL}[cycle]\n{}", c.cycle.to_toml())).unwrap();
        assert_eq!(back.cycle, c.cycle, "the [cycle] table written back reads the same");
    }

    #[test]
    fn minimal_and_full() {
        let c = parse(MINIMAL).unwrap();
        assert_eq!(c.link, LinkConfig::Sim { network: None });
        assert_eq!(c.cycle.sync0_us, 1000);
        let full = r#"
version = 1
[link]
backend = "spidev"
device = "/dev/spidev0.0"
spi_hz = 24000000
gpio_chip = "/dev/gpiochip0"
int0_line = 25
int1_line = 24
[chip]
data_size = 1024
[realtime]
priority = 90
cpu = 3
[cycle]
sync0_us = 250
[[slave]]
name = "x"
vendor_id = 0x89A
product_code = 0x30000000
  [[slave.sdo]]
  index = 0x6060
  value = 10
  size = 1
[[axis]]
slave = 0
"#;
        let c = parse(full).unwrap();
        assert_eq!(c.slaves[0].sdos[0].payload(), vec![10]);
        assert!(matches!(c.link, LinkConfig::Spidev { int0_line: Some(25), .. }));
    }

    #[test]
    fn mistakes_name_their_key() {
        let e = parse("version = 1\n[link]\nbackend = \"sim\"\n[cycle]\nsync0 = 125\n").unwrap_err().to_string();
        assert!(e.contains("sync0") && e.contains("line 5"), "{e}");
        let e = parse(&format!("{MINIMAL}[cycle]\nsync0_us = 100\n")).unwrap_err().to_string();
        assert!(e.contains("cycle.sync0_us") && e.contains("125"), "{e}");
        let e = parse(&format!("{MINIMAL}[cycle]\nsync0_us = 1000000000\n")).unwrap_err().to_string();
        assert!(e.contains("cycle.sync0_us") && e.contains("4294967") && e.contains("32-bit"), "{e}");
        assert!(parse(&format!("{MINIMAL}[cycle]\nsync0_us = 4294967\n")).is_ok(), "the largest SYNC0 fits");
        let e = parse(&format!("{MINIMAL}[realtime]\ncpu = 99999999999\n")).unwrap_err().to_string();
        assert!(e.contains("realtime.cpu"), "{e}");
        let e =
            parse(&format!("{MINIMAL}[recovery]\nbackoff_ms = 500\nmax_backoff_ms = 100\n")).unwrap_err().to_string();
        assert!(e.contains("recovery.max_backoff_ms"), "{e}");
        let e = parse(&format!("{MINIMAL}[cycle]\nshift_ns = 2000000\n")).unwrap_err().to_string();
        assert!(e.contains("cycle.shift_ns"), "{e}");
        let e = parse(&format!("{MINIMAL}{}", "[[slave]]\n".repeat(129))).unwrap_err().to_string();
        assert!(e.contains("129 slaves"), "{e}");
        let e = parse(&format!("{MINIMAL}[chip]\ndata_size = 2000\n")).unwrap_err().to_string();
        assert!(e.contains("chip.data_size"), "{e}");
        let e = parse("version = 2\n[link]\nbackend = \"sim\"\n").unwrap_err().to_string();
        assert!(e.contains("version 2"), "{e}");
        let e = parse("version = 1\n[link]\nbackend = \"usb\"\n").unwrap_err().to_string();
        assert!(e.contains("usb"), "{e}");
        let e = parse(&format!("{MINIMAL}[[slave]]\n[[slave.sdo]]\nindex = 0x6060\n")).unwrap_err().to_string();
        assert!(e.contains("slave[0].sdo[0]"), "{e}");
        let e = parse(&format!("{MINIMAL}[cycle]\nfifo_low = 30\n")).unwrap_err().to_string();
        assert!(e.contains("cycle.fifo_high"), "{e}");
        for bad in
            ["output_latency_us = 100", "sync0_us = 1000\noutput_latency_us = 1500", "output_latency_us = 2000000"]
        {
            let e = parse(&format!("{MINIMAL}[cycle]\n{bad}\n")).unwrap_err().to_string();
            assert!(e.contains("cycle.output_latency_us"), "{bad}: {e}");
        }
        let ok = parse(&format!("{MINIMAL}[cycle]\nsync0_us = 125\noutput_latency_us = 2000\n")).unwrap();
        assert_eq!(ok.cycle.output_latency(), Some(std::time::Duration::from_millis(2)));
        let e = parse("version = 1\n[link]\nbackend = \"spidev\"\ndevice = \"/dev/spidev0.0\"\nidle_us = 20\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("link.idle_us"), "{e}");
    }
}
