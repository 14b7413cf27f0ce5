//! The engine: one thread that owns the chip.
//!
//! It brings the network up ([`bringup`]), then runs it (`running.rs`: one
//! loop turn as named steps): apply output writes, keep the RxFIFO at its
//! level (`cyclic`: the latency budget's, or midway between the marks) with FIFO exchanges (reading inputs on the way), advance the
//! one transaction in the blocking slot ([`slot`]) by at most one guarded
//! call between FIFO exchanges, and judge every answer by the
//! [`supervisor`]'s rules, which decide when to go back to bring-up (with
//! back-off). It has one door, [`spawn`], which starts it and returns the
//! [`EngineHandle`]: one bounded channel of commands in (jobs, reconfigure,
//! network actions, frame streams, stop), the output writes on their own,
//! and a wait-free ring of input frames out ([`inputs`]); the status goes out
//! through atomics and a watch of snapshots ([`telemetry`]), supervision
//! events through a ring of their own ([`events`]). Once running, nothing
//! on this thread allocates (daemon/tests/zero_alloc.rs).

pub(crate) mod bringup;
pub(crate) mod cyclic;
pub(crate) mod emergencies;
pub(crate) mod error;
pub(crate) mod events;
pub(crate) mod failure;
pub(crate) mod frames;
mod handle;
// Re-exported by the master as its own (the one door).
#[allow(unreachable_pub)]
pub use handle::{EVENT_BACKLOG, QUEUE_DEPTH, SUBSCRIBER_BACKLOG};
pub(crate) use handle::{EngineHandle, spawn};
pub(crate) mod held;
pub(crate) mod inputs;
pub(crate) mod layout;
pub mod link_budget;
mod link_turn;
pub(crate) mod network_action;
pub(crate) mod output_writes;
mod running;
pub(crate) mod slot;
pub(crate) mod supervisor;
pub(crate) mod telemetry;

use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::mpsc::{Receiver, RecvTimeoutError, TryRecvError};
use std::sync::{Arc, Mutex};
use std::thread::Thread;
use std::time::{Duration, Instant};

use ecmxf_wire::EcatState;
use ecmxf_wire::payload::cia402::{Cia402State, Cia402StateSet};
use ecmxf_wire::payload::fifo::FifoEnable;
use ecmxf_wire::payload::state::{SlaveSelector, StateCheck};
use tracing::{error, info, warn};

use crate::config::{Config, WriterGoneAction};
use crate::link::Link;
use crate::port::{Port, PortError};
use bringup::bring_up;
use cyclic::Cyclic;
use error::{EngineError, NotRunning};
use events::{Event, EventKind, EventSink};
use failure::Failure;
use inputs::InputPublisher;
use layout::NetworkLayout;
use network_action::NetworkAction;
use output_writes::{OutputAssembler, OutputWrite, Writers};
use slot::{Active, FairQueue, Job};
use supervisor::RecoverCause;
use telemetry::{CounterTotal, Phase, Telemetry};

/// Messages to the engine: its one way in besides the output writes (the
/// hot path, lock-free) and the stop flag that ends a wait at once.
#[derive(Debug)]
pub(crate) enum Command {
    /// A request for the blocking slot.
    Job(Job),
    /// A new configuration to bring the network up with, and its number
    /// (published in the telemetry once taken).
    Reconfigure(u64, Box<Config>),
    /// A per-cycle output frame stream opens.
    FrameStream(frames::FrameConsumer),
    /// A re-init or warm reset (asking twice is asking once; a warm reset
    /// wins).
    Network(NetworkAction),
    /// Safe stop, then exit.
    Stop,
}

/// What a command leaves for the loop that took it: a job to queue (or
/// refuse), a stop, or nothing (the rest is kept for the running loop).
enum Taken {
    Job(Job),
    Stop,
    Kept,
}

/// Why the running loop left.
enum Exit {
    Stop,
    Recover(RecoverCause),
}

