//! The running phase: once the network is up, each turn of the loop is a
//! fixed sequence of named steps ([`Running::turn`]): take what clients
//! sent (requests, output writes, actions), count the slaves now and then,
//! keep the emergency question going, exchange (a FIFO exchange when one is
//! due, else one step of the blocking-slot transaction), take the FIFO
//! answers the exchanges brought (`settle_fifo`, see `fifo_reads`), then
//! judge what the answers said, and idle until the next thing is due. The rules that
//! decide when to go back to bring-up are the [`Supervisor`]'s: they take
//! the time as a parameter and are unit-tested there. A step that ends the
//! run returns the [`Exit`] as its error, so the turn reads top to bottom.
//! Why a run ended is said better by `explain`, what happens when clients'
//! outputs stop coming by `outputs_gone`.

use std::sync::atomic::Ordering::Relaxed;
use std::sync::mpsc::{RecvTimeoutError, TryRecvError};
use std::time::{Duration, Instant};

use ecmxf_wire::flags::ControlFlags;
use ecmxf_wire::payload::cia402::{Cia402State, Cia402StateSet};
use ecmxf_wire::payload::control::{InfoUpdate, WarmReset};
use ecmxf_wire::payload::fifo::FifoEnable;
use ecmxf_wire::payload::pdo::{FifoOpFlags, PdoFifoOp};
use ecmxf_wire::payload::slave_info::SlaveCountGet;
use ecmxf_wire::payload::state::{SlaveSelector, StateCheck};
use ecmxf_wire::{CommandCode, EcatState};
use tracing::{info, warn};

use super::bringup;
use super::command::{Command, Taken};
use super::core::Core;
use super::cyclic::{self, Counts, Cyclic, InFlight};
use super::emergencies;
use super::events::EventKind;
use super::explain;
use super::fifo_reads::{FetchRule, LinkErrors};
use super::layout::NetworkLayout;
use super::link_turn::{Fifo, PULL_FORWARD, Slot, fifo_goes_first};
use super::network_action::NetworkAction;
use super::next::Next;
use super::outputs_gone;
use super::recovering;
use super::slot::{Active, Progress, SlotRequest};
use super::supervisor::{INT0_SILENT_EXCHANGES, RecoverCause, RunShape, Supervisor, flow_limit};
use super::telemetry::Phase;
use crate::link::Link;
use crate::port::{Fate, PortError};

/// How long the loop idles at most when nothing is due (no cyclic
/// exchange, no transaction).
const IDLE: Duration = Duration::from_millis(50);

/// Why the running loop left.
enum Exit {
    Stop,
    Recover(RecoverCause),
}

impl From<PortError> for Exit {
    fn from(e: PortError) -> Self {
        Exit::Recover(RecoverCause::from_port(e))
    }
}

impl From<RecoverCause> for Exit {
    fn from(c: RecoverCause) -> Self {
        Exit::Recover(c)
    }
}

/// The network is up as `layout` says: publishes it, runs it until a
/// fault, a client's action or a stop, and keeps the outputs the run
/// ended with for the next one.
pub(super) fn run<L: Link>(core: &mut Core<L>, layout: NetworkLayout) -> Next {
    info!(slaves = layout.slaves.len(), state = %layout.state, rx = layout.rx_size, tx = layout.tx_size, "network up");
    let slaves = layout.slaves.len() as u64;
    core.telemetry.slaves.store(slaves, Relaxed);
    core.telemetry.slaves_seen.fetch_max(slaves, Relaxed);
    let mut cyclic = (layout.state == EcatState::Op && (layout.rx_size > 0 || layout.tx_size > 0)).then(|| {
        let cycle = core.config.cycle.dc_cycle();
        let plan = cyclic::Plan {
            rx_size: layout.rx_size,
            tx_size: layout.tx_size,
            cycle,
            low: layout.fifo_low,
            high: layout.fifo_high,
            tx_depth: layout.fifo_tx_depth,
            budget: core.config.cycle.output_latency(),
        };
        Cyclic::new(plan, core.port.data_size(), core.held.image_for(&layout.slaves, layout.rx_size))
    });
    *core.layout.lock().unwrap_or_else(|e| e.into_inner()) = layout;
    // With cyclic data, "running" waits for the first input frame
    // (the running loop says it): a network that reached OP but
    // delivers nothing is not running.
    if cyclic.is_none() {
        core.set_phase(Phase::Running);
        recovering::recovered(core);
    }
    let now = Instant::now();
    let running = Running::start(core, cyclic.as_ref(), now);
    let exit = running.run(cyclic.as_mut(), now);
    if let Some(c) = cyclic {
        let layout = core.layout.lock().unwrap_or_else(|e| e.into_inner());
        core.held.keep(&layout.slaves, &c.outputs);
    }
    match exit {
        Exit::Stop => Next::Stop,
        Exit::Recover(why) => Next::Recover(why),
    }
}

