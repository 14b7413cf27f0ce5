//! The MQTT Sparkplug B edge node (issue 34, docs/sparkplug.md): past one
//! gateway, plants integrate through an MQTT broker with Eclipse Sparkplug
//! 3.0, where SCADA/MES hosts (Ignition, HiveMQ, EMQX) subscribe once and
//! see every gateway and slave. With `[sparkplug]` ecmxfd is one node of
//! such a plant: NBIRTH/NDEATH with `bdSeq` (the will), a device per
//! slave (DBIRTH/DDEATH as slaves come and go), process data and
//! diagnostics as DDATA/NDATA on change, and commands (Rebirth; output
//! writes under a lease like a gRPC client's) as `sparkplug.commands`
//! allows.
//!
//! A front end like the gRPC API, beside it: it reads the engine's
//! published snapshots (status watch, newest input frame, the output
//! shadow, the laid-out image) on its own clock, so nothing of the cyclic
//! path waits on the network; writes go through the master's lease table
//! and entry writes. [`node`] decides every message without I/O;
//! [`session`] connects, fails over and moves the bytes (rumqttc: a
//! maintained, pure-Rust, tokio-native MQTT 3.1.1 client whose TLS is
//! rustls on ring, as tonic's here; no C library to cross-compile).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};

pub mod commands;
mod connection;
pub mod node;
pub mod runner;
mod seen;
pub mod session;
pub mod tls;
pub mod topic;
pub mod value;

pub use connection::{Prepared, SparkplugError, prepare};
pub use runner::Runner;
pub use session::serve;

/// The node's counters, for the metrics endpoint and its own NDATA.
#[derive(Debug, Default)]
pub struct Stats {
    /// A node is configured (the metrics endpoint shows these counters).
    pub enabled: AtomicBool,
    /// The last connection's `bdSeq` + 1 (0: none yet): a node started
    /// again on SIGHUP goes on from it.
    pub next_bd_seq: AtomicU64,
    /// 1 while connected to a broker (and births are out), else 0.
    pub connected: AtomicU64,
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

impl Stats {
    /// The counters the node publishes.
    pub fn counts(&self) -> node::Counts {
        node::Counts {
            published: self.published.load(Relaxed),
            dropped: self.dropped.load(Relaxed),
            refused: self.refused.load(Relaxed),
            connects: self.connects.load(Relaxed),
        }
    }
}

/// Shared handle to the counters.
pub type SharedStats = Arc<Stats>;
