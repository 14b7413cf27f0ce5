//! The edge node's messages, decided without I/O (Eclipse Sparkplug 3.0,
//! chapter 6 "Payloads" and 7 "Operational behavior"): what it publishes
//! is a function of what it last published and a [`View`] of the daemon
//! at one instant, with the time as a field, so every rule is unit-tested
//! (tests below) and the session (`session.rs`) only moves bytes.
//!
//! - NBIRTH: `seq` 0, every node metric by name, alias and datatype, with
//!   the connection's `bdSeq` (the same as the MQTT will's NDEATH).
//! - One device per slave (`slave-<position>`): DBIRTH while it is in the
//!   network and process data flows in the target state; DDEATH when it is
//!   lost (a shorter ring, an AL error) or the network leaves that state;
//!   DBIRTH again when it is back.
//! - DDATA/NDATA: only what moved past its deadband since last published,
//!   by alias, one message per device per publish period.
//! - `seq` counts every message but NDEATH, 0..=255 and round again.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use crate::master::EcatState;
use ecmxf_proto::sparkplug::payload::Metric;
use ecmxf_proto::sparkplug::{DataType as SpType, Payload};

use super::topic::Kind;
use super::value::{self, MetricValueExt, Value};
use crate::config::sparkplug::MetricNames;
use crate::master::image::{Image, read_bits};
use crate::master::{NetworkLayout, Phase, Snapshot};

/// What the node publishes and how.
#[derive(Clone, Debug, Default)]
pub(super) struct Settings {
    /// Process data deadband.
    pub data_deadband: f64,
    /// Node diagnostics deadband.
    pub diagnostics_deadband: f64,
    /// Slaves published (empty: all).
    pub slaves: Vec<u8>,
    /// Variables published by entry or variable name (empty: all).
    pub variables: Vec<String>,
    /// How process data metrics are named (`sparkplug.metric_names`).
    pub names: MetricNames,
}

/// Counters of the node itself, published as node metrics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Messages handed to the MQTT client.
    pub published: u64,
    /// Messages dropped (the client's queue full, or not connected).
    pub dropped: u64,
    /// Commands refused.
    pub refused: u64,
    /// Connections made.
    pub connects: u64,
}

/// The daemon at one instant, as the node reads it (published snapshots:
/// nothing here waits for the engine).
#[derive(Clone, Copy, Debug)]
pub(super) struct View<'a> {
    /// Now, ms since the Unix epoch (the payloads' timestamps).
    pub now_ms: u64,
    /// The engine's snapshot.
    pub snapshot: &'a Snapshot,
    /// Process data flows in the target state ([`crate::master::Verdict::flowing`]).
    pub flowing: bool,
    /// The health in words.
    pub health: &'a str,
    /// The network bring-up found.
    pub layout: &'a NetworkLayout,
    /// The process image; `None` while it is being laid out, an empty
    /// one when it could not be (the devices are born without process
    /// data rather than never).
    pub image: Option<&'a Arc<Image>>,
    /// The newest input frame.
    pub inputs: &'a [u8],
    /// When it was received, ms since the Unix epoch (the timestamp of
    /// input values; `now_ms` when none).
    pub inputs_ms: u64,
    /// The output image as clients last wrote it.
    pub outputs: &'a [u8],
    /// AL status reported per slave since the network last came up:
    /// state and code (a slave out of OP is lost).
    pub al: &'a BTreeMap<u8, (EcatState, u16)>,
    /// DC cycle, us.
    pub cycle_us: u32,
    /// SPI exchanges per second lately (the link's use).
    pub exchange_rate: f64,
    /// The node's own counters.
    pub counts: Counts,
}

/// One message to publish.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Outgoing {
    /// Its type.
    pub kind: Kind,
    /// The device (`None`: the node's).
    pub device: Option<u8>,
    /// The payload.
    pub payload: Payload,
    /// Why a device was born or died, in words for the log ("" else).
    pub why: &'static str,
}

/// A node metric's source.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum NodeSource {
    BdSeq,
    Rebirth,
    Reboot,
    Version,
    Firmware,
    Phase,
    State,
    Health,
    CycleUs,
    Slaves,
    SlavesSeen,
    Exchanges,
    CrcErrors,
    WkcErrors,
    FifoAlarms,
    Recoveries,
    InputFrames,
    OutputFrames,
    InputsDroppedByChip,
    RxFifo,
    MaxFifoGapUs,
    ExchangeRate,
    Published,
    Dropped,
    Refused,
    Connects,
}

