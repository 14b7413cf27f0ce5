//! Keeping the chip's RxFIFO fed and its TxFIFO drained (v049
//! PDO_DATA_FIFO_OP): the chip consumes one output frame and produces one
//! input frame per DC cycle; running the RxFIFO dry in OP is the failure to
//! avoid.
//!
//! The header's FIFO counts are two exchanges late (vendor comment;
//! docs/protocol.md §12): the answer to a FIFO call, whichever exchange
//! brings it, reports the level just before the call's own push. The
//! estimate of the level therefore starts from that count, adds that push
//! and every one sent since (calls whose answers are still on their way,
//! see `engine::fifo_reads`), and takes off one frame per cycle elapsed.
//!
//! How deep the RxFIFO is kept is the trade between latency and margin: a
//! client's write reaches the wire after every frame queued before it has
//! played, one per cycle. Without a budget the level is held midway
//! between the configured marks; with `cycle.output_latency_us` it is held
//! at the shallowest level that meets the budget ([`Plan::budget`]), and
//! refilled before it falls to half of that.
//!
//! Input frames go on through [`super::inputs`]. Nothing here allocates or
//! locks once running.

use std::time::{Duration, Instant};

/// The longest time between two FIFO exchanges, whatever the marks allow:
/// inputs reach clients at least this often, so process data that stops
/// flowing is seen within a bounded time (see `supervisor::FlowWatch`).
pub(crate) const MAX_EXCHANGE_INTERVAL: Duration = Duration::from_millis(20);

/// Output frames below a packet under the target before the outputs call
/// on their own when the inputs set the pace (see [`Cyclic::next_exchange`]).
const FOLLOW_INPUTS: i64 = 3;

/// Input frames left behind that are taken as the estimate's noise (see
/// [`Cyclic::next_exchange`]).
const BACKLOG_NOISE: usize = 1;

/// Frame sizes, cycle and marks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Plan {
    /// Output frame size.
    pub rx_size: usize,
    /// Input frame size.
    pub tx_size: usize,
    /// DC cycle.
    pub cycle: Duration,
    /// Low mark, frames.
    pub low: u8,
    /// High mark, frames.
    pub high: u8,
    /// TxFIFO depth, frames.
    pub tx_depth: u8,
    /// The output latency budget (`cycle.output_latency_us`), if any.
    pub budget: Option<Duration>,
}

/// The RxFIFO levels the exchange keeps, frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Levels {
    /// The level each push brings the FIFO back to.
    pub target: i64,
    /// Below this (plus two frames) an exchange is due at once.
    pub floor: i64,
    /// The longest gap between exchanges, in cycles, so an estimate that
    /// is off is corrected before it matters.
    pub cap_cycles: u32,
}

impl Plan {
    /// The levels for this plan. Without a budget: midway between the
    /// marks, the low mark as the floor. With one: a write waits for the
    /// frames queued before it (`target` at most) and one cycle of the
    /// chip's own, so the target is the budget in cycles less one, at
    /// least 2 frames and never deeper than the midpoint; the floor is half
    /// of it (or the low mark, when lower).
    pub(crate) fn levels(&self) -> Levels {
        let (low, high) = (i64::from(self.low), i64::from(self.high));
        let mid = (low + high) / 2;
        match self.budget {
            None => Levels { target: mid, floor: low, cap_cycles: ((high - low).max(2) / 2) as u32 },
            Some(b) => {
                let frames = (b.as_nanos() / self.cycle.as_nanos().max(1)) as i64;
                let target = (frames - 1).clamp(2, mid.max(2));
                let floor = (target / 2).min(low);
                Levels { target, floor, cap_cycles: ((target - floor).max(2) / 2) as u32 }
            }
        }
    }
}

/// Depths that fit the FIFO memory (v049 under 52/54: RxCnt x RxSize +
/// TxCnt x TxSize <= 0x4000): unchanged when they fit; otherwise the TxFIFO
/// gets at most a quarter of the memory and the RxFIFO, which is what keeps
/// outputs flowing, the rest, with the marks scaled by the same ratio.
/// Returns (rx depth, tx depth, low, high).
pub(crate) fn fit_fifo(depth: u8, low: u8, high: u8, tx_depth: u8, rx_size: usize, tx_size: usize) -> (u8, u8, u8, u8) {
    let budget = ecmxf_wire::payload::fifo::FIFO_BUDGET;
    if usize::from(depth) * rx_size + usize::from(tx_depth) * tx_size <= budget {
        return (depth, tx_depth, low, high);
    }
    let tx = if usize::from(tx_depth) * tx_size * 4 <= budget {
        tx_depth
    } else {
        (budget / 4 / tx_size.max(1)).clamp(1, 255) as u8
    };
    let left = budget - usize::from(tx) * tx_size;
    let fitted = (left / rx_size.max(1)).clamp(2, usize::from(depth)) as u8;
    let scale = |m: u8| ((usize::from(m) * usize::from(fitted)) / usize::from(depth.max(1))) as u8;
    let h = scale(high).clamp(1, fitted);
    let l = scale(low).min(h - 1);
    (fitted, tx, l, h)
}

