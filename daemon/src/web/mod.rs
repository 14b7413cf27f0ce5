//! The web dashboard (`[web]`, docs/web.md): the network, its health and
//! its data in a browser, served by the daemon through the master's door
//! (never the API's code), with the API's tokens and roles.
//!
//! - `assets`: the page, its script and its style, embedded in the binary.
//! - `visitors`: who a request comes from (a session cookie after a login
//!   with an API token, else anonymous) and what it may do.
//! - `overview`: the summary and the live feed every browser shares (one
//!   message every 250 ms, made once for all of them).
//! - `slaves`: the slave list, a slave's page, its dictionary and SDO.
//! - `plots`: input frames sampled 50 times a second, shared by all plots.
//! - `control`: output writes under leases, and the CiA 402 axes.
//!
//! Connections are admitted as every listener's are (`crate::admission`):
//! caps on all and per peer, and a deadline on the TLS handshake and the
//! first request's headers. Each is served by hyper (HTTP/1.1, keep-alive)
//! and ends when the daemon stops.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::State;
use axum::routing::{get, post};
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;
use tracing::{info, warn};

use crate::admission::{Cap, Gate, Ticket};
use crate::config::WebConfig;
use crate::config::api::TokenRole;
use crate::master::Master;

mod assets;
mod control;
mod json_body;
mod overview;
mod plots;
mod refusal;
mod shared;
mod slaves;
mod tls;
mod values;
mod visitors;

use refusal::Refusal;
use shared::{Shared, Web};

/// Why the dashboard cannot serve.
#[derive(Debug)]
pub enum WebError {
    /// The listen address could not be bound.
    Listen {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The certificate or key could not be used.
    Tls(String),
}

impl std::fmt::Display for WebError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Listen { addr, source } => write!(f, "web.listen {addr}: {source}"),
            Self::Tls(why) => write!(f, "web.tls_cert/tls_key: {why}"),
        }
    }
}

impl std::error::Error for WebError {}

/// Binds `config.listen`.
pub async fn bind(config: &WebConfig) -> Result<TcpListener, WebError> {
    TcpListener::bind(config.listen).await.map_err(|source| WebError::Listen { addr: config.listen, source })
}

/// Serves the dashboard on `listener` until `stopped` changes (or its
/// sender is dropped). `tokens` are the API's, which log visitors in.
pub async fn serve(
    master: Arc<Master>,
    config: WebConfig,
    tokens: Vec<TokenRole>,
    certificates: Vec<TokenRole>,
    listener: TcpListener,
    mut stopped: watch::Receiver<()>,
) {
    let acceptor = match config.tls_cert.as_ref().zip(config.tls_key.as_ref()) {
        Some((cert, key)) => match tls::acceptor(cert, key, config.client_ca.as_deref()) {
            Ok(a) => Some(a),
            Err(e) => {
                warn!("{}: serving no dashboard", WebError::Tls(e));
                return;
            }
        },
        None => None,
    };
    let web: Web = Arc::new(Shared {
        master: Arc::clone(&master),
        visitors: shared::Visitors::new(config.anonymous.role(), &tokens, &certificates, config.tls()),
        overview: shared::Feed::new(),
        slaves: shared::SlaveTable::default(),
        plots: shared::Sampler::new(),
        control: shared::WebLeases::new(Arc::clone(&master)),
    });
    let mut work = tokio::task::JoinSet::new();
    work.spawn(overview::produce(Arc::clone(&web)));
    work.spawn(plots::sample(Arc::clone(&web)));
    work.spawn(control::keep(Arc::clone(&web)));
    let app = routes(Arc::clone(&web), config.listen.ip().is_loopback());
    let gate = Gate::new(
        "web",
        Cap { limit: config.max_connections as usize, key: "web.max_connections" },
        Some(Cap { limit: config.max_connections_per_peer as usize, key: "web.max_connections_per_peer" }),
    );
    let deadline = Duration::from_millis(config.handshake_timeout_ms.into());
    info!(url = %config.url(), "web: serving the dashboard");
    let mut connections = tokio::task::JoinSet::new();
    loop {
        let accepted = tokio::select! {
            a = listener.accept() => a,
            _ = stopped.changed() => break,
            // Reap finished connections so the set does not grow.
            Some(_) = connections.join_next(), if !connections.is_empty() => continue,
        };
        let (io, peer) = match accepted {
            Ok(c) => c,
            Err(e) => {
                gate.accept_failed(&e).await;
                continue;
            }
        };
        let Ok(ticket) = gate.admit(Some(peer.ip())) else { continue };
        connections.spawn(connection(io, peer, ticket, deadline, acceptor.clone(), app.clone()));
    }
    // Server-sent event streams never end by themselves: the daemon's stop
    // ends them.
    connections.abort_all();
    work.abort_all();
}

