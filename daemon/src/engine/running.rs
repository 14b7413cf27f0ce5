//! The running loop: once the network is up, every turn applies output
//! writes, keeps the RxFIFO fed, advances the transaction in the blocking
//! slot, publishes inputs and status, and watches for the faults that send
//! the engine back to bring-up (see `Engine::run`).

use std::sync::atomic::Ordering::Relaxed;
use std::sync::mpsc::{RecvTimeoutError, TryRecvError};
use std::time::{Duration, Instant};

use ecmxf_wire::flags::{ControlFlags, ErrorFlags, StatusFlags};
use ecmxf_wire::payload::cia402::{Cia402State, Cia402StateSet};
use ecmxf_wire::payload::control::{InfoUpdate, WarmReset};
use ecmxf_wire::payload::pdo::{FifoOpFlags, PdoFifoOp};
use ecmxf_wire::payload::slave_info::{SlaveCountGet, SlaveInfo, SlaveInfoCode, SlaveInfoGet};
use ecmxf_wire::{CommandCode, EcatState, ResponseHeader, al_status_text};
use tracing::{debug, info, warn};

use super::cyclic::Cyclic;
use super::events::EventKind;
use super::inputs::InputPublisher;
use super::job::{NetworkAction, Request};
use super::supervisor::{FlowWatch, RecoverCause, flow_limit};
use super::telemetry::{Phase, Telemetry};
use super::transaction::{Active, Progress};
use super::{Command, Engine, Exit};
use crate::config::WriterGoneAction;
use crate::link::Link;
use crate::port::PortError;

/// Working-counter errors this long in a row mean a slave left the
/// exchange (lost, or dropped to a lower state): recover.
const WKC_STREAK: Duration = Duration::from_millis(50);
/// A streak ends after this long without a new WKC error.
const WKC_QUIET: Duration = Duration::from_millis(20);

/// How often the engine counts the slaves while idle.
const CENSUS: Duration = Duration::from_secs(1);

/// How often a transaction waiting for the chip polls its status.
const POLL: Duration = Duration::from_micros(100);

/// Where FIFO answers go: input frames to subscribers, and the watch that
/// they keep coming.
#[derive(Debug)]
pub(super) struct Intake {
    /// The input ring.
    pub inputs: InputPublisher,
    flow: FlowWatch,
    epoch: Instant,
    /// A stall the last answer confirmed, for the loop to act on.
    stall: Option<RecoverCause>,
}

impl Intake {
    pub(super) fn new(inputs: InputPublisher, epoch: Instant) -> Self {
        Self { inputs, flow: FlowWatch::new(Duration::ZERO, epoch), epoch, stall: None }
    }

    /// A run of the cyclic exchange starts at `now`.
    fn start(&mut self, c: &Cyclic, telemetry: &Telemetry, now: Instant) {
        let limit = flow_limit(c.cycle());
        self.flow = FlowWatch::new(limit, now);
        self.stall = None;
        self.inputs.resume(now, c.cycle());
        telemetry.newest_input_ns.store(self.ns(now), Relaxed);
        telemetry.flow_limit_ns.store(limit.as_nanos() as u64, Relaxed);
    }

    fn ns(&self, t: Instant) -> u64 {
        t.saturating_duration_since(self.epoch).as_nanos() as u64
    }

    /// Handles an intact answer to a FIFO exchange: inputs out, freshness
    /// noted. A network without inputs counts the answer itself as the
    /// sign of life.
    /// Returns the input frames the answer held.
    fn answer(
        &mut self,
        c: &Cyclic,
        telemetry: &Telemetry,
        header: &ResponseHeader,
        data: &[u8],
        now: Instant,
    ) -> usize {
        if header.code != CommandCode::PdoDataFifoOp {
            return 0;
        }
        let n = self.inputs.publish(data, c.tx_size, now);
        telemetry.input_frames.fetch_add(n as u64, Relaxed);
        let alive = if c.tx_size == 0 { 1 } else { n };
        if alive > 0 {
            telemetry.newest_input_ns.store(self.ns(now), Relaxed);
        }
        if let Some(stall) = self.flow.answer(alive, now) {
            self.stall.get_or_insert(stall);
        }
        n
    }
}

impl<L: Link> Engine<L> {
    fn check_health(&self, h: &ResponseHeader) -> Result<(), RecoverCause> {
        if h.is_nop() || !h.status.flags.contains(StatusFlags::ETHERNET_READY) {
            return Err(RecoverCause::ChipReset);
        }
        if h.ecat_state == EcatState::Error {
            return Err(RecoverCause::SlaveError(String::new()));
        }
        Ok(())
    }

