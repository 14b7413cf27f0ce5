//! Connection admission for every listener (the API's Unix socket and TCP
//! port, the metrics endpoint): a cap on the connections a listener holds
//! and on those of one peer address, a deadline for a new connection's
//! handshake, and the file-descriptor budget all caps together need.
//!
//! Each listener has its own [`Gate`], so peers of one listener (TCP, say)
//! can never use up the budget of another (the Unix socket, where the
//! administrator comes in). A connection over a cap is closed at once; one
//! WARN line per cap and [`REFUSAL_LOG_EVERY`] says which cap refused and
//! how many were refused since, never one line per refusal. Nothing here
//! runs per packet: the bookkeeping happens at accept and at close.

use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::net::IpAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, ReadBuf};
use tokio::sync::mpsc;

/// How often at most each cap's refusals are logged.
pub(crate) const REFUSAL_LOG_EVERY: Duration = Duration::from_secs(60);

/// How long a listener waits before accepting again when the process is out
/// of file descriptors: accepting at once would fail again at once, and
/// that loop is what burns a core while the peers stay.
const OUT_OF_FDS_PAUSE: Duration = Duration::from_millis(100);

/// The HTTP/2 client connection preface (RFC 9113, section 3.4): every
/// gRPC client sends it first.
pub(crate) const H2_PREFACE: &[u8; 24] = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n";

/// Which cap refused a connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Refused {
    /// The listener holds as many connections as it may.
    Listener,
    /// The peer address holds as many connections as it may.
    Peer,
}

/// One cap: its limit and the configuration key that sets it (named in the
/// log line when it refuses).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Cap {
    /// The most connections at once.
    pub limit: usize,
    /// Where it is set, e.g. `api.max_connections`.
    pub key: &'static str,
}

/// Rate-limited refusal log of one cap.
#[derive(Debug, Default)]
struct RefusalLog {
    last: Option<Instant>,
    since: u64,
}

impl RefusalLog {
    /// Counts a refusal; `Some(refusals since the last line)` when a line
    /// is due now.
    fn refused(&mut self, now: Instant) -> Option<u64> {
        self.since += 1;
        match self.last {
            Some(t) if now.duration_since(t) < REFUSAL_LOG_EVERY => None,
            _ => {
                self.last = Some(now);
                Some(std::mem::take(&mut self.since))
            }
        }
    }
}

#[derive(Debug, Default)]
struct State {
    open: usize,
    peers: HashMap<IpAddr, usize>,
    listener_log: RefusalLog,
    peer_log: RefusalLog,
    fds_log: RefusalLog,
}

#[derive(Debug)]
struct Shared {
    listener: &'static str,
    total: Cap,
    per_peer: Option<Cap>,
    state: Mutex<State>,
}

/// The caps of one listener. Cloning shares the counts.
#[derive(Clone, Debug)]
pub(crate) struct Gate(Arc<Shared>);

/// An admitted connection's place under its listener's caps, given back
/// when dropped (when the connection closes).
#[derive(Debug)]
pub(crate) struct Ticket {
    gate: Arc<Shared>,
    peer: Option<IpAddr>,
}

impl Gate {
    /// A gate for `listener` (its name in logs, e.g. `api.tcp`) with a cap
    /// on all its connections and, for network listeners, on each peer
    /// address's.
    pub(crate) fn new(listener: &'static str, total: Cap, per_peer: Option<Cap>) -> Self {
        Self(Arc::new(Shared { listener, total, per_peer, state: Mutex::default() }))
    }

