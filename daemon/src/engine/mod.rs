//! The engine: one thread that owns the chip.
//!
//! The thread's entry ([`thread`]) moves from phase to phase over what
//! they all share ([`core`]): bring-up ([`bringing_up`], running the
//! procedure in [`bringup`]), the running loop (`running`: one loop turn as
//! named steps), and recovery (`recovering`: back-off, the link opened
//! again) until a stop. Running, it applies output writes, keeps the RxFIFO
//! at its level (`cyclic`: the latency budget's, or midway between the
//! marks) with FIFO exchanges (reading inputs on the way), advances the one
//! transaction in the blocking slot ([`slot`]) by at most one guarded call
//! between FIFO exchanges, and judges every answer by the [`supervisor`]'s
//! rules, which decide when to go back to bring-up (with back-off). It has
//! one door, [`spawn`], which starts it and returns the [`EngineHandle`]:
//! one bounded channel of commands in ([`Command`]: jobs, reconfigure,
//! network actions, frame streams, stop), the output writes on their own,
//! and a wait-free ring of input frames out ([`inputs`]); the status goes
//! out through atomics and a watch of snapshots ([`telemetry`]),
//! supervision events through a ring of their own ([`events`]). Once
//! running, nothing on this thread allocates (daemon/tests/zero_alloc.rs).
//!
//! This file only declares the modules: no file under it uses an item
//! defined here (daemon/tests/layers.rs).

mod bringing_up;
pub(crate) mod bringup;
mod command;
mod core;
pub(crate) mod cyclic;
pub(crate) mod emergencies;
pub(crate) mod error;
pub(crate) mod events;
mod explain;
pub(crate) mod failure;
mod fifo_reads;
pub(crate) mod frames;
mod handle;
pub(crate) mod held;
pub(crate) mod inputs;
mod intake;
pub(crate) mod layout;
pub mod link_budget;
mod link_turn;
pub(crate) mod network_action;
mod next;
pub(crate) mod output_writes;
mod outputs_gone;
mod recovering;
mod running;
pub(crate) mod slot;
pub(crate) mod supervisor;
pub(crate) mod telemetry;
mod thread;
pub(crate) mod trouble;

pub(crate) use command::Command;
// Re-exported by the master as its own (the one door).
#[allow(unreachable_pub)]
pub use handle::{EVENT_BACKLOG, QUEUE_DEPTH, SUBSCRIBER_BACKLOG};
pub(crate) use handle::{EngineHandle, spawn};