/// The engine's state on its thread.
pub(crate) struct Engine<L> {
    port: Port<L>,
    config: Config,
    /// A client asked for a state below the configured target: the slaves
    /// that left OP on purpose do not count working counters, and that is
    /// not a fault to recover from. Cleared by a request for the target
    /// state (or above) and by every bring-up.
    held_below_target: bool,
    commands: Receiver<Command>,
    outputs: Receiver<OutputWrite>,
    telemetry: Arc<Telemetry>,
    layout: Arc<Mutex<NetworkLayout>>,
    intake: running::Intake,
    /// The running loop's rules, started over with every run.
    supervisor: supervisor::Supervisor,
    /// The outputs clients wrote, kept per slave across recoveries:
    /// bring-up prefills the RxFIFO with them and the next run starts from
    /// them, so the slaves see what the lease holders last wrote, not zeros.
    held: held::HeldOutputs,
    crc_errors: CounterTotal,
    wkc_errors: CounterTotal,
    emergencies: emergencies::EmergencyWatch,
    /// Set by [`crate::master::Master::stop`]: abandon bring-up and waits.
    stop: Arc<AtomicBool>,
    distributor: Option<Thread>,
    writers: Arc<Writers>,
    events: EventSink,
    /// A re-init or warm reset a client asked for, not yet done.
    action: Option<NetworkAction>,
    /// A configuration a client sent, not yet taken.
    new_config: Option<(u64, Config)>,
    /// The streams in force (room for [`frames::MAX_STREAMS`] from the
    /// start: attaching one never allocates).
    frames: Vec<frames::FrameConsumer>,
    assembler: OutputAssembler,
    queue: FairQueue,
    active: Option<Active>,
    /// When the oldest client write not yet pushed reached the daemon.
    unplayed_write: Option<Instant>,
    /// What the last snapshot sent to waiters showed, and when it went.
    announced: ((Phase, EcatState, u64, u64), Instant),
    /// A RECOVERING event went out and its RECOVERED has not: the network
    /// has not delivered input frames since. Further attempts in the same
    /// spell are counted (`recoveries`), not announced again.
    recovery_open: bool,
}

impl<L> std::fmt::Debug for Engine<L> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Engine").field("queue", &self.queue.len()).finish_non_exhaustive()
    }
}

/// The engine's ends of its two ways in: one command channel for every
/// request, and the output writes, the hot path, on their own.
#[derive(Debug)]
struct Inbound {
    commands: Receiver<Command>,
    outputs: Receiver<OutputWrite>,
}

/// Where the engine publishes without waiting on a reader: the input-frame
/// and event rings, drained by the distributor thread it wakes.
#[derive(Debug)]
struct Outbound {
    ring: rtrb::Producer<u8>,
    events: rtrb::Producer<Event>,
    distributor: Thread,
}

impl<L: Link> Engine<L> {
    /// An engine over `link`, fed by `inbound`, publishing to `outbound`
    /// and to what it shares with `handle` (telemetry, layout, writers,
    /// the stop flag).
    fn new(link: L, config: Config, inbound: Inbound, outbound: Outbound, handle: &EngineHandle) -> Self {
        let mut port = Port::new(link);
        port.set_ready_timeout(config.ready_timeout());
        let epoch = Instant::now();
        handle.telemetry.epoch_monotonic_ns.store(crate::realtime::monotonic_ns(), Relaxed);
        let distributor = Some(outbound.distributor);
        let events = EventSink::new(outbound.events, epoch, distributor.clone());
        Self {
            port,
            config,
            commands: inbound.commands,
            outputs: inbound.outputs,
            telemetry: Arc::clone(&handle.telemetry),
            layout: Arc::clone(&handle.layout),
            intake: running::Intake::new(InputPublisher::new(outbound.ring, epoch), epoch),
            supervisor: supervisor::Supervisor::new(supervisor::RunShape::idle(), 0, epoch),
            held: held::HeldOutputs::default(),
            crc_errors: CounterTotal::default(),
            wkc_errors: CounterTotal::default(),
            emergencies: emergencies::EmergencyWatch::default(),
            stop: Arc::clone(&handle.stop_engine),
            distributor,
            held_below_target: false,
            writers: Arc::clone(&handle.writers),
            action: None,
            new_config: None,
            frames: Vec::with_capacity(frames::MAX_STREAMS),
            assembler: OutputAssembler::default(),
            events,
            queue: FairQueue::default(),
            active: None,
            unplayed_write: None,
            announced: (Default::default(), epoch),
            recovery_open: false,
        }
    }

