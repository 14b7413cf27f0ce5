//! Supervision events: what changed on the chip or the network, for
//! diagnostics clients and logs. The engine thread only compares each
//! answer's header with the previous one and pushes into a wait-free ring
//! (no lock shared with async code); the distributor thread forwards to
//! subscribers.
//!
//! Counters that can rise every cycle during a fault (CRC errors, WKC
//! errors) are reported at most every [`COUNTER_QUIET`], with the total
//! since the daemon started (it never goes down: see
//! `telemetry::CounterTotal`), so a fault cannot flood the ring. Events
//! that do not fit are counted and reported as [`EventKind::Lost`] once
//! there is room.
//!
//! Every event reads as a sentence ([`EventKind`]'s `Display`, the API's
//! `Event.text`) and has a stable one-word name ([`EventKind::name`]); the
//! log gets both, plus the event's numbers as fields ([`Event::log`]).

use std::thread::Thread;
use std::time::{Duration, Instant};

use ecmxf_wire::flags::{ErrorFlags, StatusFlags};
use ecmxf_wire::payload::emergency::EmergencyRecord;
use ecmxf_wire::{EcatState, ResponseHeader};

use super::failure::Failure;
use super::supervisor::RecoverCause;
use super::telemetry::Phase;
use crate::config::WriterGoneAction;

/// Shortest interval between two reports of the same counter.
pub(crate) const COUNTER_QUIET: Duration = Duration::from_millis(100);
/// Events the ring holds before the oldest unread are lost.
pub(crate) const RING: usize = 256;

/// One event.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Event {
    /// When, ns since the engine started.
    pub time_ns: u64,
    /// What.
    pub kind: EventKind,
}

/// What happened.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum EventKind {
    /// The engine entered a phase (bring-up, running, recovering...).
    Phase(Phase),
    /// The network's EtherCAT state as the chip reports it changed.
    EcatState {
        /// Before.
        from: EcatState,
        /// Now.
        to: EcatState,
    },
    /// The chip's LINK pin changed (error byte bit0; its polarity depends on
    /// the board).
    LinkPin(bool),
    /// The DC cycle became stable (true) or lost stability (status bit2).
    DcStable(bool),
    /// The chip counted packets with bad check words.
    CrcErrors {
        /// CRC errors since the daemon started (never wraps).
        total: u64,
    },
    /// The chip counted cycles with a wrong working counter.
    WkcErrors {
        /// WKC errors since the daemon started (never wraps).
        total: u64,
    },
    /// A slave reports an AL status code (read when the network left its
    /// state or reported an error).
    AlStatus {
        /// Ring position.
        slave: u8,
        /// The slave's state.
        state: EcatState,
        /// The AL status code (ETG.1000.6 table 11; 0x001A: synchronisation
        /// error...).
        code: u16,
    },
    /// Process data stopped flowing (no input frame for longer than the
    /// limit), or flows again.
    ProcessData {
        /// Flowing now.
        flowing: bool,
        /// How long no input frame had arrived, us (0 when flowing again).
        age_us: u64,
    },
    /// The RxFIFO ran dry: the slaves got repeated outputs.
    FifoUnderrun,
    /// Bring-up failed; the reason.
    BringUpFailed(Failure),
    /// A fault was seen; recovery starts. Why.
    Recovering(RecoverCause),
    /// The last output writer went away and this was done.
    LastWriterGone(WriterGoneAction),
    /// The network is back after a fault: every configured axis came up
    /// disabled (restart interlock: a client must enable it again), and
    /// the outputs are as the policy says (hold-last and quick-stop: the
    /// image the lease holders last wrote; zero: zeros).
    Recovered {
        /// Axes held disabled.
        axes_disabled: usize,
        /// The outputs policy applied.
        outputs: WriterGoneAction,
    },
    /// A CoE emergency the chip received (read within
    /// `emergencies::POLL_LONGEST` and one exchange; the event's time is
    /// when it was read).
    Emergency(EmergencyRecord),
    /// A client's write reached the wire later than
    /// `cycle.output_latency_us` allows (told at most every
    /// `COUNTER_QUIET`): the host stalled longer than the FIFO's margin.
    OutputLate {
        /// The budget, us.
        budget_us: u32,
        /// The write's latency, us.
        latency_us: u32,
    },
    /// A client's per-cycle frame queue ran dry while its stream was open
    /// (the client sent too slowly): the policy `action` applies until
    /// frames come again.
    FramesDry {
        /// Frames taken from the queue before it ran dry.
        pushed: u64,
        /// `outputs.on_last_writer_gone`, applied to the stream's range.
        action: WriterGoneAction,
    },
    /// Events dropped because no one read them in time.
    Lost(u64),
}

