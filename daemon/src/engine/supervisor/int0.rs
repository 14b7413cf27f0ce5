//! INT0 watched while the network runs. A chip drops INT0 when a packet is
//! complete and raises it when it has processed it (v049 ECM-XF中斷), so
//! every packet makes two edges. A line that stays at its ready level
//! while packets go through (a wire broken off the chip's pin, another pin
//! configured, `int0_active_high` wrong with a line that idles high) looks
//! ready all the time: the host clocks packets while the chip still works
//! on the last one, and with a chip slower than the host's turnaround
//! those are lost. Nothing else shows it until then, so the line's edges
//! are counted once a [`super::CENSUS`] (the link's edge count: kernel
//! edge events for the hardware link, level changes for the simulator's)
//! and a line with no edge across [`SILENT_EXCHANGES`] exchanges makes the
//! health "degraded" until it moves again. A link that cannot see INT0
//! (not wired) is not judged.

/// Exchanges without an INT0 edge after which the line is taken as stuck.
/// Every packet makes two: hundreds without one is no timing accident.
pub(crate) const SILENT_EXCHANGES: u64 = 200;

/// What the watch saw at the last census.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Int0Watch {
    last: Option<(u64, u64)>,
    stuck: bool,
}

impl Int0Watch {
    /// A census: the link's INT0 edge count (`None`: it cannot see the
    /// line) and the exchanges so far. Returns the new verdict when it
    /// changed (`true`: stuck).
    pub(crate) fn census(&mut self, edges: Option<u64>, exchanges: u64) -> Option<bool> {
        let Some(edges) = edges else {
            self.last = None;
            return self.set(false);
        };
        let verdict = match self.last.replace((edges, exchanges)) {
            Some((e, x)) if edges == e && exchanges.saturating_sub(x) >= SILENT_EXCHANGES => true,
            Some((e, _)) if edges != e => false,
            _ => self.stuck,
        };
        self.set(verdict)
    }

    fn set(&mut self, stuck: bool) -> Option<bool> {
        (stuck != self.stuck).then(|| {
            self.stuck = stuck;
            stuck
        })
    }

    /// Whether INT0 is taken as stuck.
    pub(crate) fn stuck(&self) -> bool {
        self.stuck
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_that_does_not_move_while_packets_go_through_is_stuck_until_it_moves() {
        let mut w = Int0Watch::default();
        assert_eq!(w.census(Some(10), 1_000), None, "the first look only learns");
        assert_eq!(w.census(Some(900), 2_000), None, "edges: fine");
        assert_eq!(w.census(Some(900), 2_150), None, "150 exchanges without an edge: not yet");
        assert_eq!(w.census(Some(900), 2_400), Some(true));
        assert!(w.stuck());
        assert_eq!(w.census(Some(900), 2_500), None, "said once");
        assert_eq!(w.census(Some(902), 2_600), Some(false), "moves again");
    }

    #[test]
    fn an_idle_link_or_one_without_int0_is_not_judged() {
        let mut w = Int0Watch::default();
        w.census(Some(10), 100);
        assert_eq!(w.census(Some(10), 150), None, "no exchanges, no edges: nothing to judge");
        assert_eq!(w.census(None, 10_000), None);
        assert!(!w.stuck());
    }
}
