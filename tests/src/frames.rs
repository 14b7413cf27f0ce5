//! A counter streamed through `ProcessData.StreamFrames` to the demo IO
//! slave, one value per DC cycle, and the checks that each value reached
//! the slave exactly once, in order:
//! the daemon's own pairing of each frame with its cycle's input frame
//! (the IO slave loops its outputs back to its inputs in the same cycle),
//! and the simulator's record of the frames the slave consumed. Shared by
//! the end-to-end tests and `ecmxf-frames-bench`.

use std::time::{Duration, Instant};

use ecmxf_proto::v1 as pb;
use ecmxf_sim::chip::fifo::{PlayRecord, PlayedFrame};
use pb::process_data_client::ProcessDataClient;
use tokio_stream::StreamExt;
use tonic::transport::Channel;

use crate::Simulator;

/// The counter's frame `seq`: one byte, 1..=251 (never 0, so a zeroed
/// output is never mistaken for a frame).
pub fn counter_frame(seq: u64) -> Vec<u8> {
    vec![(seq % 251) as u8 + 1]
}

/// What a streamed run gave back.
#[derive(Debug)]
pub struct CounterRun {
    /// Frames sent.
    pub total: u64,
    /// Every played frame the daemon reported, in order.
    pub played: Vec<pb::PlayedFrame>,
    /// The last report.
    pub last: pb::FrameReport,
    /// From the first report to the stream's end.
    pub elapsed: Duration,
}

/// Streams frames `make(0..total)` to `slave` under `lease` with pairing
/// on, sending whenever the reports allow, and reads the reports until the
/// daemon ends the stream (every frame played and told).
pub async fn stream(
    pd: &mut ProcessDataClient<Channel>,
    lease: &str,
    slave: u32,
    total: u64,
    make: impl Fn(u64) -> Vec<u8>,
) -> CounterRun {
    let batch = |frames: Vec<pb::OutputFrame>| pb::FrameBatch {
        lease_id: lease.to_string(),
        slaves: vec![],
        queue_frames: 0,
        frames,
        pair_inputs: false,
    };
    let (tx, rx) = tokio::sync::mpsc::channel(64);
    let first = pb::FrameBatch { slaves: vec![slave], queue_frames: 1024, pair_inputs: true, ..batch(Vec::new()) };
    tx.send(first).await.expect("first message");
    let mut reports =
        pd.stream_frames(tokio_stream::wrappers::ReceiverStream::new(rx)).await.expect("StreamFrames").into_inner();
    let started = Instant::now();
    let (mut seq, mut sender) = (0u64, Some(tx));
    let (mut played, mut last) = (Vec::new(), None);
    while let Some(r) = reports.next().await {
        let r = r.expect("a report");
        if let Some(tx) = &sender {
            let n = r.allowed.saturating_sub(seq).min(total - seq);
            let frames = (seq..seq + n).map(|s| pb::OutputFrame { seq: s, data: make(s) }).collect();
            seq += n;
            tx.send(batch(frames)).await.expect("frames");
            if seq == total {
                // Done sending: the daemon reports until they are played.
                sender = None;
            }
        }
        played.extend(r.played.iter().cloned());
        last = Some(r);
    }
    CounterRun { total, played, last: last.expect("reports"), elapsed: started.elapsed() }
}

/// [`stream`] of the counter to the IO slave (slave 2, one output byte).
pub async fn stream_counter(pd: &mut ProcessDataClient<Channel>, lease: &str, total: u64) -> CounterRun {
    let run = stream(pd, lease, 2, total, counter_frame).await;
    assert_eq!(run.last.frame_bytes, 1, "the IO slave's outputs are one byte: {:?}", run.last);
    run
}

/// How the played frames the daemon reported match the counter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Pairing {
    /// Played frames reported.
    pub told: u64,
    /// Reported with their cycle's input frame.
    pub with_inputs: u64,
    /// Whose input frame did not loop back their own value: a wrong cycle.
    pub mismatched: u64,
    /// Cycles between consecutive frames other than one: underruns (a
    /// frame repeated before the next played).
    pub late_cycles: u64,
}

