//! The gRPC API (`ecmxf.v1`, see `proto/`): one service module per
//! concern, all sharing a [`Context`] — the master (which owns the domain:
//! the process image, the newest inputs, the output image as written, the
//! leases, the output ranges frame streams feed), the authenticator. Every
//! call identifies its caller
//! (see `auth`), hands the master its [`Call`] (the client whose turn the
//! chip work takes on the blocking slot, and the client's deadline), and
//! maps engine errors once (`status`, [`bounded`]).
//!
//! Served on a Unix socket (default) and optionally on TCP with TLS, plus
//! gRPC health (SERVING only while the bus runs) and reflection (v1 and
//! v1alpha).

use std::sync::Arc;
use std::time::{Duration, Instant};

use tonic::{Request, Status};

use crate::master::{Call, Master};

pub(crate) mod admin;
pub(crate) mod auth;
pub(crate) mod authority;
pub(crate) mod cia402;
pub(crate) mod convert;
pub(crate) mod diagnostics;
pub(crate) mod error_details;
pub(crate) mod frames;
pub(crate) mod image;
pub(crate) mod leases;
pub(crate) mod master;
pub(crate) mod paced;
pub(crate) mod pdo;
pub(crate) mod peripherals;
pub(crate) mod sdo;
pub(crate) mod server;
pub(crate) mod sii;
pub(crate) mod status;

use auth::{Authenticator, Caller, Role};

/// A server stream as the services return it.
pub(crate) type BoxStream<T> = std::pin::Pin<Box<dyn tokio_stream::Stream<Item = Result<T, Status>> + Send>>;

/// What every service shares.
#[derive(Debug)]
pub(crate) struct Context {
    /// The engine.
    pub master: Arc<Master>,
    /// Roles (replaced whole on SIGHUP, see [`Context::reload_roles`]).
    pub auth: std::sync::RwLock<Authenticator>,
    /// SDO transfer durations, for the metrics endpoint.
    pub sdo_latency: Arc<crate::master::histogram::Histogram>,
    /// The oldest a streamed input sample may be (`api.stream_max_age_ms`).
    pub stream_max_age: Duration,
    /// Set when the daemon stops: every open server stream ends with
    /// [`status::stopping`] instead of a connection cut mid-body.
    stopping: tokio::sync::watch::Sender<bool>,
    /// Counts reloads of the rules: open streams check their caller again.
    rules: tokio::sync::watch::Sender<u64>,
    /// The identity behind each lease holder's name.
    holders: std::sync::Mutex<std::collections::HashMap<String, auth::Identity>>,
    /// The daemon's log filter, when the daemon owns its logging (set once
    /// by the service that started it; embedded daemons have none).
    pub log_filter: std::sync::OnceLock<Arc<dyn LogFilter>>,
}

/// The daemon's log filter as `Master.GetLogFilter`/`SetLogFilter` reach
/// it: implemented by the service that started logging.
pub(crate) trait LogFilter: Send + Sync + std::fmt::Debug {
    /// The filter in force, and whether `RUST_LOG` set it.
    fn current(&self) -> (String, bool);
    /// Replaces the filter until the next reload or restart.
    fn set(&self, filter: &str) -> Result<(), LogFilterRefusal>;
}

/// Why a log filter was not applied.
#[derive(Debug)]
pub(crate) enum LogFilterRefusal {
    /// `RUST_LOG` is in force and wins.
    FromEnv,
    /// The text is not a filter: the parser's reason.
    Invalid(String),
}

impl Context {
    /// A context over `master`.
    pub(crate) fn new(master: Arc<Master>, config: &crate::config::ApiConfig, own_uid: u32) -> Arc<Self> {
        Arc::new(Self {
            master,
            auth: std::sync::RwLock::new(Authenticator::new(config, own_uid)),
            sdo_latency: Arc::default(),
            stream_max_age: Duration::from_millis(config.stream_max_age_ms.into()),
            stopping: tokio::sync::watch::Sender::new(false),
            rules: tokio::sync::watch::Sender::new(0),
            holders: std::sync::Mutex::default(),
            log_filter: std::sync::OnceLock::new(),
        })
    }

    /// Ends every open server stream with UNAVAILABLE "daemon stopping"
    /// (see [`Context::serve_stream`]); called as shutdown begins.
    pub(crate) fn stop_streams(&self) {
        self.stopping.send_replace(true);
    }

