//! The scheduler of the chip's single blocking slot (v049 表三: one
//! blocking command at a time, its end seen in the busy bit of later
//! answers).
//!
//! - [`request`]: what async code asks for ([`SlotRequest`]) and how it
//!   travels ([`Job`]: deadline, one-shot reply, client).
//! - [`client`]: the daemon's own turn ([`DAEMON_CLIENT`]).
//! - `fair`: the queue in front of the slot, round-robin between clients.
//! - `transaction`: the one job on the slot (`Active`), advanced a step
//!   at a time between FIFO exchanges (FoE transfers in
//!   `transaction/foe.rs`).
//!
//! The running loop owns the queue (`FairQueue`) and at most one
//! `Active` transaction, and takes the next job when the slot is free
//! (see `engine::running`).

pub(crate) mod client;
mod fair;
pub(crate) mod request;
mod transaction;

// Re-exported by the master as its own (the one door).
#[allow(unreachable_pub)]
pub use client::DAEMON_CLIENT;
pub(super) use fair::FairQueue;
#[allow(unreachable_pub)]
pub use request::{Immediate, TransferProgress};
pub(crate) use request::{Job, SlotRequest};
pub(super) use transaction::{Active, Progress};
