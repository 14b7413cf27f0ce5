//! Troubles that pass: the RxFIFO ran dry, the chip dropped input frames,
//! the host went too long between two FIFO exchanges. Each is over by the
//! time anyone looks, and the network runs on; counted since the start they
//! only grow, so health could never say whether they still happen. A
//! [`RecentTrouble`] keeps the latest run of one kind instead: events no
//! more than [`TROUBLE_WINDOW`] apart belong to one run, and a run is
//! "recent" until a whole window passes without another. Health is degraded
//! while one is recent and heals by itself (see `master::Health`).
//!
//! The engine thread records (a few relaxed atomics, only when the event
//! happens: nothing on the cyclic path when all is well); readers copy.

use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::Duration;

/// How long one kind of trouble keeps health degraded after it last
/// happened, and the most two events of one run may be apart.
pub const TROUBLE_WINDOW: Duration = Duration::from_secs(10);

/// The latest run of one kind of trouble, written by the engine thread.
#[derive(Debug, Default)]
pub(crate) struct RecentTrouble {
    last_ns: AtomicU64,
    count: AtomicU64,
    worst: AtomicU64,
}

impl RecentTrouble {
    /// `n` events at `now_ns` (engine epoch), `figure` their size where one
    /// matters (a gap's length, us; else 0). A quiet window since the last
    /// one starts a new run.
    pub(crate) fn record(&self, now_ns: u64, n: u64, figure: u64) {
        let count = self.count.load(Relaxed);
        let quiet = now_ns.saturating_sub(self.last_ns.load(Relaxed)) > TROUBLE_WINDOW.as_nanos() as u64;
        if count == 0 || quiet {
            self.count.store(n, Relaxed);
            self.worst.store(figure, Relaxed);
        } else {
            self.count.store(count + n, Relaxed);
            self.worst.fetch_max(figure, Relaxed);
        }
        self.last_ns.store(now_ns, Relaxed);
    }

    /// Forgets the run: the network is brought up again, and what troubled
    /// the run before belongs to the fault that ended it.
    pub(crate) fn forget(&self) {
        self.count.store(0, Relaxed);
    }

    /// A copy.
    pub(crate) fn read(&self) -> Recent {
        Recent { last_ns: self.last_ns.load(Relaxed), count: self.count.load(Relaxed), worst: self.worst.load(Relaxed) }
    }
}

/// The latest run of one kind of trouble, as a snapshot carries it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Recent {
    /// When the latest event happened, ns since the engine's epoch.
    pub last_ns: u64,
    /// Events in the run (0: none since the start).
    pub count: u64,
    /// The largest figure of the run (a gap's length in us; else 0).
    pub worst: u64,
}

impl Recent {
    /// How long ago the run's latest event was, at `now_ns`, while that is
    /// within [`TROUBLE_WINDOW`]; `None` when the run is over (or there was
    /// none).
    pub fn ago(&self, now_ns: u64) -> Option<Duration> {
        let ago = Duration::from_nanos(now_ns.saturating_sub(self.last_ns));
        (self.count > 0 && ago <= TROUBLE_WINDOW).then_some(ago)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: u64 = 1_000_000_000;

    #[test]
    fn a_run_is_recent_for_one_window_after_its_last_event() {
        let t = RecentTrouble::default();
        assert_eq!(t.read().ago(100 * S), None, "nothing happened");
        t.record(100 * S, 1, 0);
        t.record(105 * S, 2, 0);
        let r = t.read();
        assert_eq!(r.count, 3, "5 s apart: one run");
        assert_eq!(r.ago(112 * S), Some(Duration::from_secs(7)));
        assert_eq!(r.ago(115 * S), Some(TROUBLE_WINDOW), "the window's last instant");
        assert_eq!(r.ago(115 * S + 1), None, "healed by itself");
    }

    #[test]
    fn a_quiet_window_starts_a_new_run_with_its_own_worst() {
        let t = RecentTrouble::default();
        t.record(S, 1, 120_000);
        t.record(2 * S, 1, 80_000);
        assert_eq!((t.read().count, t.read().worst), (2, 120_000));
        t.record(30 * S, 1, 70_000);
        assert_eq!((t.read().count, t.read().worst), (1, 70_000), "the old run is forgotten");
    }
}
