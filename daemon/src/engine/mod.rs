//! The engine: one thread that owns the chip.
//!
//! It brings the network up, then loops: apply output writes, keep the
//! RxFIFO between its marks with pipelined FIFO exchanges (reading inputs
//! on the way), advance the one transaction in the blocking slot by at most
//! one guarded call between FIFO exchanges, watch the status for chip
//! resets and bus errors, and recover with back-off. Async code talks to it
//! through bounded channels in and a wait-free ring of input frames out; the
//! status goes out through atomics ([`telemetry`]).

pub mod bringup;
pub mod cyclic;
pub mod error;
pub mod events;
mod fair;
pub mod job;
pub mod telemetry;
mod transaction;

use std::sync::atomic::Ordering::Relaxed;
use std::sync::mpsc::{Receiver, RecvTimeoutError, TryRecvError};
use std::sync::{Arc, Mutex};
use std::thread::Thread;
use std::time::{Duration, Instant};

use ecmxf_wire::flags::{ControlFlags, ErrorFlags, StatusFlags};
use ecmxf_wire::payload::cia402::{Cia402State, Cia402StateSet};
use ecmxf_wire::payload::control::{InfoUpdate, WarmReset};
use ecmxf_wire::payload::fifo::FifoEnable;
use ecmxf_wire::payload::pdo::{FifoOpFlags, PdoFifoOp};
use ecmxf_wire::payload::slave_info::SlaveCountGet;
use ecmxf_wire::payload::state::{SlaveSelector, StateCheck};
use ecmxf_wire::{CommandCode, EcatState, ResponseHeader};
use tracing::{debug, error, info, warn};

use crate::config::{Config, WriterGoneAction};
use crate::link::Link;
use crate::port::{Port, PortError};
use bringup::{NetworkLayout, bring_up};
use cyclic::Cyclic;
use error::EngineError;
use events::{Event, EventKind, EventSink};
use fair::FairQueue;
use job::{Job, NetworkAction, OutputAssembler, OutputWrite, PendingAction, Writers};
use telemetry::{Phase, Telemetry};
use transaction::{Active, Progress};

/// Messages to the engine.
#[derive(Debug)]
pub enum Command {
    /// A request.
    Job(Job),
    /// Safe stop, then exit.
    Stop,
}

/// Working-counter errors this long in a row mean a slave left the
/// exchange (lost, or dropped to a lower state): recover.
const WKC_STREAK: Duration = Duration::from_millis(50);
/// A streak ends after this long without a new WKC error.
const WKC_QUIET: Duration = Duration::from_millis(20);

/// This many cyclic answers lost in a row means the link or the chip is
/// not what the port thinks (e.g. the chip reset to its power-up packet
/// size): recover, which resynchronises.
const LOST_IN_A_ROW: u32 = 16;

/// How often the engine counts the slaves while idle.
const CENSUS: Duration = Duration::from_secs(1);

/// How often a transaction waiting for the chip polls its status.
const POLL: Duration = Duration::from_micros(100);

/// Why the running loop left.
enum Exit {
    Stop,
    Recover(String),
}

/// The engine's state on its thread.
pub struct Engine<L> {
    port: Port<L>,
    config: Config,
    commands: Receiver<Command>,
    outputs: Receiver<OutputWrite>,
    telemetry: Arc<Telemetry>,
    layout: Arc<Mutex<NetworkLayout>>,
    ring: Option<rtrb::Producer<u8>>,
    distributor: Option<Thread>,
    writers: Arc<Writers>,
    events: EventSink,
    action: Arc<PendingAction>,
    reconfigure: Receiver<(u64, Config)>,
    assembler: OutputAssembler,
    queue: FairQueue,
    active: Option<Active>,
    epoch: Instant,
}

impl<L> std::fmt::Debug for Engine<L> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Engine").field("queue", &self.queue.len()).finish_non_exhaustive()
    }
}

