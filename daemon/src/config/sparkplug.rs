//! `[sparkplug]`: the MQTT Sparkplug B edge node (daemon/src/sparkplug,
//! docs/sparkplug.md). Absent: off. Checked at load like every section, so
//! a broker address without a host, a node id with a topic wildcard or a
//! certificate file that is not there is named before the daemon starts.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::ConfigError;
use super::api::RoleName;

/// `[sparkplug]`.
#[derive(Clone, Debug, Deserialize, schemars::JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SparkplugConfig {
    /// Brokers, tried in order (fail-over): "mqtt://host:1883",
    /// "mqtts://host:8883". One string or a list.
    #[serde(deserialize_with = "one_or_many")]
    #[schemars(with = "Vec<String>")]
    pub broker: Vec<BrokerUrl>,
    /// The Sparkplug group (topic level 2).
    pub group_id: String,
    /// This gateway's edge node id (topic level 4); default: the host name.
    #[serde(default)]
    pub node_id: Option<String>,
    /// A primary host application: publish only while its STATE says
    /// online (Sparkplug 3.0 section 5.12); absent: always.
    #[serde(default)]
    pub primary_host_id: Option<String>,
    /// CA certificates (PEM) for mqtts://; default: the system's.
    #[serde(default)]
    pub ca_file: Option<PathBuf>,
    /// Client certificate (PEM) for brokers that authenticate clients so.
    #[serde(default)]
    pub client_cert: Option<PathBuf>,
    /// Its key (PEM).
    #[serde(default)]
    pub client_key: Option<PathBuf>,
    /// A file whose first line is the MQTT user name and second the
    /// password (kept out of the configuration, mode 0600).
    #[serde(default)]
    pub credentials_file: Option<PathBuf>,
    /// MQTT keep-alive, s.
    #[serde(default = "defaults::keep_alive_s")]
    pub keep_alive_s: u16,
    /// Process data: DDATA at most this often, changes batched, ms.
    #[serde(default = "defaults::data_period_ms")]
    pub data_period_ms: u32,
    /// Process data: a numeric value is published when it moved more than
    /// this from the value last published (0: every change).
    #[serde(default)]
    pub data_deadband: f64,
    /// Node diagnostics (counters, phase, link budget): NDATA at most this
    /// often, ms.
    #[serde(default = "defaults::diagnostics_period_ms")]
    pub diagnostics_period_ms: u32,
    /// Node diagnostics: deadband of the numeric ones.
    #[serde(default)]
    pub diagnostics_deadband: f64,
    /// Slaves published as devices, by ring position; empty: all.
    #[serde(default)]
    pub slaves: Vec<u8>,
    /// Process data variables published, by entry name (`2.0x6000:01`) or
    /// variable name (the ENI's); empty: all.
    #[serde(default)]
    pub variables: Vec<String>,
    /// How process data metrics are named: "entry" (`Inputs/0x6000:01`, as
    /// `ecmxfctl data`) or "label" (the device's name for the entry,
    /// `Inputs/Acceleration X`, where unique in the slave).
    #[serde(default)]
    pub metric_names: MetricNames,
    /// What the Sparkplug hosts may command, as a gRPC role: "none" (every
    /// NCMD and DCMD refused and logged), "observer" (Node
    /// Control/Rebirth), "operator" (also DCMD writes of output variables,
    /// under an output lease like a gRPC client's).
    #[serde(default = "defaults::commands")]
    pub commands: RoleName,
}

/// `sparkplug.metric_names`.
#[derive(Clone, Copy, Debug, Default, Deserialize, schemars::JsonSchema, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum MetricNames {
    /// Entry names without the slave's number.
    #[default]
    Entry,
    /// The device's names for the entries, where unique.
    Label,
}

mod defaults {
    use super::RoleName;
    pub(super) fn keep_alive_s() -> u16 {
        30
    }
    pub(super) fn data_period_ms() -> u32 {
        100
    }
    pub(super) fn diagnostics_period_ms() -> u32 {
        1000
    }
    pub(super) fn commands() -> RoleName {
        RoleName::None
    }
}