    /// Runs until stopped: bring-up, cyclic exchange, recovery.
    pub(crate) fn run(mut self) {
        let mut backoff = Duration::from_millis(self.config.recovery.backoff_ms);
        let mut first = true;
        loop {
            self.set_phase(if first { Phase::BringUp } else { Phase::Recovering });
            self.telemetry.forget_network();
            self.events.rebase();
            self.crc_errors.rebase();
            self.wkc_errors.rebase();
            // After a fault the outputs are what the policy says: the image
            // the lease holders last wrote (hold-last, quick-stop: the axes
            // come up disabled anyway), or zeros.
            if !first && self.config.outputs.on_last_writer_gone == WriterGoneAction::Zero {
                self.held.clear();
            }
            // A stop during bring-up ends its waits at once (Port::set_abort).
            self.port.set_abort(Some(Arc::clone(&self.stop)));
            let result = bring_up(&mut self.port, &self.config, &self.held);
            self.port.set_abort(None);
            if self.stop.load(Relaxed) {
                return self.abandon_bring_up(result.is_ok());
            }
            self.publish_status(Instant::now());
            if result.is_err() {
                // The header of a failed bring-up says nothing about the network.
                self.telemetry.forget_network();
            }
            let layout = match result {
                Ok(l) => l,
                Err(e) => {
                    if !e.is_permanent() {
                        // A permanent one is said once, by the daemon as it exits.
                        error!(error = %e, "bring-up failed");
                    }
                    let permanent = e.is_permanent();
                    let reopen = matches!(&e, bringup::BringUpError::Port(PortError::Link(_)));
                    let failure = Failure::BringUp(Arc::new(e));
                    self.telemetry.set_error(failure.clone());
                    self.events.emit(EventKind::BringUpFailed(failure));
                    if permanent {
                        self.telemetry.refused.store(true, Relaxed);
                        return self.stopped();
                    }
                    if reopen {
                        self.reopen_link();
                    }
                    if !self.config.recovery.enabled || !self.pause(backoff) {
                        return self.stopped();
                    }
                    backoff = (backoff * 2).min(Duration::from_millis(self.config.recovery.max_backoff_ms));
                    first = false;
                    self.set_phase(Phase::Recovering);
                    self.count_recovery();
                    continue;
                }
            };
            info!(slaves = layout.slaves.len(), state = %layout.state, rx = layout.rx_size, tx = layout.tx_size, "network up");
            let slaves = layout.slaves.len() as u64;
            self.telemetry.slaves.store(slaves, Relaxed);
            self.telemetry.slaves_seen.fetch_max(slaves, Relaxed);
            backoff = Duration::from_millis(self.config.recovery.backoff_ms);
            first = false;
            let cyclic = (layout.state == EcatState::Op && (layout.rx_size > 0 || layout.tx_size > 0)).then(|| {
                let cycle = self.config.cycle.dc_cycle();
                let plan = cyclic::Plan {
                    rx_size: layout.rx_size,
                    tx_size: layout.tx_size,
                    cycle,
                    low: layout.fifo_low,
                    high: layout.fifo_high,
                    tx_depth: layout.fifo_tx_depth,
                    budget: self.config.cycle.output_latency(),
                };
                Cyclic::new(plan, self.port.data_size(), self.held.image_for(&layout.slaves, layout.rx_size))
            });
            *self.layout.lock().unwrap_or_else(|e| e.into_inner()) = layout;
            self.held_below_target = false;
            // With cyclic data, "running" waits for the first input frame
            // (the running loop says it): a network that reached OP but
            // delivers nothing is not running.
            if cyclic.is_none() {
                self.set_phase(Phase::Running);
                self.recovered();
            }
            let mut cyclic = cyclic;
            let exit = self.running(cyclic.as_mut());
            if let Some(c) = cyclic {
                let layout = self.layout.lock().unwrap_or_else(|e| e.into_inner());
                self.held.keep(&layout.slaves, &c.outputs);
            }
            match exit {
                Exit::Stop => return self.stopped(),
                Exit::Recover(why) => {
                    if matches!(why, RecoverCause::NewConfig | RecoverCause::ReinitRequested) {
                        // The client accepts the network as the bring-up finds it.
                        self.telemetry.slaves_seen.store(0, Relaxed);
                    }
                    self.telemetry.set_error(Failure::Recovery(why.clone()));
                    // Phase first: no one may see "running" while recovering.
                    self.set_phase(Phase::Recovering);
                    self.telemetry.forget_network();
                    if self.recovery_open {
                        // Still the same spell: nothing flowed since the
                        // last RECOVERING. One event, attempts counted.
                        warn!(reason = %why, attempt = self.telemetry.recoveries.load(Relaxed) + 1, "still recovering");
                    } else {
                        warn!(reason = %why, "recovering");
                        self.events.emit(EventKind::Recovering(why.clone()));
                        self.recovery_open = true;
                    }
                    self.count_recovery();
                    self.fail_all(EngineError::Unavailable(NotRunning::Recovering(why.clone())));
                    self.reopen_if_needed(&why);
                    if !self.config.recovery.enabled || !self.pause(backoff) {
                        return self.stopped();
                    }
                }
            }
        }
    }