/// Everything the engine thread needs.
#[derive(Debug)]
pub struct Parts<L> {
    /// The link.
    pub link: L,
    /// The configuration.
    pub config: Config,
    /// Requests in.
    pub commands: Receiver<Command>,
    /// Output writes in.
    pub outputs: Receiver<OutputWrite>,
    /// Status out.
    pub telemetry: Arc<Telemetry>,
    /// Layout out (written at bring-up only).
    pub layout: Arc<Mutex<NetworkLayout>>,
    /// Input frames out.
    pub ring: rtrb::Producer<u8>,
    /// Woken when input frames were published.
    pub distributor: Option<Thread>,
    /// Output writer leases.
    pub writers: Arc<Writers>,
    /// Supervision events out.
    pub events: rtrb::Producer<Event>,
    /// Re-init or warm reset asked for by a client.
    pub action: Arc<PendingAction>,
    /// A new configuration to bring the network up with, and its number
    /// (published in the telemetry once taken).
    pub reconfigure: Receiver<(u64, Config)>,
}

impl<L: Link> Engine<L> {
    /// An engine over its parts.
    pub fn new(p: Parts<L>) -> Self {
        let mut port = Port::new(p.link);
        port.set_ready_timeout(p.config.ready_timeout());
        let epoch = Instant::now();
        let events = EventSink::new(p.events, epoch, p.distributor.clone());
        Self {
            port,
            config: p.config,
            commands: p.commands,
            outputs: p.outputs,
            telemetry: p.telemetry,
            layout: p.layout,
            ring: Some(p.ring),
            distributor: p.distributor,
            writers: p.writers,
            action: p.action,
            reconfigure: p.reconfigure,
            assembler: OutputAssembler::default(),
            events,
            queue: FairQueue::default(),
            active: None,
            epoch,
        }
    }

    /// Runs until stopped: bring-up, cyclic exchange, recovery.
    pub fn run(mut self) {
        let mut backoff = Duration::from_millis(self.config.recovery.backoff_ms);
        let mut first = true;
        loop {
            self.set_phase(if first { Phase::BringUp } else { Phase::Recovering });
            self.events.rebase();
            let result = bring_up(&mut self.port, &self.config);
            self.publish_status();
            let layout = match result {
                Ok(l) => l,
                Err(e) => {
                    error!(error = %e, "bring-up failed");
                    self.telemetry.set_error(format!("bring-up: {e}"));
                    self.events.emit(EventKind::BringUpFailed(e.to_string()));
                    if !self.config.recovery.enabled || !self.pause(backoff) {
                        return self.stopped();
                    }
                    backoff = (backoff * 2).min(Duration::from_millis(self.config.recovery.max_backoff_ms));
                    first = false;
                    self.set_phase(Phase::Recovering);
                    self.telemetry.recoveries.fetch_add(1, Relaxed);
                    continue;
                }
            };
            info!(slaves = layout.slaves.len(), state = %layout.state, rx = layout.rx_size, tx = layout.tx_size, "network up");
            backoff = Duration::from_millis(self.config.recovery.backoff_ms);
            first = false;
            let cyclic = (layout.state == EcatState::Op && (layout.rx_size > 0 || layout.tx_size > 0)).then(|| {
                let cycle = Duration::from_micros(u64::from(if self.config.cycle.dc_assign_activate != 0 {
                    self.config.cycle.sync0_us
                } else {
                    1000
                }));
                let ring = self.ring.take().unwrap_or_else(|| rtrb::RingBuffer::new(1).0);
                let plan = cyclic::Plan {
                    rx_size: layout.rx_size,
                    tx_size: layout.tx_size,
                    cycle,
                    low: layout.fifo_low,
                    high: layout.fifo_high,
                };
                Cyclic::new(plan, self.port.data_size(), ring, self.epoch)
            });
            *self.layout.lock().unwrap_or_else(|e| e.into_inner()) = layout;
            self.set_phase(Phase::Running);
            match self.running(cyclic) {
                Exit::Stop => return self.stopped(),
                Exit::Recover(why) => {
                    warn!(reason = %why, "recovering");
                    self.telemetry.set_error(format!("recovery: {why}"));
                    // Phase first: no one may see "running" while recovering.
                    self.set_phase(Phase::Recovering);
                    self.events.emit(EventKind::Recovering(why.clone()));
                    self.telemetry.recoveries.fetch_add(1, Relaxed);
                    self.fail_all(EngineError::Unavailable(format!("recovering: {why}")));
                    if !self.config.recovery.enabled || !self.pause(backoff) {
                        return self.stopped();
                    }
                }
            }
        }
    }