impl Plan {
    /// The frames bring-up queues before OP (outputs must be waiting when
    /// the slaves enter it): the high mark; with an output latency budget,
    /// the level kept under it. Prefilled to the high mark, the first
    /// writes after every bring-up would wait for all of it (2.4 s with
    /// marks up to 240 at a 10 ms cycle, an ENI's usual one) before the
    /// budget held.
    pub(crate) fn prefill(&self) -> usize {
        let high = usize::from(self.high.max(1));
        match self.budget {
            Some(_) => usize::try_from(self.levels().target).unwrap_or(1).clamp(1, high),
            None => high,
        }
    }
}

/// A FIFO call sent whose answer the engine has not taken yet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct InFlight {
    /// The packet's index, which its answer echoes.
    pub index: u8,
    /// When it was sent.
    pub sent_at: Instant,
    /// Output frames it pushed.
    pub pushed: u8,
    /// The packet just before it was the previous FIFO call itself (sent
    /// pipelined, not resent): the chip noted the counts this call's
    /// answer reports before that call pushed and read (docs/protocol.md
    /// §12), so its effects are added to them.
    pub after_call: bool,
    /// When the packet before it went out (`sent_at` when there was none):
    /// the counts of an answer made as the call ran are the chip's as that
    /// packet arrived, however long before the call it was (an emergency
    /// question, a resend 2 ms after the call before: 3 cycles at 1 ms,
    /// which read as frames still queued made writes look 3 ms late).
    pub counted_at: Instant,
}

/// What an answer to a FIFO call reported, and which packet made it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Counts {
    /// Output frames queued (header 0x07).
    pub count: u8,
    /// Input frames queued (header 0x06).
    pub waiting: u8,
    /// Input frames the answer carries.
    pub read: usize,
    /// The answer was made by the call's `resends`-th resend (0: as the
    /// call ran; `port::Pipelined::resends`).
    pub resends: u32,
}

/// When the counts an answer reports were taken, against the calls.
#[derive(Clone, Copy, Debug)]
enum Counted {
    /// As the call before arrived, right before this one: before that
    /// call pushed and read.
    BeforeLast(Resolved),
    /// After every earlier call, before this one pushed and read, at the
    /// time given: the answer made as the call ran, after another packet
    /// (counted as that packet arrived), or by its first resend (counted
    /// as the call itself arrived).
    BeforeOwn(Instant),
    /// After the call itself pushed and read: made by its second resend
    /// or a later one.
    AfterOwn,
}

/// What the last call whose fate is known did.
#[derive(Clone, Copy, Debug)]
struct Resolved {
    index: u8,
    sent_at: Instant,
    /// Frames it pushed (0 when the chip refused it).
    pushed: u8,
    /// Input frames read from its answer (0 when lost or refused).
    read: usize,
}

/// The newest level the chip reported, and what was pushed since.
#[derive(Clone, Copy, Debug)]
struct Report {
    /// When the call whose answer reported it was sent.
    at: Instant,
    /// The RxFIFO level just before that call's push.
    level: u8,
    /// Frames pushed by that call and every call sent after it (those
    /// still unanswered included; a call the chip refused taken back).
    pushed: u32,
}

/// The cyclic state.
#[derive(Debug)]
pub(crate) struct Cyclic {
    /// Output frame size.
    pub rx_size: usize,
    /// Input frame size.
    pub tx_size: usize,
    /// TxFIFO depth: inputs beyond it are dropped by the chip, oldest first.
    pub tx_depth: u8,
    cycle: Duration,
    /// The host-side output image, pushed as every new frame.
    pub outputs: Vec<u8>,
    push_buf: Vec<u8>,
    levels: Levels,
    /// When the last FIFO call was sent.
    last_call: Instant,
    /// Calls sent whose answers are not taken yet, oldest first.
    in_flight: [Option<InFlight>; 2],
    /// The index of the last call sent.
    last_index: Option<u8>,
    /// The last call whose fate is known.
    resolved: Option<Resolved>,
    /// Input frames the last FIFO call left in the TxFIFO: the answer's
    /// count (the level before the call's read) less the frames it read.
    /// A read that fills a packet with nothing left behind is no reason to
    /// exchange again at once (a one-frame-per-packet network once made
    /// four exchanges a cycle that way).
    backlog: u8,
    report: Report,
    started: Instant,
    /// Frames pushed and input frames read in this run so far.
    pushed_total: u64,
    read_total: u64,
    /// (output frames consumed, input frames read or waiting) as of the
    /// last answer's counts: see [`Cyclic::inputs_lost`].
    sample: Option<(u64, u64)>,
}