/// The node metrics: name, datatype, source. Names with `/` are folders
/// in hosts (Ignition); `Node Control/*` and `bdSeq` are the spec's.
const NODE_METRICS: &[(&str, SpType, NodeSource)] = &[
    ("bdSeq", SpType::UInt64, NodeSource::BdSeq),
    ("Node Control/Rebirth", SpType::Boolean, NodeSource::Rebirth),
    ("Node Control/Reboot", SpType::Boolean, NodeSource::Reboot),
    ("Properties/Daemon Version", SpType::String, NodeSource::Version),
    ("Properties/Chip Firmware", SpType::UInt8, NodeSource::Firmware),
    ("Engine/Phase", SpType::String, NodeSource::Phase),
    ("Engine/EtherCAT State", SpType::String, NodeSource::State),
    ("Engine/Health", SpType::String, NodeSource::Health),
    ("Engine/Cycle us", SpType::UInt32, NodeSource::CycleUs),
    ("Engine/Slaves", SpType::UInt32, NodeSource::Slaves),
    ("Engine/Slaves Seen", SpType::UInt32, NodeSource::SlavesSeen),
    ("Counters/Exchanges", SpType::UInt64, NodeSource::Exchanges),
    ("Counters/CRC Errors", SpType::UInt64, NodeSource::CrcErrors),
    ("Counters/WKC Errors", SpType::UInt64, NodeSource::WkcErrors),
    ("Counters/FIFO Alarms", SpType::UInt64, NodeSource::FifoAlarms),
    ("Counters/Recoveries", SpType::UInt64, NodeSource::Recoveries),
    ("Counters/Input Frames", SpType::UInt64, NodeSource::InputFrames),
    ("Counters/Output Frames", SpType::UInt64, NodeSource::OutputFrames),
    ("Counters/Inputs Dropped By Chip", SpType::UInt64, NodeSource::InputsDroppedByChip),
    ("Link/RxFIFO Frames", SpType::UInt8, NodeSource::RxFifo),
    ("Link/Max FIFO Gap us", SpType::UInt64, NodeSource::MaxFifoGapUs),
    ("Link/Exchanges per s", SpType::Double, NodeSource::ExchangeRate),
    ("Sparkplug/Published", SpType::UInt64, NodeSource::Published),
    ("Sparkplug/Dropped", SpType::UInt64, NodeSource::Dropped),
    ("Sparkplug/Commands Refused", SpType::UInt64, NodeSource::Refused),
    ("Sparkplug/Connects", SpType::UInt64, NodeSource::Connects),
];

/// The name of the node metric that asks for a rebirth.
pub(super) const REBIRTH: &str = "Node Control/Rebirth";
/// The name of the node metric that asks for a reboot (refused).
pub(super) const REBOOT: &str = "Node Control/Reboot";
/// The folder of a device's output variables (the ones DCMD writes).
pub(super) const OUTPUTS: &str = "Outputs/";
/// The folder of a device's input variables.
pub(super) const INPUTS: &str = "Inputs/";

/// A device metric's source.
#[derive(Clone, Debug, PartialEq, Eq)]
enum DeviceSource {
    Name,
    Vendor,
    Product,
    Revision,
    Position,
    State,
    AlCode,
    /// A process data entry (its index in the image's entries).
    Entry(usize),
}

/// A device metric.
#[derive(Clone, Debug, PartialEq)]
struct DeviceMetric {
    name: String,
    alias: u64,
    datatype: SpType,
    source: DeviceSource,
}

/// A born device: its metrics as DBIRTH gave them and what was last
/// published of each.
#[derive(Clone, Debug)]
struct Device {
    metrics: Vec<DeviceMetric>,
    last: Vec<Value>,
    image: Option<Arc<Image>>,
}

/// The node's publishing state for one process lifetime (aliases stay the
/// same across connections and rebirths).
#[derive(Debug)]
pub(super) struct Node {
    settings: Settings,
    bd_seq: Option<u64>,
    seq: u64,
    aliases: HashMap<(Option<u8>, String), u64>,
    node_last: Vec<Value>,
    devices: BTreeMap<u8, Device>,
}