    /// Publishes a phase change, to the status snapshot and as an event.
    fn set_phase(&mut self, p: Phase) {
        if self.telemetry.phase() != p || p == Phase::BringUp {
            self.events.emit(EventKind::Phase(p));
        }
        self.telemetry.set_phase(p);
    }

    fn stopped(mut self) {
        self.fail_all(EngineError::Unavailable("stopped".into()));
        self.set_phase(Phase::Stopped);
        info!("engine stopped");
    }

    /// Waits `d` while refusing requests; false when told to stop.
    /// Takes a configuration a client sent, if any. Only what bring-up
    /// applies changes; the link and the thread stay as they are.
    fn take_new_config(&mut self) -> bool {
        let Ok((generation, config)) = self.reconfigure.try_recv() else {
            return false;
        };
        // Phase first: a caller waiting for "running with my configuration"
        // must not mistake the old run for the new one.
        self.set_phase(Phase::Recovering);
        self.config = config;
        self.telemetry.config_generation.store(generation, Relaxed);
        true
    }

    /// Waits `d` while refusing requests; false when told to stop. A new
    /// configuration ends the wait: it is tried at once.
    fn pause(&mut self, d: Duration) -> bool {
        let until = Instant::now() + d;
        while let Some(left) = until.checked_duration_since(Instant::now()) {
            if self.take_new_config() {
                return true;
            }
            match self.commands.recv_timeout(left.min(Duration::from_millis(20))) {
                Ok(Command::Job(j)) => {
                    let _ = j.reply.send(Err(EngineError::Unavailable("bringing the network up".into())));
                }
                Ok(Command::Stop) | Err(RecvTimeoutError::Disconnected) => return false,
                Err(RecvTimeoutError::Timeout) => {}
            }
        }
        true
    }

    fn fail_all(&mut self, e: EngineError) {
        if let Some(a) = self.active.take() {
            drop(a);
        }
        for j in self.queue.drain() {
            let _ = j.reply.send(Err(e.clone()));
        }
        while let Ok(c) = self.commands.try_recv() {
            if let Command::Job(j) = c {
                let _ = j.reply.send(Err(e.clone()));
            }
        }
    }

    fn publish_status(&mut self) {
        let s = self.port.stats();
        self.telemetry.header(self.port.status());
        self.events.header(self.port.status(), Instant::now());
        self.telemetry.exchanges.store(s.exchanges, Relaxed);
        self.telemetry.corrupt.store(s.corrupt, Relaxed);
        self.telemetry.not_ready.store(s.not_ready, Relaxed);
        self.telemetry.input_batches_lost.store(s.lost, Relaxed);
    }

    /// Takes new requests; false when told to stop.
    fn take_commands(&mut self) -> bool {
        loop {
            match self.commands.try_recv() {
                Ok(Command::Job(j)) => self.queue.push(j),
                Ok(Command::Stop) | Err(TryRecvError::Disconnected) => return false,
                Err(TryRecvError::Empty) => return true,
            }
        }
    }

    fn check_health(&self, h: &ResponseHeader) -> Result<(), String> {
        if h.is_nop() || !h.status.flags.contains(StatusFlags::ETHERNET_READY) {
            return Err("chip reset (status back to power-up values)".into());
        }
        if h.ecat_state == EcatState::Error {
            return Err("a slave reports an error or is missing".into());
        }
        Ok(())
    }

    /// Handles an answer to a FIFO exchange: inputs out, level noted.
    fn fifo_answer(
        cyclic: &mut Cyclic,
        telemetry: &Telemetry,
        header: &ResponseHeader,
        data: &[u8],
        now: Instant,
    ) -> usize {
        if header.code != CommandCode::PdoDataFifoOp {
            return 0;
        }
        let n = cyclic.publish(data, now);
        telemetry.input_frames.fetch_add(n as u64, Relaxed);
        n
    }

