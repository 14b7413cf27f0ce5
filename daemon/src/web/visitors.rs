//! Who a request comes from (docs/web.md, "Who may do what"): a browser
//! that logged in with one of the API's tokens holds a session cookie
//! bound to that identity and its role; any other is anonymous, with the
//! role `[web] anonymous` gives (observer by default, or none).
//!
//! The cookie is HttpOnly and SameSite=Strict, and a request that changes
//! something must be JSON from a page of this origin: a form or a script
//! on another site can neither send it with the cookie nor read answers.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::Json;
use axum::extract::{Extension, FromRequestParts, State};
use axum::http::request::Parts;
use axum::http::{HeaderMap, Method, StatusCode, header};
use axum::response::IntoResponse;
use serde::Deserialize;
use serde_json::json;
use sha2::{Digest, Sha256};

use super::json_body::JsonBody;
use super::refusal::Refusal;
use super::shared::{Session, Visitors, Web};
use crate::config::api::{Role, TokenRole};

/// The session cookie's name.
const COOKIE: &str = "ecmxf_session";
/// A session unused this long ends.
const IDLE: Duration = Duration::from_secs(8 * 3600);
/// Sessions of one token at most: its least recently used ends when it
/// opens another (one person's browsers, never someone else's).
const SESSIONS_PER_TOKEN: usize = 16;
/// Sessions of all tokens at most; beyond, a login is refused.
const MAX_SESSIONS: usize = 1024;
/// A failed login is answered this late: guessing a token costs time.
const FAILED_LOGIN_DELAY: Duration = Duration::from_millis(250);
/// Failed logins are logged at most this often (with their count).
const FAILED_LOG_EVERY: Duration = Duration::from_secs(60);

/// The peer a request comes from (set per connection by `mod.rs`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Peer(pub std::net::SocketAddr);

/// The SHA-256 (hex) of the client certificate the connection's browser
/// presented (HTTPS with `client_ca`; set per connection by `mod.rs`).
#[derive(Clone, Debug)]
pub(crate) struct PresentedCertificate(pub String);

/// The fingerprint `[[api.client_cert]]` names a certificate by.
pub(crate) fn certificate_fingerprint(der: &[u8]) -> String {
    hex::encode(Sha256::digest(der))
}

/// Who a request comes from.
#[derive(Clone, Debug)]
pub(crate) struct Visitor {
    /// The token's name, or "anonymous".
    pub name: String,
    /// What it may do.
    pub role: Option<Role>,
    /// Its session's number (logged in).
    pub session: Option<u64>,
}

impl Visitor {
    /// Refuses unless the visitor has `role`, saying for `what`.
    pub(crate) fn needs(&self, role: Role, what: &str) -> Result<(), Refusal> {
        if self.role >= Some(role) {
            return Ok(());
        }
        let has = self.role.map_or("no role".to_string(), |r| format!("the {r} role"));
        Err(Refusal::forbidden(format!("{what} needs the {role} role; {} has {has}", self.said())))
    }

    /// "anonymous" or "NAME".
    pub(crate) fn said(&self) -> String {
        if self.session.is_some() { self.name.clone() } else { "an anonymous visitor".into() }
    }

    /// The line its chip requests queue in: one per session, one for all
    /// anonymous visitors (the engine's fair queue takes turns by it).
    pub(crate) fn client(&self) -> u64 {
        self.session.map_or(0x0EB0_0000, |n| (n << 32) | 0x0EB0_0001)
    }

    /// The holder of its output leases: its name and session, so another
    /// browser of the same person is another holder.
    pub(crate) fn holder(&self) -> Option<String> {
        self.session.map(|n| format!("web:{} (session {n})", self.name))
    }
}

impl Visitors {
    pub(super) fn new(anonymous: Option<Role>, tokens: &[TokenRole], certificates: &[TokenRole], https: bool) -> Self {
        let table = |list: &[TokenRole]| {
            list.iter().map(|t| (t.sha256.to_ascii_lowercase(), (t.role.role(), t.name.clone()))).collect()
        };
        Self {
            anonymous,
            tokens: table(tokens),
            certificates: table(certificates),
            certificate_sessions: Mutex::new(HashMap::new()),
            sessions: Mutex::new(HashMap::new()),
            next: AtomicU64::new(1),
            https,
            present: Mutex::new(HashMap::new()),
            failed: Mutex::new((0, None)),
        }
    }

