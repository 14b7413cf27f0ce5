//! Client writes into the host-side output image on their way to the
//! engine: fixed-size chunks applied whole ([`OutputAssembler`]), and the
//! count of writers whose last departure triggers
//! `outputs.on_last_writer_gone` ([`Writers`]).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

/// One chunk of a write into the host-side output image. Fixed size, so
/// queuing one allocates nothing. A client write longer than one chunk is
/// several chunks with the same `batch`, queued back to back; the engine
/// applies them together (see [`OutputAssembler`]) so a frame never carries
/// half of a write, e.g. new targets for one axis and old ones for the next.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct OutputWrite {
    /// Which client write this chunk belongs to.
    pub batch: u32,
    /// Whether this is the write's last chunk.
    pub last: bool,
    /// Byte offset in the output frame.
    pub offset: u32,
    /// Bytes used of `data`.
    pub len: u8,
    /// The bytes.
    pub data: [u8; OUTPUT_CHUNK],
    /// When the client's write reached the daemon (for the write-to-wire
    /// latency).
    pub written: Instant,
}

/// Bytes per [`OutputWrite`].
pub(crate) const OUTPUT_CHUNK: usize = 32;

/// Collects the chunks of one client write and applies them at once.
#[derive(Debug)]
pub(crate) struct OutputAssembler {
    pending: Vec<OutputWrite>,
    batch: Option<u32>,
}

impl Default for OutputAssembler {
    fn default() -> Self {
        // 16 KiB of writes in one batch before the vector grows.
        Self { pending: Vec::with_capacity(512), batch: None }
    }
}

impl OutputAssembler {
    /// Takes a chunk; on a write's last chunk, copies the whole write into
    /// `image` (bytes beyond it are ignored). A write whose last chunk never
    /// came (its sender found the queue full) is dropped when the next one
    /// starts: a partial write is never applied. Returns when the write
    /// reached the daemon, once it is applied.
    pub(crate) fn push(&mut self, w: OutputWrite, image: Option<&mut [u8]>) -> Option<Instant> {
        if self.batch != Some(w.batch) {
            self.pending.clear();
            self.batch = Some(w.batch);
        }
        self.pending.push(w);
        if !w.last {
            return None;
        }
        let applied = image.is_some().then_some(w.written);
        if let Some(image) = image {
            for p in &self.pending {
                let at = p.offset as usize;
                let n = usize::from(p.len).min(OUTPUT_CHUNK);
                if let Some(dst) = image.get_mut(at..at + n) {
                    dst.copy_from_slice(&p.data[..n]);
                }
            }
        }
        self.pending.clear();
        self.batch = None;
        applied
    }
}

/// Who writes the outputs: counted leases, and a flag the last one raises
/// as it goes, so the engine can apply `outputs.on_last_writer_gone`
/// without a lock or a message on the cycle path.
#[derive(Debug, Default)]
pub(crate) struct Writers {
    count: AtomicUsize,
    gone: AtomicBool,
}

impl Writers {
    /// A writer arrives.
    pub(crate) fn acquire(&self) {
        self.count.fetch_add(1, Ordering::AcqRel);
    }

    /// A writer leaves; the last one raises the flag.
    pub(crate) fn release(&self) {
        if self.count.fetch_sub(1, Ordering::AcqRel) == 1 {
            self.gone.store(true, Ordering::Release);
        }
    }

    /// Writers now.
    pub(crate) fn count(&self) -> usize {
        self.count.load(Ordering::Acquire)
    }

    /// Whether the last writer left since the previous call, and no new one
    /// came meanwhile.
    pub(crate) fn take_gone(&self) -> bool {
        self.gone.swap(false, Ordering::AcqRel) && self.count() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chunk(batch: u32, last: bool, offset: u32, byte: u8) -> OutputWrite {
        OutputWrite { batch, last, offset, len: 2, data: [byte; OUTPUT_CHUNK], written: std::time::Instant::now() }
    }

    #[test]
    fn writes_apply_whole_or_not_at_all() {
        let mut a = OutputAssembler::default();
        let mut image = [0u8; 8];
        a.push(chunk(1, false, 0, 1), Some(&mut image));
        assert_eq!(image, [0; 8], "nothing before the last chunk");
        a.push(chunk(1, true, 4, 1), Some(&mut image));
        assert_eq!(image, [1, 1, 0, 0, 1, 1, 0, 0]);
        // Batch 2 lost its last chunk; batch 3 must not carry it in.
        a.push(chunk(2, false, 2, 2), Some(&mut image));
        a.push(chunk(3, true, 6, 3), Some(&mut image));
        assert_eq!(image, [1, 1, 0, 0, 1, 1, 3, 3]);
        // Out of range bytes are ignored, not a panic.
        a.push(chunk(4, true, 7, 4), Some(&mut image));
        a.push(chunk(5, true, u32::MAX, 4), Some(&mut image));
        assert_eq!(image, [1, 1, 0, 0, 1, 1, 3, 3]);
    }

    #[test]
    fn only_the_last_writer_leaving_counts() {
        let w = Writers::default();
        assert!(!w.take_gone());
        w.acquire();
        w.acquire();
        w.release();
        assert!(!w.take_gone(), "one writer is left");
        w.release();
        assert!(w.take_gone());
        assert!(!w.take_gone(), "reported once");
        w.acquire();
        w.release();
        w.acquire();
        assert!(!w.take_gone(), "a new writer came before the engine looked");
    }
}