    fn running(&mut self, mut cyclic: Option<Cyclic>) -> Exit {
        let mut fifo_pending = false;
        let mut last_poll = Instant::now();
        let mut lost_before = self.port.stats().lost;
        let mut lost_run = 0u32;
        let slaves = self.layout.lock().unwrap_or_else(|e| e.into_inner()).slaves.len();
        let mut last_census = Instant::now();
        let mut wkc_errors = self.port.status().wkc_errors;
        // (first WKC error of a streak, last one seen)
        let mut wkc_streak: Option<(Instant, Instant)> = None;
        // A FIFO error bit left from before this run (a fault, the bring-up)
        // is cleared, not reported.
        let mut fifo_dry = true;
        self.port.pending_control |= ControlFlags::CLEAR_FIFO_ERROR;
        loop {
            if !self.take_commands() {
                return self.safe_stop(cyclic.as_mut());
            }
            while let Ok(w) = self.outputs.try_recv() {
                self.assembler.push(w, cyclic.as_mut().map(|c| c.outputs.as_mut_slice()));
            }
            if self.writers.take_gone() {
                self.last_writer_gone(cyclic.as_mut());
            }
            if self.take_new_config() {
                return Exit::Recover("new configuration from a client".into());
            }
            match self.action.take() {
                Some(NetworkAction::Reinit) => return Exit::Recover("re-init requested by a client".into()),
                Some(NetworkAction::WarmReset) => {
                    // The chip resets at once; its answer may never come.
                    let _ = self.port.call(&WarmReset);
                    return Exit::Recover("warm reset requested by a client".into());
                }
                None => {}
            }
            let now = Instant::now();
            if self.active.is_none() && self.queue.is_empty() && now.duration_since(last_census) >= CENSUS {
                // Slaves plugged in or out change the count the chip sees.
                last_census = now;
                match self.port.call(&SlaveCountGet) {
                    Ok(a) if usize::from(a.header.return_value) != slaves => {
                        let found = a.header.return_value;
                        return Exit::Recover(format!("slave count changed from {slaves} to {found}"));
                    }
                    Ok(_) => {}
                    Err(e) => return Exit::Recover(e.to_string()),
                }
                // Its first exchange carried the answer to the last FIFO
                // packet: those inputs are published, not dropped.
                if fifo_pending {
                    if let (Some(c), Some(prev)) = (cyclic.as_mut(), self.port.previous()) {
                        let (h, data) = (prev.header, prev.data.to_vec());
                        Self::fifo_answer(c, &self.telemetry, &h, &data, now);
                    }
                    fifo_pending = false;
                }
            }
            let result = match cyclic.as_mut() {
                Some(c) if self.fifo_due(c, now) => self.fifo_exchange(c, now, &mut fifo_pending).map(|()| true),
                _ => self.transaction_step(cyclic.as_mut(), &mut fifo_pending, &mut last_poll),
            };
            let progressed = match result {
                Ok(p) => p,
                Err(e) => return Exit::Recover(e.to_string()),
            };
            let lost = self.port.stats().lost;
            lost_run = if lost > lost_before { lost_run + 1 } else { 0 };
            lost_before = lost;
            if lost_run >= LOST_IN_A_ROW {
                return Exit::Recover(format!("{LOST_IN_A_ROW} cyclic answers lost in a row"));
            }
            let h = *self.port.status();
            self.publish_status();
            if let Err(why) = self.check_health(&h) {
                return Exit::Recover(why);
            }
            let now = Instant::now();
            if h.wkc_errors != wkc_errors {
                debug!(count = h.wkc_errors, "working-counter errors");
                wkc_errors = h.wkc_errors;
                let first = wkc_streak.map_or(now, |(f, _)| f);
                wkc_streak = Some((first, now));
                if now.duration_since(first) > WKC_STREAK {
                    return Exit::Recover(format!(
                        "working-counter errors for {WKC_STREAK:?}: a slave is not exchanging"
                    ));
                }
            } else if wkc_streak.is_some_and(|(_, last)| now.duration_since(last) > WKC_QUIET) {
                wkc_streak = None;
            }
            if cyclic.is_some() && !h.status.flags.contains(StatusFlags::PDO_CONFIGURED) {
                return Exit::Recover("process-data exchange stopped (working-counter limit)".into());
            }
            // The FIFO error bit stays set until cleared, and headers lag the
            // clear: one alarm per rising edge, not one per header showing it.
            let dry = h.errors.contains(ErrorFlags::FIFO_ERROR);
            if dry && !fifo_dry {
                self.telemetry.fifo_alarms.fetch_add(1, Relaxed);
                self.events.emit(EventKind::FifoUnderrun);
                warn!("RxFIFO ran dry: outputs repeated");
            }
            if dry {
                self.port.pending_control |= ControlFlags::CLEAR_FIFO_ERROR;
            }
            fifo_dry = dry;
            if !progressed {
                let now = Instant::now();
                let wake = match cyclic.as_ref() {
                    Some(c) => c.next_exchange(now, self.rx_room(c), self.port.data_size() / c.tx_size.max(1)),
                    None => now + Duration::from_millis(50),
                };
                let until = if self.active.is_some() { now + POLL } else { wake };
                match self.idle_until(until) {
                    Some(Command::Job(j)) => self.queue.push(j),
                    Some(Command::Stop) => return self.safe_stop(cyclic.as_mut()),
                    None => {}
                }
            }
        }
    }

