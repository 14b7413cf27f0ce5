//! `[api]`: where the gRPC API is served and who may do what.
//!
//! The Unix socket is the default transport, like the Docker socket: its
//! file mode and group decide who may connect, and the peer's uid/gid
//! (SO_PEERCRED) decide the role. TCP is optional and only with TLS; there a
//! client proves who it is with a client certificate or a bearer token.
//! Tokens and certificates are stored as SHA-256 fingerprints, never in
//! clear.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::ConfigError;

/// What a caller may do.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Role {
    /// Read-only.
    Observer,
    /// Process data, SDO writes, states, CiA402, peripherals.
    Operator,
    /// Everything.
    Admin,
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Observer => "observer",
            Self::Operator => "operator",
            Self::Admin => "admin",
        })
    }
}

/// `[api]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ApiConfig {
    /// Unix socket path (default: `$ECMXF_SOCKET`, else for root
    /// /run/ecmxfd/ecmxfd.sock, for other users
    /// `$XDG_RUNTIME_DIR/ecmxfd.sock` or /tmp/ecmxfd-UID.sock).
    pub socket: Option<PathBuf>,
    /// Socket file mode, e.g. 0o660.
    pub socket_mode: u32,
    /// Group owning the socket (name or numeric gid); unset: the daemon's.
    pub socket_group: Option<String>,
    /// Role of Unix peers matched by no `[[api.user]]`/`[[api.group]]`
    /// ("none" refuses them). The daemon's own uid and root are admin.
    pub default_role: RoleName,
    /// Serve on TCP too (needs `tls_cert` and `tls_key`).
    pub tcp: Option<SocketAddr>,
    /// Server certificate chain (PEM), for TCP.
    pub tls_cert: Option<PathBuf>,
    /// Server private key (PEM), for TCP.
    pub tls_key: Option<PathBuf>,
    /// CA (PEM) that client certificates must chain to; unset: no client
    /// certificates (tokens only).
    pub client_ca: Option<PathBuf>,
    /// Roles of Unix peers by uid.
    #[serde(rename = "user")]
    pub users: Vec<UserRole>,
    /// Roles of Unix peers by gid (primary group).
    #[serde(rename = "group")]
    pub groups: Vec<GroupRole>,
    /// Bearer tokens (any transport).
    #[serde(rename = "token")]
    pub tokens: Vec<TokenRole>,
    /// Client certificates (TCP).
    #[serde(rename = "client_cert")]
    pub client_certs: Vec<TokenRole>,
    /// Default output-lease time-to-live, ms.
    pub lease_ttl_ms: u32,
    /// The oldest an input sample may be when a stream hands it to the
    /// transport, ms (10..=60000): older samples of a subscriber that
    /// reads slower than the cycle are dropped and counted in `lost`.
    pub stream_max_age_ms: u32,
    /// Time a new connection has to finish its TLS handshake (TCP) and send
    /// the HTTP/2 preface, ms (100..=60000); a slower peer is closed, so
    /// idle connections cannot hold file descriptors.
    pub handshake_timeout_ms: u32,
    /// HTTP/2 PING interval on idle connections, s (1..=3600); a peer that
    /// does not answer within the same time is closed. TCP keepalive
    /// probes start after the same idle time.
    pub keepalive_s: u32,
    /// Connections the TCP listener holds at once (1..=65536); more are
    /// closed as they come.
    pub max_connections: u32,
    /// Connections one TCP peer address holds at once (1..=max_connections).
    pub max_connections_per_peer: u32,
    /// Connections the Unix socket holds at once (1..=65536): a budget of
    /// its own, which TCP peers cannot consume.
    pub max_socket_connections: u32,
}

impl Default for ApiConfig {
    fn default() -> Self {
        Self {
            socket: None,
            socket_mode: 0o660,
            socket_group: None,
            default_role: RoleName::Observer,
            tcp: None,
            tls_cert: None,
            tls_key: None,
            client_ca: None,
            users: Vec::new(),
            groups: Vec::new(),
            tokens: Vec::new(),
            client_certs: Vec::new(),
            lease_ttl_ms: 2000,
            stream_max_age_ms: 100,
            handshake_timeout_ms: 5000,
            keepalive_s: 30,
            max_connections: 256,
            max_connections_per_peer: 32,
            max_socket_connections: 64,
        }
    }
}