    /// Opens the link again when the fault was the link's own (a restarted
    /// simulator, a device node that came back). A failure is logged; the
    /// next bring-up fails on the link again and tries again after its
    /// back-off.
    fn reopen_if_needed(&mut self, why: &RecoverCause) {
        if why.needs_reopen() {
            self.reopen_link();
        }
    }

    fn reopen_link(&mut self) {
        match self.port.link_mut().reopen() {
            Ok(()) => info!(link = %self.port.link_mut().describe(), "link opened again"),
            Err(e) => warn!(error = %e, "link could not be opened again; retrying after the back-off"),
        }
    }

    /// Told to stop during bring-up: the slaves go back to INIT if the chip
    /// answers (bounded, so the daemon still stops within a second), then
    /// the engine stops.
    fn abandon_bring_up(mut self, reached: bool) {
        self.set_phase(Phase::Stopping);
        info!(reached, "stop during bring-up");
        self.port.set_ready_timeout(self.config.ready_timeout().min(Duration::from_millis(200)));
        let init = StateCheck { target: SlaveSelector::All, state: EcatState::Init };
        if let Err(e) = bringup::blocking(&mut self.port, &init, Duration::from_millis(500)) {
            warn!(error = %e, "stop during bring-up: slaves not brought to INIT");
        }
        self.stopped();
    }

    /// Publishes a phase change, to the status snapshot and its waiters,
    /// and as an event.
    fn set_phase(&mut self, p: Phase) {
        if self.telemetry.phase() != p || p == Phase::BringUp {
            self.events.emit(EventKind::Phase(p));
        }
        self.telemetry.set_phase(p);
        self.announce(Instant::now());
    }

    /// The network runs again after a fault: process data flows (the
    /// first input frame), or there is none to exchange. RECOVERED is said
    /// then and only then, never while nothing arrives.
    fn recovered(&mut self) {
        if std::mem::take(&mut self.recovery_open) {
            // Logged with its event (a sentence, with axes_disabled as a field).
            let (axes, outputs) = (self.config.axes.len(), self.config.outputs.on_last_writer_gone);
            self.events.emit(EventKind::Recovered { axes_disabled: axes, outputs });
        }
    }

