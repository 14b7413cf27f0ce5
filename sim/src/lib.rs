//! `ecmxf-sim`: a simulator of the NEXTW ECM-XF EtherCAT master chip and the
//! EtherCAT network behind it, written from the manuals (docs/protocol.md
//! is the map), never from what a host happens to send.
//!
//! # Map
//! - [`net`]: the network: slaves with their state machine ([`net::esm`]),
//!   the SDO rules on their object dictionary ([`net::od`]), PDO mapping
//!   ([`net::pdo_map`]), CiA402 drives ([`net::cia402`]), ready-made device
//!   profiles ([`net::profiles`]) and slaves from ESI files ([`net::esi`]).
//!   What a device is (SII, ESI, dictionary) is `ecmxf-devices`'; this crate
//!   makes it behave.
//!
//! - [`chip`]: the chip: SPI byte stream, command execution, blocking slot,
//!   FIFOs and DC cycle, INT lines, peripherals.
//! - [`config`]: the network description file (TOML).
//! - [`control`]: run-time fault injection and outside-world commands.
//! - [`server`]: the chip over a Unix socket in real time, and its client.
//!
//! Time is simulated: everything takes the current time in nanoseconds as an
//! argument, so tests advance it deterministically; [`server::Server`] runs
//! it against the wall clock.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod chip;
pub mod config;
pub mod control;
pub mod net;
pub mod server;

pub use chip::{Chip, ChipConfig};
pub use net::Network;
