//! Keeping the chip's RxFIFO fed and its TxFIFO drained (v049
//! PDO_DATA_FIFO_OP): the chip consumes one output frame and produces one
//! input frame per DC cycle; running the RxFIFO dry in OP is the failure to
//! avoid.
//!
//! The header's FIFO counts are two exchanges late (vendor comment;
//! docs/protocol.md §12): the answer to a FIFO call, fetched by its guarded
//! resend, reports the level just before the call's own push. The estimate
//! of the level therefore starts from that count, adds the push, and takes
//! off one frame per cycle elapsed since then.
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
    /// (time, frames pushed) of the last FIFO call.
    last_push: (Instant, u8),
    /// Input frames the last FIFO call left in the TxFIFO: the answer's
    /// count (the level before the call's read) less the frames it read.
    /// A read that fills a packet with nothing left behind is no reason to
    /// exchange again at once (a one-frame-per-packet network once made
    /// four exchanges a cycle that way).
    backlog: u8,
    /// Level reported just before that push.
    reported: u8,
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
            last_push: (now, 0),
            backlog: 0,
            reported: 0,
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
        let waiting = u64::from(self.backlog) + self.cycles_since(self.last_push.0, now);
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
        let (at, pushed) = self.last_push;
        i64::from(self.reported) + i64::from(pushed) - self.cycles_since(at, now) as i64
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
    /// A network without outputs has no RxFIFO level to keep: only inputs
    /// and the cap decide.
    pub(crate) fn next_exchange(&self, now: Instant, rx_room: usize, tx_room: usize) -> Instant {
        let refill_at = (self.target() - rx_room as i64).max(self.levels.floor);
        let by_level =
            if self.rx_size == 0 { Duration::MAX } else { self.cycle * (self.estimate(now) - refill_at).max(0) as u32 };
        // Counted from the last exchange (one input frame per cycle since
        // it); the level is an estimate for `now` itself.
        let since = self.last_push.0;
        let by_inputs = match self.tx_size {
            0 => since + MAX_EXCHANGE_INTERVAL,
            _ => since + self.cycle * (tx_room.max(1).saturating_sub(usize::from(self.backlog)) as u32),
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

    /// Records a FIFO call at `now` that pushed `pushed` frames, whose
    /// answer reported `count` output frames queued just before the push
    /// and `waiting` input frames queued before its read, and that read
    /// `read` input frames.
    pub(crate) fn answered(&mut self, now: Instant, pushed: u8, count: u8, waiting: u8, read: usize) {
        self.last_push = (now, pushed);
        self.reported = count;
        self.backlog = usize::from(waiting).saturating_sub(read).min(usize::from(u8::MAX)) as u8;
        self.pushed_total += u64::from(pushed);
        self.read_total += read as u64;
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
    /// records this call.
    pub(crate) fn inputs_lost(&mut self, ahead: u8, waiting: u8) -> u64 {
        let consumed = self.pushed_total.saturating_sub(u64::from(ahead));
        let seen = self.read_total + u64::from(waiting);
        let lost =
            self.sample.map_or(0, |(c0, s0)| consumed.saturating_sub(c0).saturating_sub(seen.saturating_sub(s0)));
        self.sample = Some((consumed, seen));
        lost
    }

    /// When the last exchange was, if any.
    pub(crate) fn last_exchange(&self) -> Option<Instant> {
        let (t, _) = self.last_push;
        (t > self.started).then_some(t)
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

    #[test]
    fn estimate_counts_pushes_and_consumption_since_the_report() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        cy.answered(t0, 5, 3, 0, 0);
        cy.answered(t0 + Duration::from_micros(100), 10, 12, 0, 0);
        // 12 queued before this push, 10 pushed, 7 cycles gone 0.9 ms later;
        // the earlier push is in the 12 already.
        assert_eq!(cy.estimate(t0 + Duration::from_millis(1)), 12 + 10 - 7);
        assert_eq!(cy.frames_to_push(t0 + Duration::from_millis(1), 9), 0);
        assert_eq!(cy.frames_to_push(t0 + Duration::from_millis(4), 9), 9);
    }

    #[test]
    fn exchanges_are_planned_to_hold_the_target() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        // Target 14, packet room 4: refill when the level reaches 10.
        cy.answered(t0, 0, 14, 0, 0);
        let at = cy.next_exchange(t0, 4, 100);
        assert_eq!(at.duration_since(t0), Duration::from_micros(125 * 4));
        // Far below target: now.
        cy.answered(t0, 0, 2, 0, 0);
        assert_eq!(cy.next_exchange(t0, 4, 100), t0);
    }

    #[test]
    fn an_exchange_may_wait_for_the_slot_about_a_packet_past_its_time() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        let cycles = |n: u64| t0 + Duration::from_micros(125 * n);
        // Target 14, packet room 4: due at 10, behind below 6.
        cy.answered(t0, 0, 14, 0, 0);
        assert!(!cy.outputs_behind(cycles(8), 4));
        assert!(cy.outputs_behind(cycles(9), 4));
        // Inputs, 4 to a packet, TxFIFO 32: pressing at a quarter of it (8),
        // counting the 2 the last call left.
        cy.answered(t0, 0, 14, 6, 4);
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
        cy.answered(t0, 0, 240, 0, 0);
        assert_eq!(cy.next_exchange(t0, 4, 100), t0 + MAX_EXCHANGE_INTERVAL, "56 cycles of margin, 20 ms at most");
        assert_eq!(cy.next_exchange(t0, 4, 3), t0 + Duration::from_millis(3), "3 input frames per read");
        cy.answered(t0, 0, 240, 3, 3);
        assert_eq!(
            cy.next_exchange(t0, 4, 3),
            t0 + Duration::from_millis(3),
            "a full packet read, none left: no hurry"
        );
        cy.answered(t0, 0, 240, 4, 3);
        assert_eq!(cy.next_exchange(t0, 4, 3), t0 + Duration::from_millis(2), "one left behind: a cycle sooner");
        cy.answered(t0, 0, 240, 9, 3);
        assert_eq!(cy.next_exchange(t0, 4, 3), t0, "a packet's worth left behind: now");
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
        cy.answered(t0, 0, 0, 0, 0);
        assert!(!cy.outputs_low(t0), "an empty RxFIFO is no shortage without outputs");
        assert_eq!(cy.next_exchange(t0, 0, 9), t0 + Duration::from_millis(9), "inputs decide");
        // Counted from the last exchange, not from whenever it is asked.
        let later = t0 + Duration::from_millis(30);
        assert!(cy.next_exchange(later, 0, 472) <= later, "the cap has passed: due");
        let plan = Plan { rx_size: 4, ..plan };
        let mut cy = Cyclic::new(plan, 512, Vec::new());
        cy.answered(t0, 0, 0, 0, 0);
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
        cy.answered(t0, 0, 15, 0, 0);
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
        assert_eq!(cy.inputs_lost(0, 0), 0);
        cy.answered(t0, 20, 0, 0, 0);
        // 20 pushed, 12 still queued: 8 cycles; 8 input frames waiting.
        assert_eq!(cy.inputs_lost(12, 8), 0);
        cy.answered(t0, 10, 12, 8, 8);
        // 30 pushed, 2 queued: 20 more cycles, so 20 input frames made;
        // 8 read, 5 waiting: 15 of them dropped.
        assert_eq!(cy.inputs_lost(2, 5), 15);
        cy.answered(t0, 0, 2, 5, 5);
        // The last 2 output frames consumed, 3 input frames made since
        // (the RxFIFO ran dry for one cycle): never more than the output
        // side shows.
        assert_eq!(cy.inputs_lost(0, 3), 0);
    }
}