    /// Reads every slave's state and AL status code (a fault is being
    /// handled: the time is not the cycle's), reports the codes as events,
    /// and returns them as text, e.g. "slave 2 SAFE-OP, AL status 0x001a
    /// (...)". Read failures are left out.
    fn al_report(&mut self, slaves: usize) -> String {
        let mut text = String::new();
        for i in 0..slaves.min(usize::from(u8::MAX)) as u8 {
            let mut read = |item| match self.port.call(&SlaveInfoGet { slave: i, item }) {
                Ok(a) => match SlaveInfo::decode(item, a.data) {
                    Ok(SlaveInfo::State(v)) => Some(u32::from(v.to_u8())),
                    Ok(SlaveInfo::AlStatus(v)) => Some(u32::from(v)),
                    _ => None,
                },
                Err(_) => None,
            };
            let (Some(state), Some(code)) = (read(SlaveInfoCode::State), read(SlaveInfoCode::AlStatus)) else {
                continue;
            };
            let (state, code) = (EcatState::from_u8(state as u8), code as u16);
            if code != 0 {
                self.events.emit(EventKind::AlStatus { slave: i, state, code });
                if !text.is_empty() {
                    text.push_str("; ");
                }
                text.push_str(&format!("slave {i} {state}, AL status {code:#06x} ({})", al_status_text(code)));
            }
        }
        text
    }

    /// The cause, with the slaves' AL status codes read and reported where
    /// a slave is at fault.
    fn explained(&mut self, why: RecoverCause, slaves: usize) -> RecoverCause {
        match why {
            RecoverCause::SlaveError(_) | RecoverCause::WkcStreak(_) | RecoverCause::ExchangeStopped => {
                let report = self.al_report(slaves);
                match why {
                    RecoverCause::SlaveError(_) => RecoverCause::SlaveError(if report.is_empty() {
                        "no slave reports an AL status code".into()
                    } else {
                        report
                    }),
                    other => {
                        if !report.is_empty() {
                            warn!(slaves = %report, "AL status");
                        }
                        other
                    }
                }
            }
            other => other,
        }
    }

    pub(super) fn running(&mut self, cyclic: Option<&mut Cyclic>) -> Exit {
        let slaves = self.layout.lock().unwrap_or_else(|e| e.into_inner()).slaves.len();
        match self.run_loop(cyclic, slaves) {
            Exit::Recover(why) => Exit::Recover(self.explained(why, slaves)),
            stop => stop,
        }
    }

