//! What every phase of the engine works with, and outlives each of them:
//! the port, the configuration, the ways in and out, the outputs held
//! across recoveries, the counters, the streams and requests in force.
//! Only the small steps every phase takes are here (publish the phase and
//! the status, take a command, refuse every request, stop); each phase
//! does the rest in its own file (`bringing_up`, `running`, `recovering`).

use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::mpsc::Receiver;
use std::sync::{Arc, Mutex};
use std::thread::Thread;
use std::time::Instant;

use ecmxf_wire::EcatState;
use tracing::{info, warn};

use super::command::{Command, Taken};
use super::emergencies::EmergencyWatch;
use super::error::{EngineError, NotRunning};
use super::events::{Event, EventKind, EventSink};
use super::frames::{self, FrameConsumer};
use super::held::HeldOutputs;
use super::inputs::InputPublisher;
use super::intake::Intake;
use super::layout::NetworkLayout;
use super::network_action::NetworkAction;
use super::output_writes::{OutputAssembler, OutputWrite, Writers};
use super::slot::{Active, FairQueue, PollPace};
use super::telemetry::{self, CounterTotal, Phase, Telemetry};
use crate::config::{Config, WriterGoneAction};
use crate::link::Link;
use crate::port::Port;

/// The engine's ends of its two ways in: one command channel for every
/// request, and the output writes, the hot path, on their own.
#[derive(Debug)]
pub(super) struct Inbound {
    pub commands: Receiver<Command>,
    pub outputs: Receiver<OutputWrite>,
}

/// Where the engine publishes without waiting on a reader: the input-frame
/// and event rings, drained by the distributor thread it wakes.
#[derive(Debug)]
pub(super) struct Outbound {
    pub ring: rtrb::Producer<u8>,
    pub events: rtrb::Producer<Event>,
    pub distributor: Thread,
}

/// What the engine shares with its handle: read there without the engine
/// (telemetry, layout), counted there (writers), or set there (stop).
#[derive(Debug)]
pub(super) struct Shared {
    pub telemetry: Arc<Telemetry>,
    pub layout: Arc<Mutex<NetworkLayout>>,
    pub writers: Arc<Writers>,
    pub stop: Arc<AtomicBool>,
}

/// The engine's state on its thread that every phase needs.
pub(super) struct Core<L> {
    pub port: Port<L>,
    pub config: Config,
    pub commands: Receiver<Command>,
    pub outputs: Receiver<OutputWrite>,
    pub telemetry: Arc<Telemetry>,
    pub layout: Arc<Mutex<NetworkLayout>>,
    /// Kept across runs: input frames keep their numbering.
    pub intake: Intake,
    /// The outputs clients wrote, kept per slave across recoveries:
    /// bring-up prefills the RxFIFO with them and the next run starts from
    /// them, so the slaves see what the lease holders last wrote, not zeros.
    pub held: HeldOutputs,
    pub crc_errors: CounterTotal,
    pub wkc_errors: CounterTotal,
    pub emergencies: EmergencyWatch,
    /// Set by [`crate::master::Master::stop`]: abandon bring-up and waits.
    pub stop: Arc<AtomicBool>,
    pub distributor: Option<Thread>,
    pub writers: Arc<Writers>,
    pub events: EventSink,
    /// A re-init or warm reset a client asked for, not yet done.
    pub action: Option<NetworkAction>,
    /// A configuration a client sent, not yet taken.
    pub new_config: Option<(u64, Config)>,
    /// The streams in force (room for [`frames::MAX_STREAMS`] from the
    /// start: attaching one never allocates). A stream opened while the
    /// network is down is kept for the next run.
    pub frames: Vec<FrameConsumer>,
    /// Kept across runs, like the writes still in its channel.
    pub assembler: OutputAssembler,
    /// The blocking slot's queue: its lines stay across runs, so a
    /// client's next request does not allocate.
    pub queue: FairQueue,
    pub active: Option<Active>,
    /// How long PDO assignment reads take, learned across transactions and
    /// runs (see `slot::PollPace`).
    pub poll_pace: Arc<PollPace>,
    /// When the oldest client write not yet pushed reached the daemon.
    pub unplayed_write: Option<Instant>,
    /// What the last snapshot sent to waiters showed, and when it went.
    announced: ((Phase, EcatState, u64, u64), Instant),
    /// A RECOVERING event went out and its RECOVERED has not: the network
    /// has not delivered input frames since. Further attempts in the same
    /// spell are counted (`recoveries`), not announced again.
    pub recovery_open: bool,
}

impl<L> std::fmt::Debug for Core<L> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Core").field("queue", &self.queue.len()).finish_non_exhaustive()
    }
}

