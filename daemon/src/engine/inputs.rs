//! Input frames out of the engine: a wait-free single-producer ring of
//! bytes that lives as long as the engine, across every recovery (a ring
//! tied to one run of the cyclic exchange was lost with it, and subscribers
//! never heard from the network again).
//!
//! Each record is `len: u32, seq: u64, time_ns: u64, gap: u64` followed by
//! the frame. `seq` numbers DC cycles: frames the engine never received (a
//! recovery, the time the network was down) leave a hole of that many
//! numbers, and `gap` on the first frame after the hole says how many, so a
//! subscriber can tell "the network was down for N cycles" from "I fell
//! behind". The gap across a recovery is estimated from the time since the
//! last frame and the cycle time (the chip restarts its cycle counting at
//! bring-up, so there is nothing better to count).
//!
//! The distributor reads each record straight back into the
//! [`InputFrame`] subscribers get ([`read_frame`]): one copy out of the
//! ring, no intermediate type.
//!
//! Nothing here allocates or locks.

use std::time::{Duration, Instant};

use rtrb::Producer;

/// Bytes before each frame in the input ring.
pub(crate) const RECORD_HEADER: usize = 4 + 8 + 8 + 8;

/// The engine's side of the input ring.
#[derive(Debug)]
pub(crate) struct InputPublisher {
    ring: Producer<u8>,
    epoch: Instant,
    /// Sequence number of the last frame received.
    seq: u64,
    /// When the last frame was received.
    last_frame: Option<Instant>,
    /// Cycles missed before the next frame.
    pending_gap: u64,
    /// Frames received from the chip (published or not).
    pub received: u64,
    /// Frames dropped because the ring was full (the distributor fell
    /// behind; subscribers never saw them).
    pub ring_overflows: u64,
}

impl InputPublisher {
    /// A publisher into `ring`; frame times count from `epoch`.
    pub(crate) fn new(ring: Producer<u8>, epoch: Instant) -> Self {
        Self { ring, epoch, seq: 0, last_frame: None, pending_gap: 0, received: 0, ring_overflows: 0 }
    }

    /// A new run of the cyclic exchange starts at `now` (after bring-up or
    /// recovery) with DC cycle `cycle`: the cycles since the last frame
    /// received are frames that will never come, and are numbered as such.
    pub(crate) fn resume(&mut self, now: Instant, cycle: Duration) {
        if let Some(t) = self.last_frame {
            let missed = now.saturating_duration_since(t).as_nanos() / cycle.as_nanos().max(1);
            self.pending_gap = self.pending_gap.saturating_add(u64::try_from(missed).unwrap_or(u64::MAX));
        }
    }

    /// `n` input frames the chip dropped before the next ones: numbered
    /// as a gap before them.
    pub(crate) fn lost(&mut self, n: u64) {
        self.pending_gap = self.pending_gap.saturating_add(n);
    }

    /// Publishes the input frames of `frame_size` bytes in an answer's
    /// data; returns how many frames were received (whether or not the ring
    /// had room for them).
    pub(crate) fn publish(&mut self, data: &[u8], frame_size: usize, now: Instant) -> usize {
        if frame_size == 0 {
            return 0;
        }
        let t = now.saturating_duration_since(self.epoch).as_nanos() as u64;
        let mut n = 0;
        for frame in data.chunks_exact(frame_size) {
            n += 1;
            let gap = std::mem::take(&mut self.pending_gap);
            self.seq = self.seq.saturating_add(gap + 1);
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
            record[20..28].copy_from_slice(&gap.to_le_bytes());
            for (slot, byte) in a.iter_mut().chain(b.iter_mut()).zip(record.iter().chain(frame.iter())) {
                *slot = *byte;
            }
            chunk.commit_all();
        }
        if n > 0 {
            self.last_frame = Some(now);
            self.received += n as u64;
        }
        n
    }

    /// Sequence number of the last frame received.
    pub(crate) fn seq(&self) -> u64 {
        self.seq
    }
}

/// One input frame (one DC cycle's inputs).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InputFrame {
    /// DC-cycle sequence number: +1 per cycle, across recoveries too.
    pub seq: u64,
    /// When the engine received it, ns since start.
    pub time_ns: u64,
    /// Cycles just before this frame that the engine never received (the
    /// network was down, being recovered): 0 in steady operation.
    pub gap: u64,
    /// The frame.
    pub data: Vec<u8>,
}

/// Reads the next frame from the ring's consumer side, if its record is
/// whole: the frame subscribers get, its bytes copied once, out of the ring.
pub(crate) fn read_frame(c: &mut rtrb::Consumer<u8>) -> Option<InputFrame> {
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
    let mut data = Vec::with_capacity(len);
    data.extend_from_slice(a);
    data.extend_from_slice(b);
    body.commit_all();
    let word = |r: std::ops::Range<usize>| u64::from_le_bytes(h[r].try_into().unwrap_or([0; 8]));
    Some(InputFrame { seq: word(4..12), time_ns: word(12..20), gap: word(20..28), data })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn publisher(bytes: usize) -> (InputPublisher, rtrb::Consumer<u8>) {
        let (p, c) = rtrb::RingBuffer::new(bytes);
        (InputPublisher::new(p, Instant::now()), c)
    }

    #[test]
    fn frames_round_trip_through_the_ring() {
        let (mut p, mut c) = publisher(1024);
        assert_eq!(p.publish(&[1, 2, 3, 4, 5, 6, 7], 3, Instant::now()), 2, "whole frames only");
        let r1 = read_frame(&mut c).unwrap();
        let r2 = read_frame(&mut c).unwrap();
        assert_eq!((r1.seq, r1.gap, r1.data.as_slice()), (1, 0, &[1, 2, 3][..]));
        assert_eq!((r2.seq, r2.gap, r2.data.as_slice()), (2, 0, &[4, 5, 6][..]));
        assert!(read_frame(&mut c).is_none());
    }

    #[test]
    fn a_full_ring_counts_what_it_dropped_but_not_as_unreceived() {
        let (mut p, _c) = publisher(256);
        for _ in 0..100 {
            assert_eq!(p.publish(&[0; 3], 3, Instant::now()), 1);
        }
        assert!(p.ring_overflows > 0);
        assert_eq!(p.received, 100, "the chip's frames arrived; only the ring was full");
    }

    #[test]
    fn a_recovery_leaves_a_hole_of_the_cycles_missed() {
        let (mut p, mut c) = publisher(1024);
        let t0 = Instant::now();
        p.publish(&[1], 1, t0);
        // Down for 10 ms at 1 ms cycles: 10 frames never came.
        p.resume(t0 + Duration::from_millis(10), Duration::from_millis(1));
        p.publish(&[2, 3], 1, t0 + Duration::from_millis(11));
        let seqs: Vec<(u64, u64)> = std::iter::from_fn(|| read_frame(&mut c)).map(|r| (r.seq, r.gap)).collect();
        assert_eq!(seqs, [(1, 0), (12, 10), (13, 0)]);
    }

    #[test]
    fn the_first_run_has_no_gap() {
        let (mut p, mut c) = publisher(1024);
        p.resume(Instant::now(), Duration::from_micros(125));
        p.publish(&[9], 1, Instant::now());
        let r = read_frame(&mut c).unwrap();
        assert_eq!((r.seq, r.gap), (1, 0));
    }
}
