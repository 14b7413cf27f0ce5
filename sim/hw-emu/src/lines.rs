//! INT0 and INT1 as the GPIO character device shows them: levels, and edge
//! events queued per line request with kernel timestamps and sequence
//! numbers (uAPI v2, `struct gpio_v2_line_event`).
//!
//! INT0's level is a function of when the chip is ready again (v049
//! ECM-XF中斷: it drops when a packet is complete, rises when it has been
//! processed), so the process that clocks the chip knows it without
//! asking: every transfer's reply says how many packets the chip took and
//! when it is ready again ([`ecmxf_sim::server::Forecast`]), and
//! [`Int0`] turns that into edges, the last one timed in the future.
//! What no transfer causes (a fault holding the line, INT1's events) is
//! seen when a wait or a level read asks the simulator. Times are
//! parameters (CLOCK_MONOTONIC ns), so all of it is unit-tested.

use std::collections::VecDeque;

use ecmxf_sim::server::{Forecast, LINE_INT0, LINE_INT0_HELD, LINE_INT1};

use crate::uapi::{self, LineEvent, flag};

/// Edges kept for line requests that have not read them yet.
const HISTORY: usize = 4096;

/// INT0 in this process: its electrical level, the edges it made, and the
/// one the chip will make when it is ready.
#[derive(Clone, Debug, Default)]
pub struct Int0 {
    level: Option<bool>,
    pending: Option<(u64, bool)>,
    history: VecDeque<(u64, bool)>,
    /// Index of `history[0]` among all edges since the start.
    first: u64,
}

impl Int0 {
    /// Whether the level is known (a request reads it from the simulator
    /// first).
    pub fn known(&self) -> bool {
        self.level.is_some()
    }

    fn edge(&mut self, at: u64, level: bool) {
        if self.level == Some(level) {
            return;
        }
        if self.level.is_some() {
            if self.history.len() == HISTORY {
                self.history.pop_front();
                self.first += 1;
            }
            self.history.push_back((at, level));
        }
        self.level = Some(level);
    }

    /// Makes the forecast edge happen when its time has come.
    pub fn advance(&mut self, now: u64) {
        if let Some((at, level)) = self.pending.filter(|(at, _)| *at <= now) {
            self.pending = None;
            self.edge(at, level);
        }
    }

    /// The level at `now` (`false` when never known).
    pub fn level(&mut self, now: u64) -> bool {
        self.advance(now);
        self.level.unwrap_or(false)
    }

    /// When the forecast edge is due.
    pub fn next_edge_at(&self) -> Option<u64> {
        self.pending.map(|(at, _)| at)
    }

    fn forecast(&mut self, now: u64, lines: u8, forecast: &Forecast) {
        let ready = forecast.ready_lines & LINE_INT0 != 0;
        self.pending = (forecast.ready_lines & LINE_INT0_HELD == 0
            && forecast.until_ready_ns > 0
            && ready != (lines & LINE_INT0 != 0))
            .then_some((now + forecast.until_ready_ns, ready));
    }

    /// A transfer clocked from `start` to `end`: each packet the chip took
    /// made INT0 go busy and, but for the last one while it still works,
    /// ready again; then the line is at `lines`' level, and the forecast
    /// says when it moves next.
    pub fn transferred(&mut self, start: u64, end: u64, lines: u8, forecast: &Forecast) {
        self.advance(start);
        let ready = forecast.ready_lines & LINE_INT0 != 0;
        if forecast.ready_lines & LINE_INT0_HELD == 0 && self.level.is_some() {
            let packets = u64::from(forecast.packets);
            let steps = 2 * packets + 1;
            let at = |i: u64| start + (end.saturating_sub(start)) * (i + 1) / steps;
            for p in 0..packets {
                self.edge(at(2 * p), !ready);
                if p + 1 < packets || forecast.until_ready_ns == 0 {
                    self.edge(at(2 * p + 1), ready);
                }
            }
        }
        self.edge(end, lines & LINE_INT0 != 0);
        self.forecast(end, lines, forecast);
    }

    /// The simulator said the lines are `lines` at `now` (a wait or a
    /// level read).
    pub fn observed(&mut self, now: u64, lines: u8, forecast: &Forecast) {
        self.advance(now);
        self.edge(now, lines & LINE_INT0 != 0);
        self.forecast(now, lines, forecast);
    }

    /// Index of the next edge to happen.
    pub fn cursor(&self) -> u64 {
        self.first + self.history.len() as u64
    }

