//! `[opcua]`: the OPC UA server (daemon/src/opcua, docs/opcua.md).
//! Absent: off; `ecmxfd --sim` serves it on loopback. Checked at load like
//! every section, so a listen address the server could not offer safely
//! is named before the daemon starts.

use std::net::SocketAddr;
use std::path::Path;

use serde::Deserialize;

use super::ConfigError;
use super::api::RoleName;

/// `[opcua]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OpcuaConfig {
    /// TCP address to serve, e.g. "127.0.0.1:4840" (4840: the port OPC UA
    /// clients try first). The endpoint is `opc.tcp://HOST:PORT/`.
    pub listen: SocketAddr,
    /// Sessions open at once; the next CreateSession is refused
    /// (BadTooManySessions).
    #[serde(default = "defaults::max_sessions")]
    pub max_sessions: u32,
    /// Connections open at once (sessions or not); the next is closed at
    /// once.
    #[serde(default = "defaults::max_connections")]
    pub max_connections: u32,
    /// Connections open at once from one address.
    #[serde(default = "defaults::max_connections_per_peer")]
    pub max_connections_per_peer: u32,
    /// A connection that has not said Hello within this many seconds is
    /// closed.
    #[serde(default = "defaults::hello_timeout_s")]
    pub hello_timeout_s: u32,
    /// Offer the endpoint without security (SecurityPolicy None,
    /// anonymous sessions only) on an address other than loopback too. Off:
    /// on the network only the signed and encrypted endpoints are offered.
    #[serde(default)]
    pub insecure_on_network: bool,
    /// The role of anonymous sessions: "observer" (the default) reads,
    /// "none" refuses them.
    #[serde(default)]
    pub anonymous: RoleName,
    /// `[[opcua.user]]`: user name and password identities (on the
    /// encrypted endpoints only: a password never travels in clear).
    #[serde(default, rename = "user")]
    pub users: Vec<OpcuaUser>,
    /// Where the server keeps its certificate and key (`own/`,
    /// `private/`) and the client certificates it trusts (`trusted/`) or
    /// refused (`rejected/`). Default: `pki/` under the state directory.
    #[serde(default)]
    pub pki_dir: Option<std::path::PathBuf>,
    /// Read each slave's object dictionary from the device (SDO
    /// Information) in the background after bring-up, as the daemon's own
    /// work, and show it under the slave's Dictionary folder. Off: only
    /// the dictionaries the daemon already has (read for a client, or
    /// kept on disk) are shown.
    #[serde(default = "defaults::dictionaries")]
    pub dictionaries: bool,
    /// `[[opcua.certificate_user]]`: X.509 user identities.
    #[serde(default, rename = "certificate_user")]
    pub certificate_users: Vec<OpcuaCertificateUser>,
    /// A port that cannot be bound is a warning, not an error (the server
    /// `ecmxfd --sim` adds on its own); never from a file.
    #[serde(skip)]
    pub best_effort: bool,
}

/// `[[opcua.user]]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OpcuaUser {
    /// The user name a client gives.
    pub name: String,
    /// SHA-256 of the password, 64 hex digits (`printf %s PASSWORD |
    /// sha256sum`): the file never holds it in clear. Give a long random
    /// password: a fingerprint is no password hash.
    pub password_sha256: String,
    /// Its role.
    pub role: RoleName,
}

/// `[[opcua.certificate_user]]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OpcuaCertificateUser {
    /// Who this is, for the log and the leases it holds.
    pub name: String,
    /// The user certificate's thumbprint as OPC UA tools show it: SHA-1 of
    /// its DER bytes, 40 hex digits (`openssl x509 -noout -fingerprint
    /// -sha1`, colons allowed).
    pub thumbprint: String,
    /// Its role.
    pub role: RoleName,
}

/// Hex digits without the colons tools print between bytes, lower case.
pub(crate) fn bare_hex(s: &str) -> String {
    s.chars().filter(|c| *c != ':').collect::<String>().to_ascii_lowercase()
}

mod defaults {
    pub(super) fn max_sessions() -> u32 {
        10
    }
    pub(super) fn hello_timeout_s() -> u32 {
        5
    }
    pub(super) fn max_connections() -> u32 {
        64
    }
    pub(super) fn max_connections_per_peer() -> u32 {
        16
    }
    pub(super) fn dictionaries() -> bool {
        true
    }
}

