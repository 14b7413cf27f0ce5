//! `ecmxfd`: the daemon that owns the ECM-XF chip.
//!
//! # Map
//! - [`link`]: the chip behind a small trait (spidev + GPIO, simulator,
//!   simulator socket).
//! - [`port`]: packet exchange with the chip's rules: one-behind answers,
//!   fresh indices, retries that never execute a command twice.
#![warn(missing_docs)]

pub mod link;
/// Packet exchange.
pub mod port;