    /// Edges from index `from` on: (index, time, level). Edges older than
    /// the history are gone (the reader overflowed).
    pub fn edges_since(&self, from: u64) -> impl Iterator<Item = (u64, u64, bool)> + '_ {
        let skip = from.saturating_sub(self.first) as usize;
        self.history.iter().enumerate().skip(skip).map(|(i, (t, l))| (self.first + i as u64, *t, *l))
    }
}

/// What a requested line is wired to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wire {
    /// The chip's INT0.
    Int0,
    /// The chip's INT1.
    Int1,
    /// Nothing: an input pulled low.
    Other,
}

/// One line of a request.
#[derive(Clone, Debug)]
pub struct Line {
    /// Its offset on the chip.
    pub offset: u32,
    /// What it is wired to.
    pub wire: Wire,
    /// Its `GPIO_V2_LINE_FLAG_*`.
    pub flags: u64,
    /// Software debounce, ns.
    pub debounce_ns: u64,
    /// The value driven, as an output.
    pub output: bool,
    /// Events of this line so far.
    pub seqno: u32,
    /// INT1's level as last seen.
    pub int1: Option<bool>,
    /// Index of the next INT0 edge this line has not looked at.
    pub cursor: u64,
}

impl Line {
    fn logical(&self, level: bool) -> bool {
        level != (self.flags & flag::ACTIVE_LOW != 0)
    }

    fn wants(&self, logical: bool) -> bool {
        self.flags & if logical { flag::EDGE_RISING } else { flag::EDGE_FALLING } != 0
    }
}

/// Checks one line's flags as the kernel does (gpio_v2_line_flags_validate):
/// EINVAL for unknown or contradictory flags, edges without input.
pub fn validate(flags: u64) -> Result<(), i32> {
    let both = |a: u64, b: u64| flags & a != 0 && flags & b != 0;
    let bias = [flag::BIAS_PULL_UP, flag::BIAS_PULL_DOWN, flag::BIAS_DISABLED];
    let invalid = flags & !flag::ALL != 0
        || flags & flag::USED != 0
        || both(flag::INPUT, flag::OUTPUT)
        || both(flag::EVENT_CLOCK_REALTIME, flag::EVENT_CLOCK_HTE)
        || (flags & (flag::EDGE_RISING | flag::EDGE_FALLING) != 0 && flags & flag::INPUT == 0)
        || (flags & (flag::OPEN_DRAIN | flag::OPEN_SOURCE) != 0 && flags & flag::OUTPUT == 0)
        || both(flag::OPEN_DRAIN, flag::OPEN_SOURCE)
        || (flags & (flag::INPUT | flag::OUTPUT) == 0 && flags & (flag::OPEN_DRAIN | flag::OPEN_SOURCE) != 0)
        || bias.iter().filter(|b| flags & **b != 0).count() > 1
        || (flags & bias.iter().fold(0, |a, b| a | b) != 0 && flags & (flag::INPUT | flag::OUTPUT) == 0);
    if invalid { Err(libc::EINVAL) } else { Ok(()) }
}

/// A line request's lines and queued events.
#[derive(Clone, Debug)]
pub struct Request {
    /// The lines, in request order.
    pub lines: Vec<Line>,
    events: VecDeque<LineEvent>,
    capacity: usize,
    seqno: u32,
}

impl Request {
    /// A request for `lines`, keeping `capacity` events (0: 16 per line,
    /// the kernel's default).
    pub fn new(lines: Vec<Line>, capacity: u32) -> Self {
        let capacity = if capacity == 0 { 16 * lines.len() } else { capacity as usize };
        Self { lines, events: VecDeque::new(), capacity: capacity.clamp(1, 16 * uapi::LINES_MAX), seqno: 0 }
    }

    /// Whether the request has a line on `wire`.
    pub fn has(&self, wire: Wire) -> bool {
        self.lines.iter().any(|l| l.wire == wire)
    }

    /// Whether any line detects edges (else nothing ever becomes readable).
    pub fn detects_edges(&self) -> bool {
        self.lines.iter().any(|l| l.flags & (flag::EDGE_RISING | flag::EDGE_FALLING) != 0)
    }

    fn push(&mut self, index: usize, at: u64, logical: bool, realtime_offset: i64) {
        self.seqno = self.seqno.wrapping_add(1);
        let line = &mut self.lines[index];
        line.seqno = line.seqno.wrapping_add(1);
        let timestamp_ns =
            if line.flags & flag::EVENT_CLOCK_REALTIME != 0 { at.saturating_add_signed(realtime_offset) } else { at };
        if self.events.len() == self.capacity {
            // The kernel's kfifo drops the oldest; the numbers go on.
            self.events.pop_front();
        }
        self.events.push_back(LineEvent {
            timestamp_ns,
            id: if logical { uapi::EVENT_RISING } else { uapi::EVENT_FALLING },
            offset: line.offset,
            seqno: self.seqno,
            line_seqno: line.seqno,
            padding: [0; 6],
        });
    }