/// A role as written in the file.
#[derive(Clone, Copy, Debug, Default, Deserialize, schemars::JsonSchema, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum RoleName {
    /// No access.
    None,
    /// Read-only.
    #[default]
    Observer,
    /// Process data, SDO write, states, CiA402.
    Operator,
    /// Everything.
    Admin,
}

impl RoleName {
    /// The role, `None` for no access.
    pub fn role(self) -> Option<Role> {
        match self {
            Self::None => None,
            Self::Observer => Some(Role::Observer),
            Self::Operator => Some(Role::Operator),
            Self::Admin => Some(Role::Admin),
        }
    }
}

/// `[[api.user]]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct UserRole {
    /// Numeric uid.
    pub uid: u32,
    /// Role.
    pub role: RoleName,
}

/// `[[api.group]]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GroupRole {
    /// Numeric gid.
    pub gid: u32,
    /// Role.
    pub role: RoleName,
}

/// `[[api.token]]` / `[[api.client_cert]]`: a SHA-256 fingerprint (hex) of
/// the token's bytes or of the certificate's DER bytes.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TokenRole {
    /// 64 hex digits (`printf %s TOKEN | sha256sum`, or `openssl x509
    /// -outform der | sha256sum` for a certificate).
    pub sha256: String,
    /// Role.
    pub role: RoleName,
    /// Who this is, for the log.
    #[serde(default)]
    pub name: String,
}

impl ApiConfig {
    /// Checks what serde cannot: TLS for TCP, fingerprints, ranges.
    pub fn validate(&self, path: &Path) -> Result<(), ConfigError> {
        let bad =
            |key: &str, message: String| Err(ConfigError::Invalid { file: path.into(), key: key.into(), message });
        if self.socket_mode > 0o777 {
            return bad("api.socket_mode", format!("{:#o} is not a file mode (0..=0o777)", self.socket_mode));
        }
        if self.tcp.is_some() && (self.tls_cert.is_none() || self.tls_key.is_none()) {
            return bad("api.tcp", "TCP is served only with TLS: set api.tls_cert and api.tls_key".into());
        }
        if self.tcp.is_some() && self.tokens.is_empty() && self.client_certs.is_empty() {
            return bad("api.tcp", "no [[api.token]] or [[api.client_cert]]: no TCP client could authenticate".into());
        }
        for (key, list) in [("api.token", &self.tokens), ("api.client_cert", &self.client_certs)] {
            for (i, t) in list.iter().enumerate() {
                if t.sha256.len() != 64 || !t.sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
                    return bad(&format!("{key}[{i}].sha256"), format!("{:?} is not 64 hex digits", t.sha256));
                }
            }
        }
        if !(100..=60_000).contains(&self.lease_ttl_ms) {
            return bad("api.lease_ttl_ms", format!("{} ms is outside 100..=60000", self.lease_ttl_ms));
        }
        if !(10..=60_000).contains(&self.stream_max_age_ms) {
            return bad("api.stream_max_age_ms", format!("{} ms is outside 10..=60000", self.stream_max_age_ms));
        }
        if !(100..=60_000).contains(&self.handshake_timeout_ms) {
            return bad("api.handshake_timeout_ms", format!("{} ms is outside 100..=60000", self.handshake_timeout_ms));
        }
        if !(1..=3600).contains(&self.keepalive_s) {
            return bad("api.keepalive_s", format!("{} s is outside 1..=3600", self.keepalive_s));
        }
        for (key, n) in
            [("api.max_connections", self.max_connections), ("api.max_socket_connections", self.max_socket_connections)]
        {
            if !(1..=65_536).contains(&n) {
                return bad(key, format!("{n} is outside 1..=65536"));
            }
        }
        if !(1..=self.max_connections).contains(&self.max_connections_per_peer) {
            return bad(
                "api.max_connections_per_peer",
                format!(
                    "{} is outside 1..=api.max_connections ({})",
                    self.max_connections_per_peer, self.max_connections
                ),
            );
        }
        Ok(())
    }

    /// Makes relative paths relative to `base` (the config file's folder).
    pub fn resolve_paths(&mut self, base: &Path) {
        for p in [&mut self.socket, &mut self.tls_cert, &mut self.tls_key, &mut self.client_ca].into_iter().flatten() {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        }
    }

    /// The socket path in force.
    pub fn socket_path(&self) -> PathBuf {
        self.socket.clone().unwrap_or_else(ecmxf_proto::default_socket_path)
    }
}
