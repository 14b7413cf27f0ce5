//! Whole-network actions a client asks for (re-init, warm reset), sent as
//! [`Command::Network`](super::command::Command::Network) and done by the engine at
//! its next loop turn.

/// A whole-network action a client asked for, done by the engine at its
/// next loop turn (no queue: asking twice is asking once, and a warm reset,
/// ordered above a re-init, wins).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum NetworkAction {
    /// Scan again and redo the bring-up from the configuration.
    Reinit = 1,
    /// Warm-reset the chip (cmd 127), then redo the bring-up.
    WarmReset = 2,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_warm_reset_wins_over_a_reinit() {
        let pending = [NetworkAction::Reinit, NetworkAction::WarmReset, NetworkAction::Reinit]
            .into_iter()
            .fold(None, |p: Option<NetworkAction>, a| p.max(Some(a)));
        assert_eq!(pending, Some(NetworkAction::WarmReset));
    }
}