/// One run of the network: what every phase shares, and what only a run
/// has (its rules, a client's hold below the target state, the slaves it
/// started with).
struct Running<'a, L> {
    core: &'a mut Core<L>,
    /// The running loop's rules, started over with every run.
    supervisor: Supervisor,
    /// A client asked for a state below the configured target: the slaves
    /// that left OP on purpose do not count working counters, and that is
    /// not a fault to recover from. Cleared by a request for the target
    /// state (or above); a run starts without it (bring-up reached the
    /// target).
    held_below_target: bool,
    /// The slaves bring-up found.
    slaves: usize,
    /// Whether a FIFO call's answer is fetched at once.
    fetch: FetchRule,
}

/// When the loop last did its periodic things.
#[derive(Clone, Copy, Debug)]
struct Clocks {
    /// The last emergency question.
    emergency_poll: Instant,
    /// The blocking slot had its step since the last FIFO exchange.
    slot_waited: bool,
    /// FIFO exchanges in a row that went first while a transaction waited.
    slot_skipped: u32,
    /// When the last transaction ended: a client that asks one after
    /// another (a script, a loop of SDO reads) sends the next within tens
    /// of us, and a FIFO exchange that is only due, not pressing, lets it
    /// go first for one exchange time (see `fifo_first`).
    slot_freed: Option<Instant>,
}

impl<'a, L: Link> Running<'a, L> {
    /// A run starts at `now`: the rules start over, and a FIFO error bit
    /// left from before (a fault, the bring-up) is cleared.
    fn start(core: &'a mut Core<L>, cyclic: Option<&Cyclic>, now: Instant) -> Self {
        let slaves = core.layout.lock().unwrap_or_else(|e| e.into_inner()).slaves.len();
        let shape = RunShape {
            slaves,
            cyclic: cyclic.is_some(),
            has_outputs: cyclic.is_some_and(|c| c.rx_size > 0),
            flow_limit: cyclic.map_or(Duration::ZERO, |c| flow_limit(c.cycle())),
        };
        let supervisor = Supervisor::new(shape, core.port.status().wkc_errors, now);
        core.telemetry.int0_stuck.store(false, Relaxed);
        core.telemetry.stall_excused.store(false, Relaxed);
        core.port.pending_control |= ControlFlags::CLEAR_FIFO_ERROR;
        if let Some(c) = cyclic {
            core.intake.start(c, &core.telemetry, now);
        }
        let fetch = FetchRule::new(core.config.cycle.fifo_reads, link_errors(core));
        Self { core, supervisor, held_below_target: false, slaves, fetch }
    }

    /// Runs the network until a fault, a client's action or a stop.
    fn run(mut self, cyclic: Option<&mut Cyclic>, now: Instant) -> Exit {
        let mut cyclic = cyclic;
        let mut clocks = Clocks { emergency_poll: now, slot_waited: false, slot_skipped: 0, slot_freed: None };
        let exit = loop {
            if let Err(exit) = self.turn(&mut cyclic, &mut clocks) {
                break exit;
            }
        };
        match exit {
            Exit::Recover(why) => Exit::Recover(explain::explained(self.core, why, self.slaves)),
            stop => stop,
        }
    }

