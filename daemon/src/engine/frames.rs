//! Per-cycle output frames a client streams (the chip plays one RxFIFO
//! frame per DC cycle, docs/protocol.md §12, so a host that queues distinct
//! frames gives the slaves a distinct setpoint every cycle). A stream covers one byte
//! range of the output image (its slaves' share); each frame pushed into
//! the RxFIFO takes the next queued frame into that range, so frames reach
//! the slaves in order, exactly one per cycle, none repeated or dropped
//! while the queue has frames. When the queue of an open stream runs dry
//! the dry frames are counted, the range keeps the last frame or is zeroed
//! ([`DryAction`], from `outputs.on_last_writer_gone`), and the engine is
//! told once per dry spell ([`FrameConsumer::take_dry_start`]). A stream
//! the client closed plays out and ends without a dry spell.
//!
//! The queue is a wait-free single-producer ring of fixed-size records
//! (`seq: u64` then the bytes) allocated by the producer's side; the engine
//! only copies out of it.
//!
//! Cause and effect: once the chip's answer to a FIFO call says how many
//! frames were queued ahead of the call's push, the engine knows the DC
//! cycle each frame of that push plays in ([`FrameConsumer::played`]), and
//! hands (`seq`, cycle) back through a second ring; the API pairs each with
//! the input frame of that cycle.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};

/// Bytes before each frame's bytes in the ring.
const SEQ_LEN: usize = 8;

/// Streams the engine feeds at once (each on its own slaves). The engine
/// holds room for this many from the start and never grows it.
pub const MAX_STREAMS: usize = 8;

/// Frames one FIFO call pushes at most (its `frames` parameter is a byte).
const PUSH_MAX: usize = 255;

/// A frame the chip played: the client's `seq` and the DC cycle it played
/// in, numbered as input frames are (`InputSample.seq`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Played {
    /// The client's number for the frame.
    pub seq: u64,
    /// The DC cycle it played in.
    pub cycle: u64,
}

/// What the engine did with a stream, readable by its producer.
#[derive(Debug, Default)]
pub struct StreamCounters {
    /// Frames taken from the queue into the RxFIFO.
    pub pushed: AtomicU64,
    /// The sequence number of the last frame taken.
    pub last_seq: AtomicU64,
    /// Frames pushed while the queue of the open stream was empty.
    pub dry: AtomicU64,
    /// The client sent its last frame ([`FrameProducer::close`]).
    closed: AtomicBool,
}

/// What a dry queue does to the stream's range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum DryAction {
    /// Keep the last frame (the chip's own behaviour on an empty RxFIFO).
    Hold,
    /// Zero the range.
    Zero,
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
    played: rtrb::Consumer<Played>,
    len: usize,
    counters: Arc<StreamCounters>,
}

/// The engine's side.
#[derive(Debug)]
pub(crate) struct FrameConsumer {
    ring: rtrb::Consumer<u8>,
    /// What a dry queue does to the range.
    pub on_dry: DryAction,
    /// In a dry spell; whether the engine was told of its start.
    dry: Option<bool>,
    /// First byte of the range in the output image.
    pub start: usize,
    /// Bytes per frame.
    pub len: usize,
    counters: Arc<StreamCounters>,
    /// (index in the push, seq) of the frames taken into the push on its
    /// way, until its answer tells when they play.
    pending: Vec<(u8, u64)>,
    played: rtrb::Producer<Played>,
}

/// A stream of frames of `len` bytes for the output image's bytes
/// `start..start + len`, queuing up to `capacity` frames.
pub(crate) fn channel(start: usize, len: usize, capacity: usize) -> (FrameProducer, FrameConsumer) {
    let (p, c) = rtrb::RingBuffer::new(capacity.max(1) * (SEQ_LEN + len));
    // Room for every queued frame and a full push more: the producer's
    // side reads it at every report.
    let (played_p, played_c) = rtrb::RingBuffer::new(capacity.max(1) + PUSH_MAX);
    let counters = Arc::new(StreamCounters::default());
    (
        FrameProducer { ring: p, played: played_c, len, counters: Arc::clone(&counters) },
        FrameConsumer {
            ring: c,
            on_dry: DryAction::Hold,
            dry: None,
            start,
            len,
            counters,
            pending: Vec::with_capacity(PUSH_MAX),
            played: played_p,
        },
    )
}

