//! The PDO FIFOs (v049 FIFO_SET_TX_CNT/RX_CNT notes, PDO_DATA_FIFO_OP):
//! RxFIFO holds output frames the host pushed, consumed one per DC cycle;
//! TxFIFO holds input frames produced one per cycle, pulled by the host.
//! Depths share 0x4000 bytes. TxFIFO full drops the OLDEST frame (the host
//! always finds the newest data); RxFIFO full drops the NEWEST (it cannot be
//! stored).

use std::collections::VecDeque;

use ecmxf_wire::payload::fifo::{FIFO_BUDGET, FIFO_DEFAULT_DEPTH};

/// Both FIFOs and their settings.
#[derive(Clone, Debug)]
pub struct Fifos {
    /// Output frames waiting to be sent.
    pub rx: VecDeque<Vec<u8>>,
    /// Input frames waiting for the host.
    pub tx: VecDeque<Vec<u8>>,
    /// RxFIFO depth in force.
    pub rx_depth: u8,
    /// TxFIFO depth in force.
    pub tx_depth: u8,
    /// RxFIFO depth set with 54, applied by FIFO_INIT.
    pub rx_depth_set: u8,
    /// TxFIFO depth set with 52, applied by FIFO_INIT.
    pub tx_depth_set: u8,
    /// Cyclic output from the RxFIFO enabled (FIFO_ENABLE).
    pub enabled: bool,
    /// TxFIFO high mark, when enabled.
    pub tx_high: Option<u8>,
    /// RxFIFO low mark, when enabled.
    pub rx_low: Option<u8>,
    /// Cycles that found the RxFIFO empty while enabled.
    pub underruns: u64,
    /// Output frames dropped because the RxFIFO was full.
    pub rx_dropped: u64,
    /// Input frames dropped because the TxFIFO was full.
    pub tx_dropped: u64,
    /// The output frames played, when a test asked for them (`record`).
    pub played: Option<PlayRecord>,
}

/// The output frames the chip played, one per DC cycle while the RxFIFO
/// feeds the slaves, as a test asked for them (control command `record`):
/// the exact sequence a host's frames reached the slaves in, with the
/// cycles that repeated the last frame because the RxFIFO was empty.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PlayRecord {
    /// The bytes kept of each frame: `start..start + len` of the output
    /// image (one slave's share, or all of it).
    pub start: usize,
    /// Bytes kept per frame.
    pub len: usize,
    /// Frames kept at most; later ones are counted, not kept.
    pub max: usize,
    /// The frames, oldest first.
    pub frames: Vec<PlayedFrame>,
    /// Frames played after `max` was reached.
    pub not_kept: u64,
}

/// One cycle's output frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlayedFrame {
    /// The chip's DC cycle count when it played.
    pub cycle: u64,
    /// The kept bytes.
    pub bytes: Vec<u8>,
    /// The RxFIFO was empty: the last frame repeated.
    pub repeated: bool,
}

/// How a record followed a sequence of frames ([`PlayRecord::follows`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Followed {
    /// Frames of the sequence that played.
    pub played: usize,
    /// Cycles that repeated a frame because the RxFIFO was empty.
    pub underruns: usize,
    /// Where (index into the frames) the sequence's last frame played.
    pub last_at: usize,
}

impl PlayedFrame {
    /// One line of the `recorded` control answer: `cycle hex [repeat]`.
    pub fn parse(line: &str) -> Option<Self> {
        let mut f = line.split_whitespace();
        let cycle = f.next()?.parse().ok()?;
        let hex = f.next().unwrap_or("");
        let bytes = (0..hex.len() / 2)
            .map(|i| u8::from_str_radix(hex.get(2 * i..2 * i + 2)?, 16).ok())
            .collect::<Option<_>>()?;
        Some(Self { cycle, bytes, repeated: f.next() == Some("repeat") })
    }
}

impl PlayRecord {
    /// Whether `frames` (oldest first) played `sequence` in order, each
    /// once, one per cycle, from where its first element shows: a frame
    /// may repeat only in a cycle marked as an underrun, and cycles count
    /// up by one. Says which cycle broke the sequence, and how.
    pub fn follows(frames: &[PlayedFrame], sequence: &[Vec<u8>]) -> Result<Followed, String> {
        if let Some(w) = frames.windows(2).find(|w| w[1].cycle != w[0].cycle + 1) {
            return Err(format!("no frame recorded between cycles {} and {}", w[0].cycle, w[1].cycle));
        }
        let Some(first) = sequence.first() else { return Ok(Followed { played: 0, underruns: 0, last_at: 0 }) };
        let Some(start) = frames.iter().position(|f| f.bytes == *first) else {
            return Err(format!("the first frame {first:02x?} never played"));
        };
        let mut out = Followed { played: 1, underruns: 0, last_at: start };
        for (i, w) in frames[start..].windows(2).enumerate() {
            if out.played == sequence.len() {
                break;
            }
            let (before, now) = (&w[0], &w[1]);
            if now.repeated && now.bytes == before.bytes {
                out.underruns += 1;
                continue;
            }
            let want = &sequence[out.played];
            if now.bytes != *want {
                return Err(format!(
                    "cycle {}: {:02x?} after {:02x?}, wanted {want:02x?} (a gap, an unmarked repeat or a reorder)",
                    now.cycle, now.bytes, before.bytes
                ));
            }
            out.played += 1;
            out.last_at = start + i + 1;
        }
        Ok(out)
    }

    /// Notes the frame of `cycle`.
    pub fn note(&mut self, cycle: u64, image: &[u8], repeated: bool) {
        if self.frames.len() >= self.max {
            self.not_kept += 1;
            return;
        }
        let bytes = image.get(self.start..self.start + self.len).unwrap_or_default().to_vec();
        self.frames.push(PlayedFrame { cycle, bytes, repeated });
    }
}