impl Node {
    /// A node that has published nothing yet.
    pub(super) fn new(settings: Settings) -> Self {
        Self {
            settings,
            bd_seq: None,
            seq: 0,
            aliases: HashMap::new(),
            node_last: Vec::new(),
            devices: BTreeMap::new(),
        }
    }

    /// Goes on counting `bdSeq` from a node that ran before in this
    /// process (`next`: its last + 1, 0 for none).
    pub(super) fn resume(&mut self, next: u64) {
        self.bd_seq = next.checked_sub(1).map(|b| b % 256);
    }

    /// A new MQTT connection: the next `bdSeq` (0 first, then +1 modulo
    /// 256, spec 7.1.2), for the will and the NBIRTH that follows.
    pub(super) fn next_connection(&mut self) -> u64 {
        let next = self.bd_seq.map_or(0, |b| (b + 1) % 256);
        self.bd_seq = Some(next);
        next
    }

    /// The NDEATH payload of this connection (the MQTT will; also sent
    /// before a clean disconnect): the timestamp and `bdSeq`, no `seq`.
    pub(super) fn death(&self, now_ms: u64) -> Payload {
        Payload {
            timestamp: Some(now_ms),
            metrics: vec![Metric {
                name: Some("bdSeq".into()),
                datatype: Some(SpType::UInt64 as u32),
                value: Some(Value::UInt(self.bd_seq.unwrap_or(0)).to_metric(SpType::UInt64)),
                ..Metric::default()
            }],
            ..Payload::default()
        }
    }

    /// The births of a (re)connection or a rebirth request: NBIRTH with
    /// `seq` 0, then a DBIRTH for every device alive now. What hosts knew
    /// of devices before is forgotten.
    pub(super) fn birth(&mut self, view: &View) -> Vec<Outgoing> {
        self.seq = 0;
        self.devices.clear();
        let mut metrics = Vec::with_capacity(NODE_METRICS.len());
        self.node_last.clear();
        for (i, &(name, datatype, source)) in NODE_METRICS.iter().enumerate() {
            let value = self.node_value(source, view);
            metrics.push(Metric {
                name: Some(name.into()),
                alias: Some(i as u64 + 1),
                timestamp: Some(view.now_ms),
                datatype: Some(datatype as u32),
                value: Some(value.to_metric(datatype)),
                ..Metric::default()
            });
            self.node_last.push(value);
        }
        let mut out = vec![self.message(Kind::NBirth, None, view.now_ms, metrics)];
        out.extend(self.update(view, false));
        out
    }

    /// Device births and deaths for what changed in `view`, then (with
    /// `data`) a DDATA per born device with what moved.
    pub(super) fn update(&mut self, view: &View, data: bool) -> Vec<Outgoing> {
        let mut out = Vec::new();
        let positions: Vec<u8> = (0..view.layout.slaves.len().min(256) as u16)
            .map(|p| p as u8)
            .filter(|p| self.settings.slaves.is_empty() || self.settings.slaves.contains(p))
            .collect();
        // Deaths first: a device lost, or one whose image changed under it.
        let born: Vec<u8> = self.devices.keys().copied().collect();
        for p in born {
            let stale = self.image_changed_its_metrics(view, p);
            if !alive(view, p) || !positions.contains(&p) || stale {
                self.devices.remove(&p);
                let why = if !positions.contains(&p) {
                    "no longer published ([sparkplug] slaves)"
                } else if stale {
                    "its process image was laid out again (metrics change)"
                } else {
                    not_alive(view, p)
                };
                let mut death = self.message(Kind::DDeath, Some(p), view.now_ms, Vec::new());
                death.why = why;
                out.push(death);
            }
        }
        for &p in &positions {
            if self.devices.contains_key(&p) || !alive(view, p) {
                continue;
            }
            let metrics = self.device_metrics(view, p);
            let last: Vec<Value> = metrics.iter().map(|m| device_value(&m.source, view, p)).collect();
            let payload: Vec<Metric> = metrics
                .iter()
                .zip(&last)
                .map(|(m, v)| Metric {
                    name: Some(m.name.clone()),
                    alias: Some(m.alias),
                    timestamp: Some(taken_at(&m.source, view)),
                    datatype: Some(m.datatype as u32),
                    value: Some(v.to_metric(m.datatype)),
                    ..Metric::default()
                })
                .collect();
            self.devices.insert(p, Device { metrics, last, image: view.image.cloned() });
            let mut birth = self.message(Kind::DBirth, Some(p), view.now_ms, payload);
            birth.why = "in the network, in OP, its process data flowing";
            out.push(birth);
        }
        if data {
            let deadband = self.settings.data_deadband;
            let mut batches = Vec::new();
            for (&p, d) in self.devices.iter_mut() {
                let mut changed = Vec::new();
                for (m, last) in d.metrics.iter().zip(d.last.iter_mut()) {
                    let v = device_value(&m.source, view, p);
                    if v.moved_from(last, deadband) {
                        changed.push(Metric {
                            alias: Some(m.alias),
                            timestamp: Some(taken_at(&m.source, view)),
                            datatype: Some(m.datatype as u32),
                            value: Some(v.to_metric(m.datatype)),
                            ..Metric::default()
                        });
                        *last = v;
                    }
                }
                if !changed.is_empty() {
                    batches.push((p, changed));
                }
            }
            for (p, changed) in batches {
                out.push(self.message(Kind::DData, Some(p), view.now_ms, changed));
            }
        }
        out
    }