impl EventKind {
    /// The kind as one stable word (the log's `event` field).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Phase(_) => "phase",
            Self::EcatState { .. } => "state_change",
            Self::LinkPin(_) => "link",
            Self::DcStable(_) => "dc_stable",
            Self::CrcErrors { .. } => "crc_errors",
            Self::WkcErrors { .. } => "wkc_errors",
            Self::AlStatus { .. } => "al_status",
            Self::ProcessData { .. } => "process_data",
            Self::FifoUnderrun => "fifo_underrun",
            Self::BringUpFailed(_) => "bring_up_failed",
            Self::Recovering(_) => "recovering",
            Self::LastWriterGone(_) => "last_writer_gone",
            Self::Recovered { .. } => "recovered",
            Self::Emergency(_) => "emergency",
            Self::OutputLate { .. } => "output_late",
            Self::FramesDry { .. } => "frames_dry",
            Self::Lost(_) => "lost",
        }
    }

    /// Whether the event says something went wrong (logged as a warning).
    pub fn is_fault(&self) -> bool {
        match self {
            Self::AlStatus { .. }
            | Self::FifoUnderrun
            | Self::BringUpFailed(_)
            | Self::Recovering(_)
            | Self::Emergency(_)
            | Self::OutputLate { .. }
            | Self::FramesDry { .. }
            | Self::Lost(_) => true,
            Self::ProcessData { flowing, .. } => !flowing,
            Self::EcatState { to, .. } => *to == EcatState::Error,
            _ => false,
        }
    }
}

/// What the outputs are after the policy, in words.
fn outputs_text(a: WriterGoneAction) -> &'static str {
    match a {
        WriterGoneAction::HoldLast => "held at the last written values",
        WriterGoneAction::Zero => "zeroed",
        WriterGoneAction::QuickStop => "held, axes quick-stopped",
    }
}

impl std::fmt::Display for EventKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Phase(p) => write!(f, "engine {}", p.name()),
            Self::EcatState { from, to } => write!(f, "network state {from} -> {to}"),
            Self::LinkPin(v) => write!(f, "LINK pin {}", if *v { "high" } else { "low" }),
            Self::DcStable(true) => f.write_str("DC cycle stable"),
            Self::DcStable(false) => f.write_str("DC cycle lost stability"),
            Self::CrcErrors { total } => write!(f, "SPI check-word errors: {total} since start"),
            Self::WkcErrors { total } => write!(f, "working-counter errors: {total} since start"),
            Self::AlStatus { slave, state, code } => {
                write!(f, "slave {slave} in {state}: AL status {code:#06x} ({})", ecmxf_wire::al_status_text(*code))
            }
            Self::ProcessData { flowing: true, .. } => f.write_str("process data flowing again"),
            Self::ProcessData { flowing: false, age_us } => {
                write!(f, "process data stalled: no input frame for {} ms", age_us / 1000)
            }
            Self::FifoUnderrun => f.write_str("RxFIFO ran dry: slaves got repeated outputs"),
            Self::BringUpFailed(why) => write!(f, "bring-up failed: {why}"),
            Self::Recovering(why) => write!(f, "recovering: {why}"),
            Self::LastWriterGone(a) => write!(f, "last output writer gone: outputs {}", outputs_text(*a)),
            Self::Recovered { axes_disabled, outputs } => write!(
                f,
                "network back after a fault: {axes_disabled} axes disabled until enabled again, outputs {}",
                match outputs {
                    WriterGoneAction::Zero => "zeroed",
                    _ => "as last written",
                }
            ),
            Self::Emergency(r) => write!(
                f,
                "emergency {:#06x} from slave {} (error register {:#04x})",
                r.error_code, r.slave, r.error_register
            ),
            Self::OutputLate { budget_us, latency_us } => write!(
                f,
                "output write reached the wire after {latency_us} us, over the {budget_us} us budget by {} us",
                latency_us.saturating_sub(*budget_us)
            ),
            Self::FramesDry { pushed, action } => write!(
                f,
                "the client's frame queue ran dry after {pushed} frames: outputs {} until frames come again",
                outputs_text(*action)
            ),
            Self::Lost(n) => write!(f, "{n} events lost (no one read them in time)"),
        }
    }
}