/// One connection: its TLS handshake within `deadline` (HTTPS), then HTTP/1.1
/// requests, the first request's headers within `deadline` too.
async fn connection(
    io: TcpStream,
    peer: SocketAddr,
    _ticket: Ticket,
    deadline: Duration,
    acceptor: Option<tokio_rustls::TlsAcceptor>,
    app: Router,
) {
    let _ = io.set_nodelay(true);
    // Each request carries the peer's address (the login log names it) and
    // the client certificate its browser presented, if any.
    let service = |certificate: Option<visitors::PresentedCertificate>| {
        hyper::service::service_fn(move |mut req: hyper::Request<hyper::body::Incoming>| {
            req.extensions_mut().insert(visitors::Peer(peer));
            if let Some(c) = &certificate {
                req.extensions_mut().insert(c.clone());
            }
            let mut app = app.clone();
            async move { tower_service::Service::call(&mut app, req).await }
        })
    };
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new()).header_read_timeout(deadline).keep_alive(true);
    match acceptor {
        Some(acceptor) => {
            let Ok(Ok(tls)) = tokio::time::timeout(deadline, acceptor.accept(io)).await else { return };
            let certificate = tls
                .get_ref()
                .1
                .peer_certificates()
                .and_then(|c| c.first())
                .map(|c| visitors::PresentedCertificate(visitors::certificate_fingerprint(c.as_ref())));
            let _ = http.serve_connection(TokioIo::new(tls), service(certificate)).await;
        }
        None => {
            let _ = http.serve_connection(TokioIo::new(io), service(None)).await;
        }
    }
}

/// A request's `Host` when the dashboard listens on loopback: only
/// loopback names and addresses, so a web page whose name was made to
/// point at 127.0.0.1 (DNS rebinding) reads nothing from the browser it
/// runs in.
async fn loopback_host(
    State(loopback): State<bool>,
    req: axum::extract::Request,
    next: axum::middleware::Next,
) -> axum::response::Response {
    use axum::response::IntoResponse;
    let host = req.headers().get(axum::http::header::HOST).and_then(|h| h.to_str().ok()).unwrap_or("localhost");
    if !loopback || is_loopback_host(host) {
        return next.run(req).await;
    }
    Refusal::new(
        axum::http::StatusCode::MISDIRECTED_REQUEST,
        format!("Host {host:?} is not this dashboard's: on loopback it answers localhost and loopback addresses"),
    )
    .into_response()
}

/// Whether `host` (a Host header: name or address, and a port) names
/// this machine's loopback.
fn is_loopback_host(host: &str) -> bool {
    let name = match host.strip_prefix('[') {
        Some(v6) => v6.split(']').next().unwrap_or(""),
        None => host.rsplit_once(':').map_or(host, |(n, _)| n),
    };
    name.eq_ignore_ascii_case("localhost") || name.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// The pages and the HTTP API of docs/web.md.
fn routes(web: Web, loopback: bool) -> Router {
    Router::new()
        .route("/", get(assets::index))
        .route("/app.js", get(assets::script))
        .route("/style.css", get(assets::style))
        .route("/api/whoami", get(visitors::whoami))
        .route("/api/login", post(visitors::login))
        .route("/api/logout", post(visitors::logout))
        .route("/api/overview", get(overview::overview))
        .route("/api/live", get(overview::live))
        .route("/api/events", get(overview::events))
        .route("/api/trend", get(overview::trend))
        .route("/api/topology", get(slaves::topology))
        .route("/api/slaves", get(slaves::list))
        .route("/api/slaves/{p}", get(slaves::one))
        .route("/api/slaves/{p}/objects", get(slaves::objects))
        .route("/api/slaves/{p}/sdo/{index}/{sub}", get(slaves::upload).post(slaves::download))
        .route("/api/entries", get(plots::entries))
        .route("/api/plot", get(plots::plot))
        .route("/api/outputs/{name}", post(control::write_output))
        .route("/api/axes", get(control::axes))
        .route("/api/axes/{n}/command", post(control::axis_command))
        .route("/api/axes/{n}/mode", post(control::axis_mode))
        .route("/api/config.toml", get(slaves::config_toml))
        .route("/api/config.eni", get(slaves::config_eni))
        .fallback(|| async { Refusal::not_found("no such page; the dashboard is at /") })
        .method_not_allowed_fallback(|| async {
            Refusal::new(
                axum::http::StatusCode::METHOD_NOT_ALLOWED,
                "this path does not take that method (docs/web.md)",
            )
        })
        .layer(axum::extract::DefaultBodyLimit::max(json_body::BODY_LIMIT))
        .layer(axum::middleware::from_fn_with_state(loopback, loopback_host))
        .with_state(web)
}

#[cfg(test)]
mod tests {
    use super::is_loopback_host;

    #[test]
    fn only_loopback_hosts_reach_a_loopback_dashboard() {
        for host in ["localhost", "LOCALHOST:8080", "127.0.0.1:8080", "127.1.2.3", "[::1]:8080", "[::1]"] {
            assert!(is_loopback_host(host), "{host}");
        }
        for host in ["evil.example:8080", "evil.example", "10.0.0.1:8080", "localhost.evil.example", "[::2]:80"] {
            assert!(!is_loopback_host(host), "{host}");
        }
    }
}