    /// NDATA with the node metrics that moved (`None`: none did).
    pub(super) fn node_data(&mut self, view: &View) -> Option<Outgoing> {
        if self.node_last.len() != NODE_METRICS.len() {
            return None;
        }
        let mut changed = Vec::new();
        for (i, &(_, datatype, source)) in NODE_METRICS.iter().enumerate() {
            if matches!(source, NodeSource::BdSeq | NodeSource::Rebirth | NodeSource::Reboot) {
                continue;
            }
            let v = self.node_value(source, view);
            if v.moved_from(&self.node_last[i], self.settings.diagnostics_deadband) {
                changed.push(Metric {
                    alias: Some(i as u64 + 1),
                    timestamp: Some(view.now_ms),
                    datatype: Some(datatype as u32),
                    value: Some(v.to_metric(datatype)),
                    ..Metric::default()
                });
                self.node_last[i] = v;
            }
        }
        (!changed.is_empty()).then(|| self.message(Kind::NData, None, view.now_ms, changed))
    }

    /// The node metric a command names, by name or alias.
    pub(super) fn node_metric(&self, m: &Metric) -> Option<&'static str> {
        match (&m.name, m.alias) {
            (Some(name), _) => NODE_METRICS.iter().find(|(n, ..)| n == name).map(|(n, ..)| *n),
            (None, Some(alias)) => NODE_METRICS.get(usize::try_from(alias).ok()?.checked_sub(1)?).map(|(n, ..)| *n),
            (None, None) => None,
        }
    }

    /// The output entry a DCMD metric of device `p` names (by name or
    /// alias): its index in the image's entries, and the image.
    pub(super) fn output_target(&self, p: u8, m: &Metric) -> Result<(usize, Arc<Image>), String> {
        let d = self.devices.get(&p).ok_or_else(|| format!("device slave-{p} is not born (lost, or not in OP)"))?;
        let metric = d
            .metrics
            .iter()
            .find(|dm| match (&m.name, m.alias) {
                (Some(name), _) => &dm.name == name,
                (None, Some(alias)) => dm.alias == alias,
                (None, None) => false,
            })
            .ok_or_else(|| format!("device slave-{p} has no metric {}", shown_metric(m)))?;
        match (&metric.source, &d.image) {
            (DeviceSource::Entry(i), Some(image)) if image.entries.get(*i).is_some_and(|e| e.output) => {
                Ok((*i, Arc::clone(image)))
            }
            _ => Err(format!("{} is not an output variable (only {OUTPUTS}* are written)", metric.name)),
        }
    }

    /// The devices born now.
    #[cfg(test)]
    pub(crate) fn born(&self) -> impl Iterator<Item = u8> + '_ {
        self.devices.keys().copied()
    }

    fn message(&mut self, kind: Kind, device: Option<u8>, now_ms: u64, metrics: Vec<Metric>) -> Outgoing {
        let seq = self.seq;
        self.seq = (self.seq + 1) % 256;
        Outgoing {
            kind,
            device,
            payload: Payload { timestamp: Some(now_ms), metrics, seq: Some(seq), ..Payload::default() },
            why: "",
        }
    }

    /// Whether device `p` was born of another image than `view`'s and its
    /// metrics differ in this one (a new image with the same metrics, such
    /// as one whose entries the devices only named, is taken as is: no
    /// death and birth for it).
    fn image_changed_its_metrics(&mut self, view: &View, p: u8) -> bool {
        if self.devices.get(&p).is_none_or(|d| same_image(d.image.as_ref(), view.image)) {
            return false;
        }
        let now = self.device_metrics(view, p);
        match self.devices.get_mut(&p) {
            Some(d) if d.metrics == now => {
                d.image = view.image.cloned();
                false
            }
            _ => true,
        }
    }

    fn alias(&mut self, device: Option<u8>, name: &str) -> u64 {
        let next = NODE_METRICS.len() as u64 + 1 + self.aliases.len() as u64;
        *self.aliases.entry((device, name.to_owned())).or_insert(next)
    }

    fn device_metrics(&mut self, view: &View, p: u8) -> Vec<DeviceMetric> {
        let mut metrics = Vec::new();
        let mut add = |node: &mut Self, name: String, datatype: SpType, source: DeviceSource| {
            let alias = node.alias(Some(p), &name);
            metrics.push(DeviceMetric { name, alias, datatype, source });
        };
        add(self, "Properties/Name".into(), SpType::String, DeviceSource::Name);
        add(self, "Properties/Vendor ID".into(), SpType::UInt32, DeviceSource::Vendor);
        add(self, "Properties/Product Code".into(), SpType::UInt32, DeviceSource::Product);
        add(self, "Properties/Revision".into(), SpType::UInt32, DeviceSource::Revision);
        add(self, "Properties/Position".into(), SpType::UInt8, DeviceSource::Position);
        add(self, "State".into(), SpType::String, DeviceSource::State);
        add(self, "AL Status Code".into(), SpType::UInt16, DeviceSource::AlCode);
        if let Some(image) = view.image {
            let mine = |e: &&crate::master::image::Entry| e.slave == p && e.index != 0;
            let labelled = |output: bool, label: &str| {
                image.entries.iter().filter(mine).filter(|e| e.output == output && e.label == label).count() == 1
            };
            for (i, e) in image.entries.iter().enumerate() {
                if !mine(&e) {
                    continue;
                }
                let v = &self.settings.variables;
                if !v.is_empty() && !v.iter().any(|n| *n == e.name || (!e.variable.is_empty() && *n == e.variable)) {
                    continue;
                }
                let folder = if e.output { OUTPUTS } else { INPUTS };
                let name = match self.settings.names {
                    MetricNames::Label if !e.label.is_empty() && labelled(e.output, &e.label) => e.label.as_str(),
                    _ => metric_name(&e.name),
                };
                add(self, format!("{folder}{name}"), value::datatype(e.data_type), DeviceSource::Entry(i));
            }
        }
        metrics
    }

    fn node_value(&self, source: NodeSource, view: &View) -> Value {
        let s = view.snapshot;
        match source {
            NodeSource::BdSeq => Value::UInt(self.bd_seq.unwrap_or(0)),
            NodeSource::Rebirth | NodeSource::Reboot => Value::Bool(false),
            NodeSource::Version => Value::Text(env!("CARGO_PKG_VERSION").into()),
            NodeSource::Firmware => Value::UInt(view.layout.firmware.into()),
            NodeSource::Phase => Value::Text(s.phase.name().into()),
            NodeSource::State => Value::Text(s.ecat_state.to_string()),
            NodeSource::Health => Value::Text(view.health.into()),
            NodeSource::CycleUs => Value::UInt(view.cycle_us.into()),
            NodeSource::Slaves => Value::UInt(s.slaves),
            NodeSource::SlavesSeen => Value::UInt(s.slaves_seen),
            NodeSource::Exchanges => Value::UInt(s.exchanges),
            NodeSource::CrcErrors => Value::UInt(s.crc_errors),
            NodeSource::WkcErrors => Value::UInt(s.wkc_errors),
            NodeSource::FifoAlarms => Value::UInt(s.fifo_alarms),
            NodeSource::Recoveries => Value::UInt(s.recoveries),
            NodeSource::InputFrames => Value::UInt(s.input_frames),
            NodeSource::OutputFrames => Value::UInt(s.output_frames),
            NodeSource::InputsDroppedByChip => Value::UInt(s.inputs_dropped_by_chip),
            NodeSource::RxFifo => Value::UInt(s.rx_fifo.into()),
            NodeSource::MaxFifoGapUs => Value::UInt(s.max_fifo_gap_us),
            NodeSource::ExchangeRate => Value::Real(view.exchange_rate.round()),
            NodeSource::Published => Value::UInt(view.counts.published),
            NodeSource::Dropped => Value::UInt(view.counts.dropped),
            NodeSource::Refused => Value::UInt(view.counts.refused),
            NodeSource::Connects => Value::UInt(view.counts.connects),
        }
    }
}

