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

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use ecmxf_proto::v1 as pb;
use tokio::sync::mpsc;
use tonic::{Status, Streaming};

use super::status::{bad_argument, to_status};
use super::{BoxStream, Context};
use crate::master::InputFrame;
use crate::master::frame_claims::ClaimError;
use crate::master::{FrameError, FrameProducer, MAX_STREAMS, Played};

/// How often the daemon reports credits and progress.
pub(crate) const REPORT_EVERY: Duration = Duration::from_millis(5);
/// Queue length when the client does not say.
pub(crate) const DEFAULT_QUEUE: u32 = 1024;
/// The longest queue a client may ask for.
pub(crate) const MAX_QUEUE: u32 = 65_536;
/// How long the daemon waits, after the client's last frame, for the
/// queue to play out before it ends the stream.
const DRAIN_LIMIT: Duration = Duration::from_secs(10);
/// How long, once the client's side ended, the daemon waits for the cycle
/// numbers of its frames (see the task in [`serve`]).
const TELL_GRACE: Duration = Duration::from_secs(1);

/// The first message's checks: the lease owns the slaves, their output
/// bytes are contiguous and not empty. Returns (image offset, frame bytes).
fn frame_range(ctx: &Context, who: &str, first: &pb::FrameBatch) -> Result<(usize, usize), Status> {
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
        if !ctx.master.leases().owns(&first.lease_id, who, slave) {
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

/// A report; `received` frames came from the client so far, `played` the
/// frames known to have played since the last one.
fn report(p: &FrameProducer, received: u64, start: usize, len: usize, played: Vec<pb::PlayedFrame>) -> pb::FrameReport {
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
        played,
    }
}

/// A played frame as reported.
fn told(p: Played, inputs: Vec<u8>) -> pb::PlayedFrame {
    pb::PlayedFrame { seq: p.seq, cycle: p.cycle, inputs }
}

/// Played frames on their way to a report: at once, or (pairing) once the
/// input frame of their cycle arrived.
#[derive(Debug)]
struct Pairing {
    /// Frames the engine told as played so far.
    told: u64,
    /// Waiting for their cycle's input frame (pairing only).
    waiting: VecDeque<Played>,
    /// Ready for the next report.
    ready: Vec<pb::PlayedFrame>,
    pair: bool,
}

impl Pairing {
    fn new(pair: bool) -> Self {
        Self { told: 0, waiting: VecDeque::new(), ready: Vec::new(), pair }
    }

    /// Takes what the engine says has played.
    fn take(&mut self, producer: &mut FrameProducer) {
        while let Some(p) = producer.next_played() {
            self.told += 1;
            if self.pair {
                self.waiting.push_back(p);
            } else {
                self.ready.push(told(p, Vec::new()));
            }
        }
    }

    /// An input frame arrived: the frames that played in its cycle get its
    /// image; those of earlier cycles (never received) go without.
    fn input(&mut self, frame: &InputFrame) {
        while let Some(p) = self.waiting.front().copied() {
            if p.cycle > frame.seq {
                break;
            }
            self.waiting.pop_front();
            let inputs = if p.cycle == frame.seq { frame.data.clone() } else { Vec::new() };
            self.ready.push(told(p, inputs));
        }
    }

    /// The rest, without inputs (the stream ends).
    fn flush(&mut self) {
        self.ready.extend(self.waiting.drain(..).map(|p| told(p, Vec::new())));
    }
}

/// The next input frame, when pairing (never otherwise). A subscriber that
/// fell behind skips on: the frames of the cycles it missed go without.
async fn next_input(inputs: &mut Option<tokio::sync::broadcast::Receiver<Arc<InputFrame>>>) -> Option<Arc<InputFrame>> {
    use tokio::sync::broadcast::error::RecvError;
    let Some(rx) = inputs else { return std::future::pending().await };
    loop {
        match rx.recv().await {
            Ok(f) => return Some(f),
            Err(RecvError::Lagged(_)) => continue,
            Err(RecvError::Closed) => {
                *inputs = None;
                return None;
            }
        }
    }
}

/// Serves one `StreamFrames` call.
pub(crate) async fn serve(
    ctx: Arc<Context>,
    who: String,
    mut input: Streaming<pb::FrameBatch>,
) -> Result<BoxStream<pb::FrameReport>, Status> {
    let first =
        input.message().await?.ok_or_else(|| bad_argument("lease_id", "the stream ended before its first message"))?;
    let (start, len) = frame_range(&ctx, &who, &first)?;
    let capacity = match first.queue_frames {
        0 => DEFAULT_QUEUE,
        n if n <= MAX_QUEUE => n,
        n => return Err(bad_argument("queue_frames", format!("{n} is more than {MAX_QUEUE}"))),
    };
    let claim = ctx.master.frame_claims().claim(start, len).map_err(|e| match e {
        ClaimError::Overlap => Status::failed_precondition(format!(
            "the outputs of slaves {} are (partly) fed by another StreamFrames: one stream per set of slaves",
            first.slaves.iter().map(u32::to_string).collect::<Vec<_>>().join(", ")
        )),
        ClaimError::TooMany => {
            Status::resource_exhausted(format!("{MAX_STREAMS} StreamFrames are open: the most at once"))
        }
    })?;
    let mut producer = ctx.master.stream_frames(start, len, capacity as usize).map_err(to_status)?;
    // Subscribed before the first frame can play.
    let mut inputs = first.pair_inputs.then(|| ctx.master.subscribe());
    // Cycles are numbered by input frames: a network without them has no
    // played frames to tell.
    let inputs_numbered = ctx.master.layout().tx_size > 0;
    let (tx, rx) = mpsc::channel::<Result<pb::FrameReport, Status>>(4);
    let lease = first.lease_id.clone();
    tokio::spawn(async move {
        let _claim = claim;
        let mut pairing = Pairing::new(first.pair_inputs);
        let mut sent = first.frames.len() as u64;
        if let Err(e) = queue(&mut producer, &first.frames) {
            let _ = tx.send(Err(e)).await;
            return;
        }
        let r = report(&producer, sent, start, len, Vec::new());
        if tx.send(Ok(r)).await.is_err() {
            return;
        }
        let mut tick = tokio::time::interval(REPORT_EVERY);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        // Set when the client's side ended: the queue plays out (no dry
        // spell) and reports go on until every frame played and was told.
        let mut draining: Option<Instant> = None;
        let mut told_by: Option<Instant> = None;
        loop {
            tokio::select! {
                msg = input.message(), if draining.is_none() => match msg {
                    Ok(Some(m)) => {
                        if ctx.master.leases().keep_alive(&lease, &who).is_err() {
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
                    Ok(None) => {
                        producer.close();
                        draining = Some(Instant::now() + DRAIN_LIMIT);
                    }
                    Err(e) => {
                        let _ = tx.send(Err(e)).await;
                        return;
                    }
                },
                Some(frame) = next_input(&mut inputs) => {
                    // The engine tells a push's frames before any of them
                    // can play, so their cycles are known by now.
                    pairing.take(&mut producer);
                    pairing.input(&frame);
                }
                _ = tick.tick() => {
                    pairing.take(&mut producer);
                    let last = draining.is_some_and(|limit| {
                        let now = Instant::now();
                        let played = producer.counters().pushed.load(Ordering::Relaxed) >= sent;
                        // Frames pushed by a call whose answer never came
                        // (a fault) are never told: a short grace for them.
                        let all_told = !inputs_numbered || pairing.told >= sent;
                        let grace = played.then(|| *told_by.get_or_insert(now + TELL_GRACE));
                        let told = all_told || grace.is_some_and(|g| now >= g);
                        now >= limit || (played && pairing.waiting.is_empty() && told)
                    });
                    if last {
                        pairing.flush();
                    }
                    let r = report(&producer, sent, start, len, std::mem::take(&mut pairing.ready));
                    if tx.send(Ok(r)).await.is_err() || last {
                        return;
                    }
                }
            }
        }
    });
    Ok(Box::pin(tokio_stream::wrappers::ReceiverStream::new(rx)))
}
