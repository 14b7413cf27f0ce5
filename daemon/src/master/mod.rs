//! [`Master`]: the engine as async code sees it, over the handle
//! `crate::engine::spawn` returns (the master wires no channel or thread of
//! its own). Requests go into the engine's bounded command queue (full:
//! [`EngineError::QueueFull`]) with a deadline; dropping the future, or the
//! deadline passing, tells the engine to stop caring (it then finishes or
//! abandons the chip operation cleanly). Input frames come out of the
//! engine's wait-free ring through its distributor thread into a broadcast
//! channel: a subscriber that falls behind is told how many frames it
//! missed and slows no one.
//!
//! The methods are grouped by concern: here the plumbing, process data,
//! events and status; `transactions` the blocking-slot operations (SDO, SII,
//! states, PDO assignment, raw datagrams, FoE); `network` re-init, warm
//! reset and applying a new configuration.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::sync::{broadcast, oneshot};

use crate::config::{Config, LinkConfig};
use crate::engine::slot::{Job, SlotRequest};
use crate::engine::{Command, EngineHandle};
use crate::link::SimHandle;
use crate::link::{Link, LinkError};
pub use ecmxf_wire::payload::sdo::SdoAbortCode;
pub use ecmxf_wire::payload::slave_info::SlaveInfoCode;
pub use ecmxf_wire::{EcatState, al_status_text};
use outputs::OutputSender;
pub use outputs::OutputWriter;
pub use transactions::RawAnswer;

pub(crate) mod axes;
mod call;
pub mod device_dictionary;
pub(crate) mod diagnostics;
pub mod entry_writes;
pub(crate) mod esc_errors;
pub(crate) mod esi;
pub(crate) mod frame_claims;
pub(crate) mod histogram;
pub(crate) mod image;
mod leases;
pub(crate) mod mailbox;
pub(crate) mod mailbox_channel;
mod network;
pub(crate) mod objects;
pub(crate) mod opcua_state;
pub(crate) mod outputs;
pub mod pdos;
mod per_slave;
pub(crate) mod peripherals;
pub(crate) mod sii;
mod slave_listing;
pub(crate) mod sparkplug_state;
pub(crate) mod states;
pub(crate) mod transactions;
pub(crate) mod value;

/// A slave's identity: (vendor id, product code, revision).
pub type Identity = (u32, u32, u32);

pub use crate::engine::inputs::InputFrame;
pub use crate::engine::slot::DAEMON_CLIENT;
pub use crate::engine::{EVENT_BACKLOG, QUEUE_DEPTH, SUBSCRIBER_BACKLOG};
pub use call::Call;

// What front ends (the gRPC API, and any other) need of the engine, named
// here so that they import the master alone, never the engine's modules: errors, phases and
// snapshots, events, the layout, frame streams and transfer progress.
pub use crate::engine::error::{EngineError, NotRunning, WrongState};
pub use crate::engine::events::{Event, EventKind, EventLog};
pub use crate::engine::failure::Failure;
pub use crate::engine::frames::{FrameError, FrameProducer, MAX_STREAMS, Played};
pub use crate::engine::layout::{NetworkLayout, SlaveSummary};
pub use crate::engine::link_budget;
pub use crate::engine::slot::{Immediate, TransferProgress};
pub use crate::engine::supervisor::RecoverCause;
pub use crate::engine::telemetry::{Phase, Snapshot};
pub use crate::engine::trouble::TROUBLE_WINDOW;

/// The steps of bring-up, for `ecmxfd probe`: it walks them one by one on a
/// chip no engine runs, to say which one fails and why.
pub mod bring_up_steps {
    pub use crate::engine::bringup::{BringUpError, check_identity, identify, init_network, number};
}
pub use leases::{Lease, LeaseError, Leases};

/// [`Master::verdict`]: the health, and the input age it was judged on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Verdict {
    /// The health.
    pub health: Health,
    /// The newest input frame's age and its limit (`None`: no cyclic
    /// exchange runs).
    pub input_age: Option<(Duration, Duration)>,
}

impl Verdict {
    /// Healthy, with a cyclic exchange that delivers input frames.
    pub(crate) fn flowing(&self) -> bool {
        matches!(self.health, Health::Healthy | Health::SlavesMissing { .. } | Health::Int0Stuck | Health::Troubled(_))
            && self.input_age.is_some()
    }
}