impl Event {
    /// Logs the event: its sentence, its name as `event`, its time and its
    /// numbers as fields (journald keeps them as fields of their own).
    pub fn log(&self) {
        let (event, t_ms) = (self.kind.name(), self.time_ns / 1_000_000);
        macro_rules! log {
            ($($field:tt)*) => {
                if self.kind.is_fault() {
                    tracing::warn!(event, t_ms, $($field)* "{}", self.kind)
                } else {
                    tracing::info!(event, t_ms, $($field)* "{}", self.kind)
                }
            };
        }
        match &self.kind {
            EventKind::CrcErrors { total } | EventKind::WkcErrors { total } => log!(total = *total,),
            EventKind::AlStatus { slave, code, .. } => log!(slave = *slave, al_status = *code,),
            EventKind::Emergency(r) => log!(slave = r.slave, error_code = r.error_code,),
            EventKind::ProcessData { flowing, age_us } => log!(flowing = *flowing, age_us = *age_us,),
            EventKind::Recovering(why) => log!(cause = why.name(),),
            EventKind::Recovered { axes_disabled, .. } => log!(axes_disabled = *axes_disabled,),
            EventKind::Lost(n) => log!(lost = *n,),
            EventKind::FramesDry { pushed, .. } => log!(pushed = *pushed,),
            EventKind::OutputLate { budget_us, latency_us } => log!(budget_us = *budget_us, latency_us = *latency_us,),
            _ => log!(),
        }
    }
}

/// How long without an alarm ends its spell.
pub(crate) const SPELL_QUIET: Duration = Duration::from_secs(1);

/// The daemon's log of events: each one as it comes, except an alarm that
/// repeats (the RxFIFO running dry): the first of a spell at once, then
/// one line when the spell ends (no alarm for `SPELL_QUIET`) saying how
/// many there were and for how long (logged one by one, a stall of a few
/// seconds once wrote thousands of WARN lines). API subscribers still get every event.
#[derive(Debug, Default)]
pub struct EventLog {
    spell: Option<Spell>,
}

#[derive(Clone, Copy, Debug)]
struct Spell {
    first_ms: u64,
    last_ms: u64,
    count: u64,
    ends: Instant,
}

impl EventLog {
    /// Logs `e`, received at `now`.
    pub fn log(&mut self, e: &Event, now: Instant) {
        if !matches!(e.kind, EventKind::FifoUnderrun) {
            e.log();
            return;
        }
        let t_ms = e.time_ns / 1_000_000;
        match &mut self.spell {
            Some(s) => {
                s.count += 1;
                s.last_ms = t_ms;
                s.ends = now + SPELL_QUIET;
            }
            None => {
                e.log();
                self.spell = Some(Spell { first_ms: t_ms, last_ms: t_ms, count: 1, ends: now + SPELL_QUIET });
            }
        }
    }

    /// When the open spell ends if no alarm comes (`None`: none open).
    pub fn spell_ends(&self) -> Option<Instant> {
        self.spell.map(|s| s.ends)
    }