/// A broker address: `mqtt://HOST[:PORT]` or `mqtts://HOST[:PORT]`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BrokerUrl {
    /// TLS (mqtts).
    pub tls: bool,
    /// Host name or address.
    pub host: String,
    /// Port (1883, 8883 by default).
    pub port: u16,
}

impl std::fmt::Display for BrokerUrl {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let scheme = if self.tls { "mqtts" } else { "mqtt" };
        if self.host.contains(':') {
            write!(f, "{scheme}://[{}]:{}", self.host, self.port)
        } else {
            write!(f, "{scheme}://{}:{}", self.host, self.port)
        }
    }
}

impl std::str::FromStr for BrokerUrl {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let bad = |why: &str| format!("{text:?}: {why} (e.g. \"mqtt://broker:1883\" or \"mqtts://broker:8883\")");
        let (tls, rest) = if let Some(r) = text.strip_prefix("mqtt://").or_else(|| text.strip_prefix("tcp://")) {
            (false, r)
        } else if let Some(r) = text.strip_prefix("mqtts://").or_else(|| text.strip_prefix("ssl://")) {
            (true, r)
        } else {
            return Err(bad("the scheme must be mqtt:// or mqtts://"));
        };
        let rest = rest.trim_end_matches('/');
        let (host, port) = if let Some(v6) = rest.strip_prefix('[') {
            let (h, after) = v6.split_once(']').ok_or_else(|| bad("an IPv6 address needs its closing ]"))?;
            (h, after.strip_prefix(':'))
        } else {
            match rest.rsplit_once(':') {
                Some((h, p)) => (h, Some(p)),
                None => (rest, None),
            }
        };
        if host.is_empty() || host.contains(['/', '@', ' ']) {
            return Err(bad("no host"));
        }
        let port = match port {
            None => {
                if tls {
                    8883
                } else {
                    1883
                }
            }
            Some(p) => p.parse::<u16>().ok().filter(|p| *p != 0).ok_or_else(|| bad("the port must be 1..=65535"))?,
        };
        Ok(Self { tls, host: host.to_owned(), port })
    }
}

impl<'de> Deserialize<'de> for BrokerUrl {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        String::deserialize(d)?.parse().map_err(serde::de::Error::custom)
    }
}

fn one_or_many<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<BrokerUrl>, D::Error> {
    // Strings first, parsed after: an untagged enum of addresses would
    // hide why an address is wrong behind "did not match any variant".
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum OneOrMany {
        One(String),
        Many(Vec<String>),
    }
    let texts = match OneOrMany::deserialize(d)? {
        OneOrMany::One(b) => vec![b],
        OneOrMany::Many(v) => v,
    };
    texts.iter().map(|t| t.parse().map_err(serde::de::Error::custom)).collect()
}

/// Whether `id` can be a Sparkplug topic level: not empty, none of the
/// MQTT wildcards or separators (Sparkplug 3.0 section 4.1.1).
pub fn valid_id(id: &str) -> bool {
    !id.is_empty() && !id.contains(['/', '+', '#']) && !id.chars().any(char::is_control)
}

impl SparkplugConfig {
    /// The edge node id: `node_id`, else the host name (made a valid topic
    /// level).
    pub fn node_id(&self) -> String {
        if let Some(id) = &self.node_id {
            return id.clone();
        }
        let host = nix::unistd::gethostname().ok().and_then(|h| h.into_string().ok()).unwrap_or_default();
        let id: String =
            host.chars().map(|c| if matches!(c, '/' | '+' | '#') || c.is_control() { '_' } else { c }).collect();
        if id.is_empty() { "ecmxfd".into() } else { id }
    }

