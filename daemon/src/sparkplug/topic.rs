//! Sparkplug B topics (Eclipse Sparkplug 3.0, section 4.1): the node's and
//! its devices' message topics, the commands it listens to, and a primary
//! host's STATE.

use std::fmt;

/// The topic namespace of Sparkplug B.
pub(super) const NAMESPACE: &str = "spBv1.0";

/// A message type (topic level 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(super) enum Kind {
    /// Node birth.
    NBirth,
    /// Node death (the MQTT will).
    NDeath,
    /// Node data.
    NData,
    /// Command to the node.
    NCmd,
    /// Device birth.
    DBirth,
    /// Device death.
    DDeath,
    /// Device data.
    DData,
    /// Command to a device.
    DCmd,
}

impl Kind {
    /// Its topic word.
    pub(super) fn word(self) -> &'static str {
        match self {
            Self::NBirth => "NBIRTH",
            Self::NDeath => "NDEATH",
            Self::NData => "NDATA",
            Self::NCmd => "NCMD",
            Self::DBirth => "DBIRTH",
            Self::DDeath => "DDEATH",
            Self::DData => "DDATA",
            Self::DCmd => "DCMD",
        }
    }

    fn from_word(w: &str) -> Option<Self> {
        Some(match w {
            "NBIRTH" => Self::NBirth,
            "NDEATH" => Self::NDeath,
            "NDATA" => Self::NData,
            "NCMD" => Self::NCmd,
            "DBIRTH" => Self::DBirth,
            "DDEATH" => Self::DDeath,
            "DDATA" => Self::DData,
            "DCMD" => Self::DCmd,
            _ => return None,
        })
    }
}

/// The edge node's place in the namespace.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct NodeTopics {
    /// Group id.
    pub group: String,
    /// Edge node id.
    pub node: String,
}

impl NodeTopics {
    /// A node message's topic.
    pub(super) fn node(&self, kind: Kind) -> String {
        format!("{NAMESPACE}/{}/{}/{}", self.group, kind.word(), self.node)
    }

    /// A device message's topic.
    pub(super) fn device(&self, kind: Kind, device: &str) -> String {
        format!("{NAMESPACE}/{}/{}/{}/{device}", self.group, kind.word(), self.node)
    }

    /// The command topics to subscribe to: NCMD, and DCMD of every device.
    pub(super) fn commands(&self) -> [String; 2] {
        [self.node(Kind::NCmd), format!("{NAMESPACE}/{}/DCMD/{}/+", self.group, self.node)]
    }

    /// What a received topic is: a command to this node or one of its
    /// devices (`None`: another node's, or not Sparkplug).
    pub(super) fn parse<'t>(&self, topic: &'t str) -> Option<(Kind, Option<&'t str>)> {
        let mut levels = topic.split('/');
        if levels.next()? != NAMESPACE || levels.next()? != self.group {
            return None;
        }
        let kind = Kind::from_word(levels.next()?)?;
        if levels.next()? != self.node {
            return None;
        }
        let device = levels.next();
        if levels.next().is_some() {
            return None;
        }
        match (kind, device) {
            (Kind::NCmd | Kind::NBirth | Kind::NData | Kind::NDeath, None) => Some((kind, None)),
            (Kind::DCmd | Kind::DBirth | Kind::DData | Kind::DDeath, Some(d)) if !d.is_empty() => Some((kind, Some(d))),
            _ => None,
        }
    }
}

/// A primary host application's STATE topic (3.0: `spBv1.0/STATE/<id>`).
pub(super) fn host_state(host_id: &str) -> String {
    format!("{NAMESPACE}/STATE/{host_id}")
}

/// Whether a STATE payload says the host is online: 3.0's JSON
/// (`{"online": true, "timestamp": ...}`), or 2.x's `ONLINE`/`OFFLINE`.
pub(super) fn host_online(payload: &[u8]) -> Option<bool> {
    let text = std::str::from_utf8(payload).ok()?.trim();
    match text {
        "ONLINE" => return Some(true),
        "OFFLINE" => return Some(false),
        _ => {}
    }
    let v: serde_json::Value = serde_json::from_str(text).ok()?;
    v.get("online")?.as_bool()
}

/// A device id for slave `position`: `slave-<position>`, stable across
/// restarts and network changes that keep the ring.
pub(super) fn device_id(position: u8) -> String {
    format!("slave-{position}")
}

/// The slave position of a device id of [`device_id`].
pub(super) fn device_position(id: &str) -> Option<u8> {
    let n = id.strip_prefix("slave-")?;
    if n.len() > 1 && n.starts_with('0') {
        return None;
    }
    n.parse().ok()
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.word())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn topics() -> NodeTopics {
        NodeTopics { group: "plant".into(), node: "gw1".into() }
    }

    #[test]
    fn topics_are_the_specifications() {
        let t = topics();
        assert_eq!(t.node(Kind::NBirth), "spBv1.0/plant/NBIRTH/gw1");
        assert_eq!(t.device(Kind::DData, "slave-2"), "spBv1.0/plant/DDATA/gw1/slave-2");
        assert_eq!(t.commands(), ["spBv1.0/plant/NCMD/gw1".to_string(), "spBv1.0/plant/DCMD/gw1/+".to_string()]);
        assert_eq!(host_state("scada"), "spBv1.0/STATE/scada");
    }

    #[test]
    fn every_topic_round_trips_and_foreign_ones_are_not_ours() {
        let t = topics();
        for kind in [Kind::NBirth, Kind::NDeath, Kind::NData, Kind::NCmd] {
            assert_eq!(t.parse(&t.node(kind)), Some((kind, None)));
        }
        for kind in [Kind::DBirth, Kind::DDeath, Kind::DData, Kind::DCmd] {
            assert_eq!(t.parse(&t.device(kind, "slave-7")), Some((kind, Some("slave-7"))));
        }
        for other in [
            "spBv1.0/plant/NCMD/gw2",
            "spBv1.0/other/NCMD/gw1",
            "spBv1.0/plant/XCMD/gw1",
            "spBv1.0/plant/DCMD/gw1",
            "spBv1.0/plant/NCMD/gw1/x",
            "spBv1.0/plant/DCMD/gw1/slave-1/x",
            "spAv1.0/plant/NCMD/gw1",
            "",
        ] {
            assert_eq!(t.parse(other), None, "{other}");
        }
    }

    #[test]
    fn host_state_is_read_in_both_spellings() {
        assert_eq!(host_online(br#"{"online": true, "timestamp": 1}"#), Some(true));
        assert_eq!(host_online(br#"{"online":false,"timestamp":1}"#), Some(false));
        assert_eq!(host_online(b"ONLINE"), Some(true));
        assert_eq!(host_online(b"OFFLINE"), Some(false));
        assert_eq!(host_online(b"{}"), None);
        assert_eq!(host_online(&[0xFF]), None);
    }

    #[test]
    fn device_ids_name_positions() {
        for p in [0u8, 9, 255] {
            assert_eq!(device_position(&device_id(p)), Some(p));
        }
        assert_eq!(device_position("slave-01"), None);
        assert_eq!(device_position("slave-256"), None);
        assert_eq!(device_position("drive"), None);
    }
}
