//! `ecmxfd`: the daemon that owns the ECM-XF chip.
//!
//! # Map
//! - [`link`]: the chip behind a small trait (spidev + GPIO, simulator,
//!   simulator socket).
//! - [`port`]: packet exchange with the chip's rules: one-behind answers,
//!   fresh indices, retries that never execute a command twice.
//! - `engine` (private): the thread that owns the chip: bring-up, cyclic FIFO
//!   exchange, the blocking-slot transactions, supervision and recovery.
//! - [`master`]: the async handle to the engine ([`master::Master`]), and
//!   the one door front ends use: it re-exports what they need of the
//!   engine (errors, phases, events, layout, frame streams); it owns the
//!   domain: leases, the process image, output writers
//!   ([`master::outputs`]), device descriptions.
//! - [`api`]: the gRPC front end (tonic): protobuf to and from the master's
//!   domain, errors to status codes, authentication; imports the master
//!   only (daemon/tests/layers.rs checks it).
//! - [`gateway`]: the ETG.8200 mailbox gateway for engineering tools
//!   (UDP), a front end like the API, through the master only.
//! - [`realtime`]: SCHED_FIFO, affinity, mlockall for the engine thread.
//! - [`config`]: the configuration file.
//! - [`metrics`]: the Prometheus endpoint.
//! - [`service`]: life under systemd: sd_notify, watchdog, logging, reload.
//! - [`probe`]: `ecmxfd probe`, first contact with a new board, step by
//!   step with the likely cause and fix of each failure.
//! - [`lifecycle`]: the daemon as a whole: [`run`]`(config, shutdown)`
//!   starts all of the above and stops it safely; the binary is thin.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod api;
pub mod config;
pub(crate) mod engine;
pub mod gateway;
pub mod lifecycle;
pub mod link;
pub mod master;
pub mod metrics;
pub mod port;
pub mod probe;
pub mod realtime;
pub mod service;
pub mod sparkplug;

pub use lifecycle::{DaemonError, Options, run, run_with};