/// A variable's metric name: its entry name without the slave's number
/// (`2.0x6000:01` is `0x6000:01` of device `slave-2`).
pub(super) fn metric_name(entry: &str) -> &str {
    entry.split_once('.').map_or(entry, |(_, rest)| rest)
}

fn shown_metric(m: &Metric) -> String {
    match (&m.name, m.alias) {
        (Some(n), _) => format!("{n:?}"),
        (None, Some(a)) => format!("with alias {a}"),
        (None, None) => "without name or alias".into(),
    }
}

fn same_image(a: Option<&Arc<Image>>, b: Option<&Arc<Image>>) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => Arc::ptr_eq(a, b),
        (None, None) => true,
        _ => false,
    }
}

/// Whether slave `p` is a live device: process data flows in the target
/// state, the ring still reaches it, it reported no AL state other than
/// OP, and its process image is laid out (DBIRTH lists every metric).
/// Why a device is not alive, in words (see [`alive`]).
fn not_alive(view: &View, p: u8) -> &'static str {
    if view.snapshot.phase != Phase::Running {
        "the engine is not running the network"
    } else if !view.flowing {
        "process data stopped flowing"
    } else if u64::from(p) >= view.snapshot.slaves || usize::from(p) >= view.layout.slaves.len() {
        "the slave is gone from the ring"
    } else if view.al.get(&p).is_some_and(|(state, _)| *state != EcatState::Op) {
        "the slave left OP (AL status)"
    } else {
        "the process image is not laid out yet"
    }
}

