//! `[web]`: the dashboard (daemon/src/web, docs/web.md). Absent: off;
//! `ecmxfd --sim` serves it on loopback. Its identities are the API's
//! tokens (`[[api.token]]`), so a person has one token for every front end.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::ConfigError;
use super::api::RoleName;

/// `[web]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WebConfig {
    /// TCP address to serve, e.g. "127.0.0.1:8080".
    pub listen: SocketAddr,
    /// Server certificate chain (PEM): with `tls_key`, HTTPS.
    #[serde(default)]
    pub tls_cert: Option<PathBuf>,
    /// Server private key (PEM).
    #[serde(default)]
    pub tls_key: Option<PathBuf>,
    /// CA (PEM) that browsers' client certificates must chain to (HTTPS
    /// only): a browser presenting one of `[[api.client_cert]]` is that
    /// identity without logging in. Unset: no client certificates.
    #[serde(default)]
    pub client_ca: Option<PathBuf>,
    /// What a visitor who has not logged in may do: "observer" (the
    /// default) sees every page, "none" must log in first.
    #[serde(default)]
    pub anonymous: RoleName,
    /// Connections open at once; the next is closed at once.
    #[serde(default = "defaults::max_connections")]
    pub max_connections: u32,
    /// Connections open at once from one address.
    #[serde(default = "defaults::max_connections_per_peer")]
    pub max_connections_per_peer: u32,
    /// Time a new connection has to finish its TLS handshake and send its
    /// first request's headers, ms; a slower peer is closed.
    #[serde(default = "defaults::handshake_timeout_ms")]
    pub handshake_timeout_ms: u32,
    /// For `ecmxfd --sim`: a port another program holds does not stop the
    /// daemon (it serves no dashboard and says so).
    #[serde(skip)]
    pub best_effort: bool,
}

mod defaults {
    pub(super) fn max_connections() -> u32 {
        64
    }
    pub(super) fn max_connections_per_peer() -> u32 {
        16
    }
    pub(super) fn handshake_timeout_ms() -> u32 {
        5000
    }
}

impl WebConfig {
    /// On loopback, for `ecmxfd --sim`.
    pub fn loopback() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 8080)),
            tls_cert: None,
            tls_key: None,
            client_ca: None,
            anonymous: RoleName::Observer,
            max_connections: defaults::max_connections(),
            max_connections_per_peer: defaults::max_connections_per_peer(),
            handshake_timeout_ms: defaults::handshake_timeout_ms(),
            best_effort: true,
        }
    }

    /// Whether it serves HTTPS.
    pub fn tls(&self) -> bool {
        self.tls_cert.is_some()
    }

    /// The address browsers open.
    pub fn url(&self) -> String {
        format!("{}://{}/", if self.tls() { "https" } else { "http" }, self.listen)
    }

    /// What the dashboard offers, in a line (for `--check-config`).
    pub fn summary(&self, tokens: usize, certificates: usize) -> String {
        let anonymous = match self.anonymous.role() {
            Some(r) => format!("visitors are {r}s"),
            None => "visitors must log in".into(),
        };
        let certs = if self.client_ca.is_some() {
            format!(", {certificates} API client certificate(s) are known")
        } else {
            String::new()
        };
        format!("{}: {anonymous}; {tokens} API token(s) log in{certs}", self.url())
    }

    /// What a dashboard of this section could not honour, by key.
    pub fn validate(&self, path: &Path) -> Result<(), ConfigError> {
        let bad = |key: &str, message: String| {
            Err(ConfigError::Invalid { file: path.into(), key: format!("web.{key}"), message })
        };
        if self.tls_cert.is_some() != self.tls_key.is_some() {
            return bad("tls_key", "give tls_cert and tls_key together (HTTPS), or neither (HTTP)".into());
        }
        if self.client_ca.is_some() && self.tls_cert.is_none() {
            return bad("client_ca", "client certificates come with HTTPS: give tls_cert and tls_key too".into());
        }
        if self.tls_cert.is_none() && !self.listen.ip().is_loopback() {
            return bad(
                "listen",
                format!(
                    "{} is not loopback: a dashboard on the network needs tls_cert and tls_key (logins and \
                     writes travel over it)",
                    self.listen
                ),
            );
        }
        if !(1..=10_000).contains(&self.max_connections) {
            return bad("max_connections", format!("{}: give 1..=10000", self.max_connections));
        }
        if !(1..=self.max_connections).contains(&self.max_connections_per_peer) {
            return bad(
                "max_connections_per_peer",
                format!(
                    "{} is outside 1..=web.max_connections ({})",
                    self.max_connections_per_peer, self.max_connections
                ),
            );
        }
        if !(100..=60_000).contains(&self.handshake_timeout_ms) {
            return bad("handshake_timeout_ms", format!("{}: give 100..=60000 ms", self.handshake_timeout_ms));
        }
        Ok(())
    }

    /// Takes relative certificate paths relative to `base`.
    pub(super) fn resolve_paths(&mut self, base: &Path) {
        for p in [&mut self.tls_cert, &mut self.tls_key, &mut self.client_ca].into_iter().flatten() {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(text: &str) -> Result<WebConfig, String> {
        let c: WebConfig = toml::from_str(text).map_err(|e| e.to_string())?;
        c.validate(Path::new("t.toml")).map_err(|e| e.to_string())?;
        Ok(c)
    }

    #[test]
    fn plain_http_is_for_loopback_only() {
        let c = check("listen = \"127.0.0.1:8080\"").unwrap();
        assert_eq!(c.url(), "http://127.0.0.1:8080/");
        assert_eq!(c.anonymous, RoleName::Observer);
        let e = check("listen = \"0.0.0.0:8080\"").unwrap_err();
        assert!(e.contains("web.listen") && e.contains("tls_cert"), "{e}");
        let c = check("listen = \"0.0.0.0:8443\"\ntls_cert = \"a.pem\"\ntls_key = \"k.pem\"").unwrap();
        assert_eq!(c.url(), "https://0.0.0.0:8443/");
        let e = check("listen = \"127.0.0.1:8080\"\ntls_cert = \"a.pem\"").unwrap_err();
        assert!(e.contains("web.tls_key"), "{e}");
        let e = check("listen = \"127.0.0.1:8080\"\nclient_ca = \"ca.pem\"").unwrap_err();
        assert!(e.contains("web.client_ca") && e.contains("HTTPS"), "{e}");
    }

    #[test]
    fn caps_and_deadlines_are_in_range() {
        let e = check("listen = \"127.0.0.1:1\"\nmax_connections = 4\nmax_connections_per_peer = 5").unwrap_err();
        assert!(e.contains("web.max_connections_per_peer"), "{e}");
        let e = check("listen = \"127.0.0.1:1\"\nhandshake_timeout_ms = 5").unwrap_err();
        assert!(e.contains("web.handshake_timeout_ms"), "{e}");
        let e = check("listen = \"127.0.0.1:1\"\nport = 5").unwrap_err();
        assert!(e.contains("port"), "{e}");
    }
}
