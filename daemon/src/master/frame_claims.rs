//! The output ranges open per-cycle frame streams feed (StreamFrames), so
//! two streams never feed the same bytes and plain output writes leave
//! them alone: the master's, so every front end sees the same claims.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use super::MAX_STREAMS;

/// Why a range could not be claimed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum ClaimError {
    /// Another stream feeds some of these bytes.
    Overlap,
    /// [`MAX_STREAMS`] streams are open.
    TooMany,
}

/// The claimed ranges.
#[derive(Debug, Default)]
pub(crate) struct FrameClaims(Mutex<Vec<Claim>>);

#[derive(Clone, Copy, Debug)]
struct Claim {
    id: u64,
    start: usize,
    len: usize,
}

impl Claim {
    /// Whether the claim shares a byte with `from..to`.
    fn overlaps(&self, from: usize, to: usize) -> bool {
        self.start < to && from < self.start + self.len
    }
}

/// A range claimed while its stream is open; dropping it gives it back.
#[derive(Debug)]
pub(crate) struct Claimed {
    claims: Arc<FrameClaims>,
    id: u64,
}

impl Drop for Claimed {
    fn drop(&mut self) {
        self.claims.lock().retain(|c| c.id != self.id);
    }
}

impl FrameClaims {
    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<Claim>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Claims `start..start + len` for a new stream.
    pub(crate) fn claim(self: &Arc<Self>, start: usize, len: usize) -> Result<Claimed, ClaimError> {
        static NEXT: AtomicU64 = AtomicU64::new(1);
        let mut claims = self.lock();
        if claims.iter().any(|c| c.overlaps(start, start + len)) {
            return Err(ClaimError::Overlap);
        }
        if claims.len() >= MAX_STREAMS {
            return Err(ClaimError::TooMany);
        }
        let id = NEXT.fetch_add(1, Ordering::Relaxed);
        claims.push(Claim { id, start, len });
        Ok(Claimed { claims: Arc::clone(self), id })
    }

    /// The first claimed range that shares a byte with `from..to`, if any.
    pub(crate) fn overlapping(&self, from: usize, to: usize) -> Option<(usize, usize)> {
        self.lock().iter().find(|c| c.overlaps(from, to)).map(|c| (c.start, c.len))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_are_claimed_once_and_given_back_on_drop() {
        let claims = Arc::new(FrameClaims::default());
        let a = claims.claim(0, 4).unwrap();
        assert_eq!(claims.claim(3, 2).unwrap_err(), ClaimError::Overlap);
        let b = claims.claim(4, 2).unwrap();
        assert_eq!(claims.overlapping(5, 9), Some((4, 2)));
        assert_eq!(claims.overlapping(6, 9), None);
        drop(a);
        assert!(claims.claim(0, 4).is_ok(), "the first range came back (and went again)");
        let held: Vec<Claimed> = (0..MAX_STREAMS - 1).map(|k| claims.claim(100 + 10 * k, 1).unwrap()).collect();
        assert_eq!(claims.claim(1000, 1).unwrap_err(), ClaimError::TooMany);
        drop((b, held));
        assert!(claims.claim(1000, 1).is_ok());
    }
}