impl Cyclic {
    /// A plan and the packet's data size. `outputs` is the image to start
    /// from (the one clients wrote before a recovery) when it has the
    /// plan's size; otherwise the image starts zeroed.
    pub(crate) fn new(plan: Plan, data_size: usize, outputs: Vec<u8>) -> Self {
        let now = Instant::now();
        let Plan { rx_size, tx_size, cycle, tx_depth, .. } = plan;
        let outputs = if outputs.len() == rx_size { outputs } else { vec![0; rx_size] };
        Self {
            rx_size,
            tx_size,
            tx_depth,
            cycle,
            outputs,
            push_buf: Vec::with_capacity(data_size),
            levels: plan.levels(),
            last_call: now,
            in_flight: [None; 2],
            last_index: None,
            resolved: None,
            backlog: 0,
            report: Report { at: now, level: 0, pushed: 0 },
            started: now,
            pushed_total: 0,
            read_total: 0,
            sample: None,
        }
    }

    /// The DC cycle.
    pub(crate) fn cycle(&self) -> Duration {
        self.cycle
    }

    fn cycles_since(&self, t: Instant, now: Instant) -> u64 {
        (now.saturating_duration_since(t).as_nanos() / self.cycle.as_nanos().max(1)) as u64
    }

    /// Whether the RxFIFO is below its floor (plus a margin of two
    /// frames): never for a network without outputs, which has none to keep.
    pub(crate) fn outputs_low(&self, now: Instant) -> bool {
        self.rx_size > 0 && self.estimate(now) < self.levels.floor + 2
    }

    /// Whether input frames wait in the TxFIFO beyond what an exchange may
    /// leave for the blocking slot's turn (the ones the last call left
    /// plus one a cycle since): three packets' worth, or a quarter of the
    /// TxFIFO when that is less, so a host stall still has three quarters
    /// of it before the chip drops the oldest. The count the chip reported
    /// lags by up to two exchanges (docs/protocol.md §12), so this reads high by
    /// a packet or so; two packets made every other SDO read wait for a
    /// FIFO exchange it did not need.
    pub(crate) fn inputs_pressing(&self, now: Instant, tx_room: usize) -> bool {
        let waiting = u64::from(self.backlog) + self.cycles_since(self.last_call, now);
        let limit = (3 * tx_room.max(1) as u64).min(u64::from(self.tx_depth / 4).max(1));
        self.tx_size > 0 && waiting >= limit
    }

    /// Whether the RxFIFO has fallen two packets (`rx_room` frames each)
    /// below the level aimed at: one packet later than an exchange is due,
    /// the most an exchange may wait for the blocking slot's turn, so the
    /// margin against a host stall stays what the plan keeps.
    pub(crate) fn outputs_behind(&self, now: Instant, rx_room: usize) -> bool {
        self.rx_size > 0 && self.estimate(now) < self.target() - 2 * rx_room.max(1) as i64
    }

    /// The estimated RxFIFO level now.
    pub(crate) fn estimate(&self, now: Instant) -> i64 {
        let Report { at, level, pushed } = self.report;
        i64::from(level) + i64::from(pushed) - self.cycles_since(at, now) as i64
    }

    /// The level aimed at (see [`Plan::levels`]).
    fn target(&self) -> i64 {
        self.levels.target
    }

    /// Frames to push in an exchange now, at most `room`.
    pub(crate) fn frames_to_push(&self, now: Instant, room: usize) -> u8 {
        (self.target() - self.estimate(now)).clamp(0, room.min(255) as i64) as u8
    }

    /// When the next exchange should happen: when the level has fallen one
    /// packet (`rx_room` frames) below the target, so one exchange brings it
    /// back; when `tx_room` input frames are waiting, counting those the
    /// last exchange left behind (at once if that is a packet's worth); and
    /// never later than half the gap between target and floor, so an
    /// estimate that is off (the lag is the chip's, not a law) is corrected
    /// soon. A small target refills before the floor, a packet at a time
    /// or less.
    ///
    /// Both sides move a frame a cycle, so with inputs the outputs refill
    /// [`FOLLOW_INPUTS`] frames later than a packet below the target (never
    /// below the floor): the call the inputs make tops the outputs up, and
    /// the two sides do not each call on their own phase. A backlog of one
    /// frame is within the estimate's noise (the chip's counts and the
    /// host's clock place the cycle boundary differently) and brings no
    /// call forward. Measured with `ecmxfd-fifo-bench` on the demo network
    /// at 125 us: calls read 8.6 input frames of 9 without the two rules,
    /// 8.97 with them.
    /// A network without outputs has no RxFIFO level to keep: only inputs
    /// and the cap decide.
    pub(crate) fn next_exchange(&self, now: Instant, rx_room: usize, tx_room: usize) -> Instant {
        let follow = if self.tx_size > 0 { FOLLOW_INPUTS } else { 0 };
        let refill_at = (self.target() - rx_room as i64 - follow).max(self.levels.floor);
        let by_level =
            if self.rx_size == 0 { Duration::MAX } else { self.cycle * (self.estimate(now) - refill_at).max(0) as u32 };
        // Counted from the last exchange (one input frame per cycle since
        // it); the level is an estimate for `now` itself.
        let since = self.last_call;
        let by_inputs = match self.tx_size {
            0 => since + MAX_EXCHANGE_INTERVAL,
            _ => {
                let left = usize::from(self.backlog).saturating_sub(BACKLOG_NOISE);
                since + self.cycle * (tx_room.max(1).saturating_sub(left) as u32)
            }
        };
        let cap = since + (self.cycle * self.levels.cap_cycles).min(MAX_EXCHANGE_INTERVAL);
        now.checked_add(by_level).unwrap_or(cap).min(by_inputs).min(cap)
    }