    /// One turn of the running loop; `Err` ends the run.
    fn turn(&mut self, cyclic: &mut Option<&mut Cyclic>, clocks: &mut Clocks) -> Result<(), Exit> {
        self.take_client_input(cyclic)?;
        let now = Instant::now();
        if let Some(c) = cyclic.as_deref_mut() {
            self.settle_fifo(c, now)?;
        }
        self.count_slaves(now)?;
        self.ask_emergencies(cyclic.as_deref(), clocks, now)?;
        let progressed = match cyclic.as_deref_mut() {
            Some(c) if self.fifo_first(c, clocks, now) => {
                if self.slot_waits() {
                    clocks.slot_skipped += 1;
                }
                self.fifo_exchange(c, now)?;
                clocks.slot_waited = false;
                true
            }
            _ => {
                clocks.slot_waited = true;
                clocks.slot_skipped = 0;
                self.transaction_step(clocks, now)?
            }
        };
        // A transaction's packet or the emergency question may have brought
        // a FIFO answer: its inputs go out now, not after the idle wait.
        if let Some(c) = cyclic.as_deref_mut() {
            self.settle_fifo(c, Instant::now())?;
        }
        self.check_emergencies()?;
        self.watch_flow(cyclic.is_some(), Instant::now())?;
        self.watch_header(Instant::now())?;
        if !progressed {
            self.idle(cyclic, clocks)?;
        }
        Ok(())
    }

    /// Requests, output writes, the last writer leaving, a new
    /// configuration, a re-init or warm reset.
    fn take_client_input(&mut self, cyclic: &mut Option<&mut Cyclic>) -> Result<(), Exit> {
        if !self.take_commands() {
            return Err(self.safe_stop(cyclic.as_deref_mut()));
        }
        while let Ok(w) = self.core.outputs.try_recv() {
            if let Some(written) = self.core.assembler.push(w, cyclic.as_deref_mut().map(|c| c.outputs.as_mut_slice()))
            {
                // The oldest write not yet on its way to the wire.
                self.core.unplayed_write.get_or_insert(written);
            }
        }
        self.core.frames.retain(|f| !f.finished());
        if self.core.writers.take_gone() {
            outputs_gone::last_writer_gone(self.core, cyclic.as_deref_mut());
        }
        if self.core.take_new_config() {
            return Err(Exit::Recover(RecoverCause::NewConfig));
        }
        match self.core.action.take() {
            Some(NetworkAction::Reinit) => Err(Exit::Recover(RecoverCause::ReinitRequested)),
            Some(NetworkAction::WarmReset) => {
                // The chip resets at once; its answer may never come.
                let _ = self.core.port.call(&WarmReset);
                Err(Exit::Recover(RecoverCause::WarmResetRequested))
            }
            None => Ok(()),
        }
    }

    /// Counts the slaves every `supervisor::CENSUS` while the slot is idle:
    /// slaves plugged in or out change the count the chip sees.
    fn count_slaves(&mut self, now: Instant) -> Result<(), Exit> {
        // Between transactions, queued ones or not: a busy slot (16 SDO
        // clients) must not keep a replugged slave unseen.
        if self.core.active.is_none() && self.supervisor.census_due(now) {
            let count = self.core.port.call(&SlaveCountGet)?.header.return_value;
            self.supervisor.census(usize::from(count), now)?;
            self.watch_int0();
        }
        Ok(())
    }

    /// INT0's edges since the last census (see `supervisor::Int0Watch`):
    /// a line stuck at its ready level degrades the health, logged once.
    /// The hardware link reads the edge events queued in the kernel (one
    /// poll and a read a second); a link that cannot count them is not
    /// judged.
    fn watch_int0(&mut self) {
        let edges = match self.core.port.link_mut().int0_edges() {
            Ok(e) => e,
            Err(e) => {
                tracing::debug!(error = %e, "INT0 edges not readable");
                None
            }
        };
        let exchanges = self.core.port.stats().exchanges;
        match self.supervisor.int0.census(edges, exchanges) {
            Some(true) => warn!(
                exchanges,
                "INT0 has not moved across {} exchanges: it stays at its ready level, so the chip's busy time is \
                 not seen (check link.int0_line, its wiring and chip.int0_active_high; `ecmxfd probe`, step 2)",
                INT0_SILENT_EXCHANGES
            ),
            Some(false) => info!("INT0 moves again"),
            None => {}
        }
        self.core.telemetry.int0_stuck.store(self.supervisor.int0.stuck(), Relaxed);
    }