    /// Queues INT0's edges up to `now` for the lines on INT0 that detect
    /// them. A debounced line drops pulses shorter than its period, and an
    /// edge is reported once the line has been stable that long.
    pub fn collect(&mut self, int0: &Int0, now: u64, realtime_offset: i64) {
        for i in 0..self.lines.len() {
            if self.lines[i].wire != Wire::Int0 {
                continue;
            }
            let edges: Vec<(u64, u64, bool)> = int0.edges_since(self.lines[i].cursor).collect();
            let debounce = self.lines[i].debounce_ns;
            let mut k = 0;
            while let Some(&(index, at, level)) = edges.get(k) {
                let next = edges.get(k + 1);
                if debounce > 0 {
                    if let Some(&(after, _, _)) = next.filter(|n| n.1 - at < debounce) {
                        // A pulse shorter than the period: both edges vanish.
                        self.lines[i].cursor = after + 1;
                        k += 2;
                        continue;
                    }
                    if next.is_none() && now < at + debounce {
                        break;
                    }
                }
                let logical = self.lines[i].logical(level);
                if self.lines[i].wants(logical) {
                    self.push(i, at + debounce, logical, realtime_offset);
                }
                self.lines[i].cursor = index + 1;
                k += 1;
            }
        }
    }

    /// INT1 (or another line) was seen at `level` at `now`: an edge if it
    /// moved.
    pub fn int1_seen(&mut self, now: u64, level: bool, realtime_offset: i64) {
        for i in 0..self.lines.len() {
            if self.lines[i].wire != Wire::Int1 {
                continue;
            }
            let before = self.lines[i].int1.replace(level);
            if before.is_some_and(|b| b != level) {
                let logical = self.lines[i].logical(level);
                if self.lines[i].wants(logical) {
                    self.push(i, now, logical, realtime_offset);
                }
            }
        }
    }

    /// Whether events wait to be read.
    pub fn readable(&self) -> bool {
        !self.events.is_empty()
    }

    /// Takes up to `n` events.
    pub fn take(&mut self, n: usize) -> Vec<LineEvent> {
        let n = n.min(self.events.len());
        self.events.drain(..n).collect()
    }

    /// The logical value of line `index` given the electrical levels.
    pub fn value(&self, index: usize, int0: bool, int1: bool) -> bool {
        let line = &self.lines[index];
        let level = if line.flags & flag::OUTPUT != 0 {
            return line.output;
        } else {
            match line.wire {
                Wire::Int0 => int0,
                Wire::Int1 => int1,
                Wire::Other => false,
            }
        };
        line.logical(level)
    }
}

/// INT1's bit of a lines byte.
pub fn int1(lines: u8) -> bool {
    lines & LINE_INT1 != 0
}

#[cfg(test)]
mod tests {
    use super::*;

    const BOTH: u64 = flag::INPUT | flag::EDGE_RISING | flag::EDGE_FALLING;

    fn line(wire: Wire, flags: u64) -> Line {
        Line { offset: 24, wire, flags, debounce_ns: 0, output: false, seqno: 0, int1: None, cursor: 0 }
    }

    fn forecast(packets: u32, until_ready_ns: u64, ready: bool) -> Forecast {
        Forecast { packets, until_ready_ns, ready_lines: u8::from(ready) }
    }

    fn known_high() -> Int0 {
        let mut int0 = Int0::default();
        int0.observed(0, LINE_INT0, &forecast(0, 0, true));
        int0
    }

    #[test]
    fn a_packet_makes_a_falling_edge_now_and_a_rising_one_when_processed() {
        let mut int0 = known_high();
        let mut req = Request::new(vec![line(Wire::Int0, BOTH)], 0);
        int0.transferred(1_000, 2_000, 0, &forecast(1, 30_000, true));
        assert!(!int0.level(2_000));
        assert_eq!(int0.next_edge_at(), Some(32_000));
        req.collect(&int0, 2_000, 0);
        let falling = req.take(8);
        assert_eq!(falling.len(), 1);
        assert_eq!((falling[0].id, falling[0].seqno, falling[0].line_seqno), (uapi::EVENT_FALLING, 1, 1));
        assert!(!req.readable());
        assert!(int0.level(32_000));
        req.collect(&int0, 32_000, 0);
        let rising = req.take(8);
        assert_eq!((rising[0].id, rising[0].timestamp_ns, rising[0].seqno), (uapi::EVENT_RISING, 32_000, 2));
    }