    /// The bytes of `n` output frames: each the current image, after the
    /// next frame of every stream was taken into its range.
    pub(crate) fn push_frames(&mut self, n: u8, streams: &mut [super::frames::FrameConsumer]) -> &[u8] {
        self.push_buf.clear();
        for s in streams.iter_mut() {
            s.start_push();
        }
        for i in 0..n {
            for s in streams.iter_mut() {
                s.next_into(&mut self.outputs, i);
            }
            self.push_buf.extend_from_slice(&self.outputs);
        }
        &self.push_buf
    }

    /// Records a FIFO call sent (its push counts in the estimate at once).
    pub(crate) fn sent(&mut self, call: InFlight) {
        self.last_call = call.sent_at;
        self.last_index = Some(call.index);
        self.report.pushed += u32::from(call.pushed);
        if self.in_flight[1].is_some() {
            // The engine takes every answer before the next call but one;
            // should it not, the oldest is forgotten, never the newest.
            self.in_flight.rotate_left(1);
            self.in_flight[1] = None;
        }
        let free = usize::from(self.in_flight[0].is_some());
        self.in_flight[free] = Some(call);
    }

    /// The index of the last call sent, if any.
    pub(crate) fn last_index(&self) -> Option<u8> {
        self.last_index
    }

    /// The oldest call whose answer is not taken yet.
    pub(crate) fn oldest_in_flight(&self) -> Option<InFlight> {
        self.in_flight[0]
    }

    /// The newest call whose answer is not taken yet.
    pub(crate) fn newest_in_flight(&self) -> Option<InFlight> {
        self.in_flight[1].or(self.in_flight[0])
    }

    fn take(&mut self, index: u8) -> Option<InFlight> {
        let at = self.in_flight.iter().position(|c| c.is_some_and(|c| c.index == index))?;
        let call = self.in_flight[at].take();
        self.in_flight.sort_by_key(Option::is_none);
        call
    }

    /// The answer to call `index` arrived at `now` with `answer`'s counts
    /// (see [`Counted`] for when they were taken).
    pub(crate) fn answered(&mut self, index: u8, answer: Counts, now: Instant) {
        let Some(call) = self.in_flight.iter().flatten().find(|c| c.index == index).copied() else { return };
        let counted = self.counted(&call, answer.resends);
        self.take(index);
        let later: u32 = self.in_flight.iter().flatten().map(|c| u32::from(c.pushed)).sum();
        let Counts { count, waiting, read, .. } = answer;
        let (report, arrived) = match counted {
            // Counted as the call before arrived: its push comes on top,
            // its read off, and the cycles since it add input frames.
            Counted::BeforeLast(prev) => (
                Report {
                    at: prev.sent_at,
                    level: count,
                    pushed: u32::from(prev.pushed) + u32::from(call.pushed) + later,
                },
                i64::from(waiting) + self.cycles_since(prev.sent_at, call.sent_at) as i64 - prev.read as i64,
            ),
            // Counted when the packet before arrived: frames came in since.
            Counted::BeforeOwn(at) => (
                Report { at, level: count, pushed: u32::from(call.pushed) + later },
                i64::from(waiting) + self.cycles_since(at, call.sent_at) as i64,
            ),
            // Counted after the call ran: its push and read are in.
            Counted::AfterOwn => (Report { at: now, level: count, pushed: later }, i64::from(waiting) + read as i64),
        };
        self.report = report;
        self.backlog = (arrived - read as i64).clamp(0, i64::from(u8::MAX)) as u8;
        self.pushed_total += u64::from(call.pushed);
        self.read_total += read as u64;
        self.resolved = Some(Resolved { index, sent_at: call.sent_at, pushed: call.pushed, read });
    }

    /// When the counts in `call`'s answer were taken (docs/protocol.md
    /// §12): the chip notes its levels as each packet arrives, before it
    /// runs, and an answer reports those of the packet before the one that
    /// made it.
    fn counted(&self, call: &InFlight, resends: u32) -> Counted {
        match resends {
            0 => self
                .resolved
                .filter(|r| call.after_call && r.index != call.index)
                .map_or(Counted::BeforeOwn(call.counted_at), Counted::BeforeLast),
            1 => Counted::BeforeOwn(call.sent_at),
            _ => Counted::AfterOwn,
        }
    }

