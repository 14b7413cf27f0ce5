//! Per-cycle output frames a client streams (issue 15: the chip plays one
//! RxFIFO frame per DC cycle, so a host that queues distinct frames gives
//! the slaves a distinct setpoint every cycle). A stream covers one byte
//! range of the output image (its slaves' share); each frame pushed into
//! the RxFIFO takes the next queued frame into that range, so frames reach
//! the slaves in order, exactly one per cycle, none repeated or dropped
//! while the queue has frames. When the queue runs dry the image keeps the
//! last frame (the chip would repeat it too) and the dry frames are
//! counted.
//!
//! The queue is a wait-free single-producer ring of fixed-size records
//! (`seq: u64` then the bytes) allocated by the producer's side; the engine
//! only copies out of it.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Bytes before each frame's bytes in the ring.
const SEQ_LEN: usize = 8;

/// What the engine did with a stream, readable by its producer.
#[derive(Debug, Default)]
pub struct StreamCounters {
    /// Frames taken from the queue into the RxFIFO.
    pub pushed: AtomicU64,
    /// The sequence number of the last frame taken.
    pub last_seq: AtomicU64,
    /// Frames pushed while the queue was empty (the last frame repeated).
    pub dry: AtomicU64,
}

/// Why a frame was not queued.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// No credit: the queue is full.
    Full,
    /// The frame's length is not the stream's.
    WrongLength {
        /// The stream's frame length.
        expected: usize,
        /// The frame's.
        found: usize,
    },
}

impl std::fmt::Display for FrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Full => f.write_str("the frame queue is full (no credit)"),
            Self::WrongLength { expected, found } => {
                write!(f, "a frame of {found} bytes; this stream's frames are {expected} bytes")
            }
        }
    }
}

impl std::error::Error for FrameError {}

/// The client's side: queues frames while it has credits.
#[derive(Debug)]
pub struct FrameProducer {
    ring: rtrb::Producer<u8>,
    len: usize,
    counters: Arc<StreamCounters>,
}

/// The engine's side.
#[derive(Debug)]
pub struct FrameConsumer {
    ring: rtrb::Consumer<u8>,
    /// First byte of the range in the output image.
    pub start: usize,
    /// Bytes per frame.
    pub len: usize,
    counters: Arc<StreamCounters>,
}

/// A stream of frames of `len` bytes for the output image's bytes
/// `start..start + len`, queuing up to `capacity` frames.
pub fn channel(start: usize, len: usize, capacity: usize) -> (FrameProducer, FrameConsumer) {
    let (p, c) = rtrb::RingBuffer::new(capacity.max(1) * (SEQ_LEN + len));
    let counters = Arc::new(StreamCounters::default());
    (FrameProducer { ring: p, len, counters: Arc::clone(&counters) }, FrameConsumer { ring: c, start, len, counters })
}

impl FrameProducer {
    /// Frames that may be queued now.
    pub fn credits(&self) -> usize {
        self.ring.slots() / (SEQ_LEN + self.len)
    }

    /// Queues one frame.
    pub fn push(&mut self, seq: u64, bytes: &[u8]) -> Result<(), FrameError> {
        if bytes.len() != self.len {
            return Err(FrameError::WrongLength { expected: self.len, found: bytes.len() });
        }
        let Ok(mut chunk) = self.ring.write_chunk(SEQ_LEN + self.len) else { return Err(FrameError::Full) };
        let (a, b) = chunk.as_mut_slices();
        let record = seq.to_le_bytes().into_iter().chain(bytes.iter().copied());
        for (dst, v) in a.iter_mut().chain(b.iter_mut()).zip(record) {
            *dst = v;
        }
        chunk.commit_all();
        Ok(())
    }

    /// What the engine did with the stream.
    pub fn counters(&self) -> &StreamCounters {
        &self.counters
    }
}

impl FrameConsumer {
    /// Takes the next frame into `image` (its range); `None` when the
    /// queue is empty (the image keeps the last frame: counted as dry).
    pub fn next_into(&mut self, image: &mut [u8]) -> Option<u64> {
        let Ok(chunk) = self.ring.read_chunk(SEQ_LEN + self.len) else {
            self.counters.dry.fetch_add(1, Relaxed);
            return None;
        };
        let (a, b) = chunk.as_slices();
        let mut bytes = a.iter().chain(b.iter()).copied();
        let mut seq = [0u8; SEQ_LEN];
        for (dst, v) in seq.iter_mut().zip(&mut bytes) {
            *dst = v;
        }
        if let Some(dst) = image.get_mut(self.start..self.start + self.len) {
            for (d, v) in dst.iter_mut().zip(bytes) {
                *d = v;
            }
        }
        chunk.commit_all();
        let seq = u64::from_le_bytes(seq);
        self.counters.pushed.fetch_add(1, Relaxed);
        self.counters.last_seq.store(seq, Relaxed);
        Some(seq)
    }

    /// The producer is gone and every frame it queued was taken.
    pub fn finished(&self) -> bool {
        self.ring.is_abandoned() && self.ring.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_come_out_in_order_once_each_and_credits_bound_the_queue() {
        let (mut p, mut c) = channel(2, 3, 4);
        assert_eq!(p.credits(), 4);
        for seq in 0..4u64 {
            p.push(seq, &[seq as u8; 3]).unwrap();
        }
        assert_eq!(p.push(9, &[9; 3]), Err(FrameError::Full));
        assert_eq!(p.push(9, &[9; 2]), Err(FrameError::WrongLength { expected: 3, found: 2 }));
        let mut image = [0xEE; 6];
        assert_eq!(c.next_into(&mut image), Some(0));
        assert_eq!(image, [0xEE, 0xEE, 0, 0, 0, 0xEE]);
        assert_eq!(p.credits(), 1);
        for seq in 1..4 {
            assert_eq!(c.next_into(&mut image), Some(seq));
        }
        assert_eq!(c.next_into(&mut image), None, "dry: the image keeps the last frame");
        assert_eq!(image, [0xEE, 0xEE, 3, 3, 3, 0xEE]);
        let n = p.counters();
        assert_eq!((n.pushed.load(Relaxed), n.last_seq.load(Relaxed), n.dry.load(Relaxed)), (4, 3, 1));
        assert!(!c.finished());
        drop(p);
        assert!(c.finished());
    }

    #[test]
    fn records_wrap_around_the_ring() {
        let (mut p, mut c) = channel(0, 5, 3);
        let mut image = [0u8; 5];
        for seq in 0..100u64 {
            p.push(seq, &[seq as u8; 5]).unwrap();
            assert_eq!(c.next_into(&mut image), Some(seq));
            assert_eq!(image, [seq as u8; 5]);
        }
    }
}
