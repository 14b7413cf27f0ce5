//! Keeping the chip's RxFIFO fed and its TxFIFO drained (v049
//! PDO_DATA_FIFO_OP): the chip consumes one output frame and produces one
//! input frame per DC cycle; running the RxFIFO dry in OP is the failure to
//! avoid.
//!
//! The header's FIFO counts are two exchanges late (vendor comment;
//! PROTOCOL-NOTES). The estimate of the level therefore starts from the
//! count as it was two exchanges ago, adds what was pushed since, and takes
//! off one frame per cycle elapsed since then.
//!
//! Input frames go out through a wait-free single-producer ring of bytes:
//! each record is `len: u32, seq: u64, time_ns: u64` followed by the frame.
//! Nothing here allocates or locks once running.

use std::time::{Duration, Instant};

use rtrb::Producer;

/// Bytes before each frame in the input ring.
pub const RECORD_HEADER: usize = 4 + 8 + 8;

/// Frame sizes, cycle and marks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Plan {
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
}

/// The cyclic state.
#[derive(Debug)]
pub struct Cyclic {
    /// Output frame size.
    pub rx_size: usize,
    /// Input frame size.
    pub tx_size: usize,
    cycle: Duration,
    /// The host-side output image, pushed as every new frame.
    pub outputs: Vec<u8>,
    push_buf: Vec<u8>,
    low: u8,
    high: u8,
    /// (time, frames pushed) of the last three exchanges, newest last.
    recent: [(Instant, u8); 3],
    /// Level reported, and when it was true.
    reported: (u8, Instant),
    seq: u64,
    epoch: Instant,
    epoch_started: Instant,
    ring: Producer<u8>,
    /// Input frames dropped because the ring was full.
    pub ring_overflows: u64,
}

impl Cyclic {
    /// A plan, the packet's data size and the ring to publish into.
    pub fn new(plan: Plan, data_size: usize, ring: Producer<u8>, epoch: Instant) -> Self {
        let now = Instant::now();
        let Plan { rx_size, tx_size, cycle, low, high } = plan;
        Self {
            rx_size,
            tx_size,
            cycle,
            outputs: vec![0; rx_size],
            push_buf: Vec::with_capacity(data_size),
            low,
            high,
            recent: [(now, 0); 3],
            reported: (0, now),
            seq: 0,
            epoch,
            epoch_started: now,
            ring,
            ring_overflows: 0,
        }
    }

    fn cycles_since(&self, t: Instant, now: Instant) -> u64 {
        (now.saturating_duration_since(t).as_nanos() / self.cycle.as_nanos().max(1)) as u64
    }

    /// The estimated RxFIFO level now.
    pub fn estimate(&self, now: Instant) -> i64 {
        let (count, at) = self.reported;
        let pushed: i64 = self.recent.iter().filter(|(t, _)| *t >= at).map(|(_, n)| i64::from(*n)).sum();
        i64::from(count) + pushed - self.cycles_since(at, now) as i64
    }

    /// The level aimed at: midway between the marks.
    fn target(&self) -> i64 {
        (i64::from(self.low) + i64::from(self.high)) / 2
    }

    /// Frames to push in an exchange now, at most `room`.
    pub fn frames_to_push(&self, now: Instant, room: usize) -> u8 {
        (self.target() - self.estimate(now)).clamp(0, room.min(255) as i64) as u8
    }

    /// When the next exchange should happen: when the level has fallen one
    /// packet (`rx_room` frames) below the target, so one exchange brings it
    /// back; before the TxFIFO holds more than one packet of inputs; and
    /// never later than half the gap between the marks, so an estimate that
    /// is off (the lag is the chip's, not a law) is corrected soon.
    pub fn next_exchange(&self, now: Instant, rx_room: usize, tx_room: usize) -> Instant {
        let refill_at = self.target() - rx_room as i64;
        let by_level = self.cycle * (self.estimate(now) - refill_at).max(0) as u32;
        let by_inputs = self.cycle * (tx_room.max(1) as u32);
        let cap = self.cycle * u32::from((self.high - self.low).max(2) / 2);
        now + by_level.min(by_inputs).min(cap)
    }

