//! [`Call`]: on whose behalf and until when the master queues chip work.
//! A front end builds one per call and hands it to every method that
//! queues a request, so the client travels with the work (the engine's
//! `FairQueue` gives clients turns by it) and one deadline bounds every
//! request of a multi-step operation (an SII range, a scan, an axis
//! command) as a whole: no outer timeout, no per-step budget.

use std::time::{Duration, Instant};

use crate::engine::slot::DAEMON_CLIENT;

/// Who a piece of chip work is for and when its answer stops mattering.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Call {
    /// The client whose turn each request takes on the blocking slot: a
    /// connection, a peer, [`DAEMON_CLIENT`]; 0 for work no client owns
    /// (all such requests share one turn).
    pub client: u64,
    /// When the caller stops waiting. `None`: each request waits the
    /// master's `default_timeout` for its answer.
    pub deadline: Option<Instant>,
}

impl Call {
    /// Work for `client` until `deadline`.
    pub const fn new(client: u64, deadline: Option<Instant>) -> Self {
        Self { client, deadline }
    }

    /// The daemon's own work (the process-image layout after a bring-up):
    /// its line gets every other turn; no caller's deadline bounds it.
    pub const fn daemon() -> Self {
        Self { client: DAEMON_CLIENT, deadline: None }
    }

    /// Work no client owns, for `timeout` from now (`None`: each request
    /// waits the master's default).
    pub fn anonymous(timeout: Option<Duration>) -> Self {
        Self { client: 0, deadline: timeout.map(|t| Instant::now() + t) }
    }

    /// The time left until the deadline (zero once it passed); `None`
    /// without one.
    pub fn left(&self) -> Option<Duration> {
        self.deadline.map(|d| d.saturating_duration_since(Instant::now()))
    }

    /// Whether the deadline passed.
    pub fn passed(&self) -> bool {
        self.deadline.is_some_and(|d| Instant::now() >= d)
    }

    /// This call, bounded by `limit` from now when it has no deadline of
    /// its own: for operations that wait for something other than one
    /// answer (a drive's state, a network's bring-up) and need an end.
    pub fn or_within(self, limit: Duration) -> Self {
        Self { deadline: Some(self.deadline.unwrap_or_else(|| Instant::now() + limit)), ..self }
    }

    /// This call ending at `end` at the latest.
    pub fn until(self, end: Instant) -> Self {
        Self { deadline: Some(self.deadline.map_or(end, |d| d.min(end))), ..self }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_deadline_is_the_earliest_asked_and_fixed_once() {
        let c = Call::anonymous(Some(Duration::from_secs(10)));
        assert_eq!(c.client, 0);
        assert!(c.left().unwrap() <= Duration::from_secs(10));
        assert_eq!(c.or_within(Duration::from_secs(1)), c, "its own deadline stays");
        let soon = Instant::now() + Duration::from_millis(5);
        assert_eq!(c.until(soon).deadline, Some(soon));
        assert_eq!(Call::daemon().left(), None);
        assert!(Call::daemon().or_within(Duration::ZERO).passed());
        assert!(!Call::new(3, None).passed());
    }
}
