//! What reaches the engine through its command channel, and what taking
//! one leaves for the phase that took it.

use super::frames::FrameConsumer;
use super::network_action::NetworkAction;
use super::slot::Job;
use crate::config::Config;

/// Messages to the engine: its one way in besides the output writes (the
/// hot path, lock-free) and the stop flag that ends a wait at once.
#[derive(Debug)]
pub(crate) enum Command {
    /// A request for the blocking slot.
    Job(Job),
    /// A new configuration to bring the network up with, and its number
    /// (published in the telemetry once taken).
    Reconfigure(u64, Box<Config>),
    /// A per-cycle output frame stream opens.
    FrameStream(FrameConsumer),
    /// A re-init or warm reset (asking twice is asking once; a warm reset
    /// wins).
    Network(NetworkAction),
    /// Safe stop, then exit.
    Stop,
}

/// What a command leaves for the phase that took it: a job to queue (or
/// refuse), a stop, or nothing (the rest is kept for the running loop).
pub(super) enum Taken {
    Job(Job),
    Stop,
    Kept,
}
