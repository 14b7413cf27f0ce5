//! What the OPC UA server (daemon/src/opcua) tells the rest of the daemon
//! about itself: sessions, monitored items and the work they cost, the
//! writes and calls it did and refused. Kept by the master like the
//! Sparkplug node's state, so the metrics endpoint reads it without
//! knowing the server.

use std::sync::atomic::{AtomicBool, AtomicU64};

/// The server's counters; all zero while none is configured.
#[derive(Debug, Default)]
pub struct OpcuaState {
    /// A server is configured and serving.
    pub enabled: AtomicBool,
    /// Sessions open now.
    pub sessions: AtomicU64,
    /// Monitored items on process data and counters now.
    pub monitored_items: AtomicU64,
    /// Values sampled for monitored items (each a read of what the engine
    /// published, compared by the server with the last one sent).
    pub samples: AtomicU64,
    /// Output writes done.
    pub writes: AtomicU64,
    /// Method calls done.
    pub calls: AtomicU64,
    /// Writes and calls refused (role, lease, value).
    pub refused: AtomicU64,
}
