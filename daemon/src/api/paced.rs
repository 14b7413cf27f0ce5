//! A few messages per poll, so a slow client holds back the daemon, not a
//! buffer of stale samples.
//!
//! tonic's encoder pulls items from a response stream until it has 32 KiB
//! or the stream is pending, and HTTP/2 then sends that chunk as the
//! client's window allows. A stream that always has a frame ready (a
//! subscriber behind the cycle) would therefore fill 32 KiB with samples
//! that are fresh when taken and seconds old when they leave. [`Paced`]
//! answers "pending" once after every [`BURST`] items (waking itself at
//! once): the encoder hands on a small batch, and hyper polls for the next
//! only when the connection has room for it, so samples are taken from the
//! input channel (and their age checked, see `pdo::AgeGate`) just before
//! they can be sent.
//!
//! Not one item per poll: every chunk becomes an HTTP/2 DATA frame, and
//! clients limit how many small frames they buffer (h2 answers a slow
//! reader's pile of sub-256-byte frames with GOAWAY "too_many_data_frames").
//! A batch of 32 samples is well above that size and a few milliseconds of
//! frames at the fastest cycle.

use std::pin::Pin;
use std::task::{Context, Poll};

use tokio_stream::Stream;

/// Items handed on before the stream pauses once.
pub(crate) const BURST: u32 = 32;

/// A stream that pauses (pending, woken at once) after every [`BURST`]
/// items in a row.
#[derive(Debug)]
pub(crate) struct Paced<S> {
    inner: S,
    burst: u32,
    in_a_row: u32,
}

impl<S> Paced<S> {
    /// Paces `inner` with the default burst.
    pub(crate) fn new(inner: S) -> Self {
        Self::with_burst(inner, BURST)
    }

    /// Paces `inner`, pausing after `burst` items (at least 1).
    pub(crate) fn with_burst(inner: S, burst: u32) -> Self {
        Self { inner, burst: burst.max(1), in_a_row: 0 }
    }
}

impl<S: Stream + Unpin> Stream for Paced<S> {
    type Item = S::Item;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<S::Item>> {
        if self.in_a_row >= self.burst {
            self.in_a_row = 0;
            cx.waker().wake_by_ref();
            return Poll::Pending;
        }
        let item = Pin::new(&mut self.inner).poll_next(cx);
        match item {
            Poll::Ready(Some(_)) => self.in_a_row += 1,
            // The source ran dry on its own: the next batch starts afresh.
            _ => self.in_a_row = 0,
        }
        item
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::task::Waker;

    #[test]
    fn every_burst_is_followed_by_one_pending() {
        let mut s = Paced::with_burst(tokio_stream::iter([1, 2]), 1);
        let mut cx = Context::from_waker(Waker::noop());
        let mut polls = Vec::new();
        for _ in 0..5 {
            polls.push(Pin::new(&mut s).poll_next(&mut cx));
        }
        assert_eq!(
            polls,
            [Poll::Ready(Some(1)), Poll::Pending, Poll::Ready(Some(2)), Poll::Pending, Poll::Ready(None)]
        );
        let mut s = Paced::with_burst(tokio_stream::iter(0..5), 2);
        let polls: Vec<Poll<Option<i32>>> = (0..8).map(|_| Pin::new(&mut s).poll_next(&mut cx)).collect();
        let pending = polls.iter().filter(|p| p.is_pending()).count();
        assert_eq!(pending, 2, "{polls:?}");
    }
}