/// The verdict of [`Master::health`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Health {
    /// Running in the target state, process data flowing.
    Healthy,
    /// The engine is not running (bringing up, recovering, stopped...).
    NotRunning(Phase),
    /// Running, but the network is not in the target state.
    WrongState {
        /// The state now.
        state: EcatState,
        /// The configured target.
        target: EcatState,
    },
    /// Running in the target state, but no input frame arrived for `age`,
    /// longer than `limit`.
    Stalled {
        /// Time since the newest input frame.
        age: Duration,
        /// The limit.
        limit: Duration,
    },
    /// Running, process data flowing, but with fewer slaves than a network
    /// that ran since the start had: one was lost (unplugged, powered off)
    /// and the rest were brought up without it. Degraded, not healthy,
    /// whether or not the configuration lists slaves; a re-init or a new
    /// configuration accepts the network as it is.
    SlavesMissing {
        /// Slaves now.
        now: u64,
        /// The most seen since the start.
        seen: u64,
    },
    /// Running, process data flowing, but INT0 has not moved across
    /// hundreds of exchanges (`supervisor::Int0Watch`): packets may be
    /// clocked while the chip is busy. Degraded until the line moves.
    Int0Stuck,
    /// Running, process data flowing, but trouble that passes happened
    /// within the last [`TROUBLE_WINDOW`]: the RxFIFO ran dry, the chip
    /// dropped input frames, or the host went longer than the process-data
    /// limit between two FIFO exchanges. Degraded until a whole window
    /// passes without one (see `engine::trouble`).
    Troubled(Trouble),
}

impl Health {
    /// One word or two for it, as front ends show it ("healthy", "stalled").
    pub fn word(&self) -> &'static str {
        match self {
            Self::Healthy => "healthy",
            Self::NotRunning(_) => "not running",
            Self::WrongState { .. } => "wrong state",
            Self::Stalled { .. } => "stalled",
            Self::SlavesMissing { .. } => "slaves missing",
            Self::Int0Stuck => "int0 stuck",
            Self::Troubled(_) => "troubled",
        }
    }
}

/// Trouble that passes, as [`Health::Troubled`] reports it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Trouble {
    /// What happened.
    pub kind: TroubleKind,
    /// How many times in the latest run (events no more than a window
    /// apart).
    pub count: u64,
    /// The longest gap of the run ([`TroubleKind::LongGaps`]; else zero).
    pub worst: Duration,
    /// How long ago the latest was.
    pub ago: Duration,
}

/// The kinds of [`Trouble`], in the order health names them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TroubleKind {
    /// The RxFIFO ran dry: slaves got their last outputs again.
    FifoAlarms,
    /// The chip dropped input frames (its TxFIFO was full).
    InputsDroppedByChip,
    /// FIFO exchanges further apart than the process-data limit.
    LongGaps,
}

impl Trouble {
    /// The most pressing recent trouble in `s` at `now_ns`, if any.
    fn of(s: &Snapshot, now_ns: u64) -> Option<Self> {
        [
            (TroubleKind::FifoAlarms, s.recent_fifo_alarms),
            (TroubleKind::InputsDroppedByChip, s.recent_chip_drops),
            (TroubleKind::LongGaps, s.recent_long_gaps),
        ]
        .into_iter()
        .find_map(|(kind, r)| {
            let ago = r.ago(now_ns)?;
            let worst = if kind == TroubleKind::LongGaps { Duration::from_micros(r.worst) } else { Duration::ZERO };
            Some(Self { kind, count: r.count, worst, ago })
        })
    }
}

impl std::fmt::Display for Trouble {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.count;
        let times = if n == 1 { "once".to_string() } else { format!("{n} times") };
        match self.kind {
            TroubleKind::FifoAlarms => write!(f, "the RxFIFO ran dry {times} (slaves got their last outputs again)")?,
            TroubleKind::InputsDroppedByChip => {
                write!(f, "the chip dropped {n} input frame{} (its TxFIFO was full)", if n == 1 { "" } else { "s" })?
            }
            TroubleKind::LongGaps => write!(
                f,
                "FIFO exchanges came later than the process-data limit {times} (longest gap {} ms: the host stalled)",
                self.worst.as_millis()
            )?,
        }
        write!(
            f,
            ", the latest {:.1} s ago; healthy again after {} s without",
            self.ago.as_secs_f64(),
            TROUBLE_WINDOW.as_secs()
        )
    }
}

