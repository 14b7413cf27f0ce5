//! Whole-network actions a client asks for (re-init, warm reset), picked
//! up by the engine at its next loop turn.

use std::sync::atomic::{AtomicU8, Ordering};

/// A whole-network action a client asked for, picked up by the engine at
/// its next loop turn (no queue: asking twice is asking once).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NetworkAction {
    /// Scan again and redo the bring-up from the configuration.
    Reinit = 1,
    /// Warm-reset the chip (cmd 127), then redo the bring-up.
    WarmReset = 2,
}

/// The pending [`NetworkAction`], if any.
#[derive(Debug, Default)]
pub struct PendingAction(AtomicU8);

impl PendingAction {
    /// Asks for `a` (a warm reset wins over a re-init).
    pub fn request(&self, a: NetworkAction) {
        self.0.fetch_max(a as u8, Ordering::AcqRel);
    }

    /// Takes the pending action.
    pub fn take(&self) -> Option<NetworkAction> {
        match self.0.swap(0, Ordering::AcqRel) {
            1 => Some(NetworkAction::Reinit),
            2 => Some(NetworkAction::WarmReset),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_warm_reset_wins_and_an_action_is_taken_once() {
        let a = PendingAction::default();
        assert_eq!(a.take(), None);
        a.request(NetworkAction::Reinit);
        a.request(NetworkAction::WarmReset);
        a.request(NetworkAction::Reinit);
        assert_eq!(a.take(), Some(NetworkAction::WarmReset));
        assert_eq!(a.take(), None);
    }
}