    /// The chip refused call `index` for its check word: it pushed and
    /// read nothing.
    pub(crate) fn refused(&mut self, index: u8) {
        if let Some(call) = self.take(index) {
            self.report.pushed = self.report.pushed.saturating_sub(u32::from(call.pushed));
            self.resolved = Some(Resolved { index, sent_at: call.sent_at, pushed: 0, read: 0 });
        }
    }

    /// The answer to call `index` was lost: the call ran (pushed its
    /// frames and read input frames that are gone), and the next answer's
    /// counts number the frames it took as lost ([`Cyclic::inputs_lost`]).
    pub(crate) fn lost(&mut self, index: u8) {
        if let Some(call) = self.take(index) {
            self.pushed_total += u64::from(call.pushed);
            self.resolved = Some(Resolved { index, sent_at: call.sent_at, pushed: call.pushed, read: 0 });
        }
    }

    /// Input frames the chip dropped (its TxFIFO full: the oldest go)
    /// since the last answer, from an answer's counts (taken at the packet
    /// before the call, when every frame pushed and read before the call
    /// was in): `ahead` output frames and `waiting` input frames queued.
    /// Each DC cycle consumes one output frame and produces one input
    /// frame, so the cycles between two answers are the output frames
    /// consumed in between, and the input frames produced are as many:
    /// those neither read nor waiting since were dropped. Exact while the
    /// RxFIFO did not run dry in between (fewer frames consumed than
    /// cycles: then it counts low, never high; a network without outputs
    /// consumes none and counts none). Call before [`Cyclic::answered`]
    /// records this call. A call whose answer was lost read frames that are
    /// neither read nor waiting: they count here too.
    pub(crate) fn inputs_lost(&mut self, index: u8, answer: Counts) -> u64 {
        let Counts { count: ahead, waiting, read, resends } = answer;
        let call = self.in_flight.iter().flatten().find(|c| c.index == index).copied();
        // The totals as of when the counts were taken.
        let (pushed, read_before) = match call.map(|c| (c, self.counted(&c, resends))) {
            Some((_, Counted::BeforeLast(prev))) => (
                self.pushed_total.saturating_sub(u64::from(prev.pushed)),
                self.read_total.saturating_sub(prev.read as u64),
            ),
            Some((c, Counted::AfterOwn)) => (self.pushed_total + u64::from(c.pushed), self.read_total + read as u64),
            _ => (self.pushed_total, self.read_total),
        };
        let consumed = pushed.saturating_sub(u64::from(ahead));
        let seen = read_before + u64::from(waiting);
        let lost =
            self.sample.map_or(0, |(c0, s0)| consumed.saturating_sub(c0).saturating_sub(seen.saturating_sub(s0)));
        self.sample = Some((consumed, seen));
        lost
    }

    /// When the last exchange was, if any.
    pub(crate) fn last_exchange(&self) -> Option<Instant> {
        (self.last_call > self.started).then_some(self.last_call)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cyclic() -> (Cyclic, ()) {
        let plan = Plan {
            rx_size: 4,
            tx_size: 3,
            cycle: Duration::from_micros(125),
            low: 8,
            high: 20,
            tx_depth: 32,
            budget: None,
        };
        (Cyclic::new(plan, 112, Vec::new()), ())
    }

    /// A call sent at `t` and answered at once, as a guarded one is.
    fn call(cy: &mut Cyclic, t: Instant, pushed: u8, count: u8, waiting: u8, read: usize) {
        let index = 0;
        cy.sent(InFlight { index, sent_at: t, pushed, after_call: false, counted_at: t });
        cy.answered(index, counts(count, waiting, read), t);
    }

    /// An answer made as its call ran.
    fn counts(count: u8, waiting: u8, read: usize) -> Counts {
        Counts { count, waiting, read, resends: 0 }
    }

    #[test]
    fn estimate_counts_pushes_and_consumption_since_the_report() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        call(&mut cy, t0, 5, 3, 0, 0);
        call(&mut cy, t0 + Duration::from_micros(100), 10, 12, 0, 0);
        // 12 queued before this push, 10 pushed, 7 cycles gone 0.9 ms later;
        // the earlier push is in the 12 already.
        assert_eq!(cy.estimate(t0 + Duration::from_millis(1)), 12 + 10 - 7);
        assert_eq!(cy.frames_to_push(t0 + Duration::from_millis(1), 9), 0);
        assert_eq!(cy.frames_to_push(t0 + Duration::from_millis(4), 9), 9);
    }