    /// Keeps the emergency question going: an answer no exchange has
    /// brought yet is fetched with a status exchange; a new question is
    /// asked every `emergencies::POLL` while the slot is idle (during a
    /// transaction, it stands in for one of its polls: see
    /// `transaction_step`).
    fn ask_emergencies(&mut self, cyclic: Option<&Cyclic>, clocks: &mut Clocks, now: Instant) -> Result<(), Exit> {
        let since = now.saturating_duration_since(clocks.emergency_poll);
        if self.core.emergencies.asked() && self.core.active.is_none() && since >= emergencies::ANSWER_WAIT {
            self.core.port.send_once(&InfoUpdate)?;
            self.check_emergencies()?;
        }
        // With cyclic data the question goes out just before a FIFO
        // exchange, whose first packet brings its answer: one exchange per
        // question, none to fetch it (unless no FIFO exchange came for
        // `emergencies::POLL_LONGEST`).
        let rides = cyclic.is_none_or(|c| self.fifo_due(c, now)) || since >= emergencies::POLL_LONGEST;
        // Not while a client's next transaction is likely on its way (see
        // `Clocks::slot_freed`): it would wait for the question.
        let lingering = self.lingering(clocks, now);
        if self.core.active.is_none() && self.core.queue.is_empty() && since >= emergencies::POLL && rides && !lingering
        {
            self.poll_emergencies(&mut clocks.emergency_poll, now)?;
        }
        Ok(())
    }

    /// Input frames must keep coming (a deliberate hold below the target
    /// state excuses them); the first one makes the engine "running".
    fn watch_flow(&mut self, cyclic: bool, now: Instant) -> Result<(), Exit> {
        if let Some(stall) = self.supervisor.take_stall(self.held_below_target, now) {
            if let RecoverCause::InputStall { age, .. } = &stall {
                let age_us = age.as_micros() as u64;
                if self.core.telemetry.claim_stall_notice() {
                    self.core.events.emit(EventKind::ProcessData { flowing: false, age_us });
                }
            }
            return Err(stall.into());
        }
        if cyclic && self.core.telemetry.phase() != Phase::Running && self.supervisor.flowed() {
            // Running means process data flows: said at the first frame,
            // and so is the end of a recovery.
            self.core.set_phase(Phase::Running);
            recovering::recovered(self.core);
        }
        Ok(())
    }

    /// Publishes the last answer's header and judges it (see
    /// [`Supervisor::header`]); a RxFIFO that ran dry is an alarm.
    fn watch_header(&mut self, now: Instant) -> Result<(), Exit> {
        let h = *self.core.port.status();
        self.core.publish_status(now);
        let news = self.supervisor.header(&h, self.held_below_target, now)?;
        if news.ran_dry {
            // Logged with the event (one line, not two).
            self.core.telemetry.fifo_alarms.fetch_add(1, Relaxed);
            self.core.telemetry.recent_fifo_alarms.record(self.core.intake.ns(now), 1, 0);
            self.core.events.emit(EventKind::FifoUnderrun);
        }
        if news.clear_fifo_error {
            self.core.port.pending_control |= ControlFlags::CLEAR_FIFO_ERROR;
        }
        Ok(())
    }

    /// Nothing progressed: waits until the next exchange, transaction poll
    /// or emergency question is due, or a command arrives.
    fn idle(&mut self, cyclic: &mut Option<&mut Cyclic>, clocks: &Clocks) -> Result<(), Exit> {
        let now = Instant::now();
        let wake = match cyclic.as_deref() {
            Some(c) if self.lingering(clocks, now) => {
                let linger_end = clocks.slot_freed.map_or(now, |t| t + self.core.port.exchange_time());
                c.next_exchange(now, self.rx_room(c), self.tx_room(c)).max(linger_end)
            }
            Some(c) => c.next_exchange(now, self.rx_room(c), self.tx_room(c)),
            None => now + IDLE,
        };
        // With cyclic data the question waits for a FIFO exchange (see
        // `ask_emergencies`): the FIFO's wake time covers it.
        let ask_every = if cyclic.is_some() { emergencies::POLL_LONGEST } else { emergencies::POLL };
        let emergency =
            clocks.emergency_poll + if self.core.emergencies.asked() { emergencies::ANSWER_WAIT } else { ask_every };
        let until = match &self.core.active {
            Some(a) => wake.min(a.next_poll()),
            None => wake.min(emergency),
        };
        // An answer no exchange has brought is fetched in time.
        let fetch = cyclic.as_deref().and_then(Cyclic::newest_in_flight).map(|f| FetchRule::fetch_at(f.sent_at));
        let until = fetch.map_or(until, |f| until.min(f));
        if let Some(c) = self.idle_until(until) {
            match self.core.take(c) {
                Taken::Job(j) => self.core.queue.push(j),
                Taken::Stop => return Err(self.safe_stop(cyclic.as_deref_mut())),
                Taken::Kept => {}
            }
        }
        Ok(())
    }