    /// Checks values serde cannot, naming the key.
    pub fn validate(&self, path: &Path) -> Result<(), ConfigError> {
        let bad = |key: &str, message: String| {
            Err(ConfigError::Invalid { file: path.into(), key: format!("sparkplug.{key}"), message })
        };
        if self.broker.is_empty() {
            return bad("broker", "no broker given".into());
        }
        for (key, id) in [("group_id", Some(&self.group_id)), ("node_id", self.node_id.as_ref())]
            .into_iter()
            .chain(std::iter::once(("primary_host_id", self.primary_host_id.as_ref())))
        {
            if let Some(id) = id
                && !valid_id(id)
            {
                return bad(key, format!("{id:?} cannot be a topic level: empty, or has '/', '+' or '#'"));
            }
        }
        for (key, ms) in
            [("data_period_ms", self.data_period_ms), ("diagnostics_period_ms", self.diagnostics_period_ms)]
        {
            if !(10..=3_600_000).contains(&ms) {
                return bad(key, format!("{ms} ms is outside 10..=3600000"));
            }
        }
        for (key, d) in [("data_deadband", self.data_deadband), ("diagnostics_deadband", self.diagnostics_deadband)] {
            if !d.is_finite() || d < 0.0 {
                return bad(key, format!("{d} is not a deadband (a finite number >= 0)"));
            }
        }
        if self.keep_alive_s < 5 {
            return bad("keep_alive_s", format!("{} s is shorter than 5 s", self.keep_alive_s));
        }
        if self.client_cert.is_some() != self.client_key.is_some() {
            return bad("client_cert", "a client certificate needs client_key, and a key its certificate".into());
        }
        let tls = self.broker.iter().any(|b| b.tls);
        for (key, file) in
            [("ca_file", &self.ca_file), ("client_cert", &self.client_cert), ("client_key", &self.client_key)]
        {
            if let Some(f) = file {
                if !tls {
                    return bad(key, "TLS files given, but no broker is mqtts://".into());
                }
                if !f.is_file() {
                    return bad(key, format!("{} is not a readable file", f.display()));
                }
            }
        }
        if let Some(f) = &self.credentials_file
            && let Err(e) = Credentials::read(f)
        {
            return bad("credentials_file", e);
        }
        Ok(())
    }
}

/// An MQTT user name and password from `credentials_file`.
#[derive(Clone, PartialEq, Eq)]
pub struct Credentials {
    /// The user name.
    pub username: String,
    /// The password.
    pub password: String,
}

impl std::fmt::Debug for Credentials {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Credentials").field("username", &self.username).finish_non_exhaustive()
    }
}

impl Credentials {
    /// Reads the file: user name on the first line, password on the second.
    pub fn read(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut lines = text.lines();
        let username = lines.next().unwrap_or_default().trim().to_owned();
        let password = lines.next().unwrap_or_default().trim_end_matches('\r').to_owned();
        if username.is_empty() {
            return Err(format!("{}: the first line (the user name) is empty", path.display()));
        }
        Ok(Self { username, password })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broker_addresses_parse_with_default_ports_and_name_what_is_wrong() {
        let b: BrokerUrl = "mqtt://broker.plant".parse().unwrap();
        assert_eq!((b.tls, b.host.as_str(), b.port), (false, "broker.plant", 1883));
        let b: BrokerUrl = "mqtts://10.0.0.5".parse().unwrap();
        assert_eq!((b.tls, b.port), (true, 8883));
        let b: BrokerUrl = "mqtt://[fd00::1]:1884".parse().unwrap();
        assert_eq!((b.host.as_str(), b.port), ("fd00::1", 1884));
        assert_eq!(b.to_string(), "mqtt://[fd00::1]:1884");
        assert!("http://x".parse::<BrokerUrl>().unwrap_err().contains("mqtt:// or mqtts://"));
        assert!("mqtt://:1883".parse::<BrokerUrl>().unwrap_err().contains("no host"));
        assert!("mqtt://h:0".parse::<BrokerUrl>().unwrap_err().contains("1..=65535"));
        assert!("mqtt://h:99999".parse::<BrokerUrl>().unwrap_err().contains("1..=65535"));
    }

    #[test]
    fn ids_with_topic_wildcards_are_refused() {
        assert!(valid_id("line-3 gw"));
        for bad in ["", "a/b", "a+", "#", "a\nb"] {
            assert!(!valid_id(bad), "{bad:?}");
        }
    }
}