impl OpcuaConfig {
    /// On loopback, for `ecmxfd --sim`.
    pub fn loopback() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 4840)),
            max_sessions: defaults::max_sessions(),
            max_connections: defaults::max_connections(),
            max_connections_per_peer: defaults::max_connections_per_peer(),
            hello_timeout_s: defaults::hello_timeout_s(),
            insecure_on_network: false,
            anonymous: RoleName::Observer,
            users: Vec::new(),
            pki_dir: None,
            dictionaries: defaults::dictionaries(),
            certificate_users: Vec::new(),
            best_effort: true,
        }
    }

    /// Whether the endpoint without security (SecurityPolicy None, for
    /// anonymous sessions) is offered: on loopback, or where the file asks
    /// for it.
    pub fn serves_without_security(&self) -> bool {
        self.anonymous.role().is_some() && (self.listen.ip().is_loopback() || self.insecure_on_network)
    }

    /// What the server offers, in a line (for `--check-config`).
    pub fn summary(&self) -> String {
        let none = match (self.serves_without_security(), self.listen.ip().is_loopback()) {
            (true, true) => ", and None for anonymous sessions (loopback)",
            (true, false) => ", and None for anonymous sessions (insecure_on_network)",
            (false, _) => "",
        };
        let anonymous = match self.anonymous.role() {
            Some(r) => format!("anonymous sessions {r}"),
            None => "anonymous sessions refused".into(),
        };
        let pki = self.pki_dir.as_ref().map_or("pki/ under the state directory".into(), |p| p.display().to_string());
        format!(
            "opc.tcp://{}/: Basic256Sha256 and Aes128_Sha256_RsaOaep signed and encrypted{none}; {anonymous}, {} \
             password user(s), {} certificate user(s); certificates in {pki}",
            self.listen,
            self.users.len(),
            self.certificate_users.len()
        )
    }

    /// What a server of this section could not honour, by key.
    pub fn validate(&self, path: &Path) -> Result<(), ConfigError> {
        let bad = |key: &str, message: String| {
            Err(ConfigError::Invalid { file: path.into(), key: format!("opcua.{key}"), message })
        };
        if !(1..=1000).contains(&self.max_sessions) {
            return bad("max_sessions", format!("{}: give 1..=1000", self.max_sessions));
        }
        for (key, n) in
            [("max_connections", self.max_connections), ("max_connections_per_peer", self.max_connections_per_peer)]
        {
            if !(1..=10_000).contains(&n) {
                return bad(key, format!("{n}: give 1..=10000"));
            }
        }
        if !(1..=60).contains(&self.hello_timeout_s) {
            return bad("hello_timeout_s", format!("{}: give 1..=60 s", self.hello_timeout_s));
        }
        let mut names = std::collections::HashSet::new();
        for (i, u) in self.users.iter().enumerate() {
            let key = format!("user[{i}]");
            if u.name.is_empty() || !names.insert(u.name.clone()) {
                return bad(&format!("{key}.name"), format!("{:?}: give each user a name of its own", u.name));
            }
            if u.password_sha256.len() != 64 || !u.password_sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
                return bad(&format!("{key}.password_sha256"), format!("{:?} is not 64 hex digits", u.password_sha256));
            }
        }
        for (i, u) in self.certificate_users.iter().enumerate() {
            let key = format!("certificate_user[{i}]");
            if u.name.is_empty() || !names.insert(u.name.clone()) {
                return bad(&format!("{key}.name"), format!("{:?}: give each user a name of its own", u.name));
            }
            let hex = bare_hex(&u.thumbprint);
            if hex.len() != 40 || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
                return bad(
                    &format!("{key}.thumbprint"),
                    format!("{:?} is not a SHA-1 thumbprint (40 hex digits)", u.thumbprint),
                );
            }
        }
        if self.anonymous == RoleName::None && self.users.is_empty() && self.certificate_users.is_empty() {
            return bad(
                "anonymous",
                "\"none\" with no [[opcua.user]] or [[opcua.certificate_user]]: no client could open a session".into(),
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> OpcuaConfig {
        toml::from_str(text).unwrap()
    }

    #[test]
    fn identities_are_checked_by_key() {
        let check = |text: &str| parse(text).validate(Path::new("f.toml")).map_err(|e| e.to_string());
        assert!(check("listen = \"127.0.0.1:4840\"").is_ok());
        assert!(check("listen = \"0.0.0.0:4840\"").is_ok(), "the network gets the encrypted endpoints");
        let e = check("listen = \"127.0.0.1:4840\"\nmax_sessions = 0").unwrap_err();
        assert!(e.contains("opcua.max_sessions") && e.contains("1..=1000"), "{e}");
        assert!(toml::from_str::<OpcuaConfig>("listen = \"127.0.0.1:4840\"\nport = 1").is_err());
        let user = |hash: &str| {
            format!(
                "listen = \"127.0.0.1:4840\"\n[[user]]\nname = \"op\"\npassword_sha256 = \"{hash}\"\nrole = \"operator\"\n"
            )
        };
        assert!(check(&user(&"ab".repeat(32))).is_ok());
        let e = check(&user("secret")).unwrap_err();
        assert!(e.contains("opcua.user[0].password_sha256"), "{e}");
        let cert = "listen = \"127.0.0.1:4840\"\n[[certificate_user]]\nname = \"c\"\nrole = \"admin\"\nthumbprint = ";
        assert!(check(&format!("{cert}\"{}\"", ["AB"; 20].join(":"))).is_ok(), "colons as openssl prints them");
        let e = check(&format!("{cert}\"abcd\"")).unwrap_err();
        assert!(e.contains("opcua.certificate_user[0].thumbprint") && e.contains("SHA-1"), "{e}");
        let e = check("listen = \"127.0.0.1:4840\"\nanonymous = \"none\"").unwrap_err();
        assert!(e.contains("opcua.anonymous"), "{e}");
    }

    #[test]
    fn the_endpoint_without_security_is_offered_on_loopback_only_unless_asked() {
        let summary = |text: &str| parse(text).summary();
        assert!(summary("listen = \"127.0.0.1:4840\"").contains("None for anonymous sessions (loopback)"));
        let network = summary("listen = \"0.0.0.0:4840\"");
        assert!(!network.contains("None") && network.contains("Basic256Sha256"), "{network}");
        assert!(summary("listen = \"0.0.0.0:4840\"\ninsecure_on_network = true").contains("None"));
    }
}