    #[test]
    fn packets_finished_within_a_transfer_make_both_edges_each() {
        let mut int0 = known_high();
        let mut req = Request::new(vec![line(Wire::Int0, BOTH)], 0);
        int0.transferred(0, 10_000, LINE_INT0, &forecast(3, 0, true));
        req.collect(&int0, 10_000, 0);
        let ev = req.take(16);
        assert_eq!(ev.len(), 6);
        assert!(ev.windows(2).all(|w| w[0].timestamp_ns < w[1].timestamp_ns && w[0].id != w[1].id));
    }

    #[test]
    fn a_held_line_makes_no_edges() {
        let mut int0 = known_high();
        let mut req = Request::new(vec![line(Wire::Int0, BOTH)], 0);
        let held = Forecast { packets: 2, until_ready_ns: 30_000, ready_lines: LINE_INT0 | LINE_INT0_HELD };
        int0.transferred(0, 1_000, LINE_INT0, &held);
        req.collect(&int0, 100_000, 0);
        assert!(!req.readable());
        assert_eq!(int0.next_edge_at(), None);
    }

    #[test]
    fn active_low_inverts_values_and_edge_ids_and_flags_filter_edges() {
        let mut int0 = known_high();
        let mut req = Request::new(vec![line(Wire::Int0, flag::INPUT | flag::ACTIVE_LOW | flag::EDGE_RISING)], 0);
        int0.transferred(0, 1_000, 0, &forecast(1, 5_000, true));
        req.collect(&int0, 10_000, 0);
        let ev = req.take(8);
        // Electrical fall = logical rise (reported); the electrical rise is a
        // logical fall, not asked for.
        assert_eq!(ev.len(), 1);
        assert_eq!(ev[0].id, uapi::EVENT_RISING);
        assert!(!req.value(0, true, false));
    }

    #[test]
    fn a_short_pulse_vanishes_under_debounce() {
        let mut int0 = known_high();
        let mut l = line(Wire::Int0, BOTH);
        l.debounce_ns = 100_000;
        let mut req = Request::new(vec![l], 0);
        int0.transferred(0, 1_000, 0, &forecast(1, 30_000, true));
        assert!(int0.level(1_000_000));
        req.collect(&int0, 1_000_000, 0);
        assert!(!req.readable(), "a 30 us busy pulse under a 100 us debounce");
        // A busy period longer than the period is reported, late by it.
        int0.transferred(2_000_000, 2_001_000, 0, &forecast(1, 500_000, true));
        req.collect(&int0, 2_050_000, 0);
        assert!(!req.readable(), "not stable for 100 us yet");
        assert!(int0.level(3_000_000));
        req.collect(&int0, 3_000_000, 0);
        let ev = req.take(4);
        assert_eq!(ev.len(), 2);
        assert_eq!(ev[1].timestamp_ns, 2_501_000 + 100_000);
    }

    #[test]
    fn a_full_queue_drops_the_oldest_and_numbers_go_on() {
        let mut int0 = known_high();
        let mut req = Request::new(vec![line(Wire::Int0, BOTH)], 4);
        int0.transferred(0, 10_000, LINE_INT0, &forecast(5, 0, true));
        req.collect(&int0, 10_000, 0);
        let ev = req.take(16);
        assert_eq!(ev.len(), 4);
        assert_eq!(ev[0].seqno, 7);
        assert_eq!(ev[3].seqno, 10);
    }

    #[test]
    fn the_kernels_flag_rules() {
        assert_eq!(validate(BOTH), Ok(()));
        assert_eq!(validate(flag::EDGE_RISING), Err(libc::EINVAL));
        assert_eq!(validate(flag::INPUT | flag::OUTPUT), Err(libc::EINVAL));
        assert_eq!(validate(flag::INPUT | flag::BIAS_PULL_UP | flag::BIAS_PULL_DOWN), Err(libc::EINVAL));
        assert_eq!(validate(1 << 20), Err(libc::EINVAL));
    }

    #[test]
    fn int1_changes_seen_become_edges() {
        let mut req = Request::new(vec![line(Wire::Int1, BOTH)], 0);
        req.int1_seen(10, true, 0);
        assert!(!req.readable(), "the first look only learns the level");
        req.int1_seen(20, false, 0);
        assert_eq!(req.take(4)[0].id, uapi::EVENT_FALLING);
    }
}