impl Default for Fifos {
    fn default() -> Self {
        Self {
            rx: VecDeque::new(),
            tx: VecDeque::new(),
            rx_depth: FIFO_DEFAULT_DEPTH,
            tx_depth: FIFO_DEFAULT_DEPTH,
            rx_depth_set: FIFO_DEFAULT_DEPTH,
            tx_depth_set: FIFO_DEFAULT_DEPTH,
            enabled: false,
            tx_high: None,
            rx_low: None,
            underruns: 0,
            rx_dropped: 0,
            tx_dropped: 0,
            played: None,
        }
    }
}

impl Fifos {
    /// Pushes an output frame; returns false when the RxFIFO was full and
    /// the frame was dropped.
    pub fn push_output(&mut self, frame: Vec<u8>) -> bool {
        if self.rx.len() >= usize::from(self.rx_depth) {
            self.rx_dropped += 1;
            return false;
        }
        self.rx.push_back(frame);
        true
    }

    /// Stores an input frame, dropping the oldest when full.
    pub fn push_input(&mut self, frame: Vec<u8>) {
        if self.tx_depth == 0 {
            self.tx_dropped += 1;
            return;
        }
        while self.tx.len() >= usize::from(self.tx_depth) {
            self.tx.pop_front();
            self.tx_dropped += 1;
        }
        self.tx.push_back(frame);
    }

    /// Applies the depths set with 52/54 (FIFO_INIT); fails when they do not
    /// fit the budget for these frame sizes.
    pub fn init(&mut self, rx_size: usize, tx_size: usize) -> bool {
        let need = usize::from(self.rx_depth_set) * rx_size + usize::from(self.tx_depth_set) * tx_size;
        if need > FIFO_BUDGET {
            return false;
        }
        self.rx_depth = self.rx_depth_set;
        self.tx_depth = self.tx_depth_set;
        self.rx.clear();
        self.tx.clear();
        true
    }

    /// Whether the TxFIFO is at or above its high mark.
    pub fn tx_high_reached(&self) -> bool {
        self.tx_high.is_some_and(|m| self.tx.len() >= usize::from(m))
    }

    /// Whether the RxFIFO is at or below its low mark.
    pub fn rx_low_reached(&self) -> bool {
        self.rx_low.is_some_and(|m| self.rx.len() <= usize::from(m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(cycle: u64, v: u8, repeated: bool) -> PlayedFrame {
        PlayedFrame { cycle, bytes: vec![v], repeated }
    }

    #[test]
    fn a_record_follows_a_sequence_only_in_order_once_each() {
        let seq: Vec<Vec<u8>> = (1..=3).map(|v| vec![v]).collect();
        let ok =
            [frame(9, 0, false), frame(10, 1, false), frame(11, 1, true), frame(12, 2, false), frame(13, 3, false)];
        assert_eq!(PlayRecord::follows(&ok, &seq), Ok(Followed { played: 3, underruns: 1, last_at: 4 }));
        let unmarked = [frame(10, 1, false), frame(11, 1, false), frame(12, 2, false)];
        assert!(PlayRecord::follows(&unmarked, &seq).unwrap_err().contains("cycle 11"));
        let gap = [frame(10, 1, false), frame(11, 3, false)];
        assert!(PlayRecord::follows(&gap, &seq).unwrap_err().contains("wanted [02]"));
        let hole = [frame(10, 1, false), frame(12, 2, false)];
        assert!(PlayRecord::follows(&hole, &seq).unwrap_err().contains("between cycles 10 and 12"));
        assert_eq!(
            PlayedFrame::parse("12 0a0b repeat"),
            Some(PlayedFrame { cycle: 12, bytes: vec![10, 11], repeated: true })
        );
        assert_eq!(PlayedFrame::parse("12 0a"), Some(frame(12, 10, false)));
        assert_eq!(PlayedFrame::parse("x"), None);
    }

    #[test]
    fn tx_full_drops_the_oldest() {
        let mut f = Fifos { tx_depth: 3, ..Fifos::default() };
        for i in 0..5u8 {
            f.push_input(vec![i]);
        }
        assert_eq!(f.tx.iter().map(|v| v[0]).collect::<Vec<_>>(), [2, 3, 4]);
        assert_eq!(f.tx_dropped, 2);
    }

    #[test]
    fn rx_full_drops_the_newest() {
        let mut f = Fifos { rx_depth: 2, ..Fifos::default() };
        assert!(f.push_output(vec![0]));
        assert!(f.push_output(vec![1]));
        assert!(!f.push_output(vec![2]));
        assert_eq!(f.rx.iter().map(|v| v[0]).collect::<Vec<_>>(), [0, 1]);
        assert_eq!(f.rx_dropped, 1);
    }

    #[test]
    fn budget_is_enforced_at_init() {
        let mut f = Fifos { rx_depth_set: 128, tx_depth_set: 128, ..Fifos::default() };
        assert!(f.init(64, 64));
        assert_eq!((f.rx_depth, f.tx_depth), (128, 128));
        f.rx_depth_set = 129;
        assert!(!f.init(64, 64));
        assert_eq!(f.rx_depth, 128, "a refused init changes nothing");
    }

    #[test]
    fn marks() {
        let mut f = Fifos { tx_high: Some(2), rx_low: Some(1), ..Fifos::default() };
        assert!(f.rx_low_reached() && !f.tx_high_reached());
        f.push_input(vec![]);
        f.push_input(vec![]);
        assert!(f.tx_high_reached());
        f.push_output(vec![]);
        f.push_output(vec![]);
        assert!(!f.rx_low_reached());
    }
}
