//! [`Master`]: the engine as async code sees it. Requests go into a bounded
//! queue (full: [`EngineError::QueueFull`]) with a deadline; dropping the
//! future, or the deadline passing, tells the engine to stop caring (it then
//! finishes or abandons the chip operation cleanly). Input frames come out
//! of the engine's wait-free ring through a distributor thread into a
//! broadcast channel: a subscriber that falls behind is told how many frames
//! it missed and slows no one.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use ecmxf_wire::payload::pdo::{PdoConfig, PdoConfigReply, RX_PDO_ASSIGN, TX_PDO_ASSIGN};
use ecmxf_wire::payload::raw::{DatagramHead, RAW_MAX_DATA};
use ecmxf_wire::payload::slave_info::{SlaveInfo, SlaveInfoCode};
use ecmxf_wire::payload::state::SlaveSelector;
use ecmxf_wire::{EcatState, Reply, ReplyFields};
use tokio::sync::{broadcast, oneshot};

use crate::config::{Config, LinkConfig};
use crate::engine::bringup::NetworkLayout;
use crate::engine::cyclic::read_record;
use crate::engine::error::EngineError;
use crate::engine::events::Event;
use crate::engine::job::{
    Job, NetworkAction, OUTPUT_CHUNK, OutputWrite, PendingAction, Request, TransferProgress, Writers,
};
use crate::engine::telemetry::{Phase, Snapshot, Telemetry};
use crate::engine::{Command, Engine, Parts};
use crate::link::sim::{SimHandle, SimLink};
use crate::link::{Link, LinkError};

/// Requests that may wait at once.
pub const QUEUE_DEPTH: usize = 256;
/// Input frames a subscriber may fall behind by before losing some.
pub const SUBSCRIBER_BACKLOG: usize = 4096;
/// Events a subscriber may fall behind by before losing some.
pub const EVENT_BACKLOG: usize = 1024;

/// One input frame (one DC cycle's inputs).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InputFrame {
    /// Sequence number, +1 per frame received.
    pub seq: u64,
    /// When the engine received it, ns since start.
    pub time_ns: u64,
    /// The frame.
    pub data: Vec<u8>,
}

tokio::task_local! {
    /// The client the current task works for (see [`as_client`]).
    static CLIENT: u64;
}

/// Runs `work` on behalf of client `id` (non-zero: a connection, a peer):
/// its requests to the chip's blocking slot take turns with other clients'
/// instead of queuing behind them. Requests made outside any client share
/// one turn.
pub async fn as_client<F: std::future::Future>(id: u64, work: F) -> F::Output {
    CLIENT.scope(id, work).await
}

/// A client's lease on the outputs (see [`Master::output_writer`]).
#[derive(Debug)]
pub struct OutputWriter {
    outputs: Arc<OutputSender>,
    layout: Arc<Mutex<NetworkLayout>>,
    writers: Arc<Writers>,
}

impl OutputWriter {
    /// Writes bytes into the output image at `offset` (of the whole output
    /// frame); they go out together with the next frames pushed.
    pub fn write(&self, offset: usize, bytes: &[u8]) -> Result<(), EngineError> {
        let size = self.layout.lock().unwrap_or_else(|e| e.into_inner()).rx_size;
        self.outputs.send(size, offset, bytes)
    }
}

impl Drop for OutputWriter {
    fn drop(&mut self) {
        self.writers.release();
    }
}

/// The async side of the output queue: cuts writes into chunks that stay
/// together (one lock, held only while queuing and never touched by the
/// engine thread) under one batch number.
#[derive(Debug)]
struct OutputSender {
    tx: SyncSender<OutputWrite>,
    queuing: Mutex<()>,
    next_batch: AtomicU32,
}