    /// Connections held now.
    #[cfg(test)]
    pub(crate) fn open(&self) -> usize {
        self.lock().open
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // The counts stay consistent even if a holder panicked: every
        // update is a single step.
        self.0.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Admits a connection from `peer` (`None`: a Unix peer) or says which
    /// cap refuses it; a refusal is logged, rate-limited.
    pub(crate) fn admit(&self, peer: Option<IpAddr>) -> Result<Ticket, Refused> {
        let mut s = self.lock();
        let refused = if s.open >= self.0.total.limit {
            Some(Refused::Listener)
        } else if let (Some(cap), Some(ip)) = (self.0.per_peer, peer) {
            (s.peers.get(&ip).copied().unwrap_or(0) >= cap.limit).then_some(Refused::Peer)
        } else {
            None
        };
        if let Some(why) = refused {
            let (cap, log) = match why {
                Refused::Listener => (self.0.total, &mut s.listener_log),
                Refused::Peer => (self.0.per_peer.unwrap_or(self.0.total), &mut s.peer_log),
            };
            if let Some(since) = log.refused(Instant::now()) {
                tracing::warn!(
                    listener = self.0.listener,
                    cap = cap.key,
                    limit = cap.limit,
                    peer = peer.map(|p| p.to_string()).unwrap_or_else(|| "unix".into()),
                    refused_since_last_line = since,
                    "connection refused: {} ({}) reached; the next refusals of this cap are logged at most once a minute",
                    cap.key,
                    cap.limit,
                );
            }
            return Err(why);
        }
        s.open += 1;
        if let (Some(_), Some(ip)) = (self.0.per_peer, peer) {
            *s.peers.entry(ip).or_insert(0) += 1;
        }
        Ok(Ticket { gate: Arc::clone(&self.0), peer: peer.filter(|_| self.0.per_peer.is_some()) })
    }

    /// After a failed accept: when the process is out of file descriptors,
    /// says so (rate-limited) and pauses before the next accept; other
    /// failures concern only the one connection.
    pub(crate) async fn accept_failed(&self, e: &io::Error) {
        use nix::errno::Errno;
        let out_of_fds = matches!(e.raw_os_error().map(Errno::from_raw), Some(Errno::EMFILE | Errno::ENFILE));
        if !out_of_fds {
            return;
        }
        if let Some(since) = self.lock().fds_log.refused(Instant::now()) {
            tracing::warn!(
                listener = self.0.listener,
                failed_since_last_line = since,
                "cannot accept: {e} (raise LimitNOFILE= or lower the connection caps; docs/troubleshooting.md)"
            );
        }
        tokio::time::sleep(OUT_OF_FDS_PAUSE).await;
    }
}

impl Drop for Ticket {
    fn drop(&mut self) {
        let mut s = self.gate.state.lock().unwrap_or_else(|e| e.into_inner());
        s.open = s.open.saturating_sub(1);
        if let Some(ip) = self.peer {
            if let Some(n) = s.peers.get_mut(&ip) {
                *n -= 1;
                if *n == 0 {
                    s.peers.remove(&ip);
                }
            }
        }
    }
}

/// A connection that passed admission and its handshake: the stream, the
/// HTTP/2 preface read to check it (handed to the server again first), and
/// the ticket that frees its place when it closes.
#[derive(Debug)]
pub(crate) struct Admitted<S> {
    io: S,
    preface_left: usize,
    _ticket: Ticket,
}

impl<S: AsyncRead + AsyncWrite + Unpin> Admitted<S> {
    /// Reads the HTTP/2 preface from `io`; a stream that sends something
    /// else is not HTTP/2 (gRPC) and is refused.
    pub(crate) async fn read_preface(mut io: S, ticket: Ticket) -> io::Result<Self> {
        let mut got = [0u8; 24];
        io.read_exact(&mut got).await?;
        if &got != H2_PREFACE {
            return Err(io::Error::new(io::ErrorKind::InvalidData, "not an HTTP/2 client preface"));
        }
        Ok(Self { io, preface_left: H2_PREFACE.len(), _ticket: ticket })
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for Admitted<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        if self.preface_left > 0 {
            let start = H2_PREFACE.len() - self.preface_left;
            let n = self.preface_left.min(buf.remaining());
            buf.put_slice(&H2_PREFACE[start..start + n]);
            self.preface_left -= n;
            return Poll::Ready(Ok(()));
        }
        Pin::new(&mut self.io).poll_read(cx, buf)
    }
}

/// `AsyncWrite` for a connection wrapper whose writes go to its `io` field
/// as they are (what the server writes needs no admission), and
/// `Connected` from it (the peer's credentials): for [`Admitted`] and the
/// API's Unix-socket reader (`api/authority.rs`).
macro_rules! writes_and_peer_from_io {
    ($wrapper:ident) => {
        impl<S: tokio::io::AsyncWrite + Unpin> tokio::io::AsyncWrite for $wrapper<S> {
            fn poll_write(
                mut self: std::pin::Pin<&mut Self>,
                cx: &mut std::task::Context<'_>,
                buf: &[u8],
            ) -> std::task::Poll<std::io::Result<usize>> {
                std::pin::Pin::new(&mut self.io).poll_write(cx, buf)
            }

            fn poll_write_vectored(
                mut self: std::pin::Pin<&mut Self>,
                cx: &mut std::task::Context<'_>,
                bufs: &[std::io::IoSlice<'_>],
            ) -> std::task::Poll<std::io::Result<usize>> {
                std::pin::Pin::new(&mut self.io).poll_write_vectored(cx, bufs)
            }

            fn is_write_vectored(&self) -> bool {
                self.io.is_write_vectored()
            }

            fn poll_flush(
                mut self: std::pin::Pin<&mut Self>,
                cx: &mut std::task::Context<'_>,
            ) -> std::task::Poll<std::io::Result<()>> {
                std::pin::Pin::new(&mut self.io).poll_flush(cx)
            }

            fn poll_shutdown(
                mut self: std::pin::Pin<&mut Self>,
                cx: &mut std::task::Context<'_>,
            ) -> std::task::Poll<std::io::Result<()>> {
                std::pin::Pin::new(&mut self.io).poll_shutdown(cx)
            }
        }

        impl<S: tonic::transport::server::Connected> tonic::transport::server::Connected for $wrapper<S> {
            type ConnectInfo = S::ConnectInfo;

            fn connect_info(&self) -> Self::ConnectInfo {
                self.io.connect_info()
            }
        }
    };
}
pub(crate) use writes_and_peer_from_io;

writes_and_peer_from_io!(Admitted);

/// A listener the admission loop accepts from.
pub(crate) trait Accept: Send + 'static {
    /// The accepted stream.
    type Io: AsyncRead + AsyncWrite + Unpin + Send + 'static;
    /// The next connection and its peer address (`None` for a Unix peer).
    fn accept(&self) -> impl Future<Output = io::Result<(Self::Io, Option<IpAddr>)>> + Send;
}

impl Accept for tokio::net::TcpListener {
    type Io = tokio::net::TcpStream;
    async fn accept(&self) -> io::Result<(Self::Io, Option<IpAddr>)> {
        let (s, a) = tokio::net::TcpListener::accept(self).await?;
        Ok((s, Some(a.ip())))
    }
}

impl Accept for tokio::net::UnixListener {
    type Io = tokio::net::UnixStream;
    async fn accept(&self) -> io::Result<(Self::Io, Option<IpAddr>)> {
        let (s, _) = tokio::net::UnixListener::accept(self).await?;
        Ok((s, None))
    }
}

/// Accepts from `listener` for as long as `out` is read: each connection
/// is admitted by `gate` (or closed at once), then has `deadline` to run
/// `handshake` (TLS, or nothing) and send the HTTP/2 preface, each in a
/// task of its own so a slow peer holds up no other. A connection that
/// misses the deadline, fails the handshake or sends something else is
/// closed without a word: a peer that cannot speak gRPC gets no answer.
pub(crate) async fn admit_loop<L, H, F, O>(
    listener: L,
    gate: Gate,
    deadline: Duration,
    handshake: H,
    out: mpsc::Sender<Admitted<O>>,
) where
    L: Accept,
    H: Fn(L::Io) -> F + Send + Sync + 'static,
    F: Future<Output = io::Result<O>> + Send + 'static,
    O: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let handshake = Arc::new(handshake);
    loop {
        let (io, peer) = match listener.accept().await {
            Ok(c) => c,
            Err(e) => {
                gate.accept_failed(&e).await;
                continue;
            }
        };
        let Ok(ticket) = gate.admit(peer) else { continue };
        let (handshake, tx) = (Arc::clone(&handshake), out.clone());
        tokio::spawn(async move {
            let ready = tokio::time::timeout(deadline, async {
                let io = handshake(io).await?;
                Admitted::read_preface(io, ticket).await
            })
            .await;
            if let Ok(Ok(conn)) = ready {
                let _ = tx.send(conn).await;
            }
        });
        if out.is_closed() {
            return;
        }
    }
}