    /// The bytes of `n` output frames, each the current image.
    pub fn push_bytes(&mut self, n: u8) -> &[u8] {
        self.push_buf.clear();
        for _ in 0..n {
            self.push_buf.extend_from_slice(&self.outputs);
        }
        &self.push_buf
    }

    /// Records an exchange that pushed `n` frames and whose answer (if
    /// intact) reported `count` frames queued.
    pub fn exchanged(&mut self, now: Instant, pushed: u8, count: Option<u8>) {
        self.recent.rotate_left(1);
        self.recent[2] = (now, pushed);
        if let Some(c) = count {
            // The count was true two exchanges ago.
            self.reported = (c, self.recent[0].0);
        }
    }

    /// Publishes the input frames in an answer's data; returns how many.
    pub fn publish(&mut self, data: &[u8], now: Instant) -> usize {
        if self.tx_size == 0 {
            return 0;
        }
        let t = now.saturating_duration_since(self.epoch).as_nanos() as u64;
        let mut n = 0;
        for frame in data.chunks_exact(self.tx_size) {
            self.seq += 1;
            let need = RECORD_HEADER + frame.len();
            let Ok(mut chunk) = self.ring.write_chunk(need) else {
                self.ring_overflows += 1;
                continue;
            };
            let (a, b) = chunk.as_mut_slices();
            let mut record = [0u8; RECORD_HEADER];
            record[..4].copy_from_slice(&(frame.len() as u32).to_le_bytes());
            record[4..12].copy_from_slice(&self.seq.to_le_bytes());
            record[12..20].copy_from_slice(&t.to_le_bytes());
            for (slot, byte) in a.iter_mut().chain(b.iter_mut()).zip(record.iter().chain(frame.iter())) {
                *slot = *byte;
            }
            chunk.commit_all();
            n += 1;
        }
        n
    }

    /// When the last exchange was, if any.
    pub fn last_exchange(&self) -> Option<Instant> {
        let (t, _) = self.recent[2];
        (t > self.epoch_started).then_some(t)
    }

    /// The low mark.
    pub fn low(&self) -> u8 {
        self.low
    }

    /// Sequence number of the last frame published.
    pub fn seq(&self) -> u64 {
        self.seq
    }
}

/// One input frame as read back from the ring.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InputRecord {
    /// Frame sequence number (one per DC cycle received).
    pub seq: u64,
    /// When the engine received it, ns since the engine started.
    pub time_ns: u64,
    /// The frame.
    pub data: Vec<u8>,
}