impl OutputSender {
    fn send(&self, size: usize, offset: usize, bytes: &[u8]) -> Result<(), EngineError> {
        if offset.saturating_add(bytes.len()) > size {
            return Err(EngineError::BadArgument {
                field: "offset",
                reason: format!("{} bytes at {offset} exceed the {size}-byte output image", bytes.len()),
            });
        }
        if bytes.is_empty() {
            return Ok(());
        }
        let _queuing = self.queuing.lock().unwrap_or_else(|e| e.into_inner());
        let batch = self.next_batch.fetch_add(1, Ordering::Relaxed);
        let chunks = bytes.len().div_ceil(OUTPUT_CHUNK);
        for (i, chunk) in bytes.chunks(OUTPUT_CHUNK).enumerate() {
            let mut data = [0u8; OUTPUT_CHUNK];
            data[..chunk.len()].copy_from_slice(chunk);
            let w = OutputWrite {
                batch,
                last: i + 1 == chunks,
                offset: (offset + i * OUTPUT_CHUNK) as u32,
                len: chunk.len() as u8,
                data,
            };
            // A write cut short here is dropped whole by the engine.
            self.tx.try_send(w).map_err(|e| match e {
                TrySendError::Full(_) => EngineError::QueueFull,
                TrySendError::Disconnected(_) => EngineError::Unavailable("engine stopped".into()),
            })?;
        }
        Ok(())
    }
}

/// What a raw datagram brought back.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RawAnswer {
    /// Working counter: how many slaves acted on it.
    pub working_counter: u16,
    /// The datagram's data as it returned.
    pub data: Vec<u8>,
}

/// Why the master could not start.
#[derive(Debug)]
pub enum StartError {
    /// The link could not be opened.
    Link(LinkError),
    /// The simulator's network file is wrong.
    Network(String),
}