/// Copies bytes `at..at + dst.len()` of a record the ring holds as two
/// slices (it wraps around the ring's end) into `dst`.
fn read_split(a: &[u8], b: &[u8], at: usize, dst: &mut [u8]) {
    let in_a = a.len().saturating_sub(at).min(dst.len());
    if in_a > 0 {
        dst[..in_a].copy_from_slice(&a[at..at + in_a]);
    }
    let from_b = (at + in_a).saturating_sub(a.len());
    let rest = dst.len() - in_a;
    dst[in_a..].copy_from_slice(&b[from_b..from_b + rest]);
}

/// Writes `src` at `at` of a record the ring holds as two slices.
fn write_split(a: &mut [u8], b: &mut [u8], at: usize, src: &[u8]) {
    let in_a = a.len().saturating_sub(at).min(src.len());
    if in_a > 0 {
        a[at..at + in_a].copy_from_slice(&src[..in_a]);
    }
    let from_b = (at + in_a).saturating_sub(a.len());
    b[from_b..from_b + src.len() - in_a].copy_from_slice(&src[in_a..]);
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
        write_split(a, b, 0, &seq.to_le_bytes());
        write_split(a, b, SEQ_LEN, bytes);
        chunk.commit_all();
        Ok(())
    }

    /// What the engine did with the stream.
    pub fn counters(&self) -> &StreamCounters {
        &self.counters
    }

    /// The next frame known to have played (in order), if any.
    pub fn next_played(&mut self) -> Option<Played> {
        self.played.pop().ok()
    }

    /// No more frames will come: the queue plays out and the stream ends,
    /// without counting the end as a dry spell.
    pub fn close(&self) {
        self.counters.closed.store(true, Relaxed);
    }
}

impl FrameConsumer {
    /// A new push starts: frames taken before whose answer never came
    /// (the call failed) are not reported as played.
    pub(crate) fn start_push(&mut self) {
        self.pending.clear();
    }

    /// Takes the next frame into `image` (its range) as frame `index` of
    /// the push on its way; `None` when the queue is empty (the image keeps
    /// the last frame: counted as dry).
    pub(crate) fn next_into(&mut self, image: &mut [u8], index: u8) -> Option<u64> {
        let Ok(chunk) = self.ring.read_chunk(SEQ_LEN + self.len) else {
            // Before the first frame, and after the client closed, an
            // empty queue is no shortage.
            if self.counters.closed.load(Relaxed) || self.counters.pushed.load(Relaxed) == 0 {
                return None;
            }
            self.counters.dry.fetch_add(1, Relaxed);
            self.dry.get_or_insert(false);
            if self.on_dry == DryAction::Zero {
                if let Some(dst) = image.get_mut(self.start..self.start + self.len) {
                    dst.fill(0);
                }
            }
            return None;
        };
        self.dry = None;
        let (a, b) = chunk.as_slices();
        let mut seq = [0u8; SEQ_LEN];
        read_split(a, b, 0, &mut seq);
        if let Some(dst) = image.get_mut(self.start..self.start + self.len) {
            read_split(a, b, SEQ_LEN, dst);
        }
        chunk.commit_all();
        let seq = u64::from_le_bytes(seq);
        if self.pending.len() < self.pending.capacity() {
            self.pending.push((index, seq));
        }
        self.counters.pushed.fetch_add(1, Relaxed);
        self.counters.last_seq.store(seq, Relaxed);
        Some(seq)
    }

    /// The producer closed the stream or is gone, and every frame it
    /// queued was taken.
    pub(crate) fn finished(&self) -> bool {
        (self.ring.is_abandoned() || self.counters.closed.load(Relaxed)) && self.ring.is_empty()
    }

    /// Whether a dry spell started since the last call (once per spell):
    /// the engine reports it and applies what needs more than the image.
    pub(crate) fn take_dry_start(&mut self) -> bool {
        match self.dry {
            Some(false) => {
                self.dry = Some(true);
                true
            }
            _ => false,
        }
    }

    /// The push's answer came: its first frame plays in DC cycle
    /// `first_cycle`, each next one a cycle later. Frames the producer's
    /// side has no room for are not reported (it reads at every report).
    pub(crate) fn played(&mut self, first_cycle: u64) {
        for &(index, seq) in &self.pending {
            let _ = self.played.push(Played { seq, cycle: first_cycle + u64::from(index) });
        }
        self.pending.clear();
    }