    /// Waits until `until` or the next command. The last `spin_us` of a
    /// wait are spent yielding, not sleeping (see [`RealtimeConfig`]), but
    /// never more than half of it: at 125 us the FIFO calls come about
    /// every millisecond, so a 2000 us spin never slept, and a SCHED_FIFO
    /// thread that never sleeps is stopped by the kernel's real-time
    /// throttling (`sched_rt_runtime_us`, 950 ms a second by default) for
    /// the rest of each second: 21 ms with no exchange, the RxFIFO dry at a
    /// 20 ms budget (`ecmxf-latency-bench --rt`, 6 underruns in 20 s).
    ///
    /// [`RealtimeConfig`]: crate::config::RealtimeConfig
    fn idle_until(&mut self, until: Instant) -> Option<Command> {
        let wait = until.saturating_duration_since(Instant::now());
        let spin = Duration::from_micros(self.core.config.realtime.spin_us.into()).min(wait / 2);
        loop {
            let now = Instant::now();
            let left = until.checked_duration_since(now).filter(|d| !d.is_zero())?;
            if left > spin {
                match self.core.commands.recv_timeout(left - spin) {
                    Ok(c) => return Some(c),
                    Err(RecvTimeoutError::Disconnected) => return Some(Command::Stop),
                    Err(RecvTimeoutError::Timeout) => {}
                }
            } else {
                match self.core.commands.try_recv() {
                    Ok(c) => return Some(c),
                    Err(TryRecvError::Disconnected) => return Some(Command::Stop),
                    Err(TryRecvError::Empty) => std::thread::yield_now(),
                }
            }
        }
    }

    fn rx_room(&self, c: &Cyclic) -> usize {
        self.core.port.data_size().checked_div(c.rx_size).unwrap_or(0)
    }

    /// Input frames one exchange should read: a packet's worth, and at most
    /// half the TxFIFO, so small input frames (many to a packet) are read
    /// before the chip has to drop any.
    fn tx_room(&self, c: &Cyclic) -> usize {
        let per_packet = self.core.port.data_size() / c.tx_size.max(1);
        per_packet.min(usize::from(c.tx_depth / 2).max(1))
    }

    /// Whether a transaction is in the slot or queued for it.
    fn slot_waits(&self) -> bool {
        self.core.active.is_some() || !self.core.queue.is_empty()
    }

    /// Whether this turn is the FIFO's (the rules: `link_turn`).
    fn fifo_first(&self, c: &Cyclic, clocks: &Clocks, now: Instant) -> bool {
        let exchange = self.core.port.exchange_time();
        let slot = match (&self.core.active, self.slot_on_chip()) {
            (Some(a), Some(true)) => {
                Slot::Runs { pulled: a.polled() || c.last_exchange().is_some_and(|t| t >= a.began_at()) }
            }
            (Some(_), Some(false)) => Slot::WantsLink,
            (Some(_), None) => Slot::Other { had_turn: clocks.slot_waited },
            (None, _) if !self.core.queue.is_empty() => Slot::Queued,
            (None, _) => Slot::Empty { just_freed: self.lingering(clocks, now) },
        };
        let fifo = Fifo {
            due: self.fifo_due(c, now),
            due_soon: self.fifo_due(c, now + exchange * PULL_FORWARD),
            // Behind its aim or near its floor, whichever comes first (a
            // shallow FIFO's floor is less than two packets below its aim).
            pressing: c.outputs_low(now)
                || c.outputs_behind(now, self.rx_room(c))
                || c.inputs_pressing(now, self.tx_room(c)),
        };
        fifo_goes_first(fifo, slot, clocks.slot_skipped)
    }