    /// Waits until `until` or the next command. The last `spin_us` of a
    /// wait are spent yielding, not sleeping (see [`RealtimeConfig`]).
    ///
    /// [`RealtimeConfig`]: crate::config::RealtimeConfig
    fn idle_until(&mut self, until: Instant) -> Option<Command> {
        let spin = Duration::from_micros(self.config.realtime.spin_us.into());
        loop {
            let now = Instant::now();
            let left = until.checked_duration_since(now).filter(|d| !d.is_zero())?;
            if left > spin {
                match self.commands.recv_timeout(left - spin) {
                    Ok(c) => return Some(c),
                    Err(RecvTimeoutError::Disconnected) => return Some(Command::Stop),
                    Err(RecvTimeoutError::Timeout) => {}
                }
            } else {
                match self.commands.try_recv() {
                    Ok(c) => return Some(c),
                    Err(TryRecvError::Disconnected) => return Some(Command::Stop),
                    Err(TryRecvError::Empty) => std::thread::yield_now(),
                }
            }
        }
    }

    fn rx_room(&self, c: &Cyclic) -> usize {
        self.port.data_size().checked_div(c.rx_size).unwrap_or(0)
    }

    fn fifo_due(&self, c: &Cyclic, now: Instant) -> bool {
        let tx_room = self.port.data_size() / c.tx_size.max(1);
        now >= c.next_exchange(now, self.rx_room(c), tx_room) || c.estimate(now) < i64::from(c.low()) + 2
    }

    fn fifo_exchange(&mut self, c: &mut Cyclic, now: Instant, fifo_pending: &mut bool) -> Result<(), PortError> {
        if let Some(last) = c.last_exchange() {
            let gap = now.saturating_duration_since(last).as_micros() as u64;
            self.telemetry.max_fifo_gap_us.fetch_max(gap, Relaxed);
        }
        let room = self.port.data_size().checked_div(c.rx_size).unwrap_or(0);
        let n = if c.rx_size > 0 { c.frames_to_push(now, room) } else { 0 };
        let outputs = c.push_bytes(n).to_vec();
        let answer = self.port.pipelined(&PdoFifoOp {
            op: FifoOpFlags::WRITE | FifoOpFlags::READ,
            frames: n,
            outputs: &outputs,
        })?;
        let count = match answer {
            Some(a) => {
                if *fifo_pending {
                    let h = a.header;
                    let data = a.data.to_vec();
                    Self::fifo_answer(c, &self.telemetry, &h, &data, now);
                }
                Some(self.port.status().rx_fifo_count)
            }
            None => None,
        };
        c.exchanged(now, n, count);
        self.telemetry.output_frames.fetch_add(u64::from(n), Relaxed);
        *fifo_pending = true;
        if let Some(t) = &self.distributor {
            t.unpark();
        }
        Ok(())
    }

