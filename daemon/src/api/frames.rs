//! `ProcessData.StreamFrames`: per-cycle output frames from a client into
//! the engine's frame queue (`engine::frames`), with credits so a client
//! that sends as fast as it is allowed never overfills anything.
//!
//! The first message names the lease and the slaves; their output bytes,
//! contiguous in the image, are a frame. Frames go into a queue of
//! `queue_frames` records allocated here, on the async side; the engine
//! takes one per frame it pushes into the RxFIFO. Reports go back about
//! every [`REPORT_EVERY`]: `allowed` (frames received + free records: a
//! total that only grows, so a late report never lets a client overfill
//! the queue), frames taken, the last `seq` taken, dry pushes.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use tokio::sync::mpsc;
use tonic::{Status, Streaming};

use super::status::{bad_argument, to_status};
use super::{BoxStream, Context};
use crate::engine::frames::{FrameError, FrameProducer};

/// How often the daemon reports credits and progress.
pub const REPORT_EVERY: Duration = Duration::from_millis(5);
/// Queue length when the client does not say.
pub const DEFAULT_QUEUE: u32 = 1024;
/// The longest queue a client may ask for.
pub const MAX_QUEUE: u32 = 65_536;
/// How long the daemon waits, after the client's last frame, for the
/// queue to play out before it ends the stream.
const DRAIN_LIMIT: Duration = Duration::from_secs(10);

/// Held while a stream is open: one at a time.
#[derive(Debug)]
struct Open<'a>(&'a AtomicBool);

impl Drop for Open<'_> {
    fn drop(&mut self) {
        self.0.store(false, Ordering::Release);
    }
}

/// The first message's checks: the lease owns the slaves, their output
/// bytes are contiguous and not empty. Returns (image offset, frame bytes).
fn frame_range(ctx: &Context, first: &pb::FrameBatch) -> Result<(usize, usize), Status> {
    if first.slaves.is_empty() {
        return Err(bad_argument("slaves", "name the slaves whose outputs make a frame, e.g. [2]"));
    }
    let layout = ctx.master.layout();
    let mut slaves: Vec<u32> = first.slaves.clone();
    slaves.sort_unstable();
    slaves.dedup();
    let mut range: Option<(usize, usize)> = None;
    for s in slaves {
        let slave = ctx.slave(s)?;
        if !ctx.leases.owns(&first.lease_id, slave) {
            return Err(Status::permission_denied(format!(
                "streaming frames to slave {s} needs a lease on it: {:?} does not own it (see AcquireLease)",
                first.lease_id
            )));
        }
        let l = &layout.slaves[usize::from(slave)];
        if l.rx_bytes == 0 {
            return Err(bad_argument("slaves", format!("slave {s} has no outputs")));
        }
        range = match range {
            None => Some((l.rx_offset, l.rx_bytes)),
            Some((start, len)) if start + len == l.rx_offset => Some((start, len + l.rx_bytes)),
            Some((start, len)) => {
                return Err(bad_argument(
                    "slaves",
                    format!(
                        "slave {s}'s outputs (bytes {}..{}) do not follow bytes {start}..{}: a frame is one contiguous range",
                        l.rx_offset,
                        l.rx_offset + l.rx_bytes,
                        start + len
                    ),
                ));
            }
        };
    }
    range.ok_or_else(|| bad_argument("slaves", "no slave given"))
}

/// Queues a message's frames; an error names the frame.
fn queue(producer: &mut FrameProducer, frames: &[pb::OutputFrame]) -> Result<(), Status> {
    for f in frames {
        producer.push(f.seq, &f.data).map_err(|e| match e {
            FrameError::Full => Status::resource_exhausted(format!(
                "frame {} was sent without a credit: the queue is full (send at most the reported credits)",
                f.seq
            )),
            FrameError::WrongLength { .. } => bad_argument("frames.data", format!("frame {}: {e}", f.seq)),
        })?;
    }
    Ok(())
}

/// A report; `received` frames came from the client so far.
fn report(p: &FrameProducer, received: u64, start: usize, len: usize) -> pb::FrameReport {
    let c = p.counters();
    let credits = p.credits();
    pb::FrameReport {
        allowed: received + credits as u64,
        credits: credits.min(u32::MAX as usize) as u32,
        pushed: c.pushed.load(Ordering::Relaxed),
        last_seq: c.last_seq.load(Ordering::Relaxed),
        dry: c.dry.load(Ordering::Relaxed),
        frame_bytes: len as u32,
        image_offset: start as u32,
    }
}

/// Serves one `StreamFrames` call.
pub async fn serve(
    ctx: Arc<Context>,
    mut input: Streaming<pb::FrameBatch>,
) -> Result<BoxStream<pb::FrameReport>, Status> {
    let first =
        input.message().await?.ok_or_else(|| bad_argument("lease_id", "the stream ended before its first message"))?;
    let (start, len) = frame_range(&ctx, &first)?;
    let capacity = match first.queue_frames {
        0 => DEFAULT_QUEUE,
        n if n <= MAX_QUEUE => n,
        n => return Err(bad_argument("queue_frames", format!("{n} is more than {MAX_QUEUE}"))),
    };
    if ctx.frame_stream_open.swap(true, Ordering::AcqRel) {
        return Err(Status::failed_precondition("another StreamFrames is open; one at a time"));
    }
    let guard_ctx = Arc::clone(&ctx);
    let mut producer = match ctx.master.stream_frames(start, len, capacity as usize) {
        Ok(p) => p,
        Err(e) => {
            ctx.frame_stream_open.store(false, Ordering::Release);
            return Err(to_status(e));
        }
    };
    let (tx, rx) = mpsc::channel::<Result<pb::FrameReport, Status>>(4);
    let lease = first.lease_id.clone();
    tokio::spawn(async move {
        let _open = Open(&guard_ctx.frame_stream_open);
        let ctx = &guard_ctx;
        let mut sent = first.frames.len() as u64;
        if let Err(e) = queue(&mut producer, &first.frames) {
            let _ = tx.send(Err(e)).await;
            return;
        }
        let r = report(&producer, sent, start, len);
        let _ = tx.send(Ok(r)).await;
        let mut tick = tokio::time::interval(REPORT_EVERY);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                msg = input.message() => match msg {
                    Ok(Some(m)) => {
                        if ctx.leases.keep_alive(&lease).is_err() {
                            let e = Status::permission_denied(format!("lease {lease:?} is gone: the stream ends"));
                            let _ = tx.send(Err(e)).await;
                            return;
                        }
                        sent += m.frames.len() as u64;
                        if let Err(e) = queue(&mut producer, &m.frames) {
                            let _ = tx.send(Err(e)).await;
                            return;
                        }
                    }
                    Ok(None) => break,
                    Err(e) => {
                        let _ = tx.send(Err(e)).await;
                        return;
                    }
                },
                _ = tick.tick() => {
                    let r = report(&producer, sent, start, len);
                    if tx.send(Ok(r)).await.is_err() {
                        return;
                    }
                }
            }
        }
        // The client is done: its queue plays out, which is no dry spell;
        // report until its frames are played.
        producer.close();
        let deadline = std::time::Instant::now() + DRAIN_LIMIT;
        while producer.counters().pushed.load(Ordering::Relaxed) < sent && std::time::Instant::now() < deadline {
            tick.tick().await;
            let r = report(&producer, sent, start, len);
            if tx.send(Ok(r)).await.is_err() {
                return;
            }
        }
        let r = report(&producer, sent, start, len);
        let _ = tx.send(Ok(r)).await;
    });
    Ok(Box::pin(tokio_stream::wrappers::ReceiverStream::new(rx)))
}