fn alive(view: &View, p: u8) -> bool {
    view.snapshot.phase == Phase::Running
        && view.flowing
        && u64::from(p) < view.snapshot.slaves
        && usize::from(p) < view.layout.slaves.len()
        && view.al.get(&p).is_none_or(|(state, _)| *state == EcatState::Op)
        && view.image.is_some()
}

/// When a device metric's value was taken: an input's when its frame
/// arrived, the rest now.
fn taken_at(source: &DeviceSource, view: &View) -> u64 {
    match (source, view.image) {
        (DeviceSource::Entry(i), Some(image)) if image.entries.get(*i).is_some_and(|e| !e.output) => view.inputs_ms,
        _ => view.now_ms,
    }
}

fn device_value(source: &DeviceSource, view: &View, p: u8) -> Value {
    let slave = view.layout.slaves.get(usize::from(p));
    match source {
        DeviceSource::Name => Value::Text(slave.map(|s| s.name.clone()).unwrap_or_default()),
        DeviceSource::Vendor => Value::UInt(slave.map_or(0, |s| s.vendor_id).into()),
        DeviceSource::Product => Value::UInt(slave.map_or(0, |s| s.product_code).into()),
        DeviceSource::Revision => Value::UInt(slave.map_or(0, |s| s.revision).into()),
        DeviceSource::Position => Value::UInt(p.into()),
        DeviceSource::State => {
            Value::Text(view.al.get(&p).map_or(view.snapshot.ecat_state, |(state, _)| *state).to_string())
        }
        DeviceSource::AlCode => Value::UInt(view.al.get(&p).map_or(0, |(_, code)| *code).into()),
        DeviceSource::Entry(i) => match view.image.and_then(|image| image.entries.get(*i)) {
            Some(e) => {
                let frame = if e.output { view.outputs } else { view.inputs };
                Value::decode(e.data_type, &read_bits(frame, e.bit_offset, e.bit_length))
            }
            None => Value::Bytes(Vec::new()),
        },
    }
}

#[cfg(test)]
#[path = "node_tests.rs"]
mod tests;