    /// `inner`, for `caller`, until the daemon stops or the caller loses
    /// the access the stream was opened with. Stopping: one UNAVAILABLE
    /// status with reason STOPPING, and the end, so a client (ecmxfctl
    /// events, the Python package) tells a stopping daemon from a broken
    /// connection. Access lost (a reload revoked the token, removed the
    /// certificate or lowered the role): PERMISSION_DENIED naming the
    /// caller, at once, not at the stream's next item. A stream that ends
    /// by itself first ends as it would.
    pub(crate) fn serve_stream<T: Send + 'static>(
        self: &Arc<Self>,
        caller: &Caller,
        inner: BoxStream<T>,
    ) -> BoxStream<T> {
        use tokio_stream::StreamExt;
        // Everything the stream needs travels in its state: nothing is
        // copied per item.
        struct Open<T> {
            inner: BoxStream<T>,
            stop: tokio::sync::watch::Receiver<bool>,
            rules: tokio::sync::watch::Receiver<u64>,
            ctx: Arc<Context>,
            caller: Caller,
        }
        enum Next<T> {
            Stop,
            Rules,
            Item(Option<Result<T, Status>>),
        }
        let open = Open {
            inner,
            stop: self.stopping.subscribe(),
            rules: self.rules.subscribe(),
            ctx: Arc::clone(self),
            caller: caller.clone(),
        };
        Box::pin(futures_util::stream::unfold(Some(open), |state| async move {
            let mut open = state?;
            loop {
                let next = tokio::select! {
                    biased;
                    _ = open.stop.wait_for(|s| *s) => Next::Stop,
                    // The sender lives in `ctx`, held here: never closed.
                    _ = open.rules.changed() => Next::Rules,
                    item = open.inner.next() => Next::Item(item),
                };
                match next {
                    Next::Stop => return Some((Err(status::stopping()), None)),
                    Next::Rules if !open.ctx.still_allowed(&open.caller) => {
                        return Some((Err(status::access_revoked(&open.caller.who)), None));
                    }
                    Next::Rules => {}
                    Next::Item(item) => return item.map(|i| (i, Some(open))),
                }
            }
        }))
    }

    /// Whether `caller` still has the role its call was authorized for
    /// under the rules in force.
    fn still_allowed(&self, caller: &Caller) -> bool {
        let auth = self.auth.read().unwrap_or_else(|e| e.into_inner());
        auth.role_of(&caller.identity).is_some_and(|r| r >= caller.needed)
    }

    /// Notes who took a lease, so that a reload that takes their access
    /// away ends it (see [`Context::reload_roles`]).
    pub(crate) fn note_lease_holder(&self, caller: &Caller) {
        let mut holders = self.holders.lock().unwrap_or_else(|e| e.into_inner());
        holders.insert(caller.who.clone(), caller.identity.clone());
    }

    /// A slave position from a request that must name a slave on the ring
    /// (INVALID_ARGUMENT naming `slave` otherwise: the chip would only
    /// answer "refused" for a slave that is not there).
    pub(crate) fn slave(&self, v: u32) -> Result<u8, Status> {
        convert::existing_slave(&self.master, v, "slave")
    }

    /// Takes the `[api]` roles, tokens and client certificates of a reloaded
    /// configuration; calls already authorized keep their role, but open
    /// streams and leases of a caller who lost the access they were opened
    /// or taken with end now (a revoked token must not keep streaming or
    /// holding outputs).
    pub(crate) fn reload_roles(&self, config: &crate::config::ApiConfig) {
        let own_uid = nix::unistd::getuid().as_raw();
        let auth = Authenticator::new(config, own_uid);
        {
            let mut holders = self.holders.lock().unwrap_or_else(|e| e.into_inner());
            // A holder this front end does not know (another front end's)
            // keeps its lease.
            let allowed =
                |who: &str| holders.get(who).is_none_or(|id| auth.role_of(id).is_some_and(|r| r >= Role::Operator));
            for (lease, who) in self.master.leases().end_unless(allowed) {
                tracing::warn!(lease = %lease, %who, "output lease ended: its holder lost operator access on reload");
            }
            let held = self.master.leases().holders();
            holders.retain(|who, _| held.contains(who));
        }
        *self.auth.write().unwrap_or_else(|e| e.into_inner()) = auth;
        self.rules.send_modify(|g| *g += 1);
    }

    /// Authorizes a call for `role`.
    pub(crate) fn authorize<T>(&self, request: &Request<T>, role: Role) -> Result<Caller, Status> {
        self.auth.read().unwrap_or_else(|e| e.into_inner()).authorize(request, role)
    }
}

/// How long a whole-network action (re-init, warm reset, a new
/// configuration) may take when the client sets no deadline: a bring-up
/// takes seconds.
pub(crate) const NETWORK_WAIT: Duration = Duration::from_secs(30);