    #[test]
    fn exchanges_are_planned_to_hold_the_target() {
        let cycle = Duration::from_micros(125);
        let plan = Plan { rx_size: 4, tx_size: 0, cycle, low: 4, high: 24, tx_depth: 32, budget: None };
        let mut cy = Cyclic::new(plan, 112, Vec::new());
        let t0 = Instant::now();
        // Target 14, packet room 4: refill when the level reaches 10.
        call(&mut cy, t0, 0, 14, 0, 0);
        let at = cy.next_exchange(t0, 4, 100);
        assert_eq!(at.duration_since(t0), Duration::from_micros(125 * 4));
        // With inputs, three frames later, for the inputs' call to top up.
        let mut cy = Cyclic::new(Plan { tx_size: 3, ..plan }, 112, Vec::new());
        call(&mut cy, t0, 0, 14, 0, 0);
        assert_eq!(cy.next_exchange(t0, 4, 100), t0 + Duration::from_micros(125 * 7));
        // Far below target: now.
        call(&mut cy, t0, 0, 2, 0, 0);
        assert_eq!(cy.next_exchange(t0, 4, 100), t0);
    }

    #[test]
    fn an_exchange_may_wait_for_the_slot_about_a_packet_past_its_time() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        let cycles = |n: u64| t0 + Duration::from_micros(125 * n);
        // Target 14, packet room 4: due at 10, behind below 6.
        call(&mut cy, t0, 0, 14, 0, 0);
        assert!(!cy.outputs_behind(cycles(8), 4));
        assert!(cy.outputs_behind(cycles(9), 4));
        // Inputs, 4 to a packet, TxFIFO 32: pressing at a quarter of it (8),
        // counting the 2 the last call left.
        call(&mut cy, t0, 0, 14, 6, 4);
        assert!(!cy.inputs_pressing(cycles(5), 4));
        assert!(cy.inputs_pressing(cycles(6), 4));
        // Three packets when that is less than a quarter of the TxFIFO.
        cy.tx_depth = 64;
        assert!(!cy.inputs_pressing(cycles(9), 4));
        assert!(cy.inputs_pressing(cycles(10), 4));
    }

    #[test]
    fn fifo_depth_fits_the_memory() {
        assert_eq!(fit_fifo(32, 8, 20, 32, 53, 53), (32, 32, 8, 20), "fits: unchanged");
        assert_eq!(fit_fifo(255, 96, 192, 40, 53, 53), (255, 40, 96, 192), "255 x 53 + 40 x 53 fits");
        for (rx, tx) in [(80, 53), (400, 400), (1408, 1408), (1, 1408)] {
            let (d, t, l, h) = fit_fifo(255, 96, 192, 40, rx, tx);
            assert!(usize::from(d) * rx + usize::from(t) * tx <= 0x4000, "{rx}/{tx}: {d} x {rx} + {t} x {tx}");
            assert!(l < h && h <= d && t >= 1, "{rx}/{tx}: {d} {t} {l} {h}");
        }
    }

    #[test]
    fn an_image_of_the_right_size_is_kept_across_runs() {
        let plan = Plan {
            rx_size: 2,
            tx_size: 1,
            cycle: Duration::from_millis(1),
            low: 8,
            high: 20,
            tx_depth: 32,
            budget: None,
        };
        assert_eq!(Cyclic::new(plan, 112, vec![7, 9]).outputs, [7, 9]);
        assert_eq!(Cyclic::new(plan, 112, vec![7, 9, 1]).outputs, [0, 0], "another layout starts zeroed");
    }

    #[test]
    fn exchanges_happen_at_least_every_max_interval() {
        let plan = Plan {
            rx_size: 4,
            tx_size: 3,
            cycle: Duration::from_millis(1),
            low: 128,
            high: 240,
            tx_depth: 40,
            budget: None,
        };
        let mut cy = Cyclic::new(plan, 112, Vec::new());
        let t0 = Instant::now();
        call(&mut cy, t0, 0, 240, 0, 0);
        assert_eq!(cy.next_exchange(t0, 4, 100), t0 + MAX_EXCHANGE_INTERVAL, "56 cycles of margin, 20 ms at most");
        assert_eq!(cy.next_exchange(t0, 4, 3), t0 + Duration::from_millis(3), "3 input frames per read");
        call(&mut cy, t0, 0, 240, 3, 3);
        assert_eq!(
            cy.next_exchange(t0, 4, 3),
            t0 + Duration::from_millis(3),
            "a full packet read, none left: no hurry"
        );
        call(&mut cy, t0, 0, 240, 4, 3);
        assert_eq!(cy.next_exchange(t0, 4, 3), t0 + Duration::from_millis(3), "one left behind: the estimate's noise");
        call(&mut cy, t0, 0, 240, 5, 3);
        assert_eq!(cy.next_exchange(t0, 4, 3), t0 + Duration::from_millis(2), "two left behind: a cycle sooner");
        call(&mut cy, t0, 0, 240, 10, 3);
        assert_eq!(cy.next_exchange(t0, 4, 3), t0, "a packet's worth left behind, beyond the noise: now");
    }

    #[test]
    fn a_network_without_outputs_keeps_no_level() {
        let plan = Plan {
            rx_size: 0,
            tx_size: 1,
            cycle: Duration::from_millis(1),
            low: 128,
            high: 240,
            tx_depth: 40,
            budget: None,
        };
        let mut cy = Cyclic::new(plan, 512, Vec::new());
        let t0 = Instant::now();
        call(&mut cy, t0, 0, 0, 0, 0);
        assert!(!cy.outputs_low(t0), "an empty RxFIFO is no shortage without outputs");
        assert_eq!(cy.next_exchange(t0, 0, 9), t0 + Duration::from_millis(9), "inputs decide");
        // Counted from the last exchange, not from whenever it is asked.
        let later = t0 + Duration::from_millis(30);
        assert!(cy.next_exchange(later, 0, 472) <= later, "the cap has passed: due");
        let plan = Plan { rx_size: 4, ..plan };
        let mut cy = Cyclic::new(plan, 512, Vec::new());
        call(&mut cy, t0, 0, 0, 0, 0);
        assert!(cy.outputs_low(t0));
    }

    #[test]
    fn a_latency_budget_keeps_the_shallowest_level_that_meets_it() {
        let us = Duration::from_micros;
        let plan = |budget: Option<u64>| Plan {
            rx_size: 53,
            tx_size: 53,
            cycle: us(125),
            low: 128,
            high: 240,
            tx_depth: 40,
            budget: budget.map(us),
        };
        assert_eq!(plan(None).levels(), Levels { target: 184, floor: 128, cap_cycles: 56 }, "no budget: as before");
        // 2 ms at 125 us: 16 cycles, 15 frames ahead of a write.
        assert_eq!(plan(Some(2000)).levels(), Levels { target: 15, floor: 7, cap_cycles: 4 });
        assert_eq!(plan(Some(250)).levels().target, 2, "never fewer than two frames");
        assert_eq!(plan(Some(1_000_000)).levels().target, 184, "never deeper than the midpoint");
        // Bring-up queues the high mark, or with a budget only its level.
        assert_eq!((plan(None).prefill(), plan(Some(2000)).prefill()), (240, 15));
        // Held at the target: a packet of 19 frames is more than the room
        // between target and floor, so it refills at the floor.
        let mut cy = Cyclic::new(plan(Some(2000)), 1024, Vec::new());
        let t0 = Instant::now();
        call(&mut cy, t0, 0, 15, 0, 0);
        assert_eq!(cy.frames_to_push(t0, 19), 0);
        assert_eq!(cy.next_exchange(t0, 19, 1000), t0 + us(125 * 4), "the cap: half of 15 - 7 cycles");
        assert!(!cy.outputs_low(t0 + us(125 * 5)));
        assert!(cy.outputs_low(t0 + us(125 * 7)), "below the floor plus two");
        assert_eq!(cy.frames_to_push(t0 + us(125 * 8), 19), 8, "back to 15");
    }

    #[test]
    fn push_bytes_repeat_the_image() {
        let (mut cy, _) = cyclic();
        cy.outputs.copy_from_slice(&[1, 2, 3, 4]);
        assert_eq!(cy.push_frames(2, &mut []), &[1, 2, 3, 4, 1, 2, 3, 4]);
    }

    #[test]
    fn input_frames_the_chip_dropped_are_counted_from_the_output_side() {
        let (mut cy, _) = cyclic();
        // First answer: a reference only.
        let t0 = Instant::now();
        assert_eq!(cy.inputs_lost(0, counts(0, 0, 0)), 0);
        call(&mut cy, t0, 20, 0, 0, 0);
        // 20 pushed, 12 still queued: 8 cycles; 8 input frames waiting.
        assert_eq!(cy.inputs_lost(0, counts(12, 8, 0)), 0);
        call(&mut cy, t0, 10, 12, 8, 8);
        // 30 pushed, 2 queued: 20 more cycles, so 20 input frames made;
        // 8 read, 5 waiting: 15 of them dropped.
        assert_eq!(cy.inputs_lost(0, counts(2, 5, 0)), 15);
        call(&mut cy, t0, 0, 2, 5, 5);
        // The last 2 output frames consumed, 3 input frames made since
        // (the RxFIFO ran dry for one cycle): never more than the output
        // side shows.
        assert_eq!(cy.inputs_lost(0, counts(0, 3, 0)), 0);
    }

    #[test]
    fn an_answer_on_its_way_keeps_its_push_in_the_estimate_and_counts_from_its_own_time() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        let at = |us: u64| t0 + Duration::from_micros(us);
        call(&mut cy, t0, 0, 14, 0, 0);
        // Two calls sent pipelined, 4 and 3 frames; no answer yet.
        cy.sent(InFlight { index: 1, sent_at: at(250), pushed: 4, after_call: false, counted_at: at(250) });
        cy.sent(InFlight { index: 2, sent_at: at(500), pushed: 3, after_call: false, counted_at: at(500) });
        assert_eq!(cy.estimate(at(500)), 14 + 4 + 3 - 4);
        assert_eq!(cy.last_exchange(), Some(at(500)));
        assert_eq!(cy.oldest_in_flight().map(|c| c.index), Some(1));
        assert_eq!(cy.newest_in_flight().map(|c| c.index), Some(2));
        // The first answer, taken later, reports 12 just before its push
        // (at 250 us): the second push is still on top of it.
        cy.answered(1, counts(12, 2, 2), t0);
        assert_eq!(cy.estimate(at(1000)), 12 + 4 + 3 - 6);
        // The chip refused the second: its frames never went in.
        cy.refused(2);
        assert_eq!(cy.estimate(at(1000)), 12 + 4 - 6);
        assert_eq!(cy.oldest_in_flight(), None);
    }

    #[test]
    fn input_frames_of_a_lost_answer_are_counted_lost_by_the_next_one() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        assert_eq!(cy.inputs_lost(0, counts(0, 0, 0)), 0);
        call(&mut cy, t0, 20, 0, 0, 0);
        // 8 cycles: 8 input frames, read by a call whose answer is lost.
        cy.sent(InFlight { index: 1, sent_at: t0, pushed: 8, after_call: false, counted_at: t0 });
        cy.lost(1);
        // The next answer: 28 pushed, 20 queued, so 8 cycles; nothing
        // read, nothing waiting: the 8 frames are lost.
        assert_eq!(cy.inputs_lost(2, counts(20, 0, 0)), 8);
    }

    #[test]
    fn counts_taken_as_the_call_before_arrived_get_its_push_and_read() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        let cycles = |n: u64| t0 + Duration::from_micros(125 * n);
        assert_eq!(cy.inputs_lost(1, counts(0, 0, 0)), 0);
        call(&mut cy, t0, 20, 0, 0, 0);
        // 12 output frames queued and 8 input frames waiting as this call
        // arrives: it pushes 10 and reads the 8.
        cy.sent(InFlight { index: 2, sent_at: cycles(8), pushed: 10, after_call: false, counted_at: cycles(8) });
        assert_eq!(cy.inputs_lost(2, counts(12, 8, 0)), 0);
        cy.answered(2, counts(12, 8, 8), t0);
        // The next call goes right behind it, 3 cycles later: the chip took
        // its counts as the call before arrived (12 and 8 again).
        cy.sent(InFlight { index: 3, sent_at: cycles(11), pushed: 5, after_call: true, counted_at: cycles(11) });
        assert_eq!(cy.inputs_lost(3, counts(12, 8, 0)), 0, "the earlier call's read is not a loss");
        cy.answered(3, counts(12, 8, 3), t0);
        // 12 + 10 + 5 - 4 cycles since the earlier call.
        assert_eq!(cy.estimate(cycles(12)), 12 + 10 + 5 - 4);
        // 8 waiting then, 8 read by it, 3 made since, 3 read: none left.
        assert!(!cy.inputs_pressing(cycles(11), 4));
        assert_eq!(cy.backlog, 0);
    }

    #[test]
    fn counts_made_by_a_second_resend_already_hold_the_call_itself() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        assert_eq!(cy.inputs_lost(1, counts(0, 0, 0)), 0);
        call(&mut cy, t0, 20, 0, 0, 0);
        // 12 queued and 8 waiting as it arrives; it pushes 10 and reads
        // the 8. Its first answer and the first resend's were corrupt: the
        // second resend's counts were taken after it ran.
        cy.sent(InFlight { index: 2, sent_at: t0, pushed: 10, after_call: false, counted_at: t0 });
        let after = Counts { count: 22, waiting: 0, read: 8, resends: 2 };
        assert_eq!(cy.inputs_lost(2, after), 0, "its own read is not a loss");
        cy.answered(2, after, t0);
        assert_eq!(cy.estimate(t0), 22);
        assert_eq!(cy.backlog, 0);
    }

    #[test]
    fn counts_noted_at_an_earlier_packet_are_dated_by_it() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        let cycles = |n: u32| t0 + Duration::from_micros(125) * n;
        call(&mut cy, t0, 0, 14, 0, 0);
        // The packet before the call (an emergency question, a resend) went
        // out 3 cycles before it: 12 queued and 5 waiting then.
        cy.sent(InFlight { index: 2, sent_at: cycles(10), pushed: 4, after_call: false, counted_at: cycles(7) });
        cy.answered(2, counts(12, 5, 8), cycles(11));
        // 3 cycles consumed by the call, 4 pushed: 13 as it ran, 12 a cycle on.
        assert_eq!(cy.estimate(cycles(10)), 13);
        assert_eq!(cy.estimate(cycles(11)), 12);
        // 5 waiting and 3 come since, 8 read: none left behind.
        assert_eq!(cy.backlog, 0);
    }
}
