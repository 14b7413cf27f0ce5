//! The engine's one door (the rest of the daemon reaches the engine only
//! through it): [`spawn`] starts the real-time thread over a link, and the
//! input distributor beside it, and returns the [`EngineHandle`] the rest
//! of the daemon uses. In: one command channel
//! for every request (jobs, reconfigure, network actions, frame streams,
//! stop) and the output writes, the hot path, on their own channel. Out:
//! the telemetry, the layout, input frames and events, each published by
//! the engine without waiting on a reader.
//!
//! The engine thread never blocks on the async side: input frames and
//! events leave it through lock-free rings (rtrb), and the distributor
//! thread moves them onto broadcast channels for any number of
//! subscribers, woken by the engine when there is something to move.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use tokio::sync::{broadcast, watch};

use super::command::Command;
use super::core::{Inbound, Outbound, Shared};
use super::error::{EngineError, NotRunning};
use super::events::{Event, EventKind, RING as EVENT_RING};
use super::inputs::{InputFrame, read_frame};
use super::layout::NetworkLayout;
use super::output_writes::{OutputWrite, Writers};
use super::telemetry::Telemetry;
use super::thread::Engine;
use crate::config::Config;
use crate::link::Link;

/// Requests that may wait for the engine at once.
pub const QUEUE_DEPTH: usize = 256;
/// Output writes that may wait for the engine at once.
const OUTPUT_QUEUE: usize = 1024;
/// Input frames a subscriber may fall behind by before losing some.
pub const SUBSCRIBER_BACKLOG: usize = 4096;
/// Events a subscriber may fall behind by before losing some.
pub const EVENT_BACKLOG: usize = 1024;

/// The running engine, as the rest of the daemon holds it: requests go in
/// through [`EngineHandle::send`], output writes through the sender
/// [`EngineHandle::output_sender`] hands out; what the engine publishes is
/// read through the other methods, without the engine.
#[derive(Debug)]
pub(crate) struct EngineHandle {
    /// Every request in.
    commands: SyncSender<Command>,
    /// Output writes in (the hot path beside the commands).
    outputs: SyncSender<OutputWrite>,
    /// Status out, read without the engine.
    pub(super) telemetry: Arc<Telemetry>,
    /// Where each slave's data sits, written at bring-up only.
    pub(super) layout: Arc<Mutex<NetworkLayout>>,
    /// Input frames out.
    inputs: broadcast::Sender<Arc<InputFrame>>,
    /// The newest input frame, kept by the distributor (what a front end
    /// reads a drive's state from, and waits on for the next one).
    latest: watch::Sender<Option<Arc<InputFrame>>>,
    /// Supervision events out.
    events: broadcast::Sender<Event>,
    /// Output writer leases, counted for `outputs.on_last_writer_gone`.
    pub(super) writers: Arc<Writers>,
    threads: Mutex<Vec<JoinHandle<()>>>,
    pub(super) stop_engine: Arc<AtomicBool>,
    stop_distributor: Arc<AtomicBool>,
}