    /// Whether a transaction ended less than an exchange ago (see
    /// `Clocks::slot_freed`).
    fn lingering(&self, clocks: &Clocks, now: Instant) -> bool {
        clocks.slot_freed.is_some_and(|t| now < t + self.core.port.exchange_time())
    }

    /// What the newest header says of the slot's blocking command (see
    /// `Active::on_chip`).
    fn slot_on_chip(&self) -> Option<bool> {
        self.core.active.as_ref()?.on_chip(&self.core.port)
    }

    fn fifo_due(&self, c: &Cyclic, now: Instant) -> bool {
        now >= c.next_exchange(now, self.rx_room(c), self.tx_room(c)) || c.outputs_low(now)
    }

    /// One FIFO call: pushes the output frames the level needs and reads
    /// the input frames waiting. Its answer is fetched at once (guarded) or
    /// left for the next exchange to bring (pipelined), as `fifo_reads`
    /// decides; the turn's `settle_fifo` takes it either way. Sent pipelined, a
    /// corrupt answer loses its batch (40% of them at a bit error rate of
    /// 1e-3 when every call went so, hence guarded after any error). The
    /// count in the answer is the RxFIFO level just before this push
    /// (v049: an answer reports the level of the packet before, see the
    /// simulator's `note_fifo_levels`).
    fn fifo_exchange(&mut self, c: &mut Cyclic, now: Instant) -> Result<(), PortError> {
        if let Some(last) = c.last_exchange() {
            let gap = now.saturating_duration_since(last).as_micros() as u64;
            self.core.telemetry.max_fifo_gap_us.fetch_max(gap, Relaxed);
            // Longer than the process-data limit: inputs were that stale
            // for a moment though no stall is left to see afterwards.
            let limit_ns = self.core.telemetry.flow_limit_ns.load(Relaxed);
            if limit_ns > 0 && gap.saturating_mul(1000) > limit_ns {
                self.core.telemetry.recent_long_gaps.record(self.core.intake.ns(now), 1, gap);
            }
        }
        let room = self.core.port.data_size().checked_div(c.rx_size).unwrap_or(0);
        let n = if c.rx_size > 0 { c.frames_to_push(now, room) } else { 0 };
        let guarded = self.fetch.guarded(link_errors(self.core), !self.core.frames.is_empty(), now);
        // Borrowed, not copied: this runs thousands of times a second.
        let mut op = FifoOpFlags::empty();
        op.set(FifoOpFlags::WRITE, c.rx_size > 0);
        op.set(FifoOpFlags::READ, c.tx_size > 0);
        // The first frame pushed now plays after the ones queued before it.
        let ahead = c.estimate(now).max(0) as u32;
        // Right behind the last call, this one's counts come from before it.
        let after_call = c.last_index().is_some_and(|i| self.core.port.ran_last(i, CommandCode::PdoDataFifoOp));
        // The packet before this one: the chip notes its counts as it arrives.
        let counted_at = self.core.port.last_began().unwrap_or(now);
        let outputs = c.push_frames(n, &mut self.core.frames);
        let req = PdoFifoOp { op, frames: n, outputs };
        let index = self.core.port.send_pipelined(&req)?;
        c.sent(InFlight { index, sent_at: now, pushed: n, after_call, counted_at });
        if guarded {
            self.core.port.fetch_pipelined(index, CommandCode::PdoDataFifoOp)?;
        }
        if n > 0 {
            if let Some(written) = self.core.unplayed_write.take() {
                let on_wire = now + c.cycle() * ahead;
                self.output_latency(on_wire.saturating_duration_since(written), now);
            }
        }
        // Its answer (fetched) and the one before it (brought by this
        // call's exchange) are taken by the turn's `settle_fifo` next.
        Ok(())
    }

