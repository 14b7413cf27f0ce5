//! The scheduler of the chip's single blocking slot (v049 表三: one
//! blocking command at a time, its end seen in the busy bit of later
//! answers).
//!
//! - [`request`]: what async code asks for ([`SlotRequest`]) and how it
//!   travels ([`Job`]: deadline, one-shot reply, client).
//! - [`client`]: the daemon's own turn ([`DAEMON_CLIENT`]).
//! - `fair`: the queue in front of the slot, round-robin between clients.
//! - `transaction`: the one job on the slot (`Active`), advanced a step
//!   at a time between FIFO exchanges. What every kind of request shares
//!   lives there: a read started once, deadlines, the reply; the polls (a
//!   GET that is the poll, the answer one exchange behind) and what the
//!   transaction wants of the link in `transaction/polls.rs`.
//! - `handler`: what one kind of request does on the slot (`Handler`:
//!   start, the GET that polls it, what to do when the chip ends a
//!   command). `kind`: the one place a request picks its handler
//!   (`Kind`). One file per kind:
//!   - `sdo`: SDO upload and download;
//!   - `eeprom`: SII word reads, and writes verified by a read-back;
//!   - `state`: state changes and state reads;
//!   - `pdo`: a slave's PDO assignment and mapping;
//!   - `raw`: raw EtherCAT datagrams;
//!   - `foe`: FoE file transfers, several blocking steps each;
//!   - `immediate`: commands answered in their own exchange (peripherals,
//!     the CiA402 helper, emergencies, slave information).
//!
//! The running loop owns the queue (`FairQueue`) and at most one
//! `Active` transaction, and takes the next job when the slot is free
//! (see `engine::running`).

pub(crate) mod client;
mod eeprom;
mod fair;
mod foe;
mod handler;
mod immediate;
mod kind;
mod pdo;
mod raw;
pub(crate) mod request;
mod sdo;
mod state;
mod transaction;

// Re-exported by the master as its own (the one door).
#[allow(unreachable_pub)]
pub use client::DAEMON_CLIENT;
pub(super) use fair::FairQueue;
#[allow(unreachable_pub)]
pub use request::{Immediate, TransferProgress};
pub(crate) use request::{Job, SlotRequest};
pub(super) use transaction::{Active, PollPace, Progress};