    fn transaction_step(
        &mut self,
        mut cyclic: Option<&mut Cyclic>,
        fifo_pending: &mut bool,
        last_poll: &mut Instant,
    ) -> Result<bool, PortError> {
        let now = Instant::now();
        if self.active.is_none() {
            while let Some(j) = self.queue.pop() {
                if let Some(a) = Active::new(j) {
                    self.active = Some(a);
                    break;
                }
            }
        }
        let Some(active) = self.active.take() else {
            return Ok(false);
        };
        let exchanges = self.port.stats().exchanges;
        let (rest, progress) = active.step(&mut self.port, now)?;
        self.active = rest;
        if progress == Progress::Done {
            self.telemetry.transactions.fetch_add(1, Relaxed);
        }
        let sent = self.port.stats().exchanges != exchanges;
        if sent && *fifo_pending {
            if let (Some(c), Some(prev)) = (cyclic.as_deref_mut(), self.port.previous()) {
                let h = prev.header;
                let data = prev.data.to_vec();
                Self::fifo_answer(c, &self.telemetry, &h, &data, now);
            }
            *fifo_pending = false;
        }
        if progress == Progress::Waiting && now.duration_since(*last_poll) >= POLL {
            // The busy bit only changes in answers: fetch one now. With
            // cyclic data running, a FIFO exchange is the poll (it reads
            // inputs and tops up outputs anyway).
            match cyclic {
                Some(c) => self.fifo_exchange(c, now, fifo_pending)?,
                None => {
                    self.port.call(&InfoUpdate)?;
                }
            }
            *last_poll = now;
            return Ok(true);
        }
        Ok(sent && progress != Progress::Waiting)
    }

    /// The last output writer went away: `outputs.on_last_writer_gone`.
    fn last_writer_gone(&mut self, cyclic: Option<&mut Cyclic>) {
        self.events.emit(EventKind::LastWriterGone(self.config.outputs.on_last_writer_gone));
        match self.config.outputs.on_last_writer_gone {
            WriterGoneAction::HoldLast => info!("last output writer gone: holding the last outputs"),
            WriterGoneAction::Zero => {
                if let Some(c) = cyclic {
                    c.outputs.fill(0);
                }
                warn!("last output writer gone: outputs zeroed");
            }
            WriterGoneAction::QuickStop => {
                for n in 0..self.config.axes.len() {
                    let r = self.port.call(&Cia402StateSet { axis: n as u8, state: Cia402State::QuickStopActive });
                    if let Err(e) = r {
                        warn!("quick stop of axis {n}: {e}");
                    }
                }
                warn!("last output writer gone: {} axes quick-stopped", self.config.axes.len());
            }
        }
    }

    /// Safe stop: CiA402 axes disabled through the helper, slaves to SAFE-OP
    /// then INIT.
    fn safe_stop(&mut self, cyclic: Option<&mut Cyclic>) -> Exit {
        self.set_phase(Phase::Stopping);
        info!("safe stop");
        let mut fifo_pending = false;
        for n in 0..self.config.axes.len() {
            let _ = self.port.call(&Cia402StateSet { axis: n as u8, state: Cia402State::SwitchOnDisabled });
        }
        if let Some(c) = cyclic {
            // Let the helper walk the axes down while outputs keep flowing.
            let until = Instant::now() + Duration::from_millis(50);
            while Instant::now() < until {
                if self.fifo_exchange(c, Instant::now(), &mut fifo_pending).is_err() {
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
                Duration::from_secs(2),
            ) {
                warn!(error = %e, %state, "safe stop");
            }
        }
        self.publish_status();
        Exit::Stop
    }
}