impl Health {
    /// The verdict on a snapshot at `now_ns` (engine epoch).
    pub(crate) fn judge(s: &Snapshot, target: EcatState, now_ns: u64) -> Self {
        if s.phase != Phase::Running {
            return Self::NotRunning(s.phase);
        }
        if s.ecat_state != target {
            return Self::WrongState { state: s.ecat_state, target };
        }
        match s.input_age(now_ns) {
            Some((age, limit)) if age > limit => Self::Stalled { age, limit },
            _ if s.slaves < s.slaves_seen => Self::SlavesMissing { now: s.slaves, seen: s.slaves_seen },
            _ if s.int0_stuck => Self::Int0Stuck,
            _ => Trouble::of(s, now_ns).map_or(Self::Healthy, Self::Troubled),
        }
    }

    /// Healthy or not.
    pub fn is_healthy(&self) -> bool {
        *self == Self::Healthy
    }
}

impl std::fmt::Display for Health {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Healthy => f.write_str("healthy: process data flowing"),
            Self::NotRunning(p) => write!(f, "engine not running ({})", p.name()),
            Self::WrongState { state, target } => write!(f, "network in {state}, not {target}"),
            Self::Stalled { age, limit } => write!(
                f,
                "process data stalled: no input frame for {} ms (limit {} ms)",
                age.as_millis(),
                limit.as_millis()
            ),
            Self::SlavesMissing { now, seen } => write!(
                f,
                "degraded: {now} of {seen} slaves since start (one seen then is missing; a re-init accepts the \
                 network as it is)"
            ),
            Self::Int0Stuck => f.write_str(
                "degraded: INT0 stays at its ready level while packets go through, so the chip's busy time is not \
                 seen (check link.int0_line, its wiring and chip.int0_active_high; `ecmxfd probe`, step 2)",
            ),
            Self::Troubled(t) => write!(f, "degraded: {t}"),
        }
    }
}

/// Why the master could not start.
#[derive(Debug)]
pub enum StartError {
    /// The link could not be opened.
    Link(LinkError),
    /// The simulator's network file is wrong (file, line and key in it).
    Network(crate::config::ConfigError),
    /// The configuration asks for the simulator, and this daemon was built
    /// without it.
    NoSimulator,
}

impl std::fmt::Display for StartError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Link(e) => write!(f, "{e}"),
            Self::Network(e) => write!(f, "{e}"),
            Self::NoSimulator => f.write_str(
                "link.backend asks for the simulator, and this ecmxfd was built without it \
                 (cargo feature `sim`); use backend = \"spidev\"",
            ),
        }
    }
}

impl std::error::Error for StartError {}

/// The running master.
#[derive(Debug)]
pub struct Master {
    /// The engine (crate::engine::spawn): its one command channel, the
    /// outputs path and what it publishes.
    engine: EngineHandle,
    /// The outputs path as the async side writes it (chunked writes).
    outputs: Arc<OutputSender>,
    /// The output image as front ends last wrote it (bit-sized entries are
    /// merged into it, so writing one bit keeps its neighbours).
    shadow: Mutex<Vec<u8>>,
    /// The process image, named, kept built ([`Master::keep_image_built`]).
    image: image::ImageCache,
    /// The slaves' addresses and clocks as this run set them.
    slave_setups: slave_listing::SetupCache,
    /// The output ranges open frame streams feed.
    frame_claims: Arc<frame_claims::FrameClaims>,
    config: Mutex<Config>,
    config_generation: AtomicU64,
    /// Timeout for requests that give none.
    pub default_timeout: Duration,
    /// The configured ESI files, parsed.
    esi: esi::EsiLibrary,
    /// SII descriptions by slave identity.
    sii_cache: sii::SiiCache,
    /// Mailbox protocols by slave position.
    mailbox: mailbox::MailboxProtocols,
    /// The host's mailbox channel: geometry and per-slave locks.
    channels: mailbox_channel::MailboxChannels,
    /// Dictionaries read from the devices (SDO Information).
    dictionaries: device_dictionary::DeviceDictionaries,
    /// The Sparkplug node's connection and counters.
    sparkplug: Arc<sparkplug_state::SparkplugState>,
    /// The OPC UA server's sessions and counters.
    opcua: Arc<opcua_state::OpcuaState>,
    /// Output leases: one table for every front end (gRPC, Sparkplug,
    /// and the ones to come), swept by [`Master::sweep_leases`].
    leases: Leases,
    /// A lease's time-to-live when its taker names none
    /// (`api.lease_ttl_ms`).
    lease_ttl: Duration,
}