    /// Takes what became of the FIFO calls sent, oldest first (see
    /// `fifo_reads`): an answer that arrived, a call the chip refused, an
    /// answer lost; one no exchange has brought is fetched once its time
    /// is up.
    fn settle_fifo(&mut self, c: &mut Cyclic, now: Instant) -> Result<(), PortError> {
        const CODE: CommandCode = CommandCode::PdoDataFifoOp;
        while let Some(call) = c.oldest_in_flight() {
            let port = &mut self.core.port;
            let fate = match port.pipelined(call.index, CODE).map(|p| p.fate) {
                Some(Fate::Waiting) if port.is_last_sent(call.index, CODE) => {
                    if now < FetchRule::fetch_at(call.sent_at) {
                        return Ok(());
                    }
                    port.fetch_pipelined(call.index, CODE)?;
                    continue;
                }
                Some(fate) => fate,
                // Not followed any more (a recovery's search clocked raw
                // bytes): nothing can fetch it now.
                None => Fate::Lost,
            };
            match fate {
                Fate::Answered => self.fifo_answered(c, call, now),
                Fate::Refused => c.refused(call.index),
                Fate::Waiting | Fate::Lost => {
                    c.lost(call.index);
                    self.core.telemetry.input_batches_lost.fetch_add(1, Relaxed);
                    self.core.telemetry.output_frames.fetch_add(u64::from(call.pushed), Relaxed);
                    self.fetch.answer_lost(now);
                }
            }
            self.core.port.forget_pipelined(call.index, CODE);
        }
        Ok(())
    }

    /// The answer to FIFO call `call` arrived: input frames out, their
    /// freshness noted and judged (a network without inputs counts the
    /// answer itself as the sign of life), the plan told.
    fn fifo_answered(&mut self, c: &mut Cyclic, call: InFlight, now: Instant) {
        let Some(p) = self.core.port.pipelined(call.index, CommandCode::PdoDataFifoOp) else { return };
        let Some(a) = p.answer else { return };
        let asked = PdoFifoOp { op: FifoOpFlags::empty(), frames: 0, outputs: &[] };
        let inputs = a.answer_to(&asked).map(|reply| reply.inputs);
        let frames = inputs.map_or(0, |i| i.len().checked_div(c.tx_size).unwrap_or(0));
        let counts =
            Counts { count: a.header.rx_fifo_count, waiting: a.header.tx_fifo_count, read: frames, resends: p.resends };
        // Input frames the chip dropped, or that went with a lost answer,
        // are numbered as a gap before them, so `seq` keeps counting DC
        // cycles.
        let mut read = 0;
        if let Ok(inputs) = inputs {
            let lost = if c.tx_size > 0 { c.inputs_lost(call.index, counts) } else { 0 };
            if lost > 0 {
                self.core.intake.inputs.lost(lost);
                self.core.telemetry.inputs_dropped_by_chip.fetch_add(lost, Relaxed);
                self.core.telemetry.recent_chip_drops.record(self.core.intake.ns(now), lost, 0);
            }
            read = self.core.intake.inputs.publish(inputs, c.tx_size, now);
            self.core.telemetry.input_frames.fetch_add(read as u64, Relaxed);
            if self.supervisor.fifo_answer(read, c.tx_size > 0, now) {
                self.core.telemetry.newest_input_ns.store(self.core.intake.ns(now), Relaxed);
            }
        }
        c.answered(call.index, Counts { read, ..counts }, now);
        self.core.telemetry.output_frames.fetch_add(u64::from(call.pushed), Relaxed);
        if !self.core.frames.is_empty() {
            outputs_gone::frames_played(self.core, c.tx_size > 0, read, counts.waiting, counts.count);
        }
        if let Some(t) = &self.core.distributor {
            t.unpark();
        }
    }

    /// A client's write reaches the wire `latency` after it reached the
    /// daemon: into the window the API reads, and against the budget.
    fn output_latency(&mut self, latency: Duration, now: Instant) {
        let us = latency.as_micros().min(u128::from(u32::MAX)) as u32;
        self.core.telemetry.output_latency.record(us);
        if let Some(budget) = self.core.config.cycle.output_latency_us {
            if us > budget {
                self.core.telemetry.output_latency_misses.fetch_add(1, Relaxed);
                self.core.events.output_late(budget, us, now);
            }
        }
    }