/// File descriptors the daemon needs besides its listeners' connections:
/// the chip's devices, the listeners, the log, the journal, MQTT, the
/// runtime's own, and room for a few files opened at once.
pub(crate) const FD_RESERVE: u64 = 128;

/// Makes room for `needed` open files: raises the soft RLIMIT_NOFILE up to
/// the hard limit where it is lower, and warns once when even the hard
/// limit is too low (then the caps cannot all be filled, and a full
/// listener starts failing accepts instead of refusing cleanly).
pub(crate) fn ensure_fd_budget(needed: u64) {
    use nix::sys::resource::{Resource, getrlimit, setrlimit};
    let Ok((soft, hard)) = getrlimit(Resource::RLIMIT_NOFILE) else { return };
    if soft >= needed {
        return;
    }
    let target = needed.min(hard);
    if setrlimit(Resource::RLIMIT_NOFILE, target, hard).is_err() {
        tracing::warn!(soft, hard, needed, "cannot raise the open-file limit; the connection caps may not fit");
        return;
    }
    if target < needed {
        tracing::warn!(
            limit = target,
            needed,
            "the open-file limit is below what the connection caps need (api.max_connections + \
             api.max_socket_connections + the metrics endpoint's + {FD_RESERVE}): raise LimitNOFILE= \
             or lower the caps"
        );
    } else {
        tracing::debug!(from = soft, to = target, "raised the open-file limit for the connection caps");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gate(total: usize, per_peer: usize) -> Gate {
        Gate::new(
            "test",
            Cap { limit: total, key: "test.max" },
            Some(Cap { limit: per_peer, key: "test.max_per_peer" }),
        )
    }

    const A: IpAddr = IpAddr::V4(std::net::Ipv4Addr::new(10, 0, 0, 1));
    const B: IpAddr = IpAddr::V4(std::net::Ipv4Addr::new(10, 0, 0, 2));

    #[test]
    fn a_peer_over_its_cap_is_refused_and_others_still_come_in() {
        let g = gate(10, 2);
        let a1 = g.admit(Some(A)).unwrap();
        let _a2 = g.admit(Some(A)).unwrap();
        assert_eq!(g.admit(Some(A)).unwrap_err(), Refused::Peer);
        let _b = g.admit(Some(B)).unwrap();
        assert_eq!(g.open(), 3, "a refusal takes no place");
        drop(a1);
        let _a3 = g.admit(Some(A)).expect("a closed connection frees its peer's place");
    }

    #[test]
    fn the_listener_cap_refuses_every_peer_until_one_closes() {
        let g = gate(2, 2);
        let a = g.admit(Some(A)).unwrap();
        let _b = g.admit(Some(B)).unwrap();
        assert_eq!(g.admit(Some(B)).unwrap_err(), Refused::Listener, "the listener's cap is checked first");
        assert_eq!(g.admit(None).unwrap_err(), Refused::Listener);
        drop(a);
        assert_eq!(g.open(), 1);
        g.admit(Some(B)).expect("room again");
    }

    #[test]
    fn places_are_counted_per_gate() {
        let tcp = gate(1, 1);
        let unix = Gate::new("unix", Cap { limit: 1, key: "unix.max" }, None);
        let _t = tcp.admit(Some(A)).unwrap();
        assert!(tcp.admit(Some(B)).is_err());
        let _u = unix.admit(None).expect("another listener's budget is its own");
        assert_eq!((tcp.open(), unix.open()), (1, 1));
    }

    #[test]
    fn the_per_peer_table_forgets_peers_that_left() {
        let g = gate(100, 5);
        let tickets: Vec<_> = (0..50u8).map(|i| g.admit(Some(IpAddr::from([10, 0, 1, i]))).unwrap()).collect();
        drop(tickets);
        assert_eq!(g.open(), 0);
        assert!(g.lock().peers.is_empty(), "no entry left for a peer without connections");
    }

    #[test]
    fn refusals_are_logged_once_per_interval_with_the_count_since() {
        let mut log = RefusalLog::default();
        let t0 = Instant::now();
        assert_eq!(log.refused(t0), Some(1), "the first refusal is logged");
        assert_eq!(log.refused(t0 + Duration::from_secs(1)), None);
        assert_eq!(log.refused(t0 + Duration::from_secs(59)), None);
        assert_eq!(log.refused(t0 + REFUSAL_LOG_EVERY), Some(3), "the line counts the unlogged ones too");
    }

    #[tokio::test]
    async fn the_preface_is_handed_on_and_anything_else_is_refused() {
        let g = gate(4, 4);
        let (mut client, server) = tokio::io::duplex(64);
        use tokio::io::AsyncWriteExt;
        client.write_all(H2_PREFACE).await.unwrap();
        client.write_all(b"frame").await.unwrap();
        let mut conn = Admitted::read_preface(server, g.admit(Some(A)).unwrap()).await.unwrap();
        let mut got = vec![0u8; 29];
        conn.read_exact(&mut got).await.unwrap();
        assert_eq!(&got[..24], H2_PREFACE);
        assert_eq!(&got[24..], b"frame");
        drop(conn);
        assert_eq!(g.open(), 0, "closing frees the place");

        let (mut client, server) = tokio::io::duplex(64);
        client.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n").await.unwrap();
        assert!(Admitted::read_preface(server, g.admit(Some(A)).unwrap()).await.is_err());
        assert_eq!(g.open(), 0);
    }
}
