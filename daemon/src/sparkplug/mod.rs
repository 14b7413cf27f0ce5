//! The MQTT Sparkplug B edge node (docs/sparkplug.md): past one
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
use std::sync::atomic::Ordering::Relaxed;

mod commands;
mod connection;
mod node;
mod runner;
mod seen;
mod session;
mod tls;
mod topic;
mod value;

pub use connection::{Prepared, SparkplugError, prepare};
pub use runner::Runner;
pub use session::serve;

/// The node's state as the master keeps it (connection, counters), for
/// the API, the metrics endpoint and the node's own NDATA.
pub type SharedStats = Arc<crate::master::sparkplug_state::SparkplugState>;

/// The counters the node publishes.
pub fn counts(s: &crate::master::sparkplug_state::SparkplugState) -> node::Counts {
    node::Counts {
        published: s.published.load(Relaxed),
        dropped: s.dropped.load(Relaxed),
        refused: s.refused.load(Relaxed),
        connects: s.connects.load(Relaxed),
    }
}