    /// Ends the open spell: one line with its count, when there was more
    /// than the one already logged. Returns that count.
    pub fn end_spell(&mut self) -> u64 {
        let Some(s) = self.spell.take() else { return 0 };
        if s.count > 1 {
            let (count, over_ms) = (s.count, s.last_ms - s.first_ms);
            tracing::warn!(
                event = EventKind::FifoUnderrun.name(),
                count,
                over_ms,
                "RxFIFO ran dry {count} times in {over_ms} ms (the first is logged above)"
            );
        }
        s.count
    }
}

/// The engine side: detects changes and pushes events.
#[derive(Debug)]
pub(crate) struct EventSink {
    ring: rtrb::Producer<Event>,
    epoch: Instant,
    waker: Option<Thread>,
    seen: Option<Seen>,
    crc_reported: Option<Instant>,
    wkc_reported: Option<Instant>,
    late_reported: Option<Instant>,
    /// Totals last reported.
    crc_told: u64,
    wkc_told: u64,
    lost: u64,
}

/// What the previous header said.
#[derive(Clone, Copy, Debug)]
struct Seen {
    state: EcatState,
    link: bool,
    dc_stable: bool,
}

impl Seen {
    fn of(h: &ResponseHeader) -> Self {
        Self {
            state: h.ecat_state,
            link: h.errors.contains(ErrorFlags::LINK_PIN),
            dc_stable: h.status.flags.contains(StatusFlags::DC_STABLE),
        }
    }
}

impl EventSink {
    /// A sink into `ring`; `waker` is unparked after each push.
    pub(crate) fn new(ring: rtrb::Producer<Event>, epoch: Instant, waker: Option<Thread>) -> Self {
        Self {
            ring,
            epoch,
            waker,
            seen: None,
            crc_reported: None,
            wkc_reported: None,
            late_reported: None,
            crc_told: 0,
            wkc_told: 0,
            lost: 0,
        }
    }

    /// Pushes an event (counted as lost when the ring is full).
    pub(crate) fn emit(&mut self, kind: EventKind) {
        let time_ns = self.epoch.elapsed().as_nanos() as u64;
        if self.lost > 0 && self.ring.slots() >= 2 {
            let lost = std::mem::take(&mut self.lost);
            let _ = self.ring.push(Event { time_ns, kind: EventKind::Lost(lost) });
        }
        if self.ring.push(Event { time_ns, kind }).is_err() {
            self.lost += 1;
        }
        if let Some(w) = &self.waker {
            w.unpark();
        }
    }

    /// Compares an answer's header with the previous one; `totals` are the
    /// CRC and WKC error totals after it. A chip that answers NOP (just
    /// reset) has no meaningful state and is skipped.
    pub(crate) fn header(&mut self, h: &ResponseHeader, totals: (u64, u64), now: Instant) {
        if h.is_nop() {
            return;
        }
        let new = Seen::of(h);
        let (crc, wkc) = totals;
        let Some(old) = self.seen.replace(new) else {
            (self.crc_told, self.wkc_told) = (crc, wkc);
            return;
        };
        if new.state != old.state {
            self.emit(EventKind::EcatState { from: old.state, to: new.state });
        }
        if new.link != old.link {
            self.emit(EventKind::LinkPin(new.link));
        }
        if new.dc_stable != old.dc_stable {
            self.emit(EventKind::DcStable(new.dc_stable));
        }
        // A rise since the last report is news, told at most every
        // COUNTER_QUIET.
        if crc != self.crc_told && quiet(&mut self.crc_reported, now) {
            self.crc_told = crc;
            self.emit(EventKind::CrcErrors { total: crc });
        }
        if wkc != self.wkc_told && quiet(&mut self.wkc_reported, now) {
            self.wkc_told = wkc;
            self.emit(EventKind::WkcErrors { total: wkc });
        }
    }

    /// A write was late for the budget; told at most every
    /// [`COUNTER_QUIET`] (the misses are counted in the telemetry).
    pub(crate) fn output_late(&mut self, budget_us: u32, latency_us: u32, now: Instant) {
        if quiet(&mut self.late_reported, now) {
            self.emit(EventKind::OutputLate { budget_us, latency_us });
        }
    }

