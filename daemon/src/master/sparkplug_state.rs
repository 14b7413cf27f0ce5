//! What the Sparkplug B edge node (daemon/src/sparkplug) tells the rest of
//! the daemon about itself: connection, counters, the `bdSeq` a restarted
//! node goes on from. Kept by the master like the mailbox gateway's
//! counters, so every front end reads it the same way (the API's
//! GetStatus and `ecmxfctl master`, the metrics endpoint) without knowing
//! the node.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64};

/// The node's state; all zero while none is configured.
#[derive(Debug, Default)]
pub struct SparkplugState {
    /// A node is configured.
    pub enabled: AtomicBool,
    /// 1 while connected to a broker and born, else 0.
    pub connected: AtomicU64,
    /// The broker of the current or last connection (`mqtt://host:port`).
    pub broker: Mutex<String>,
    /// The last connection's `bdSeq` + 1 (0: none yet).
    pub next_bd_seq: AtomicU64,
    /// Messages handed to the MQTT client.
    pub published: AtomicU64,
    /// Messages dropped: the client's queue was full.
    pub dropped: AtomicU64,
    /// Commands applied.
    pub commands: AtomicU64,
    /// Commands refused (disabled, role, unknown metric, bad value).
    pub refused: AtomicU64,
    /// Connections made.
    pub connects: AtomicU64,
}

impl SparkplugState {
    /// The broker of the current or last connection ("" before the first).
    pub(crate) fn broker(&self) -> String {
        self.broker.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Records the broker a connection was made to.
    pub(crate) fn set_broker(&self, broker: String) {
        *self.broker.lock().unwrap_or_else(|e| e.into_inner()) = broker;
    }
}