impl std::fmt::Display for StartError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Link(e) => write!(f, "{e}"),
            Self::Network(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for StartError {}

/// The running master.
#[derive(Debug)]
pub struct Master {
    commands: SyncSender<Command>,
    outputs: Arc<OutputSender>,
    telemetry: Arc<Telemetry>,
    layout: Arc<Mutex<NetworkLayout>>,
    inputs: broadcast::Sender<Arc<InputFrame>>,
    events: broadcast::Sender<Event>,
    threads: Mutex<Vec<JoinHandle<()>>>,
    stop_distributor: Arc<AtomicBool>,
    writers: Arc<Writers>,
    action: Arc<PendingAction>,
    reconfigure: SyncSender<(u64, Config)>,
    config: Mutex<Config>,
    config_generation: AtomicU64,
    /// Timeout for requests that give none.
    pub default_timeout: Duration,
}

/// Opens the link the configuration names. For the in-process simulator,
/// also returns the handle to it.
pub fn open_link(config: &Config) -> Result<(Box<dyn Link>, Option<SimHandle>), StartError> {
    match &config.link {
        LinkConfig::Sim { network } => {
            let (net, chip_config) = match network {
                None => (ecmxf_sim::Network::demo(), ecmxf_sim::ChipConfig::default()),
                Some(p) => {
                    let f = ecmxf_sim::config::NetworkFile::load(p).map_err(|e| StartError::Network(e.to_string()))?;
                    (f.build(p).map_err(|e| StartError::Network(e.to_string()))?, f.chip_config())
                }
            };
            let (link, handle) = SimLink::new(ecmxf_sim::Chip::new(net, chip_config));
            Ok((Box::new(link), Some(handle)))
        }
        LinkConfig::SimSocket { socket } => {
            Ok((Box::new(crate::link::socket::SocketLink::connect(socket).map_err(StartError::Link)?), None))
        }
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
    /// Starts the engine thread (real-time as configured) over `link`, and
    /// the input distributor.
    pub fn start<L: Link + 'static>(link: L, config: Config) -> Self {
        let (commands, command_rx) = sync_channel(QUEUE_DEPTH);
        let (output_tx, output_rx) = sync_channel(1024);
        let outputs = Arc::new(OutputSender { tx: output_tx, queuing: Mutex::new(()), next_batch: AtomicU32::new(0) });
        let telemetry = Arc::new(Telemetry::default());
        let layout = Arc::new(Mutex::new(NetworkLayout::default()));
        let writers = Arc::new(Writers::default());
        let action = Arc::new(PendingAction::default());
        let (reconfigure, reconfigure_rx) = sync_channel(1);
        let (inputs, _) = broadcast::channel(SUBSCRIBER_BACKLOG);
        let (producer, mut consumer) = rtrb::RingBuffer::new(1 << 20);
        let (events, _) = broadcast::channel(EVENT_BACKLOG);
        let (event_producer, mut event_consumer) = rtrb::RingBuffer::new(crate::engine::events::RING);
        let event_tx = events.clone();
        let stop_distributor = Arc::new(AtomicBool::new(false));

        let tx = inputs.clone();
        let stop = Arc::clone(&stop_distributor);
        let distributor = std::thread::Builder::new()
            .name("ecmxf-inputs".into())
            .spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    while let Some(r) = read_record(&mut consumer) {
                        // No subscribers is fine: the frame is dropped.
                        let _ = tx.send(Arc::new(InputFrame { seq: r.seq, time_ns: r.time_ns, data: r.data }));
                    }
                    while let Ok(e) = event_consumer.pop() {
                        let _ = event_tx.send(e);
                    }
                    std::thread::park_timeout(Duration::from_millis(5));
                }
            })
            .expect("spawn the input distributor thread");
        let parts = Parts {
            link,
            config: config.clone(),
            commands: command_rx,
            outputs: output_rx,
            telemetry: Arc::clone(&telemetry),
            layout: Arc::clone(&layout),
            ring: producer,
            distributor: Some(distributor.thread().clone()),
            writers: Arc::clone(&writers),
            events: event_producer,
            action: Arc::clone(&action),
            reconfigure: reconfigure_rx,
        };
        let rt = config.realtime.clone();
        let engine = std::thread::Builder::new()
            .name("ecmxf-rt".into())
            .spawn(move || {
                crate::realtime::apply(&rt);
                Engine::new(parts).run();
            })
            .expect("spawn the engine thread");
        Self {
            commands,
            outputs,
            telemetry,
            layout,
            inputs,
            events,
            threads: Mutex::new(vec![engine, distributor]),
            stop_distributor,
            writers,
            action,
            reconfigure,
            config: Mutex::new(config),
            config_generation: AtomicU64::new(0),
            default_timeout: Duration::from_secs(3),
        }
    }

    /// Opens the configured link and starts.
    pub fn from_config(config: Config) -> Result<(Self, Option<SimHandle>), StartError> {
        let (link, sim) = open_link(&config)?;
        Ok((Self::start(link, config), sim))
    }

    async fn request(&self, request: Request, timeout: Option<Duration>) -> Result<Vec<u8>, EngineError> {
        self.request_with_progress(request, timeout, None).await
    }

    async fn request_with_progress(
        &self,
        request: Request,
        timeout: Option<Duration>,
        progress: Option<Arc<TransferProgress>>,
    ) -> Result<Vec<u8>, EngineError> {
        let timeout = timeout.unwrap_or(self.default_timeout);
        let (reply, rx) = oneshot::channel();
        let client = CLIENT.try_with(|c| *c).unwrap_or(0);
        let job = Job { request, deadline: Instant::now() + timeout, reply, progress, client };
        match self.commands.try_send(Command::Job(job)) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => return Err(EngineError::QueueFull),
            Err(TrySendError::Disconnected(_)) => return Err(EngineError::Unavailable("engine stopped".into())),
        }
        match tokio::time::timeout(timeout, rx).await {
            Ok(Ok(r)) => r,
            Ok(Err(_)) => Err(EngineError::Unavailable("engine stopped".into())),
            // Dropping `rx` here tells the engine.
            Err(_) => Err(EngineError::Timeout),
        }
    }

    /// SDO upload.
    pub async fn sdo_read(
        &self,
        slave: u8,
        index: u16,
        subindex: u8,
        complete: bool,
        timeout: Option<Duration>,
    ) -> Result<Vec<u8>, EngineError> {
        self.request(Request::SdoRead { slave, index, subindex, complete }, timeout).await
    }

    /// SDO download.
    pub async fn sdo_write(
        &self,
        slave: u8,
        index: u16,
        subindex: u8,
        complete: bool,
        data: Vec<u8>,
        timeout: Option<Duration>,
    ) -> Result<(), EngineError> {
        self.request(Request::SdoWrite { slave, index, subindex, complete, data }, timeout).await.map(|_| ())
    }

    /// SII words `word` and `word + 1`.
    pub async fn eeprom_read(&self, slave: u8, word: u16, timeout: Option<Duration>) -> Result<[u8; 4], EngineError> {
        let d = self.request(Request::EepromRead { slave, word }, timeout).await?;
        let mut out = [0xFF; 4];
        for (o, b) in out.iter_mut().zip(d) {
            *o = b;
        }
        Ok(out)
    }

    /// `count` SII words from `word` on. Each word pair is its own
    /// transaction, so a long read shares the blocking slot fairly with
    /// other callers; `timeout` applies to each.
    pub async fn eeprom_read_words(
        &self,
        slave: u8,
        word: u16,
        count: u16,
        timeout: Option<Duration>,
    ) -> Result<Vec<u16>, EngineError> {
        if u32::from(word) + u32::from(count) > 0x1_0000 {
            let reason = format!("{count} words from {word:#06x} run past the 16-bit word address space");
            return Err(EngineError::BadArgument { field: "count", reason });
        }
        let mut out = Vec::with_capacity(usize::from(count));
        let mut at = word;
        while out.len() < usize::from(count) {
            let pair = self.eeprom_read(slave, at, timeout).await?;
            out.push(u16::from_le_bytes([pair[0], pair[1]]));
            if out.len() < usize::from(count) {
                out.push(u16::from_le_bytes([pair[2], pair[3]]));
            }
            at = at.wrapping_add(2);
        }
        Ok(out)
    }

    /// Writes SII words from `word` on, each verified by reading it back;
    /// stops at the first failure, which names the word.
    pub async fn eeprom_write_words(
        &self,
        slave: u8,
        word: u16,
        values: &[u16],
        timeout: Option<Duration>,
    ) -> Result<(), EngineError> {
        if u32::from(word) + values.len() as u32 > 0x1_0000 {
            let reason = format!("{} words from {word:#06x} run past the 16-bit word address space", values.len());
            return Err(EngineError::BadArgument { field: "values", reason });
        }
        for (i, v) in values.iter().enumerate() {
            self.eeprom_write(slave, word + i as u16, *v, timeout).await?;
        }
        Ok(())
    }

    /// Writes one SII word and verifies it.
    pub async fn eeprom_write(
        &self,
        slave: u8,
        word: u16,
        value: u16,
        timeout: Option<Duration>,
    ) -> Result<(), EngineError> {
        self.request(Request::EepromWrite { slave, word, value }, timeout).await.map(|_| ())
    }

    /// Requests a state.
    pub async fn set_state(
        &self,
        target: SlaveSelector,
        state: EcatState,
        timeout: Option<Duration>,
    ) -> Result<(), EngineError> {
        if !state.is_requestable() {
            return Err(EngineError::BadArgument { field: "state", reason: format!("{state} cannot be requested") });
        }
        self.request(Request::SetState { target, state }, timeout).await.map(|_| ())
    }

    /// The state a slave (or, for `All`, the network) is in now, freshly
    /// read from the slaves.
    pub async fn get_state(&self, target: SlaveSelector, timeout: Option<Duration>) -> Result<EcatState, EngineError> {
        let d = self.request(Request::GetState { target }, timeout).await?;
        Ok(EcatState::from_u8(d.first().copied().unwrap_or(0)))
    }

    /// One item of slave information, as the chip answers it; decode with
    /// [`SlaveInfo::decode`] for `item`.
    pub async fn slave_info(&self, slave: u8, item: SlaveInfoCode) -> Result<Vec<u8>, EngineError> {
        let d = self.request(Request::SlaveInfo { slave, item }, None).await?;
        SlaveInfo::decode(item, &d).map_err(|e| EngineError::Failed(format!("slave {slave} {item:?}: {e}")))?;
        Ok(d)
    }

    /// A slave's PDO assignment (`assign_index` 0x1C12 for RxPDOs, 0x1C13
    /// for TxPDOs) and the mapping of each assigned PDO, read from the slave.
    pub async fn pdo_config_read(
        &self,
        slave: u8,
        assign_index: u16,
        timeout: Option<Duration>,
    ) -> Result<PdoConfig, EngineError> {
        if ![RX_PDO_ASSIGN, TX_PDO_ASSIGN].contains(&assign_index) {
            let reason = format!("{assign_index:#06x}; use {RX_PDO_ASSIGN:#06x} or {TX_PDO_ASSIGN:#06x}");
            return Err(EngineError::BadArgument { field: "assign_index", reason });
        }
        let d = self.request(Request::PdoConfigRead { slave, assign_index }, timeout).await?;
        let fields = ReplyFields { value: 0, data_len: d.len() as u16 };
        PdoConfigReply::decode(&fields, &d)
            .map(|r| r.0)
            .map_err(|e| EngineError::Failed(format!("PDO assignment {assign_index:#06x} of slave {slave}: {e}")))
    }

    /// Sends one raw EtherCAT datagram and returns what came back. A reading
    /// datagram sends `head.length` zero bytes; a writing one sends `data`,
    /// which must be exactly `head.length` bytes.
    pub async fn raw_datagram(
        &self,
        head: DatagramHead,
        data: Vec<u8>,
        timeout: Option<Duration>,
    ) -> Result<RawAnswer, EngineError> {
        if head.length > RAW_MAX_DATA {
            let reason = format!("{} bytes; a datagram carries at most {RAW_MAX_DATA}", head.length);
            return Err(EngineError::BadArgument { field: "length", reason });
        }
        if head.command.writes() && data.len() != usize::from(head.length) {
            let reason = format!("{} bytes given for a {}-byte writing datagram", data.len(), head.length);
            return Err(EngineError::BadArgument { field: "data", reason });
        }
        if !head.command.writes() && !data.is_empty() {
            let reason = format!("{:?} is a reading datagram and sends no data", head.command);
            return Err(EngineError::BadArgument { field: "data", reason });
        }
        let d = self.request(Request::Raw { head, data }, timeout).await?;
        let Some((wkc, data)) = d.split_first_chunk::<2>() else {
            return Err(EngineError::Failed("raw datagram: answer without a working counter".into()));
        };
        Ok(RawAnswer { working_counter: u16::from_le_bytes(*wkc), data: data.to_vec() })
    }

    /// Writes a file to a slave over FoE (the slave must be in PRE-OP or
    /// above). `progress`, when given, follows the bytes staged.
    pub async fn foe_write(
        &self,
        slave: u8,
        name: &str,
        password: u32,
        data: Vec<u8>,
        progress: Option<Arc<TransferProgress>>,
        timeout: Option<Duration>,
    ) -> Result<(), EngineError> {
        let request = Request::FoeWrite { slave, name: name.to_owned(), password, data };
        self.request_with_progress(request, timeout, progress).await.map(|_| ())
    }

    /// Reads a file of at most `max_len` bytes from a slave over FoE.
    /// `progress`, when given, follows the bytes read back.
    pub async fn foe_read(
        &self,
        slave: u8,
        name: &str,
        password: u32,
        max_len: u32,
        progress: Option<Arc<TransferProgress>>,
        timeout: Option<Duration>,
    ) -> Result<Vec<u8>, EngineError> {
        let request = Request::FoeRead { slave, name: name.to_owned(), password, max_len };
        self.request_with_progress(request, timeout, progress).await
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
        self.writers.acquire();
        OutputWriter {
            outputs: Arc::clone(&self.outputs),
            layout: Arc::clone(&self.layout),
            writers: Arc::clone(&self.writers),
        }
    }

    /// Output writers now.
    pub fn output_writers(&self) -> usize {
        self.writers.count()
    }

    /// Scans the network again and redoes the whole bring-up from the
    /// configuration (mapping, start-up SDOs, states); returns once the
    /// network runs again. Requests in flight fail with `Unavailable`.
    pub async fn reinit(&self, timeout: Option<Duration>) -> Result<(), EngineError> {
        self.network_action(NetworkAction::Reinit, timeout).await
    }

    /// Warm-resets the chip (cmd 127), then redoes the bring-up; returns once
    /// the network runs again.
    pub async fn warm_reset(&self, timeout: Option<Duration>) -> Result<(), EngineError> {
        self.network_action(NetworkAction::WarmReset, timeout).await
    }

    /// Brings the network up again with `config`: expected slaves, PDO
    /// mappings, start-up SDOs, axes, DC cycle, FIFO sizes, target state,
    /// recovery and output policy all take effect (ECAT_INIT, PDO_CONFIG_SET,
    /// FIFO_INIT... as at start). The link and the real-time settings belong
    /// to the running process and cannot change. Returns once the network
    /// runs with it; on a bring-up failure the engine keeps retrying the new
    /// configuration, and [`Master::last_error`] says why.
    pub async fn apply_config(&self, config: Config, timeout: Option<Duration>) -> Result<(), EngineError> {
        config
            .validate(std::path::Path::new("(applied)"))
            .map_err(|e| EngineError::BadArgument { field: "config", reason: e.to_string() })?;
        {
            let current = self.config.lock().unwrap_or_else(|e| e.into_inner());
            if config.link != current.link {
                let reason = "the link cannot change while the daemon runs; restart it".to_string();
                return Err(EngineError::BadArgument { field: "link", reason });
            }
            if config.realtime != current.realtime {
                let reason = "real-time settings apply at start; restart the daemon".to_string();
                return Err(EngineError::BadArgument { field: "realtime", reason });
            }
        }
        if matches!(self.status().phase, Phase::Stopping | Phase::Stopped) {
            return Err(EngineError::Unavailable("engine stopped".into()));
        }
        let generation = self.config_generation.fetch_add(1, Ordering::AcqRel) + 1;
        self.reconfigure.try_send((generation, config.clone())).map_err(|e| match e {
            TrySendError::Full(_) => EngineError::QueueFull,
            TrySendError::Disconnected(_) => EngineError::Unavailable("engine stopped".into()),
        })?;
        *self.config.lock().unwrap_or_else(|e| e.into_inner()) = config;
        self.until(timeout, |s| s.config_generation >= generation && s.phase == Phase::Running).await
    }

    /// The configuration in force.
    pub fn config(&self) -> Config {
        self.config.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    fn running_or_unavailable(&self) -> Result<(), EngineError> {
        if self.status().phase != Phase::Running {
            let why = self.last_error().unwrap_or_else(|| format!("{:?}", self.status().phase));
            return Err(EngineError::Unavailable(format!("the network is not running: {why}")));
        }
        Ok(())
    }

    async fn network_action(&self, action: NetworkAction, timeout: Option<Duration>) -> Result<(), EngineError> {
        self.running_or_unavailable()?;
        let before = self.status().recoveries;
        self.action.request(action);
        self.until(timeout, |s| s.recoveries > before && s.phase == Phase::Running).await
    }

    /// Waits until the status satisfies `done` (default limit 30 s).
    async fn until(&self, timeout: Option<Duration>, done: impl Fn(&Snapshot) -> bool) -> Result<(), EngineError> {
        let deadline = Instant::now() + timeout.unwrap_or(Duration::from_secs(30));
        loop {
            let s = self.status();
            if done(&s) {
                return Ok(());
            }
            if s.phase == Phase::Stopped {
                return Err(EngineError::Unavailable("engine stopped".into()));
            }
            if Instant::now() >= deadline {
                return Err(match self.last_error() {
                    Some(why) if s.phase != Phase::Running => {
                        EngineError::Failed(format!("the network is not back up yet: {why}"))
                    }
                    _ => EngineError::Timeout,
                });
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// A new subscriber to supervision events (state changes, link, DC,
    /// error counters, underruns, recoveries) from now on.
    pub fn events(&self) -> broadcast::Receiver<Event> {
        self.events.subscribe()
    }

    /// A new subscriber to input frames.
    pub fn subscribe(&self) -> broadcast::Receiver<Arc<InputFrame>> {
        self.inputs.subscribe()
    }

    /// The engine's status.
    pub fn status(&self) -> Snapshot {
        self.telemetry.snapshot()
    }

    /// Why bring-up last failed or recovery last started.
    pub fn last_error(&self) -> Option<String> {
        self.telemetry.last_error()
    }

    /// The network as bring-up found it.
    pub fn layout(&self) -> NetworkLayout {
        self.layout.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Safe stop, then waits for the threads (blocking).
    pub fn stop(&self) {
        // A full queue still takes the stop: retry briefly.
        for _ in 0..100 {
            match self.commands.try_send(Command::Stop) {
                Err(TrySendError::Full(_)) => std::thread::sleep(Duration::from_millis(10)),
                _ => break,
            }
        }
        let mut threads = self.threads.lock().unwrap_or_else(|e| e.into_inner());
        // The engine thread first (it finishes the safe stop), then the
        // distributor.
        if !threads.is_empty() {
            let _ = threads.remove(0).join();
        }
        self.stop_distributor.store(true, Ordering::Relaxed);
        for t in threads.drain(..) {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

impl Drop for Master {
    fn drop(&mut self) {
        self.stop();
    }
}