/// Starts the engine thread (real-time as configured) over `link`, and the
/// input distributor.
pub(crate) fn spawn<L: Link + 'static>(link: L, config: Config) -> EngineHandle {
    let (commands, command_rx) = sync_channel(QUEUE_DEPTH);
    let (outputs, output_rx) = sync_channel(OUTPUT_QUEUE);
    let telemetry = Arc::new(Telemetry::default());
    let layout = Arc::new(Mutex::new(NetworkLayout::default()));
    let writers = Arc::new(Writers::default());
    let (inputs, _) = broadcast::channel(SUBSCRIBER_BACKLOG);
    let (producer, mut consumer) = rtrb::RingBuffer::new(1 << 20);
    let (events, _) = broadcast::channel(EVENT_BACKLOG);
    let (event_producer, mut event_consumer) = rtrb::RingBuffer::new(EVENT_RING);
    let stop_distributor = Arc::new(AtomicBool::new(false));
    let stop_engine = Arc::new(AtomicBool::new(false));

    let (latest, _) = watch::channel(None);
    let (tx, latest_tx) = (inputs.clone(), latest.clone());
    let (event_tx, stop) = (events.clone(), Arc::clone(&stop_distributor));
    let watched = Arc::clone(&telemetry);
    let distributor = std::thread::Builder::new()
        .name("ecmxf-inputs".into())
        .spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                let mut newest = None;
                while let Some(frame) = read_frame(&mut consumer) {
                    // No subscribers is fine: the frame is dropped.
                    let frame = Arc::new(frame);
                    let _ = tx.send(Arc::clone(&frame));
                    newest = Some(frame);
                }
                // Once per batch: waiters wake for the newest frame only.
                if newest.is_some() {
                    latest_tx.send_replace(newest);
                }
                while let Ok(e) = event_consumer.pop() {
                    let _ = event_tx.send(e);
                }
                // A stall the engine cannot announce while a link call
                // holds it (a link that stopped answering), announced
                // within this thread's few ms of the limit instead.
                let now_ns =
                    crate::realtime::monotonic_ns().saturating_sub(watched.epoch_monotonic_ns.load(Ordering::Relaxed));
                if let Some(age_us) = watched.unannounced_stall(now_ns) {
                    let _ = event_tx
                        .send(Event { time_ns: now_ns, kind: EventKind::ProcessData { flowing: false, age_us } });
                }
                std::thread::park_timeout(Duration::from_millis(5));
            }
        })
        .expect("spawn the input distributor thread");
    let handle = EngineHandle {
        commands,
        outputs,
        telemetry,
        layout,
        inputs,
        latest,
        events,
        writers,
        threads: Mutex::new(Vec::new()),
        stop_engine,
        stop_distributor,
    };
    let inbound = Inbound { commands: command_rx, outputs: output_rx };
    let outbound = Outbound { ring: producer, events: event_producer, distributor: distributor.thread().clone() };
    let rt = config.realtime.clone();
    let shared = Shared {
        telemetry: Arc::clone(&handle.telemetry),
        layout: Arc::clone(&handle.layout),
        writers: Arc::clone(&handle.writers),
        stop: Arc::clone(&handle.stop_engine),
    };
    let engine = Engine::new(link, config, inbound, outbound, shared);
    let engine = std::thread::Builder::new()
        .name("ecmxf-rt".into())
        .spawn(move || {
            crate::realtime::apply(&rt);
            engine.run();
        })
        .expect("spawn the engine thread");
    // The engine thread first: `stop` joins it before the distributor.
    handle.threads.lock().unwrap_or_else(|e| e.into_inner()).extend([engine, distributor]);
    handle
}

impl EngineHandle {
    /// Queues `command` for the engine: refused at once when the queue is
    /// full or the engine has stopped, never waiting on it.
    pub(crate) fn send(&self, command: Command) -> Result<(), EngineError> {
        self.commands.try_send(command).map_err(|e| match e {
            TrySendError::Full(_) => EngineError::QueueFull,
            TrySendError::Disconnected(_) => EngineError::Unavailable(NotRunning::Stopped),
        })
    }

    /// A sender of output writes (the hot path beside the commands).
    pub(crate) fn output_sender(&self) -> SyncSender<OutputWrite> {
        self.outputs.clone()
    }

    /// What the engine reports of itself, read without it.
    pub(crate) fn telemetry(&self) -> &Telemetry {
        &self.telemetry
    }

    /// The network as bring-up found it, shared with output writers.
    pub(crate) fn layout(&self) -> &Arc<Mutex<NetworkLayout>> {
        &self.layout
    }

    /// The counted output writers (`outputs.on_last_writer_gone`).
    pub(crate) fn writers(&self) -> &Arc<Writers> {
        &self.writers
    }

    /// A new subscriber to input frames.
    pub(crate) fn subscribe_inputs(&self) -> broadcast::Receiver<Arc<InputFrame>> {
        self.inputs.subscribe()
    }

    /// The newest input frame, if any arrived.
    pub(crate) fn latest_inputs(&self) -> Option<Arc<InputFrame>> {
        self.latest.borrow().clone()
    }

    /// A watcher of the newest input frame.
    pub(crate) fn watch_latest_inputs(&self) -> watch::Receiver<Option<Arc<InputFrame>>> {
        self.latest.subscribe()
    }

    /// A new subscriber to supervision events.
    pub(crate) fn subscribe_events(&self) -> broadcast::Receiver<Event> {
        self.events.subscribe()
    }

    /// Publishes an event found outside the engine (an emergency a host
    /// mailbox read fetched) to the same subscribers.
    pub(crate) fn publish_event(&self, event: Event) {
        let _ = self.events.send(event);
    }

    /// Safe stop, then waits for the threads (blocking). A bring-up or
    /// recovery under way ends at once.
    pub(crate) fn stop(&self) {
        self.stop_engine.store(true, Ordering::Relaxed);
        // A full queue still takes the stop: retry briefly.
        for _ in 0..100 {
            match self.commands.try_send(Command::Stop) {
                Err(TrySendError::Full(_)) => std::thread::sleep(Duration::from_millis(10)),
                _ => break,
            }
        }
        let mut threads = self.threads.lock().unwrap_or_else(|e| e.into_inner());
        // The engine thread first (it finishes the safe stop), then the
        // distributor.
        if !threads.is_empty() {
            let _ = threads.remove(0).join();
        }
        self.stop_distributor.store(true, Ordering::Relaxed);
        for t in threads.drain(..) {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}
