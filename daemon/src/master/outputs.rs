//! The async side of the output image: client writes cut into chunks that
//! the engine applies whole (see `engine::output_writes::OutputAssembler`), and the
//! counted writer leases behind `outputs.on_last_writer_gone`.

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::sync::{Arc, Mutex};

use crate::engine::error::{EngineError, NotRunning};
use crate::engine::layout::NetworkLayout;
use crate::engine::output_writes::{OUTPUT_CHUNK, OutputWrite, Writers};

/// A client's lease on the outputs (see [`Master::output_writer`](crate::master::Master::output_writer)).
#[derive(Debug)]
pub struct OutputWriter {
    pub(crate) outputs: Arc<OutputSender>,
    pub(crate) layout: Arc<Mutex<NetworkLayout>>,
    pub(crate) writers: Arc<Writers>,
}

impl OutputWriter {
    /// Writes bytes into the output image at `offset` (of the whole output
    /// frame); they go out together with the next frames pushed.
    pub fn write(&self, offset: usize, bytes: &[u8]) -> Result<(), EngineError> {
        let size = self.layout.lock().unwrap_or_else(|e| e.into_inner()).rx_size;
        self.outputs.send(size, offset, bytes)
    }
}

impl Drop for OutputWriter {
    fn drop(&mut self) {
        self.writers.release();
    }
}

/// The async side of the output queue: cuts writes into chunks that stay
/// together (one lock, held only while queuing and never touched by the
/// engine thread) under one batch number.
#[derive(Debug)]
pub(crate) struct OutputSender {
    tx: SyncSender<OutputWrite>,
    queuing: Mutex<()>,
    next_batch: AtomicU32,
}

impl OutputSender {
    /// A sender over the engine's output channel.
    pub(crate) fn new(tx: SyncSender<OutputWrite>) -> Self {
        Self { tx, queuing: Mutex::new(()), next_batch: AtomicU32::new(0) }
    }

    /// Queues one client write of `bytes` at `offset` of a `size`-byte image.
    pub(crate) fn send(&self, size: usize, offset: usize, bytes: &[u8]) -> Result<(), EngineError> {
        if offset.saturating_add(bytes.len()) > size {
            return Err(EngineError::BadArgument {
                field: "offset",
                reason: format!("{} bytes at {offset} exceed the {size}-byte output image", bytes.len()),
            });
        }
        if bytes.is_empty() {
            return Ok(());
        }
        let _queuing = self.queuing.lock().unwrap_or_else(|e| e.into_inner());
        let batch = self.next_batch.fetch_add(1, Ordering::Relaxed);
        let written = std::time::Instant::now();
        let chunks = bytes.len().div_ceil(OUTPUT_CHUNK);
        for (i, chunk) in bytes.chunks(OUTPUT_CHUNK).enumerate() {
            let mut data = [0u8; OUTPUT_CHUNK];
            data[..chunk.len()].copy_from_slice(chunk);
            let w = OutputWrite {
                batch,
                last: i + 1 == chunks,
                offset: (offset + i * OUTPUT_CHUNK) as u32,
                len: chunk.len() as u8,
                data,
                written,
            };
            // A write cut short here is dropped whole by the engine.
            self.tx.try_send(w).map_err(|e| match e {
                TrySendError::Full(_) => EngineError::QueueFull,
                TrySendError::Disconnected(_) => EngineError::Unavailable(NotRunning::Stopped),
            })?;
        }
        Ok(())
    }
}