    fn run_loop(&mut self, cyclic: Option<&mut Cyclic>, slaves: usize) -> Exit {
        let mut cyclic = cyclic;
        let mut last_poll = Instant::now();
        let mut last_census = Instant::now();
        let mut last_emergency_poll = Instant::now();
        let mut wkc_errors = self.port.status().wkc_errors;
        // (first WKC error of a streak, last one seen)
        let mut wkc_streak: Option<(Instant, Instant)> = None;
        // A FIFO error bit left from before this run (a fault, the bring-up)
        // is cleared, not reported.
        let mut fifo_dry = true;
        self.port.pending_control |= ControlFlags::CLEAR_FIFO_ERROR;
        if let Some(c) = cyclic.as_deref() {
            self.intake.start(c, &self.telemetry, Instant::now());
        }
        let mut flowing = false;
        loop {
            if !self.take_commands() {
                return self.safe_stop(cyclic.as_deref_mut());
            }
            while let Ok(w) = self.outputs.try_recv() {
                self.assembler.push(w, cyclic.as_deref_mut().map(|c| c.outputs.as_mut_slice()));
            }
            if self.writers.take_gone() {
                self.last_writer_gone(cyclic.as_deref_mut());
            }
            if self.take_new_config() {
                return Exit::Recover(RecoverCause::NewConfig);
            }
            match self.action.take() {
                Some(NetworkAction::Reinit) => return Exit::Recover(RecoverCause::ReinitRequested),
                Some(NetworkAction::WarmReset) => {
                    // The chip resets at once; its answer may never come.
                    let _ = self.port.call(&WarmReset);
                    return Exit::Recover(RecoverCause::WarmResetRequested);
                }
                None => {}
            }
            let now = Instant::now();
            if self.active.is_none() && self.queue.is_empty() && now.duration_since(last_census) >= CENSUS {
                // Slaves plugged in or out change the count the chip sees.
                last_census = now;
                match self.port.call(&SlaveCountGet) {
                    Ok(a) if usize::from(a.header.return_value) != slaves => {
                        let to = usize::from(a.header.return_value);
                        return Exit::Recover(RecoverCause::SlaveCount { from: slaves, to });
                    }
                    Ok(_) => {}
                    Err(e) => return Exit::Recover(RecoverCause::from_port(&e)),
                }
            }
            // An emergency question whose answer no exchange has brought
            // yet: fetch it with a status exchange.
            if self.emergencies.asked()
                && self.active.is_none()
                && now.duration_since(last_emergency_poll) >= super::emergencies::ANSWER_WAIT
            {
                if let Err(e) = self.port.send_once(&InfoUpdate).and_then(|()| self.check_emergencies()) {
                    return Exit::Recover(RecoverCause::from_port(&e));
                }
            }
            // Emergencies are read when the slot is idle; during a
            // transaction, its status polls do it (see transaction_step).
            if self.active.is_none()
                && self.queue.is_empty()
                && now.duration_since(last_emergency_poll) >= super::emergencies::POLL
                && !cyclic.as_deref().is_some_and(|c| self.fifo_due(c, now))
            {
                if let Err(e) = self.poll_emergencies(&mut last_emergency_poll, now) {
                    return Exit::Recover(RecoverCause::from_port(&e));
                }
            }
            let result = match cyclic.as_deref_mut() {
                Some(c) if self.fifo_due(c, now) => self.fifo_exchange(c, now).map(|()| true),
                _ => self.transaction_step(cyclic.as_deref_mut(), &mut last_poll, &mut last_emergency_poll),
            };
            let progressed = match result {
                Ok(p) => p,
                Err(e) => return Exit::Recover(RecoverCause::from_port(&e)),
            };
            if let Err(e) = self.check_emergencies() {
                return Exit::Recover(RecoverCause::from_port(&e));
            }
            if self.held_below_target {
                // Slaves held below OP on purpose may deliver nothing.
                self.intake.flow.excuse(Instant::now());
            } else if let Some(stall) = self.intake.stall.take() {
                if let RecoverCause::InputStall { age, .. } = &stall {
                    let age_us = age.as_micros() as u64;
                    self.events.emit(EventKind::ProcessData { flowing: false, age_us });
                }
                return Exit::Recover(stall);
            }
            if !flowing && cyclic.is_some() && self.intake.flow.flowed() {
                // Running means process data flows: said at the first frame.
                flowing = true;
                self.set_phase(Phase::Running);
            }
            let h = *self.port.status();
            self.publish_status(Instant::now());
            if let Err(why) = self.check_health(&h) {
                return Exit::Recover(why);
            }
            let now = Instant::now();
            if self.held_below_target {
                // Slaves held below the target on purpose miss the
                // exchange; a streak counts from when the hold ends.
                wkc_streak = None;
                wkc_errors = h.wkc_errors;
            } else if h.wkc_errors != wkc_errors {
                debug!(count = h.wkc_errors, "working-counter errors");
                wkc_errors = h.wkc_errors;
                let first = wkc_streak.map_or(now, |(f, _)| f);
                wkc_streak = Some((first, now));
                if now.duration_since(first) > WKC_STREAK {
                    return Exit::Recover(RecoverCause::WkcStreak(WKC_STREAK));
                }
            } else if wkc_streak.is_some_and(|(_, last)| now.duration_since(last) > WKC_QUIET) {
                wkc_streak = None;
            }
            if cyclic.is_some() && !h.status.flags.contains(StatusFlags::PDO_CONFIGURED) {
                return Exit::Recover(RecoverCause::ExchangeStopped);
            }
            // The FIFO error bit stays set until cleared, and headers lag the
            // clear: one alarm per rising edge, not one per header showing it.
            // Without outputs there is nothing to run dry.
            let has_outputs = cyclic.as_deref().is_some_and(|c| c.rx_size > 0);
            let dry = has_outputs && h.errors.contains(ErrorFlags::FIFO_ERROR);
            if dry && !fifo_dry {
                self.telemetry.fifo_alarms.fetch_add(1, Relaxed);
                self.events.emit(EventKind::FifoUnderrun);
                warn!("RxFIFO ran dry: outputs repeated");
            }
            if h.errors.contains(ErrorFlags::FIFO_ERROR) {
                self.port.pending_control |= ControlFlags::CLEAR_FIFO_ERROR;
            }
            fifo_dry = dry;
            if !progressed {
                let now = Instant::now();
                let wake = match cyclic.as_deref() {
                    Some(c) => c.next_exchange(now, self.rx_room(c), self.tx_room(c)),
                    None => now + Duration::from_millis(50),
                };
                // Idle, the next emergency question (or the exchange that
                // brings its answer) is due too.
                let emergency = last_emergency_poll
                    + if self.emergencies.asked() { super::emergencies::ANSWER_WAIT } else { super::emergencies::POLL };
                let until = if self.active.is_some() { now + POLL } else { wake.min(emergency) };
                match self.idle_until(until) {
                    Some(Command::Job(j)) => self.queue.push(j),
                    Some(Command::Stop) => return self.safe_stop(cyclic.as_deref_mut()),
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

    /// Input frames one exchange should read: a packet's worth, and at most
    /// half the TxFIFO, so small input frames (many to a packet) are read
    /// before the chip has to drop any.
    fn tx_room(&self, c: &Cyclic) -> usize {
        let per_packet = self.port.data_size() / c.tx_size.max(1);
        per_packet.min(usize::from(c.tx_depth / 2).max(1))
    }

    fn fifo_due(&self, c: &Cyclic, now: Instant) -> bool {
        now >= c.next_exchange(now, self.rx_room(c), self.tx_room(c)) || c.outputs_low(now)
    }

    /// One FIFO exchange: pushes the output frames the level needs and
    /// reads the input frames waiting, as a guarded call (see `port`): its
    /// own answer comes back intact or the call fails, so a bit error on
    /// the way to the host costs one more exchange, never the input frames
    /// the answer carries (sent pipelined, a corrupt answer lost its batch
    /// for good: 40% of them at a bit error rate of 1e-3). The count in the
    /// answer is the RxFIFO level just before this push (v049: an answer
    /// reports the level of the packet before, see the simulator's
    /// `note_fifo_levels`).
    pub(super) fn fifo_exchange(&mut self, c: &mut Cyclic, now: Instant) -> Result<(), PortError> {
        if let Some(last) = c.last_exchange() {
            let gap = now.saturating_duration_since(last).as_micros() as u64;
            self.telemetry.max_fifo_gap_us.fetch_max(gap, Relaxed);
        }
        let room = self.port.data_size().checked_div(c.rx_size).unwrap_or(0);
        let n = if c.rx_size > 0 { c.frames_to_push(now, room) } else { 0 };
        // Borrowed, not copied: this runs thousands of times a second.
        let mut op = FifoOpFlags::empty();
        op.set(FifoOpFlags::WRITE, c.rx_size > 0);
        op.set(FifoOpFlags::READ, c.tx_size > 0);
        let outputs = c.push_bytes(n);
        let a = self.port.call(&PdoFifoOp { op, frames: n, outputs })?;
        let count = a.header.rx_fifo_count;
        let read = self.intake.answer(c, &self.telemetry, &a.header, a.data, now);
        // A full packet of inputs: more may be waiting.
        let drained = read < self.port.data_size() / c.tx_size.max(1);
        c.answered(now, n, count, drained);
        self.telemetry.output_frames.fetch_add(u64::from(n), Relaxed);
        if let Some(t) = &self.distributor {
            t.unpark();
        }
        Ok(())
    }

    /// Looks at the answer to an emergency question, once an exchange has
    /// brought it, and emits what is new.
    fn check_emergencies(&mut self) -> Result<(), PortError> {
        let events = &mut self.events;
        self.emergencies.check(&mut self.port, |r| events.emit(EventKind::Emergency(r)))
    }

    /// Asks for the newest CoE emergency (see `emergencies`); the answer is
    /// looked at after the next exchange.
    fn poll_emergencies(&mut self, last: &mut Instant, now: Instant) -> Result<(), PortError> {
        *last = now;
        self.emergencies.ask(&mut self.port)
    }

    fn transaction_step(
        &mut self,
        cyclic: Option<&mut Cyclic>,
        last_poll: &mut Instant,
        last_emergency_poll: &mut Instant,
    ) -> Result<bool, PortError> {
        let now = Instant::now();
        if self.active.is_none() {
            while let Some(j) = self.queue.pop() {
                if let Request::SetState { state, .. } = &j.request {
                    self.held_below_target = state.to_u8() < self.config.cycle.target().to_u8();
                }
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
        if progress == Progress::Waiting && now.duration_since(*last_poll) >= POLL {
            // The busy bit only changes in answers: fetch one now. An
            // emergency read that is due is the poll; else, with cyclic
            // data running, a FIFO exchange (it reads inputs and tops up
            // outputs anyway).
            if now.duration_since(*last_emergency_poll) >= super::emergencies::POLL {
                self.poll_emergencies(last_emergency_poll, now)?;
            } else {
                match cyclic {
                    Some(c) => self.fifo_exchange(c, now)?,
                    None => {
                        self.port.call(&InfoUpdate)?;
                    }
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
}