    /// Notes that session `n` acted now (a write): a script without a
    /// page is present while it acts at least once a lease time.
    pub(crate) fn acted(&self, n: u64) {
        let mut present = self.present.lock().unwrap_or_else(|e| e.into_inner());
        let p = present.entry(n).or_insert((0, Instant::now()));
        p.1 = Instant::now();
    }

    /// Whether session `n` has a page open, or closed its last one less
    /// than `grace` ago (a reload, a network hiccup).
    pub(crate) fn is_present(&self, n: u64, grace: Duration) -> bool {
        let present = self.present.lock().unwrap_or_else(|e| e.into_inner());
        present.get(&n).is_some_and(|(pages, closed)| *pages > 0 || closed.elapsed() < grace)
    }

    /// Counts a failed login from `peer`; logs the count at most once a
    /// minute.
    fn failed_login(&self, peer: Option<Peer>) {
        let mut failed = self.failed.lock().unwrap_or_else(|e| e.into_inner());
        failed.0 += 1;
        if failed.1.is_none_or(|t| t.elapsed() >= FAILED_LOG_EVERY) {
            let peer = peer.map_or("unknown".to_string(), |p| p.0.ip().to_string());
            tracing::warn!(count = failed.0, last_peer = %peer, "web: logins with a token no [[api.token]] has");
            *failed = (0, Some(Instant::now()));
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, Session>> {
        self.sessions.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The visitor of a browser that presented the certificate of
    /// fingerprint `fp`; anonymous for a certificate no entry names, none
    /// for one whose entry has the role none.
    fn by_certificate(&self, fp: &str) -> Option<Visitor> {
        let anonymous = Visitor { name: "anonymous".into(), role: self.anonymous, session: None };
        let Some((role, name)) = self.certificates.get(fp) else { return Some(anonymous) };
        let role = (*role)?;
        let mut sessions = self.certificate_sessions.lock().unwrap_or_else(|e| e.into_inner());
        let number = *sessions.entry(fp.to_string()).or_insert_with(|| self.next.fetch_add(1, Ordering::Relaxed));
        Some(Visitor { name: format!("certificate {name}"), role: Some(role), session: Some(number) })
    }

    /// The visitor a request with `headers`, from a browser that presented
    /// `certificate` (if any), comes from: a login's session first, then
    /// the certificate, else anonymous.
    fn identify(&self, headers: &HeaderMap, certificate: Option<&PresentedCertificate>, now: Instant) -> Visitor {
        let by_certificate = || match certificate {
            Some(c) => {
                self.by_certificate(&c.0).unwrap_or(Visitor { name: "refused".into(), role: None, session: None })
            }
            None => Visitor { name: "anonymous".into(), role: self.anonymous, session: None },
        };
        let anonymous = by_certificate();
        let Some(id) = cookie(headers) else { return anonymous };
        let mut sessions = self.lock();
        match sessions.get_mut(id) {
            Some(s) if now.duration_since(s.used) < IDLE => {
                s.used = now;
                Visitor { name: s.name.clone(), role: Some(s.role), session: Some(s.number) }
            }
            Some(_) => {
                sessions.remove(id);
                anonymous
            }
            None => anonymous,
        }
    }

    /// Opens a session for `token`: its cookie value and the visitor.
    fn open(&self, token: &str, now: Instant) -> Result<(String, Visitor), Refusal> {
        let fingerprint = hex::encode(Sha256::digest(token.trim().as_bytes()));
        let Some((role, name)) = self.tokens.get(&fingerprint) else {
            return Err(Refusal::new(StatusCode::UNAUTHORIZED, "no [[api.token]] has this token"));
        };
        let Some(role) = *role else {
            return Err(Refusal::forbidden(format!("the token of {name:?} has the role none")));
        };
        let mut raw = [0u8; 32];
        getrandom::fill(&mut raw).map_err(|e| Refusal::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?;
        let id = hex::encode(raw);
        let number = self.next.fetch_add(1, Ordering::Relaxed);
        let name = if name.is_empty() { format!("token {}", &fingerprint[..8]) } else { name.clone() };
        let mut sessions = self.lock();
        sessions.retain(|_, s| now.duration_since(s.used) < IDLE);
        let own: Vec<(&String, &Session)> = sessions.iter().filter(|(_, s)| s.name == name).collect();
        if own.len() >= SESSIONS_PER_TOKEN {
            let oldest = own.iter().min_by_key(|(_, s)| s.used).map(|(k, s)| ((*k).clone(), s.number));
            if let Some((k, n)) = oldest {
                tracing::info!(who = %name, session = n, "web: a session ended for a newer login of the same token");
                sessions.remove(&k);
            }
        } else if sessions.len() >= MAX_SESSIONS {
            return Err(Refusal::new(
                StatusCode::SERVICE_UNAVAILABLE,
                format!("{MAX_SESSIONS} sessions are open; log out elsewhere first"),
            ));
        }
        sessions.insert(id.clone(), Session { name: name.clone(), role, number, used: now });
        Ok((id, Visitor { name, role: Some(role), session: Some(number) }))
    }

    /// Ends the session of `headers`, if any; the visitor it was.
    fn close(&self, headers: &HeaderMap) -> Option<u64> {
        let id = cookie(headers)?;
        self.lock().remove(id).map(|s| s.number)
    }

    /// Whether the session numbered `n` is open (a login's, or a
    /// certificate's, which lasts as long as the daemon).
    pub(crate) fn is_open(&self, n: u64) -> bool {
        self.lock().values().any(|s| s.number == n && s.used.elapsed() < IDLE)
            || self.certificate_sessions.lock().unwrap_or_else(|e| e.into_inner()).values().any(|&c| c == n)
    }
}

/// The session cookie's value in `headers`.
fn cookie(headers: &HeaderMap) -> Option<&str> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .find_map(|c| c.trim().strip_prefix(COOKIE)?.strip_prefix('='))
}

/// Whether a request that changes something comes from a page of this
/// origin: browsers send `Origin` with every cross-site POST, and it must
/// name the host the request went to.
fn same_origin(headers: &HeaderMap, https: bool) -> bool {
    let Some(origin) = headers.get(header::ORIGIN).and_then(|o| o.to_str().ok()) else { return true };
    let host = headers.get(header::HOST).and_then(|h| h.to_str().ok()).unwrap_or("");
    let scheme = if https { "https" } else { "http" };
    origin.split_once("://").is_some_and(|(s, rest)| s == scheme && rest == host)
}

/// A page's live feed open for a session; dropped when it closes.
pub(crate) struct Watching {
    web: Web,
    session: u64,
}

/// Notes that a page of session `n` opened its live feed; the guard notes
/// when it closes.
pub(crate) fn watching(web: &Web, n: u64) -> Watching {
    let mut present = web.visitors.present.lock().unwrap_or_else(|e| e.into_inner());
    present.entry(n).or_insert((0, Instant::now())).0 += 1;
    Watching { web: Arc::clone(web), session: n }
}

impl Drop for Watching {
    fn drop(&mut self) {
        let mut present = self.web.visitors.present.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(p) = present.get_mut(&self.session) {
            p.0 = p.0.saturating_sub(1);
            p.1 = Instant::now();
        }
    }
}

impl FromRequestParts<Web> for Visitor {
    type Rejection = Refusal;

    async fn from_request_parts(parts: &mut Parts, web: &Web) -> Result<Self, Self::Rejection> {
        if parts.method != Method::GET && !same_origin(&parts.headers, web.visitors.https) {
            return Err(Refusal::forbidden("a request from a page of another site"));
        }
        let certificate = parts.extensions.get::<PresentedCertificate>();
        let v = web.visitors.identify(&parts.headers, certificate, Instant::now());
        if v.role.is_none() {
            return Err(Refusal::new(StatusCode::UNAUTHORIZED, "log in first: visitors have no role here"));
        }
        Ok(v)
    }
}

pub(super) async fn whoami(
    State(web): State<Web>,
    certificate: Option<Extension<PresentedCertificate>>,
    headers: HeaderMap,
) -> impl IntoResponse {
    let certificate = certificate.map(|Extension(c)| c);
    let v = web.visitors.identify(&headers, certificate.as_ref(), Instant::now());
    Json(json!({
        "name": v.name,
        "role": v.role.map_or("none".to_string(), |r| r.to_string()),
        "login": !web.visitors.tokens.is_empty(),
    }))
}

#[derive(Deserialize)]
pub(super) struct Login {
    token: String,
}

pub(super) async fn login(
    State(web): State<Web>,
    peer: Option<Extension<Peer>>,
    headers: HeaderMap,
    JsonBody(body): JsonBody<Login>,
) -> Result<impl IntoResponse, Refusal> {
    if !same_origin(&headers, web.visitors.https) {
        return Err(Refusal::forbidden("a login from a page of another site"));
    }
    let peer = peer.map(|Extension(p)| p);
    let (id, v) = match web.visitors.open(&body.token, Instant::now()) {
        Ok(opened) => opened,
        Err(refusal) => {
            if refusal.status == StatusCode::UNAUTHORIZED {
                web.visitors.failed_login(peer);
                tokio::time::sleep(FAILED_LOGIN_DELAY).await;
            }
            return Err(refusal);
        }
    };
    let role = v.role.map_or("none".to_string(), |r| r.to_string());
    let from = peer.map_or("unknown".to_string(), |p| p.0.ip().to_string());
    tracing::info!(who = %v.name, %role, session = v.session, peer = %from, "web: logged in");
    let secure = if web.visitors.https { "; Secure" } else { "" };
    let set = format!("{COOKIE}={id}; HttpOnly; SameSite=Strict; Path=/{secure}");
    Ok(([(header::SET_COOKIE, set)], Json(json!({ "name": v.name, "role": role }))))
}

pub(super) async fn logout(State(web): State<Web>, headers: HeaderMap) -> Result<impl IntoResponse, Refusal> {
    if !same_origin(&headers, web.visitors.https) {
        return Err(Refusal::forbidden("a logout from a page of another site"));
    }
    if let Some(n) = web.visitors.close(&headers) {
        web.control.release_session(n);
    }
    let clear = format!("{COOKIE}=; HttpOnly; SameSite=Strict; Path=/; Max-Age=0");
    Ok(([(header::SET_COOKIE, clear)], Json(json!({}))))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::api::RoleName;

    fn token(name: &str, secret: &str, role: RoleName) -> TokenRole {
        TokenRole { sha256: hex::encode(Sha256::digest(secret.as_bytes())), role, name: name.into() }
    }

    fn with_cookie(id: &str) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert(header::COOKIE, format!("theme=dark; {COOKIE}={id}").parse().unwrap());
        h
    }

    #[test]
    fn a_token_opens_a_session_bound_to_its_name_and_role() {
        let v = Visitors::new(
            Some(Role::Observer),
            &[token("op", "s3cret", RoleName::Operator), token("off", "x", RoleName::None)],
            &[token("robot", "robot-der", RoleName::Admin)],
            false,
        );
        let now = Instant::now();
        let anon = v.identify(&HeaderMap::new(), None, now);
        assert_eq!((anon.role, anon.session), (Some(Role::Observer), None));
        assert!(anon.needs(Role::Operator, "writing outputs").is_err());
        let (id, op) = v.open(" s3cret\n", now).unwrap();
        assert_eq!((op.name.as_str(), op.role), ("op", Some(Role::Operator)));
        let again = v.identify(&with_cookie(&id), None, now);
        assert_eq!(again.session, op.session);
        assert!(again.needs(Role::Operator, "writing outputs").is_ok());
        let e = again.needs(Role::Admin, "a re-init").unwrap_err();
        assert!(e.why.contains("needs the admin role; op has the operator role"), "{}", e.why);
        assert_eq!(v.open("wrong", now).unwrap_err().status, StatusCode::UNAUTHORIZED);
        assert_eq!(v.open("x", now).unwrap_err().status, StatusCode::FORBIDDEN);
        // A forged or stale cookie is anonymous; idle sessions end.
        assert_eq!(v.identify(&with_cookie("00"), None, now).session, None);
        assert_eq!(v.identify(&with_cookie(&id), None, now + IDLE).session, None);
        assert!(!v.is_open(op.session.unwrap()));
        // A known certificate is its identity, one session for good; an
        // unknown one is anonymous.
        let robot = PresentedCertificate(hex::encode(Sha256::digest(b"robot-der")));
        let r = v.identify(&HeaderMap::new(), Some(&robot), now);
        assert_eq!((r.name.as_str(), r.role), ("certificate robot", Some(Role::Admin)));
        assert_eq!(v.identify(&HeaderMap::new(), Some(&robot), now + IDLE).session, r.session);
        assert!(v.is_open(r.session.unwrap()));
        let stranger = PresentedCertificate("00".repeat(32));
        assert_eq!(v.identify(&HeaderMap::new(), Some(&stranger), now).role, Some(Role::Observer));
    }

    #[test]
    fn only_pages_of_this_origin_change_things() {
        let mut h = HeaderMap::new();
        h.insert(header::HOST, "127.0.0.1:8080".parse().unwrap());
        assert!(same_origin(&h, false), "no Origin: not a browser's cross-site request");
        h.insert(header::ORIGIN, "http://127.0.0.1:8080".parse().unwrap());
        assert!(same_origin(&h, false));
        assert!(!same_origin(&h, true), "an https page is another origin");
        h.insert(header::ORIGIN, "http://evil.example".parse().unwrap());
        assert!(!same_origin(&h, false));
    }
}