    /// A recovery started: counted, and said to waiters at once.
    fn count_recovery(&mut self) {
        self.telemetry.recoveries.fetch_add(1, Relaxed);
        self.announce(Instant::now());
    }

    /// Sends the snapshot to its waiters (see [`telemetry`]).
    fn announce(&mut self, now: Instant) {
        self.announced = (self.telemetry.announce().key(), now);
    }

    fn stopped(mut self) {
        self.fail_all(EngineError::Unavailable(NotRunning::Stopped));
        self.set_phase(Phase::Stopped);
        info!("engine stopped");
    }

    /// Waits `d` while refusing requests; false when told to stop.
    /// Takes a configuration a client sent, if any. Only what bring-up
    /// applies changes; the link and the thread stay as they are.
    fn take_new_config(&mut self) -> bool {
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

    /// Waits `d` while refusing requests; false when told to stop. A new
    /// configuration ends the wait: it is tried at once.
    fn pause(&mut self, d: Duration) -> bool {
        let until = Instant::now() + d;
        while let Some(left) = until.checked_duration_since(Instant::now()) {
            if self.stop.load(Relaxed) {
                return false;
            }
            if self.take_new_config() {
                return true;
            }
            match self.commands.recv_timeout(left.min(Duration::from_millis(20))).map(|c| self.take(c)) {
                Ok(Taken::Job(j)) => {
                    let _ = j.reply.send(Err(EngineError::Unavailable(NotRunning::BringingUp)));
                }
                Ok(Taken::Stop) | Err(RecvTimeoutError::Disconnected) => return false,
                Ok(Taken::Kept) | Err(RecvTimeoutError::Timeout) => {}
            }
        }
        true
    }

    fn fail_all(&mut self, e: EngineError) {
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
    fn take(&mut self, c: Command) -> Taken {
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
    fn publish_status(&mut self, now: Instant) {
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

    /// Takes new requests; false when told to stop.
    fn take_commands(&mut self) -> bool {
        loop {
            match self.commands.try_recv().map(|c| self.take(c)) {
                Ok(Taken::Job(j)) => self.queue.push(j),
                Ok(Taken::Kept) => {}
                Ok(Taken::Stop) | Err(TryRecvError::Disconnected) => return false,
                Err(TryRecvError::Empty) => return true,
            }
        }
    }

    /// Safe stop: CiA402 axes disabled through the helper, slaves to SAFE-OP
    /// then INIT.
    fn safe_stop(&mut self, cyclic: Option<&mut Cyclic>) -> Exit {
        // A safe stop must not outlast the daemon's one-second promise:
        // each wait for the chip is short.
        self.port.set_ready_timeout(self.config.ready_timeout().min(Duration::from_millis(200)));
        self.set_phase(Phase::Stopping);
        info!("safe stop");
        for n in 0..self.config.axes.len() {
            let _ = self.port.call(&Cia402StateSet { axis: n as u8, state: Cia402State::SwitchOnDisabled });
        }
        if let Some(c) = cyclic {
            // Let the helper walk the axes down while outputs keep flowing.
            let until = Instant::now() + Duration::from_millis(50);
            while Instant::now() < until {
                if self.fifo_exchange(c, Instant::now()).is_err() {
                    break;
                }
                std::thread::sleep(Duration::from_micros(500));
            }
            let _ = self.port.call(&FifoEnable(false));
        }
        for state in [EcatState::SafeOp, EcatState::Init] {
            if let Err(e) = bringup::blocking(
                &mut self.port,
                &StateCheck { target: SlaveSelector::All, state },
                Duration::from_millis(400),
            ) {
                warn!(error = %e, %state, "safe stop");
            }
        }
        self.publish_status(Instant::now());
        Exit::Stop
    }
}