    /// Looks at the answer to an emergency question, once an exchange has
    /// brought it, and emits what is new.
    fn check_emergencies(&mut self) -> Result<(), PortError> {
        let events = &mut self.core.events;
        self.core.emergencies.check(&mut self.core.port, |r| events.emit(EventKind::Emergency(r)))
    }

    /// Asks for the newest CoE emergency (see `emergencies`); the answer is
    /// looked at after the next exchange.
    fn poll_emergencies(&mut self, last: &mut Instant, now: Instant) -> Result<(), PortError> {
        *last = now;
        self.core.emergencies.ask(&mut self.core.port)
    }

    /// One step of the transaction on the blocking slot (taking the next
    /// job when the slot is free). True when it sent something worth not
    /// idling for.
    fn transaction_step(&mut self, clocks: &mut Clocks, now: Instant) -> Result<bool, PortError> {
        if self.core.active.is_none() {
            while let Some(j) = self.core.queue.pop() {
                if let SlotRequest::SetState { state, .. } = &j.request {
                    self.held_below_target = state.to_u8() < self.core.config.cycle.target().to_u8();
                    self.core.telemetry.stall_excused.store(self.held_below_target, Relaxed);
                }
                if let Some(a) = Active::new(j, now, &self.core.telemetry, &self.core.poll_pace) {
                    self.core.active = Some(a);
                    break;
                }
            }
        }
        let Some(active) = self.core.active.take() else {
            return Ok(false);
        };
        let exchanges = self.core.port.stats().exchanges;
        let since = now.saturating_duration_since(clocks.emergency_poll);
        let poll_due = active.on_chip(&self.core.port) == Some(true) && active.next_poll() <= now;
        if active.may_lend_an_exchange(&self.core.port)
            && ((poll_due && since >= emergencies::POLL) || since >= emergencies::POLL_LONGEST)
        {
            // A poll is due and so is the emergency question: it is the
            // poll (its answer refreshes the busy bit like any other). A
            // question overdue takes any step's exchange (its own brings
            // whatever answer the transaction waits for, which it reads
            // by index), so emergencies are seen under a steady load of
            // transactions however short their polls (EEPROM reads).
            self.core.active = Some(active);
            self.poll_emergencies(&mut clocks.emergency_poll, now)?;
            return Ok(true);
        }
        let (rest, progress) = active.step(&mut self.core.port, now)?;
        self.core.active = rest;
        if progress == Progress::Done {
            clocks.slot_freed = Some(Instant::now());
        }
        let sent = self.core.port.stats().exchanges != exchanges;
        Ok(sent && progress != Progress::Waiting)
    }

    /// Takes new requests; false when told to stop.
    fn take_commands(&mut self) -> bool {
        loop {
            match self.core.commands.try_recv().map(|c| self.core.take(c)) {
                Ok(Taken::Job(j)) => self.core.queue.push(j),
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
        self.core.port.set_ready_timeout(self.core.config.ready_timeout().min(Duration::from_millis(200)));
        self.core.set_phase(Phase::Stopping);
        info!("safe stop");
        for n in 0..self.core.config.axes.len() {
            let _ = self.core.port.call(&Cia402StateSet { axis: n as u8, state: Cia402State::SwitchOnDisabled });
        }
        if let Some(c) = cyclic {
            // Let the helper walk the axes down while outputs keep flowing.
            let until = Instant::now() + Duration::from_millis(50);
            while Instant::now() < until {
                let now = Instant::now();
                if self.fifo_exchange(c, now).and_then(|()| self.settle_fifo(c, now)).is_err() {
                    break;
                }
                std::thread::sleep(Duration::from_micros(500));
            }
            let _ = self.core.port.call(&FifoEnable(false));
        }
        for state in [EcatState::SafeOp, EcatState::Init] {
            if let Err(e) = bringup::blocking(
                &mut self.core.port,
                &StateCheck { target: SlaveSelector::All, state },
                Duration::from_millis(400),
            ) {
                warn!(error = %e, %state, "safe stop");
            }
        }
        self.core.publish_status(Instant::now());
        Exit::Stop
    }
}

/// The link errors counted so far (see `fifo_reads::LinkErrors`).
fn link_errors<L: Link>(core: &Core<L>) -> LinkErrors {
    LinkErrors { corrupt: core.port.stats().corrupt, refused: core.port.status().crc_errors }
}