/// The time left of the client's deadline (`grpc-timeout`), less a margin
/// (a tenth, at most 20 ms) so that this daemon answers first with
/// DEADLINE_EXCEEDED: tonic's own deadline layer, which fires at the exact
/// deadline, answers CANCELLED "Timeout expired" (it still may, when the
/// host stalls longer than the margin). `None` when the client gave none.
/// A header that is no timeout (gRPC over HTTP/2, "Timeout": 1 to 8
/// digits and a unit) is refused naming it: tonic's layer ignores it, and
/// a call the client meant to bound would run with the daemon's default.
pub(crate) fn deadline<T>(request: &Request<T>) -> Result<Option<Duration>, Status> {
    let Some(v) = request.metadata().get("grpc-timeout") else { return Ok(None) };
    let bad = || {
        status::bad_argument(
            "grpc-timeout",
            format!(
                "{:?} is no timeout: 1 to 8 digits and a unit (H, M, S, m, u, n), e.g. 500m",
                String::from_utf8_lossy(v.as_bytes())
            ),
        )
    };
    let v = v.to_str().map_err(|_| bad())?;
    let Some(split) = v.len().checked_sub(1).filter(|n| (1..=8).contains(n)) else { return Err(bad()) };
    let (digits, unit) = v.split_at(split);
    if !digits.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad());
    }
    let n: u64 = digits.parse().map_err(|_| bad())?;
    let d = match unit {
        "H" => Duration::from_secs(n * 3600),
        "M" => Duration::from_secs(n * 60),
        "S" => Duration::from_secs(n),
        "m" => Duration::from_millis(n),
        "u" => Duration::from_micros(n),
        "n" => Duration::from_nanos(n),
        _ => return Err(bad()),
    };
    Ok(Some(d.saturating_sub((d / 10).min(Duration::from_millis(20)))))
}

/// The outcome of `work`, which runs as `caller.call` (its client's
/// turns, its deadline on every request and wait), as a status: an error
/// that comes once the deadline passed is DEADLINE_EXCEEDED saying so,
/// whatever step of a multi-step call it ended (an SII range, a scan, an
/// axis command), as the caller needs no other reason. A result that did
/// come is kept, late or not: the margin of [`deadline`] leaves the client
/// time to take it.
pub(crate) async fn bounded<T, E: Into<Status>>(
    caller: &Caller,
    work: impl std::future::Future<Output = Result<T, E>>,
) -> Result<T, Status> {
    match (work.await, caller.budget) {
        (Err(_), Some(d)) if caller.call.passed() => Err(Status::deadline_exceeded(format!(
            "no result after {d:.1?}, all the time the caller's deadline allowed (its grpc-timeout, less a margin \
             to answer before it ends); give the call a longer deadline"
        ))),
        (r, _) => r.map_err(Into::into),
    }
}

/// `caller.call` ending at the latest `timeout_ms` from now (0: no such
/// limit), and `default` from now when neither it nor the client sets an
/// end: for calls that wait for something to happen.
pub(crate) fn wait_budget(caller: &Caller, timeout_ms: u32, default: Duration) -> Call {
    let call = match timeout_ms {
        0 => caller.call,
        ms => caller.call.until(Instant::now() + Duration::from_millis(ms.into())),
    };
    call.or_within(default)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grpc_timeout_units_are_read() {
        for (v, ms) in [("5S", 4980), ("100m", 90), ("1M", 59_980), ("2000000u", 1980), ("10m", 9)] {
            let mut r = Request::new(());
            r.metadata_mut().insert("grpc-timeout", v.parse().unwrap());
            assert_eq!(deadline(&r).unwrap(), Some(Duration::from_millis(ms)), "{v}");
        }
        assert_eq!(deadline(&Request::new(())).unwrap(), None);
    }

    #[test]
    fn a_malformed_grpc_timeout_is_refused_naming_it() {
        for v in ["x", "S", "-5S", "abcS", "5", "5s", "+5S", "123456789m", "1.5S", " 5S"] {
            let mut r = Request::new(());
            r.metadata_mut().insert("grpc-timeout", v.parse().unwrap());
            let e = deadline(&r).unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument, "{v}");
            assert!(e.message().contains("grpc-timeout"), "{v}: {}", e.message());
        }
        let mut r = Request::new(());
        r.metadata_mut().insert("grpc-timeout", "99999999H".parse().unwrap());
        assert!(deadline(&r).unwrap().is_some(), "8 digits are a timeout");
    }
}