impl CounterRun {
    /// Checks the reported frames: every seq once, in order; cycles rising;
    /// each frame's paired input frame loops back its own value (input
    /// byte `in_at`). Errors name the first frame out of order.
    pub fn pairing(&self, in_at: usize) -> Result<Pairing, String> {
        let mut out = Pairing { told: self.played.len() as u64, ..Pairing::default() };
        for (i, p) in self.played.iter().enumerate() {
            if p.seq != i as u64 {
                return Err(format!("the {i}th frame reported is seq {} (a gap, repeat or reorder)", p.seq));
            }
            if let Some(prev) = i.checked_sub(1).map(|j| &self.played[j]) {
                if p.cycle <= prev.cycle {
                    return Err(format!("seq {} played in cycle {}, not after {}", p.seq, p.cycle, prev.cycle));
                }
                out.late_cycles += p.cycle - prev.cycle - 1;
            }
            if let Some(&v) = p.inputs.get(in_at) {
                out.with_inputs += 1;
                if v != counter_frame(p.seq)[0] {
                    out.mismatched += 1;
                }
            }
        }
        Ok(out)
    }
}

/// The simulator's whole record (`recorded`, a page at a time: its control
/// socket carries 64 KiB an answer).
pub fn recorded(sim: &Simulator) -> Vec<PlayedFrame> {
    let head = sim.ctl("recorded 0 0");
    let frames: usize = head
        .split_whitespace()
        .find_map(|w| w.strip_prefix("frames="))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{head}"));
    // A page's size from the first line's (the frames' size decides it),
    // with room for longer cycle numbers and " repeat".
    let line = sim.ctl("recorded 0 1").lines().nth(1).map_or(64, |l| l.len() + 1);
    let page = (60_000 / (line + 16)).max(1);
    let mut played = Vec::with_capacity(frames);
    while played.len() < frames {
        let text = sim.ctl(&format!("recorded {} {}", played.len(), (frames - played.len()).min(page)));
        let page: Vec<PlayedFrame> = text.lines().skip(1).filter_map(PlayedFrame::parse).collect();
        if page.is_empty() {
            break;
        }
        played.extend(page);
    }
    played
}

/// What the simulator's record says of the counter's `total` frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Recorded {
    /// Frames of the counter that played, in order, once each.
    pub played: u64,
    /// Cycles in which the slave got the last frame again (the RxFIFO ran
    /// dry): repeats the record marks.
    pub underruns: u64,
    /// The daemon's cycle numbers differ from the chip's by one constant
    /// for every frame (the pairing is exact).
    pub cycles_agree: bool,
}

/// Checks the record: the counter played in order, once each, one per
/// cycle (repeats only where the record marks an underrun); and the cycle
/// the daemon reported for each frame is the chip's, up to a constant.
pub fn check_record(record: &[PlayedFrame], run: &CounterRun) -> Result<Recorded, String> {
    let sequence: Vec<Vec<u8>> = (0..run.total).map(counter_frame).collect();
    let followed = PlayRecord::follows(record, &sequence)?;
    // The chip's cycle of each frame of the counter: where its value first
    // shows, after the first frame.
    let start = record.iter().position(|f| f.bytes == sequence[0]).unwrap_or(0);
    let mut chip_cycles = Vec::with_capacity(followed.played);
    for (i, f) in record.iter().enumerate().take(followed.last_at + 1).skip(start) {
        if i == start || !(f.repeated && f.bytes == record[i - 1].bytes) {
            chip_cycles.push(f.cycle);
        }
    }
    let offsets: Vec<i128> =
        run.played.iter().zip(&chip_cycles).map(|(p, &c)| i128::from(c) - i128::from(p.cycle)).collect();
    let cycles_agree = !offsets.is_empty() && offsets.iter().all(|o| *o == offsets[0]);
    Ok(Recorded { played: followed.played as u64, underruns: followed.underruns as u64, cycles_agree })
}