/// Reads the next record from the ring's consumer side, if whole.
pub fn read_record(c: &mut rtrb::Consumer<u8>) -> Option<InputRecord> {
    // Records are committed whole, so a header means its frame is there too;
    // the check below only guards against a foreign writer.
    let available = c.slots();
    if available < RECORD_HEADER {
        return None;
    }
    let head = c.read_chunk(RECORD_HEADER).ok()?;
    let (a, b) = head.as_slices();
    let mut h = [0u8; RECORD_HEADER];
    for (d, s) in h.iter_mut().zip(a.iter().chain(b.iter())) {
        *d = *s;
    }
    let len = u32::from_le_bytes([h[0], h[1], h[2], h[3]]) as usize;
    if available < RECORD_HEADER + len {
        return None;
    }
    head.commit_all();
    let body = c.read_chunk(len).ok()?;
    let (a, b) = body.as_slices();
    let data: Vec<u8> = a.iter().chain(b.iter()).copied().collect();
    body.commit_all();
    Some(InputRecord {
        seq: u64::from_le_bytes(h[4..12].try_into().unwrap_or([0; 8])),
        time_ns: u64::from_le_bytes(h[12..20].try_into().unwrap_or([0; 8])),
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cyclic() -> (Cyclic, rtrb::Consumer<u8>) {
        let (p, c) = rtrb::RingBuffer::new(1024);
        let plan = Plan { rx_size: 4, tx_size: 3, cycle: Duration::from_micros(125), low: 8, high: 20 };
        (Cyclic::new(plan, 112, p, Instant::now()), c)
    }

    #[test]
    fn estimate_counts_pushes_and_consumption_since_the_report() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        cy.exchanged(t0, 10, None);
        cy.exchanged(t0 + Duration::from_micros(100), 5, None);
        cy.exchanged(t0 + Duration::from_micros(200), 0, Some(12));
        // Reported 12 as of t0, 15 pushed since, 8 cycles gone at t0+1 ms.
        assert_eq!(cy.estimate(t0 + Duration::from_millis(1)), 12 + 15 - 8);
        assert_eq!(cy.frames_to_push(t0 + Duration::from_millis(1), 9), 0);
        assert_eq!(cy.frames_to_push(t0 + Duration::from_millis(4), 9), 9);
    }

    #[test]
    fn records_round_trip_through_the_ring() {
        let (mut cy, mut c) = cyclic();
        assert_eq!(cy.publish(&[1, 2, 3, 4, 5, 6, 7], Instant::now()), 2, "whole frames only");
        let r1 = read_record(&mut c).unwrap();
        let r2 = read_record(&mut c).unwrap();
        assert_eq!((r1.seq, r1.data.as_slice()), (1, &[1, 2, 3][..]));
        assert_eq!((r2.seq, r2.data.as_slice()), (2, &[4, 5, 6][..]));
        assert!(read_record(&mut c).is_none());
        // A full ring drops frames and counts them.
        for _ in 0..100 {
            cy.publish(&[0; 3], Instant::now());
        }
        assert!(cy.ring_overflows > 0);
    }

    #[test]
    fn exchanges_are_planned_to_hold_the_target() {
        let (mut cy, _) = cyclic();
        let t0 = Instant::now();
        // Target 14, packet room 4: refill when the level reaches 10.
        cy.exchanged(t0, 0, Some(14));
        cy.exchanged(t0, 0, None);
        cy.exchanged(t0, 0, None);
        let at = cy.next_exchange(t0, 4, 100);
        assert_eq!(at.duration_since(t0), Duration::from_micros(125 * 4));
        // Far below target: now.
        cy.exchanged(t0, 0, Some(2));
        cy.exchanged(t0, 0, None);
        cy.exchanged(t0, 0, None);
        assert_eq!(cy.next_exchange(t0, 4, 100), t0);
    }

    #[test]
    fn fifo_depth_fits_the_memory() {
        use crate::engine::bringup::fit_fifo;
        assert_eq!(fit_fifo(32, 8, 20, 32, 53, 53), (32, 32, 8, 20), "fits: unchanged");
        assert_eq!(fit_fifo(255, 96, 192, 40, 53, 53), (255, 40, 96, 192), "255 x 53 + 40 x 53 fits");
        for (rx, tx) in [(80, 53), (400, 400), (1408, 1408), (1, 1408)] {
            let (d, t, l, h) = fit_fifo(255, 96, 192, 40, rx, tx);
            assert!(usize::from(d) * rx + usize::from(t) * tx <= 0x4000, "{rx}/{tx}: {d} x {rx} + {t} x {tx}");
            assert!(l < h && h <= d && t >= 1, "{rx}/{tx}: {d} {t} {l} {h}");
        }
    }

    #[test]
    fn push_bytes_repeat_the_image() {
        let (mut cy, _) = cyclic();
        cy.outputs.copy_from_slice(&[1, 2, 3, 4]);
        assert_eq!(cy.push_bytes(2), &[1, 2, 3, 4, 1, 2, 3, 4]);
    }
}