/// Opens the link the configuration names. For the in-process simulator,
/// also returns the handle to it.
pub fn open_link(config: &Config) -> Result<(Box<dyn Link>, Option<SimHandle>), StartError> {
    match &config.link {
        #[cfg(feature = "sim")]
        LinkConfig::Sim { network } => {
            use crate::link::sim::SimLink;
            let (net, chip_config) = match network {
                None => (ecmxf_sim::Network::demo(), ecmxf_sim::ChipConfig::default()),
                Some(p) => {
                    let f = ecmxf_sim::config::NetworkFile::load(p).map_err(StartError::Network)?;
                    (f.build(p).map_err(StartError::Network)?, f.chip_config())
                }
            };
            let (link, handle) = SimLink::new(ecmxf_sim::Chip::new(net, chip_config));
            Ok((Box::new(link), Some(handle)))
        }
        #[cfg(feature = "sim")]
        LinkConfig::SimSocket { socket } => {
            Ok((Box::new(crate::link::socket::SocketLink::connect(socket).map_err(StartError::Link)?), None))
        }
        #[cfg(not(feature = "sim"))]
        LinkConfig::Sim { .. } | LinkConfig::SimSocket { .. } => Err(StartError::NoSimulator),
        #[cfg(target_os = "linux")]
        LinkConfig::Spidev { device, spi_hz, gpio_chip, int0_line, int1_line, debounce_us, idle_us } => {
            let hw = crate::link::hardware::HardwareConfig {
                spi_device: device.clone(),
                spi_hz: *spi_hz,
                gpio_chip: gpio_chip.clone(),
                int0_line: *int0_line,
                int1_line: *int1_line,
                debounce: debounce_us.map(|us| Duration::from_micros(us.into())),
                idle: Duration::from_micros((*idle_us).into()),
            };
            Ok((Box::new(crate::link::hardware::HardwareLink::open(hw).map_err(StartError::Link)?), None))
        }
        #[cfg(not(target_os = "linux"))]
        LinkConfig::Spidev { device, .. } => Err(StartError::Link(LinkError::io(
            format!("open {}", device.display()),
            std::io::Error::new(std::io::ErrorKind::Unsupported, "spidev needs Linux"),
        ))),
    }
}

