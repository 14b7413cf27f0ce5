//! `ecmxfd`: the daemon that owns the ECM-XF chip. docs/architecture.md
//! is the map for a newcomer: the layers, the threads, and two requests
//! traced through the files.
//!
//! # Map
//! Layers point one way: link -> port -> engine -> master -> front ends ->
//! lifecycle (config and realtime beside them all; daemon/tests/layers.rs
//! checks it).
//! - [`link`]: the chip behind a small trait (spidev + GPIO, simulator,
//!   simulator socket).
//! - [`port`]: packet exchange with the chip's rules: one-behind answers,
//!   fresh indices, retries that never execute a command twice
//!   (docs/protocol.md).
//! - `engine` (private): the thread that owns the chip: bring-up, cyclic FIFO
//!   exchange, the blocking-slot transactions, supervision and recovery.
//! - [`master`]: the domain and the one door every front end uses: the
//!   engine's requests as typed methods, leases, the process image and
//!   entry writes, typed values, CiA 402 axes, peripherals, device
//!   descriptions.
//! - Front ends (private), each through the master alone: `api` (gRPC),
//!   [`sparkplug`] (MQTT Sparkplug B), `gateway` (ETG.8200 mailbox
//!   gateway), `metrics` (Prometheus).
//! - [`config`]: the configuration file; [`check_config`] is
//!   `--check-config`.
//! - [`realtime`]: SCHED_FIFO, affinity, mlockall for the engine thread.
//! - [`probe`]: `ecmxfd probe`, first contact with a new board, step by
//!   step with the likely cause and fix of each failure.
//! - The daemon as a whole: [`run`]`(config, shutdown)` starts all of the
//!   above and stops it safely, joining every task it started;
//!   [`run_until_signalled`] adds SIGTERM, SIGINT and SIGHUP; the binary
//!   only parses arguments.
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![warn(unreachable_pub)]

mod admission;
mod api;
mod check_config;
pub mod config;
pub(crate) mod engine;
mod gateway;
mod lifecycle;
pub mod link;
pub mod master;
mod metrics;
pub mod opcua;
pub mod port;
pub mod probe;
pub mod realtime;
mod service;
mod signals;
pub mod sparkplug;
pub mod web;

pub use api::status::debug_looking_messages;
pub use check_config::{EXIT_CONFIG, check_config, preflight};
pub use lifecycle::{DaemonError, EXIT_REFUSED, Options, run, run_with};
pub use service::{Logging, Notifier, init_logging};
pub use signals::run_until_signalled;