    /// Frames taken so far.
    pub(crate) fn pushed(&self) -> u64 {
        self.counters.pushed.load(Relaxed)
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
        assert_eq!(c.next_into(&mut image, 0), Some(0));
        assert_eq!(image, [0xEE, 0xEE, 0, 0, 0, 0xEE]);
        assert_eq!(p.credits(), 1);
        for seq in 1..4 {
            assert_eq!(c.next_into(&mut image, 0), Some(seq));
        }
        assert_eq!(c.next_into(&mut image, 0), None, "dry: the image keeps the last frame");
        assert_eq!(image, [0xEE, 0xEE, 3, 3, 3, 0xEE]);
        let n = p.counters();
        assert_eq!((n.pushed.load(Relaxed), n.last_seq.load(Relaxed), n.dry.load(Relaxed)), (4, 3, 1));
        assert!(c.take_dry_start(), "a dry spell is told once");
        assert!(!c.take_dry_start());
        assert!(!c.finished());
        drop(p);
        assert!(c.finished());
    }

    #[test]
    fn an_empty_queue_before_the_first_frame_is_not_dry() {
        let (_p, mut c) = channel(0, 1, 4);
        let mut image = [7u8];
        assert_eq!(c.next_into(&mut image, 0), None);
        assert!(!c.take_dry_start());
        assert_eq!(c.counters.dry.load(Relaxed), 0);
    }

    #[test]
    fn a_closed_stream_plays_out_without_a_dry_spell_and_zero_clears_the_range() {
        let (p, mut c) = channel(0, 2, 4);
        let mut p = p;
        p.push(1, &[5, 5]).unwrap();
        p.close();
        let mut image = [9u8; 3];
        assert!(!c.finished(), "a frame is still queued");
        assert_eq!(c.next_into(&mut image, 0), Some(1));
        assert!(c.finished());
        assert_eq!(c.next_into(&mut image, 0), None);
        assert!(!c.take_dry_start());
        assert_eq!(p.counters().dry.load(Relaxed), 0);
        let (mut p, mut c) = channel(1, 2, 4);
        c.on_dry = DryAction::Zero;
        p.push(1, &[5, 5]).unwrap();
        c.next_into(&mut image, 0);
        assert_eq!(image, [5, 5, 5]);
        c.next_into(&mut image, 0);
        assert_eq!(image, [5, 0, 0], "zeroed when dry");
        assert!(c.take_dry_start());
    }

    #[test]
    fn a_record_split_at_the_ring_end_is_read_and_written_whole() {
        let record: Vec<u8> = (0..13).collect();
        for split in 0..=13 {
            let (mut a, mut b) = (vec![0u8; split], vec![0u8; 13 - split]);
            write_split(&mut a, &mut b, 0, &record[..8]);
            write_split(&mut a, &mut b, 8, &record[8..]);
            let joined: Vec<u8> = a.iter().chain(&b).copied().collect();
            assert_eq!(joined, record, "split at {split}");
            let (mut seq, mut data) = ([0u8; 8], [0u8; 5]);
            read_split(&a, &b, 0, &mut seq);
            read_split(&a, &b, 8, &mut data);
            assert_eq!((&seq[..], &data[..]), (&record[..8], &record[8..]), "split at {split}");
        }
    }

    #[test]
    fn records_wrap_around_the_ring() {
        let (mut p, mut c) = channel(0, 5, 3);
        let mut image = [0u8; 5];
        for seq in 0..100u64 {
            p.push(seq, &[seq as u8; 5]).unwrap();
            assert_eq!(c.next_into(&mut image, 0), Some(seq));
            assert_eq!(image, [seq as u8; 5]);
        }
    }

    #[test]
    fn each_frame_of_a_push_is_told_with_the_cycle_it_plays_in() {
        let (mut p, mut c) = channel(0, 1, 8);
        for seq in 10..15u64 {
            p.push(seq, &[seq as u8]).unwrap();
        }
        let mut image = [0u8; 1];
        // A push whose answer never came: its frame (10) is not reported.
        c.start_push();
        c.next_into(&mut image, 0);
        c.start_push();
        // The next push carries stream frames at indexes 1 and 2; 7 frames
        // were queued ahead of it and the newest cycle is 100: its first
        // frame plays in 108, so they play in 109 and 110.
        c.next_into(&mut image, 1);
        c.next_into(&mut image, 2);
        assert_eq!(p.next_played(), None, "not before the answer");
        c.played(100 + 7 + 1);
        assert_eq!(p.next_played(), Some(Played { seq: 11, cycle: 109 }));
        assert_eq!(p.next_played(), Some(Played { seq: 12, cycle: 110 }));
        assert_eq!(p.next_played(), None);
        c.played(200);
        assert_eq!(p.next_played(), None, "told once");
    }
}