impl Master {
    /// Starts the engine over `link` (`crate::engine::spawn`: its
    /// real-time thread and the input distributor).
    pub fn start<L: Link + 'static>(link: L, config: Config) -> Self {
        let engine = crate::engine::spawn(link, config.clone());
        let outputs = Arc::new(OutputSender::new(engine.output_sender()));
        let lease_ttl = Duration::from_millis(config.api.lease_ttl_ms.into());
        Self {
            engine,
            outputs,
            shadow: Mutex::default(),
            image: image::ImageCache::default(),
            slave_setups: slave_listing::SetupCache::default(),
            frame_claims: Arc::default(),
            config: Mutex::new(config),
            config_generation: AtomicU64::new(0),
            default_timeout: Duration::from_secs(3),
            esi: esi::EsiLibrary::default(),
            sii_cache: sii::SiiCache::default(),
            mailbox: mailbox::MailboxProtocols::default(),
            channels: mailbox_channel::MailboxChannels::default(),
            dictionaries: device_dictionary::DeviceDictionaries::default(),
            sparkplug: Arc::default(),
            opcua: Arc::default(),
            leases: Leases::default(),
            lease_ttl,
        }
    }

    /// The output lease table every front end writes under.
    pub fn leases(&self) -> &Leases {
        &self.leases
    }

    /// Takes the outputs of `slaves` (all when empty) for `who`, for `ttl`
    /// (`None`: `api.lease_ttl_ms`).
    pub fn acquire_lease(&self, slaves: &[u8], ttl: Option<Duration>, who: &str) -> Result<Lease, LeaseError> {
        self.leases.acquire(self, slaves, ttl.unwrap_or(self.lease_ttl), who)
    }

    /// The time-to-live of a lease whose taker names none.
    pub(crate) fn lease_ttl(&self) -> Duration {
        self.lease_ttl
    }

    /// Drops the leases whose time-to-live ran out without a keep-alive
    /// (their writers go with them, so `outputs.on_last_writer_gone`
    /// applies when the last one goes).
    pub(crate) fn sweep_leases(&self) {
        self.leases.sweep();
    }

    /// The Sparkplug node's connection and counters (zero while none is
    /// configured).
    pub fn sparkplug_state(&self) -> &Arc<sparkplug_state::SparkplugState> {
        &self.sparkplug
    }

    /// The OPC UA server's sessions and counters (zero while none is
    /// configured).
    pub fn opcua_state(&self) -> &Arc<opcua_state::OpcuaState> {
        &self.opcua
    }

    /// Opens the configured link and starts.
    pub fn from_config(config: Config) -> Result<(Self, Option<SimHandle>), StartError> {
        let (link, sim) = open_link(&config)?;
        Ok((Self::start(link, config), sim))
    }

    async fn request(&self, request: SlotRequest, call: Call) -> Result<Vec<u8>, EngineError> {
        self.request_with_progress(request, call, None).await
    }

    /// Queues `request` for `call`'s client and waits for its answer until
    /// `call`'s deadline (none: [`Master::default_timeout`] from now). The
    /// job carries the same instant, so the engine drops it unanswered
    /// when it comes too late, as it does when this future is dropped.
    async fn request_with_progress(
        &self,
        request: SlotRequest,
        call: Call,
        progress: Option<Arc<TransferProgress>>,
    ) -> Result<Vec<u8>, EngineError> {
        let deadline = call.deadline.unwrap_or_else(|| Instant::now() + self.default_timeout);
        let (reply, rx) = oneshot::channel();
        let buffer = Vec::with_capacity(crate::engine::slot::request::reply_capacity(&request));
        let job = Job { request, deadline, reply, progress, client: call.client, buffer };
        self.engine.send(Command::Job(job))?;
        match tokio::time::timeout_at(deadline.into(), rx).await {
            Ok(Ok(r)) => r,
            // The engine drops a job it took too late, unanswered: at
            // the deadline that is the caller's time-out, not a stop.
            Ok(Err(_)) if Instant::now() >= deadline => Err(EngineError::Timeout),
            Ok(Err(_)) => Err(EngineError::Unavailable(NotRunning::Stopped)),
            // Dropping `rx` here tells the engine.
            Err(_) => Err(EngineError::Timeout),
        }
    }

    /// Writes bytes into the output image at `offset` (of the whole output
    /// frame); they go out with the next frames pushed.
    ///
    /// Anonymous: it does not count as a writer for
    /// `outputs.on_last_writer_gone`; clients use [`Master::output_writer`].
    pub fn write_outputs(&self, offset: usize, bytes: &[u8]) -> Result<(), EngineError> {
        self.outputs.send(self.layout().rx_size, offset, bytes)
    }

    /// A counted writer of outputs: when the last one is dropped, the
    /// engine applies `outputs.on_last_writer_gone`.
    pub fn output_writer(&self) -> OutputWriter {
        self.engine.writers().acquire();
        OutputWriter {
            outputs: Arc::clone(&self.outputs),
            layout: Arc::clone(self.engine.layout()),
            writers: Arc::clone(self.engine.writers()),
        }
    }

    /// Output writers now.
    pub fn output_writers(&self) -> usize {
        self.engine.writers().count()
    }

    /// A new subscriber to supervision events (state changes, link, DC,
    /// error counters, underruns, recoveries) from now on.
    pub fn events(&self) -> broadcast::Receiver<Event> {
        self.engine.subscribe_events()
    }

    /// A new subscriber to input frames.
    pub fn subscribe(&self) -> broadcast::Receiver<Arc<InputFrame>> {
        self.engine.subscribe_inputs()
    }

    /// The engine's status.
    pub fn status(&self) -> Snapshot {
        self.engine.telemetry().snapshot()
    }

    /// The engine's status as it changes: a new snapshot at once when the
    /// phase, network state, configuration generation or recovery count
    /// changes, and at least every few ms while the engine exchanges
    /// packets. Await this instead of polling [`Master::status`].
    pub fn watch_status(&self) -> tokio::sync::watch::Receiver<Snapshot> {
        self.engine.telemetry().watch()
    }

    /// Waits until a snapshot satisfies `done`, for at most `limit`;
    /// returns that snapshot, or the newest one at the limit as the error.
    pub async fn wait_status(
        &self,
        limit: Duration,
        done: impl FnMut(&Snapshot) -> bool,
    ) -> Result<Snapshot, Snapshot> {
        let mut rx = self.watch_status();
        let mut done = done;
        match tokio::time::timeout(limit, rx.wait_for(|s| done(s))).await {
            Ok(Ok(s)) => Ok(*s),
            // The sender lives as long as `self`: closed cannot happen.
            Ok(Err(_)) | Err(_) => Err(self.status()),
        }
    }

    /// The engine's epoch (time 0 of frame and event times) on the host's
    /// CLOCK_MONOTONIC, ns.
    pub(crate) fn epoch_monotonic_ns(&self) -> u64 {
        self.engine.telemetry().epoch_monotonic_ns.load(Ordering::Relaxed)
    }

    /// Now, ns since the engine's epoch (the time base of frames, events
    /// and the snapshot's `newest_input_ns`).
    pub(crate) fn now_ns(&self) -> u64 {
        crate::realtime::monotonic_ns().saturating_sub(self.epoch_monotonic_ns())
    }

    /// Whether the network does what the configuration asks, judged from
    /// one snapshot: the engine runs, the network is in the target state,
    /// and process data flows (the newest input frame is younger than the
    /// limit). Health, `diag`, the systemd watchdog and READY all use this.
    pub fn health(&self) -> Health {
        self.health_of(&self.status(), self.now_ns())
    }

    /// [`Master::health`] of a snapshot already taken, at `now_ns`.
    pub(crate) fn health_of(&self, s: &Snapshot, now_ns: u64) -> Health {
        let target = self.config.lock().unwrap_or_else(|e| e.into_inner()).cycle.target();
        Health::judge(s, target, now_ns)
    }

    /// Whether process data flows, judged on snapshot `s` now: the health
    /// and the newest input frame's age against its limit.
    pub(crate) fn verdict(&self, s: &Snapshot) -> Verdict {
        let now = self.now_ns();
        Verdict { health: self.health_of(s, now), input_age: s.input_age(now) }
    }

    /// Write-to-wire latency of client output writes over the latest ones
    /// (see `Telemetry::output_latency`); `None` before the first.
    pub(crate) fn output_latency(&self) -> Option<crate::engine::telemetry::LatencyStats> {
        self.engine.telemetry().output_latency.stats()
    }

    /// The output latency budget in force (`cycle.output_latency_us`), us;
    /// read without copying the configuration.
    pub(crate) fn output_latency_budget_us(&self) -> Option<u32> {
        self.config.lock().unwrap_or_else(|e| e.into_inner()).cycle.output_latency_us
    }

    /// Opens a stream of per-cycle output frames for the output image's
    /// bytes `start..start + len`, queuing up to `capacity` frames on this
    /// side: from now on every frame the engine pushes into the RxFIFO takes
    /// the next queued frame into that range (in order, one per DC cycle;
    /// when the queue is empty the last frame repeats, counted). It
    /// replaces the stream in force, if any; dropping the producer ends it
    /// once its frames are played.
    pub fn stream_frames(
        &self,
        start: usize,
        len: usize,
        capacity: usize,
    ) -> Result<crate::engine::frames::FrameProducer, EngineError> {
        let size = self.layout().rx_size;
        if len == 0 || start + len > size {
            let reason = format!("bytes {start}..{} are not within the {size}-byte output image", start + len);
            return Err(EngineError::BadArgument { field: "range", reason });
        }
        let (producer, consumer) = crate::engine::frames::channel(start, len, capacity);
        self.engine.send(Command::FrameStream(consumer))?;
        Ok(producer)
    }

    /// Why bring-up last failed or recovery last started.
    pub fn last_error(&self) -> Option<Failure> {
        self.engine.telemetry().last_error()
    }

    /// Whether the engine stopped because the network can never run with
    /// the configuration in force (see `BringUpError::is_permanent`).
    pub(crate) fn refused(&self) -> bool {
        self.engine.telemetry().refused.load(Ordering::Relaxed)
    }

    /// (vendor id, product code, revision) of the slave at `position` as
    /// bring-up read them; `None` past the end of the ring.
    pub(crate) fn identity(&self, position: u8) -> Option<Identity> {
        let layout = self.engine.layout().lock().unwrap_or_else(|e| e.into_inner());
        layout.slaves.get(usize::from(position)).map(|s| (s.vendor_id, s.product_code, s.revision))
    }

    /// The network as bring-up found it.
    pub fn layout(&self) -> NetworkLayout {
        self.engine.layout().lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Safe stop, then waits for the threads (blocking). A bring-up or
    /// recovery in progress is abandoned at once (see `Port::set_abort`).
    pub fn stop(&self) {
        self.engine.stop();
    }

    /// The newest input frame, if any arrived.
    pub(crate) fn latest_inputs(&self) -> Option<Arc<InputFrame>> {
        self.engine.latest_inputs()
    }

    /// Waits, at most `limit`, for an input frame newer than the newest
    /// now; false when none came. What a drive reports (its state, its mode)
    /// changes only with a frame, so a waiter looks again after each one.
    pub(crate) async fn next_inputs(&self, limit: Duration) -> bool {
        let mut rx = self.engine.watch_latest_inputs();
        matches!(tokio::time::timeout(limit, rx.changed()).await, Ok(Ok(())))
    }

    /// The output ranges open frame streams feed (one stream per range;
    /// plain output writes leave them alone).
    pub(crate) fn frame_claims(&self) -> &Arc<frame_claims::FrameClaims> {
        &self.frame_claims
    }

    /// The process image of the network in force (image::ImageCache::get:
    /// at once when built, else after the build under way). `call`'s
    /// deadline ends the wait ([`EngineError::Timeout`]), never the build,
    /// which is the daemon's own work.
    pub async fn image(&self, call: Call) -> Result<Arc<image::Image>, EngineError> {
        match call.deadline {
            None => self.image.get(self).await,
            Some(end) => {
                tokio::time::timeout_at(end.into(), self.image.get(self)).await.unwrap_or(Err(EngineError::Timeout))
            }
        }
    }

    /// Changes each time an image is built, named or its build fails (the
    /// value says nothing: ask [`Master::current_image`]).
    pub(crate) fn watch_images(&self) -> tokio::sync::watch::Receiver<Option<image::Built>> {
        self.image.changes()
    }

    /// The process image of the network in force if it is built (or its
    /// build failed), at once ([`image::ImageCache::current`]).
    pub(crate) fn current_image(&self) -> Option<Result<Arc<image::Image>, EngineError>> {
        self.image.current(self)
    }

    /// Keeps the process image built after every bring-up, as the
    /// daemon's own client on the blocking slot (runs until the status
    /// channel closes).
    pub async fn keep_image_built(self: Arc<Self>) {
        self.image.keep_built(Arc::clone(&self)).await
    }

    /// The output image as front ends last wrote it (zero-filled at start),
    /// to stage writes on and read back (ReadOutputs).
    pub(crate) fn output_shadow(&self) -> std::sync::MutexGuard<'_, Vec<u8>> {
        self.shadow.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Drop for Master {
    fn drop(&mut self) {
        self.stop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::telemetry::Telemetry;

    fn running(state: EcatState, newest_ms: u64, limit_ms: u64) -> Snapshot {
        let t = Telemetry::default();
        t.set_phase(Phase::Running);
        t.header(&ecmxf_wire::ResponseHeader { ecat_state: state, ..Default::default() });
        t.newest_input_ns.store(newest_ms * 1_000_000, Ordering::Relaxed);
        t.flow_limit_ns.store(limit_ms * 1_000_000, Ordering::Relaxed);
        t.snapshot()
    }

    #[test]
    fn health_needs_the_target_state_and_fresh_inputs() {
        let ms = |v: u64| v * 1_000_000;
        let s = running(EcatState::Op, 100, 50);
        assert_eq!(Health::judge(&s, EcatState::Op, ms(140)), Health::Healthy);
        assert_eq!(
            Health::judge(&s, EcatState::Op, ms(151)),
            Health::Stalled { age: Duration::from_millis(51), limit: Duration::from_millis(50) }
        );
        assert!(matches!(Health::judge(&s, EcatState::SafeOp, ms(101)), Health::WrongState { .. }));
        let mut r = s;
        r.phase = Phase::Recovering;
        assert_eq!(Health::judge(&r, EcatState::Op, ms(101)), Health::NotRunning(Phase::Recovering));
        // No cyclic exchange (target PRE-OP): nothing to flow.
        let p = running(EcatState::PreOp, 0, 0);
        assert_eq!(Health::judge(&p, EcatState::PreOp, ms(10_000)), Health::Healthy);
    }

    /// A slave a running network had is missing: degraded, not healthy,
    /// though the rest runs and its data flows; a stall still says stall.
    #[test]
    fn a_network_missing_a_slave_seen_at_start_is_degraded() {
        let ms = |v: u64| v * 1_000_000;
        let mut s = running(EcatState::Op, 100, 50);
        (s.slaves, s.slaves_seen) = (2, 3);
        let h = Health::judge(&s, EcatState::Op, ms(140));
        assert_eq!(h, Health::SlavesMissing { now: 2, seen: 3 });
        assert!(!h.is_healthy());
        assert!(h.to_string().starts_with("degraded: 2 of 3 slaves since start"), "{h}");
        let v = Verdict { health: h, input_age: s.input_age(ms(140)) };
        assert!(v.flowing(), "process data still flows for the rest");
        assert!(matches!(Health::judge(&s, EcatState::Op, ms(151)), Health::Stalled { .. }));
        (s.slaves, s.slaves_seen) = (3, 3);
        assert_eq!(Health::judge(&s, EcatState::Op, ms(140)), Health::Healthy);
    }

    /// INT0 stuck at its ready level: degraded while data flows.
    #[test]
    fn a_stuck_int0_degrades_a_network_whose_data_flows() {
        let ms = |v: u64| v * 1_000_000;
        let mut s = running(EcatState::Op, 100, 50);
        s.int0_stuck = true;
        let h = Health::judge(&s, EcatState::Op, ms(140));
        assert_eq!(h, Health::Int0Stuck);
        assert!(h.to_string().starts_with("degraded: INT0 stays at its ready level"), "{h}");
        assert!(Verdict { health: h, input_age: s.input_age(ms(140)) }.flowing());
        assert!(matches!(Health::judge(&s, EcatState::Op, ms(151)), Health::Stalled { .. }));
    }

    /// FIFO alarms, chip-dropped inputs and long gaps: degraded with the
    /// figure while recent, healthy again one quiet window later; a stall
    /// still says stall.
    #[test]
    fn recent_trouble_degrades_health_until_a_quiet_window_passes() {
        let ms = |v: u64| v * 1_000_000;
        let t = Telemetry::default();
        t.set_phase(Phase::Running);
        t.header(&ecmxf_wire::ResponseHeader { ecat_state: EcatState::Op, ..Default::default() });
        t.flow_limit_ns.store(ms(50), Ordering::Relaxed);
        t.recent_long_gaps.record(ms(1_000), 1, 122_000);
        t.recent_fifo_alarms.record(ms(1_000), 1, 0);
        t.recent_fifo_alarms.record(ms(1_500), 1, 0);
        t.newest_input_ns.store(ms(2_000), Ordering::Relaxed);
        let s = t.snapshot();
        let h = Health::judge(&s, EcatState::Op, ms(2_010));
        let Health::Troubled(trouble) = h else { panic!("{h:?}") };
        assert_eq!((trouble.kind, trouble.count), (TroubleKind::FifoAlarms, 2), "FIFO alarms named first");
        assert!(!h.is_healthy());
        assert!(Verdict { health: h, input_age: s.input_age(ms(2_010)) }.flowing());
        let said = h.to_string();
        assert!(said.starts_with("degraded: the RxFIFO ran dry 2 times"), "{said}");
        assert!(said.contains("the latest 0.5 s ago; healthy again after 10 s without"), "{said}");
        assert!(matches!(Health::judge(&s, EcatState::Op, ms(2_051)), Health::Stalled { .. }));

        t.recent_fifo_alarms.forget();
        let s = t.snapshot();
        let h = Health::judge(&s, EcatState::Op, ms(2_010));
        assert!(h.to_string().contains("longest gap 122 ms"), "{h}");

        let mut quiet = s;
        quiet.newest_input_ns = ms(11_001);
        assert_eq!(Health::judge(&quiet, EcatState::Op, ms(11_001)), Health::Healthy, "a whole window without");
    }
}