    /// Forgets the previous header (after a chip reset or re-init, the
    /// first header is a new baseline).
    pub(crate) fn rebase(&mut self) {
        self.seen = None;
    }
}

/// Whether a counter may be reported now; notes the report.
fn quiet(last: &mut Option<Instant>, now: Instant) -> bool {
    if last.is_some_and(|t| now.duration_since(t) < COUNTER_QUIET) {
        return false;
    }
    *last = Some(now);
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use ecmxf_wire::CommandCode;

    #[test]
    fn a_spell_of_underruns_is_one_line_then_one_count() {
        let mut log = EventLog::default();
        let t0 = Instant::now();
        let underrun = |ms: u64| Event { time_ns: ms * 1_000_000, kind: EventKind::FifoUnderrun };
        log.log(&Event { time_ns: 0, kind: EventKind::Lost(1) }, t0);
        assert_eq!(log.spell_ends(), None, "other events open no spell");
        for i in 0..5 {
            log.log(&underrun(10 + i * 45), t0 + Duration::from_millis(i * 45));
        }
        assert_eq!(log.spell_ends(), Some(t0 + Duration::from_millis(4 * 45) + SPELL_QUIET));
        assert_eq!(log.end_spell(), 5);
        assert_eq!(log.spell_ends(), None);
        // The next alarm opens a new spell, logged at once again.
        log.log(&underrun(5000), t0 + Duration::from_secs(5));
        assert_eq!(log.end_spell(), 1);
    }

    fn header(state: EcatState, crc: u8, link: bool) -> ResponseHeader {
        let mut h =
            ResponseHeader { code: CommandCode::InfoUpdate, ecat_state: state, crc_errors: crc, ..Default::default() };
        h.status.flags = StatusFlags::ETHERNET_READY;
        h.errors.set(ErrorFlags::LINK_PIN, link);
        h
    }

    fn drain(c: &mut rtrb::Consumer<Event>) -> Vec<EventKind> {
        std::iter::from_fn(|| c.pop().ok()).map(|e| e.kind).collect()
    }

    #[test]
    fn changes_become_events_and_repeats_do_not() {
        let (p, mut c) = rtrb::RingBuffer::new(RING);
        let mut s = EventSink::new(p, Instant::now(), None);
        let t = Instant::now();
        s.header(&header(EcatState::PreOp, 0, true), (0, 0), t);
        s.header(&header(EcatState::PreOp, 0, true), (0, 0), t);
        assert!(drain(&mut c).is_empty(), "the first header is the baseline");
        s.header(&header(EcatState::Op, 0, false), (0, 0), t);
        assert_eq!(
            drain(&mut c),
            [EventKind::EcatState { from: EcatState::PreOp, to: EcatState::Op }, EventKind::LinkPin(false)]
        );
    }

    #[test]
    fn counters_are_reported_at_most_every_quiet_interval() {
        let (p, mut c) = rtrb::RingBuffer::new(RING);
        let mut s = EventSink::new(p, Instant::now(), None);
        let t = Instant::now();
        s.header(&header(EcatState::Op, 0, true), (0, 0), t);
        for n in 1..=50u8 {
            s.header(&header(EcatState::Op, n, true), (n.into(), 0), t + Duration::from_millis(u64::from(n)));
        }
        assert_eq!(drain(&mut c), [EventKind::CrcErrors { total: 1 }]);
        s.header(&header(EcatState::Op, 50, true), (50, 0), t + Duration::from_millis(200));
        assert_eq!(drain(&mut c), [EventKind::CrcErrors { total: 50 }], "the rise is not forgotten");
    }

    #[test]
    fn a_full_ring_counts_what_it_lost() {
        let (p, mut c) = rtrb::RingBuffer::new(4);
        let mut s = EventSink::new(p, Instant::now(), None);
        for _ in 0..10 {
            s.emit(EventKind::FifoUnderrun);
        }
        assert_eq!(drain(&mut c).len(), 4);
        s.emit(EventKind::Phase(Phase::Running));
        assert_eq!(drain(&mut c), [EventKind::Lost(6), EventKind::Phase(Phase::Running)]);
    }
}