impl<L: Link> Core<L> {
    /// The engine's state over `link`, fed by `inbound`, publishing to
    /// `outbound` and to what it shares with its handle.
    pub(super) fn new(link: L, config: Config, inbound: Inbound, outbound: Outbound, shared: Shared) -> Self {
        let mut port = Port::new(link);
        port.set_ready_timeout(config.ready_timeout());
        let epoch = Instant::now();
        shared.telemetry.epoch_monotonic_ns.store(crate::realtime::monotonic_ns(), Relaxed);
        let distributor = Some(outbound.distributor);
        let events = EventSink::new(outbound.events, epoch, distributor.clone());
        Self {
            port,
            config,
            commands: inbound.commands,
            outputs: inbound.outputs,
            telemetry: shared.telemetry,
            layout: shared.layout,
            intake: Intake::new(InputPublisher::new(outbound.ring, epoch), epoch),
            held: HeldOutputs::default(),
            crc_errors: CounterTotal::default(),
            wkc_errors: CounterTotal::default(),
            emergencies: EmergencyWatch::default(),
            stop: shared.stop,
            distributor,
            writers: shared.writers,
            action: None,
            new_config: None,
            frames: Vec::with_capacity(frames::MAX_STREAMS),
            assembler: OutputAssembler::default(),
            events,
            queue: FairQueue::default(),
            active: None,
            poll_pace: Arc::default(),
            unplayed_write: None,
            announced: (Default::default(), epoch),
            recovery_open: false,
        }
    }

    /// Publishes a phase change, to the status snapshot and its waiters,
    /// and as an event.
    pub(super) fn set_phase(&mut self, p: Phase) {
        if self.telemetry.phase() != p || p == Phase::BringUp {
            self.events.emit(EventKind::Phase(p));
        }
        self.telemetry.set_phase(p);
        self.announce(Instant::now());
    }

    /// Sends the snapshot to its waiters (see [`telemetry`]).
    pub(super) fn announce(&mut self, now: Instant) {
        self.announced = (self.telemetry.announce().key(), now);
    }

    /// The engine's last step: every request refused, STOPPED said.
    pub(super) fn stopped(&mut self) {
        self.fail_all(EngineError::Unavailable(NotRunning::Stopped));
        self.set_phase(Phase::Stopped);
        info!("engine stopped");
    }

    /// Takes a configuration a client sent, if any. Only what bring-up
    /// applies changes; the link and the thread stay as they are.
    pub(super) fn take_new_config(&mut self) -> bool {
        let Some((generation, config)) = self.new_config.take() else {
            return false;
        };
        // Phase first: a caller waiting for "running with my configuration"
        // must not mistake the old run for the new one.
        self.set_phase(Phase::Recovering);
        self.config = config;
        self.telemetry.config_generation.store(generation, Relaxed);
        self.announce(Instant::now());
        true
    }

    /// Answers `e` to the transaction on the slot, every queued job and
    /// every job still in the channel.
    pub(super) fn fail_all(&mut self, e: EngineError) {
        if let Some(a) = self.active.take() {
            a.fail(e.clone());
        }
        for j in self.queue.drain() {
            let _ = j.reply.send(Err(e.clone()));
        }
        while let Ok(c) = self.commands.try_recv() {
            match self.take(c) {
                Taken::Job(j) => {
                    let _ = j.reply.send(Err(e.clone()));
                }
                // A stop stays the engine's next thing to do.
                Taken::Stop => self.stop.store(true, Relaxed),
                Taken::Kept => {}
            }
        }
    }

    /// Takes one command: a new configuration, a network action or a frame
    /// stream is kept for the running loop; a job or a stop is the caller's.
    pub(super) fn take(&mut self, c: Command) -> Taken {
        match c {
            Command::Job(j) => return Taken::Job(j),
            Command::Stop => return Taken::Stop,
            Command::Reconfigure(generation, config) => self.new_config = Some((generation, *config)),
            Command::Network(a) => self.action = self.action.max(Some(a)),
            Command::FrameStream(mut f) => {
                f.on_dry = match self.config.outputs.on_last_writer_gone {
                    WriterGoneAction::Zero => frames::DryAction::Zero,
                    _ => frames::DryAction::Hold,
                };
                if self.frames.len() < self.frames.capacity() {
                    self.frames.push(f);
                } else {
                    // The API opens no more than MAX_STREAMS; never grow.
                    warn!("a frame stream beyond {} was refused", frames::MAX_STREAMS);
                }
            }
        }
        Taken::Kept
    }

    /// Publishes the last header and the port's counters; waiters get a
    /// snapshot when what they wait for changed, or [`ANNOUNCE_EVERY`]
    /// after the last one.
    ///
    /// [`ANNOUNCE_EVERY`]: telemetry::ANNOUNCE_EVERY
    pub(super) fn publish_status(&mut self, now: Instant) {
        let s = self.port.stats();
        let h = *self.port.status();
        self.telemetry.header(&h);
        // A chip that answers NOP has just reset: its counters restart.
        if h.is_nop() {
            self.crc_errors.rebase();
            self.wkc_errors.rebase();
        } else {
            let totals = (self.crc_errors.update(h.crc_errors), self.wkc_errors.update(h.wkc_errors));
            self.telemetry.crc_errors.store(totals.0, Relaxed);
            self.telemetry.wkc_errors.store(totals.1, Relaxed);
            self.events.header(&h, totals, now);
        }
        self.telemetry.exchanges.store(s.exchanges, Relaxed);
        self.telemetry.corrupt.store(s.corrupt, Relaxed);
        self.telemetry.not_ready.store(s.not_ready, Relaxed);
        self.telemetry.ring_overflows.store(self.intake.inputs.ring_overflows, Relaxed);
        if self.telemetry.key() != self.announced.0
            || now.saturating_duration_since(self.announced.1) >= telemetry::ANNOUNCE_EVERY
        {
            self.announce(now);
        }
    }
}
