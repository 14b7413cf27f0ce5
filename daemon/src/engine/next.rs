//! What a phase of the engine hands on: the phase that comes next, and
//! what it needs to begin.

use super::layout::NetworkLayout;
use super::supervisor::RecoverCause;

/// The engine's next phase (see `thread`).
#[derive(Debug)]
pub(super) enum Next {
    /// Bring the network up.
    BringUp,
    /// Run the network bring-up found.
    Run(NetworkLayout),
    /// Bring-up failed: back off, then try again (the link opened again
    /// first when it was the link that failed).
    Retry { reopen: bool },
    /// A run ended on a fault or a client's action: recover.
    Recover(RecoverCause),
    /// Every request refused, STOPPED said, the thread ends.
    Stop,
}
