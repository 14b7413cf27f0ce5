//! When to poll a PDO assignment read, learned from the reads before it.
//!
//! A layout reads two assignments (PDO_CONFIG_REQ, v049 8) per slave, one
//! after another through the blocking slot: 256 reads for 128 slaves. The
//! chip takes about as long for each (it reads the same objects over CoE),
//! but the polls of [`super::Active::next_poll`] know nothing of that: back
//! to back while the read is young, then every quarter of its age, which
//! at 3 ms is a dozen polls filling the link and an end seen up to 0.7 ms
//! late. So each read that ends is remembered by when the poll that found
//! it ended went out; the next read is polled once it started, then at
//! seven eighths of the shortest of the last [`KEPT`] and at the whole of
//! it, and only after that by the quarter rule. The probe at seven eighths
//! lets a faster read be seen, so the figure follows reads that get
//! quicker as well as slower. SDO transfers keep the quarter rule: their
//! time depends on the object and the slave, not on the command.

use std::sync::atomic::{AtomicU32, AtomicUsize, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// Reads remembered.
const KEPT: usize = 8;

/// The times of the last PDO assignment reads, us (0: none yet). Shared by
/// the engine's transactions, written only by its thread; atomics so a
/// transaction holds it without a lock or an allocation.
#[derive(Debug, Default)]
pub(crate) struct PollPace {
    took_us: [AtomicU32; KEPT],
    next: AtomicUsize,
}

impl PollPace {
    /// The shortest time a recent read took, if one was seen.
    pub(crate) fn expected(&self) -> Option<Duration> {
        let shortest = self.took_us.iter().map(|t| t.load(Relaxed)).filter(|t| *t > 0).min()?;
        Some(Duration::from_micros(u64::from(shortest)))
    }

    /// A read that started at `since` was found ended by a poll sent at
    /// `polled`.
    pub(crate) fn ended(&self, since: Instant, polled: Instant) {
        let took = polled.saturating_duration_since(since).as_micros().clamp(1, u128::from(u32::MAX)) as u32;
        let at = self.next.fetch_add(1, Relaxed) % KEPT;
        self.took_us[at].store(took, Relaxed);
    }
}

/// The next poll of a read that started at `since` and was last polled at
/// `at`, expected to take `expected`: at seven eighths of it, then at the
/// whole of it; `None` once that has passed (the quarter rule takes over).
pub(super) fn paced_poll(since: Instant, at: Instant, expected: Duration) -> Option<Instant> {
    let probe = since + expected * 7 / 8;
    let end = since + expected;
    if at < probe {
        Some(probe)
    } else if at < end {
        Some(end)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shortest_recent_read_is_expected() {
        let pace = PollPace::default();
        assert_eq!(pace.expected(), None);
        let t0 = Instant::now();
        let ms = Duration::from_millis;
        pace.ended(t0, t0 + ms(4));
        pace.ended(t0, t0 + ms(3));
        pace.ended(t0, t0 + ms(5));
        assert_eq!(pace.expected(), Some(ms(3)));
        // Eight later reads of 6 ms push the 3 ms one out.
        for _ in 0..KEPT {
            pace.ended(t0, t0 + ms(6));
        }
        assert_eq!(pace.expected(), Some(ms(6)));
    }

    #[test]
    fn a_read_is_polled_at_seven_eighths_then_at_its_expected_end() {
        let t0 = Instant::now();
        let us = Duration::from_micros;
        let expected = us(3200);
        assert_eq!(paced_poll(t0, t0, expected), Some(t0 + us(2800)), "the probe, however young");
        assert_eq!(paced_poll(t0, t0 + us(2800), expected), Some(t0 + us(3200)));
        assert_eq!(paced_poll(t0, t0 + us(3200), expected), None, "overdue: the quarter rule");
    }
}
