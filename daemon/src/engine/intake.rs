//! Where FIFO answers' input frames go: to subscribers through the input
//! ring ([`InputPublisher`]), with their freshness published. One for the
//! engine's life: input frames keep their numbering across runs.

use std::sync::atomic::Ordering::Relaxed;
use std::time::Instant;

use super::cyclic::Cyclic;
use super::inputs::InputPublisher;
use super::supervisor::flow_limit;
use super::telemetry::Telemetry;

/// The input ring and the clock its times count from.
#[derive(Debug)]
pub(super) struct Intake {
    /// The input ring.
    pub inputs: InputPublisher,
    epoch: Instant,
}

impl Intake {
    pub(super) fn new(inputs: InputPublisher, epoch: Instant) -> Self {
        Self { inputs, epoch }
    }

    /// A run of the cyclic exchange starts at `now`.
    pub(super) fn start(&mut self, c: &Cyclic, telemetry: &Telemetry, now: Instant) {
        self.inputs.resume(now, c.cycle());
        telemetry.newest_input_ns.store(self.ns(now), Relaxed);
        telemetry.flow_limit_ns.store(flow_limit(c.cycle()).as_nanos() as u64, Relaxed);
    }

    /// `t` as nanoseconds since the engine started.
    pub(super) fn ns(&self, t: Instant) -> u64 {
        t.saturating_duration_since(self.epoch).as_nanos() as u64
    }
}
