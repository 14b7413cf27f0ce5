//! The address space (docs/opcua.md): `Objects/EtherCAT` with the master's
//! diagnostics, and its `Slaves` folder with one object per slave named
//! as the OPC UA DI companion specification names a device's identity
//! (OPC 10000-100 4.5: Manufacturer, Model, ProductCode,
//! HardwareRevision, DeviceHealth), its EtherCAT state and AL status code,
//! and `Inputs`/`Outputs` folders with one variable per process-image
//! entry, typed as its CoE type, named as the device names it.
//!
//! Every value is read when asked (a Read, or a monitored item's sample)
//! by a callback over what the engine already publishes: the newest input
//! frame (shared, never copied per client), the output shadow, the status
//! snapshot. Nothing here runs in the cyclic path. Output variables are
//! writable (by operators, [`super::writes`]); each slave has its methods
//! ([`super::methods`]).

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use opcua::server::address_space::{
    AccessLevel, AddressSpace, EventNotifier, MethodBuilder, ObjectBuilder, VariableBuilder,
};
use opcua::types::{
    Argument, DataTypeId, DataValue, DateTime, LocalizedText, NodeId, ObjectTypeId, QualifiedName, StatusCode,
    VariableTypeId, Variant,
};

use super::manager::{Plant, Reading};
use super::methods::{Argument as Arg, Kind, Method, Target};
use super::values::{data_type_id, variant, wall_now_ns, wall_time};
use super::writes::OutputTarget;
use crate::master::axes::Cia402State;
use crate::master::image::{Image, read_bits};
use crate::master::value::Value;
use crate::master::{EcatState, Master, SlaveSummary, Snapshot, al_status_text};
use ecmxf_devices::od::ObjectDictionary;

/// The fastest a value changes for a client: the sampler's tick.
const SAMPLING_MS: f64 = super::manager::SAMPLING_FLOOR_MS;

/// What slaves last reported of their AL state since the network came up
/// (AL status events), by ring position.
pub(super) type AlStates = Mutex<BTreeMap<u8, (EcatState, u16)>>;

/// The node ids of the daemon's namespace.
pub(super) struct Ids {
    ns: u16,
}

impl Ids {
    pub(super) fn new(ns: u16) -> Self {
        Self { ns }
    }
    /// The namespace's index.
    pub(super) fn ns(&self) -> u16 {
        self.ns
    }
    fn id(&self, s: &str) -> NodeId {
        NodeId::new(self.ns, s.to_string())
    }
    /// A browse name in the daemon's namespace.
    fn browse(&self, name: &str) -> QualifiedName {
        QualifiedName::new(self.ns, name)
    }
    /// `Objects/EtherCAT`.
    pub(super) fn master(&self) -> NodeId {
        self.id("EtherCAT")
    }
    fn slaves(&self) -> NodeId {
        self.id("EtherCAT.Slaves")
    }
    pub(super) fn slave(&self, p: u8) -> NodeId {
        self.id(&format!("EtherCAT.Slaves.{p}"))
    }
}

/// The parts that live as long as the server: the master object and its
/// diagnostics, the Slaves folder.
pub(super) fn add_master(nm: &Plant, ids: &Ids, master: &Arc<Master>) {
    let mut space = nm.address_space().write();
    let root = ids.master();
    ObjectBuilder::new(&root, ids.browse("EtherCAT"), "EtherCAT")
        .organized_by(NodeId::objects_folder_id())
        .has_type_definition(ObjectTypeId::BaseObjectType)
        // The daemon's events (emergencies, AL status, recoveries...) are
        // notified here; they reach Server subscribers too.
        .event_notifier(EventNotifier::SUBSCRIBE_TO_EVENTS)
        .description("The EtherCAT master (ecmxfd): its state and counters")
        .insert(&mut *space);
    ObjectBuilder::new(&ids.slaves(), ids.browse("Slaves"), "Slaves")
        .is_folder()
        .component_of(root.clone())
        .has_type_definition(ObjectTypeId::FolderType)
        .insert(&mut *space);
    type Reading = fn(&Master, &Snapshot) -> Variant;
    let diagnostics: [(&str, &str, DataTypeId, Reading); 14] = [
        ("Phase", "The engine's phase (bringing up, running, recovering...)", DataTypeId::String, |_, s| {
            Variant::from(s.phase.name())
        }),
        ("State", "The network's EtherCAT state", DataTypeId::String, |_, s| Variant::from(s.ecat_state.to_string())),
        ("Health", "The daemon's verdict on what flows", DataTypeId::String, |m, s| {
            Variant::from(m.verdict(s).health.word())
        }),
        ("ProcessDataFlowing", "Input frames arrive within the flow limit", DataTypeId::Boolean, |m, s| {
            Variant::from(m.verdict(s).flowing())
        }),
        ("CycleTimeUs", "The DC cycle, us", DataTypeId::UInt32, |m, _| Variant::from(m.config().cycle.sync0_us)),
        ("SlaveCount", "Slaves on the ring", DataTypeId::UInt64, |_, s| Variant::from(s.slaves)),
        ("Exchanges", "SPI exchanges with the chip", DataTypeId::UInt64, |_, s| Variant::from(s.exchanges)),
        ("InputFrames", "Input frames received", DataTypeId::UInt64, |_, s| Variant::from(s.input_frames)),
        ("OutputFrames", "Output frames sent", DataTypeId::UInt64, |_, s| Variant::from(s.output_frames)),
        ("CrcErrors", "Packets with bad check words", DataTypeId::UInt64, |_, s| Variant::from(s.crc_errors)),
        ("WkcErrors", "Cycles with a wrong working counter", DataTypeId::UInt64, |_, s| Variant::from(s.wkc_errors)),
        ("FifoAlarms", "RxFIFO underruns and overruns", DataTypeId::UInt64, |_, s| Variant::from(s.fifo_alarms)),
        ("Recoveries", "Network recoveries", DataTypeId::UInt64, |_, s| Variant::from(s.recoveries)),
        ("RxFifoLevel", "Output frames queued in the chip", DataTypeId::Byte, |_, s| Variant::from(s.rx_fifo)),
    ];
    for (name, description, data_type, reading) in diagnostics {
        let id = ids.id(&format!("EtherCAT.{name}"));
        let master = Arc::clone(master);
        let read = Arc::new(move || {
            let s = master.status();
            DataValue::new_now(reading(&master, &s))
        });
        add_live(nm, &mut space, ids, (&root, &id), (name, data_type, description), read);
    }
}

/// A variable `id` named `name`, a component of `parent`, whose value
/// `reading` gives when it is read or sampled.
fn add_live(
    nm: &Plant,
    space: &mut AddressSpace,
    ids: &Ids,
    (parent, id): (&NodeId, &NodeId),
    (name, data_type, description): (&str, DataTypeId, &str),
    reading: Reading,
) {
    VariableBuilder::new(id, ids.browse(name), name)
        .data_type(data_type)
        .description(description)
        .component_of(parent.clone())
        .has_type_definition(VariableTypeId::BaseDataVariableType)
        .minimum_sampling_interval(SAMPLING_MS)
        .insert(&mut *space);
    nm.inner().read_by(id.clone(), reading);
}

/// One slave's object: identity, state, process data.
pub(super) struct SlaveNodes<'a> {
    pub(super) position: u8,
    pub(super) summary: &'a SlaveSummary,
    /// The image its entries come from, if laid out.
    pub(super) image: Option<&'a Arc<Image>>,
}

/// Adds a slave's object and everything under it; returns the ids added
/// (to remove them when the network changes).
pub(super) fn add_slave(
    nm: &Plant,
    space: &mut AddressSpace,
    ids: &Ids,
    master: &Arc<Master>,
    al: &Arc<AlStates>,
    slave: &SlaveNodes,
) -> Vec<NodeId> {
    let mut added = Vec::new();
    let p = slave.position;
    let s = slave.summary;
    let object = ids.slave(p);
    let shown = if s.name.is_empty() { format!("Slave {p}") } else { format!("{p}: {}", s.name) };
    ObjectBuilder::new(&object, ids.browse(&format!("Slave{p}")), shown)
        .component_of(ids.slaves())
        .has_type_definition(ObjectTypeId::BaseObjectType)
        .description(format!("The slave at ring position {p}"))
        .insert(&mut *space);
    added.push(object.clone());
    // Identity: DI's names (strings), and the EtherCAT numbers as numbers.
    let text = |v: String| (DataTypeId::String, Variant::from(v));
    let number = |v: u32| (DataTypeId::UInt32, Variant::from(v));
    let properties: [(&str, (DataTypeId, Variant)); 8] = [
        ("Manufacturer", text(format!("{:#010x}", s.vendor_id))),
        ("Model", text(s.name.clone())),
        ("ProductCode", text(format!("{:#010x}", s.product_code))),
        ("HardwareRevision", text(format!("{:#010x}", s.revision))),
        ("Position", (DataTypeId::UInt16, Variant::from(u16::from(p)))),
        ("VendorId", number(s.vendor_id)),
        ("ProductCodeNumber", number(s.product_code)),
        ("RevisionNumber", number(s.revision)),
    ];
    for (name, (data_type, value)) in properties {
        let id = ids.id(&format!("EtherCAT.Slaves.{p}.{name}"));
        VariableBuilder::new(&id, ids.browse(name), name)
            .data_type(data_type)
            .description(format!("{name} of the slave at position {p}"))
            .value(value)
            .property_of(object.clone())
            .has_type_definition(VariableTypeId::PropertyType)
            .insert(&mut *space);
        added.push(id);
    }
    // State, as the slave last reported it (else the network's).
    let status: [(&str, &str, DataTypeId); 4] = [
        ("EtherCATState", "The state it last reported (else the network's)", DataTypeId::String),
        ("ALStatusCode", "The AL status code it last reported (ETG.1000.6 table 11)", DataTypeId::UInt16),
        ("ALStatusText", "What that AL status code means (ETG.1000.6 table 11)", DataTypeId::String),
        ("DeviceHealth", "DI DeviceHealthEnumeration: 0 NORMAL, 1 FAILURE", DataTypeId::Int32),
    ];
    for (name, description, data_type) in status {
        let id = ids.id(&format!("EtherCAT.Slaves.{p}.{name}"));
        let (master, al) = (Arc::clone(master), Arc::clone(al));
        let read = Arc::new(move || {
            let reported = al.lock().unwrap_or_else(|e| e.into_inner()).get(&p).copied();
            let s = master.status();
            let (state, code) = reported.unwrap_or((s.ecat_state, 0));
            DataValue::new_now(match name {
                "EtherCATState" => Variant::from(state.to_string()),
                "ALStatusCode" => Variant::from(code),
                "ALStatusText" => Variant::from(al_status_text(code).to_string()),
                // DI's DeviceHealthEnumeration: NORMAL (0) while process
                // data flows and the slave reports no error, else
                // FAILURE (1).
                _ => Variant::from(if master.verdict(&s).flowing() && code == 0 { 0i32 } else { 1i32 }),
            })
        });
        add_live(nm, space, ids, (&object, &id), (name, data_type, description), read);
        added.push(id);
    }
    let prefix = format!("EtherCAT.Slaves.{p}");
    add_methods(nm, space, ids, (&object, &prefix), Target::Slave(p), &Kind::SLAVE, &mut added);
    let Some(image) = slave.image else { return added };
    for output in [false, true] {
        let (folder_name, dir) = if output { ("Outputs", "out") } else { ("Inputs", "in") };
        // Outputs are written by operators (the user's own level strips
        // the write for others: `super::access`).
        let level =
            if output { AccessLevel::CURRENT_READ | AccessLevel::CURRENT_WRITE } else { AccessLevel::CURRENT_READ };
        let mine: Vec<usize> = (0..image.entries.len())
            .filter(|&i| image.entries[i].slave == p && image.entries[i].output == output)
            .collect();
        if mine.is_empty() {
            continue;
        }
        let folder = ids.id(&format!("EtherCAT.Slaves.{p}.{folder_name}"));
        ObjectBuilder::new(&folder, ids.browse(folder_name), folder_name)
            .is_folder()
            .component_of(object.clone())
            .has_type_definition(ObjectTypeId::FolderType)
            .insert(&mut *space);
        added.push(folder.clone());
        for i in mine {
            let e = &image.entries[i];
            let id = ids.id(&format!("EtherCAT.Slaves.{p}.{dir}.{}", e.name));
            let shown = if e.label.is_empty() { e.name.clone() } else { e.label.clone() };
            let what = if e.index == 0 {
                format!("{}: bits the description does not cover", e.name)
            } else {
                format!("{} ({:#06x}:{:02x}){}", e.name, e.index, e.subindex, variable_said(&e.variable))
            };
            VariableBuilder::new(&id, ids.browse(&e.name), shown)
                .data_type(data_type_id(e.data_type))
                .component_of(folder.clone())
                .has_type_definition(VariableTypeId::BaseDataVariableType)
                .description(what)
                .access_level(level)
                .user_access_level(level)
                .minimum_sampling_interval(SAMPLING_MS)
                .insert(&mut *space);
            added.push(id.clone());
            if output {
                nm.inner().write_to(id.clone(), OutputTarget::new(Arc::clone(image), i));
            }
            let (master, image) = (Arc::clone(master), Arc::clone(image));
            nm.inner().read_by(id, Arc::new(move || entry_value(&master, &image, i)));
        }
    }
    added
}

/// Adds `kinds` of methods to `object` (node id `prefix`), acting on
/// `target`, with their argument properties; notes their ids in `added`.
fn add_methods(
    nm: &Plant,
    space: &mut AddressSpace,
    ids: &Ids,
    (object, prefix): (&NodeId, &str),
    target: Target,
    kinds: &[Kind],
    added: &mut Vec<NodeId>,
) {
    let args = |list: &[Arg]| -> Vec<Argument> {
        list.iter()
            .map(|(name, t, what)| Argument { description: LocalizedText::from(*what), ..(*name, *t).into() })
            .collect()
    };
    for &kind in kinds {
        let id = ids.id(&format!("{prefix}.{}", kind.name()));
        let name = format!("{prefix}.{}", kind.name());
        let (inputs, outputs) = (ids.id(&format!("{name}.InputArguments")), ids.id(&format!("{name}.OutputArguments")));
        let mut method = MethodBuilder::new(&id, ids.browse(kind.name()), kind.name())
            .component_of(object.clone())
            .description(kind.description())
            .executable(true)
            .user_executable(true);
        if !kind.inputs().is_empty() {
            method = method.input_args(&mut *space, &inputs, &args(kind.inputs()));
            added.push(inputs);
        }
        if !kind.outputs().is_empty() {
            method = method.output_args(&mut *space, &outputs, &args(kind.outputs()));
            added.push(outputs);
        }
        method.insert(&mut *space);
        nm.inner().calls(id.clone(), Method { target, kind });
        added.push(id);
    }
}

/// The `[[axis]]` entries under `EtherCAT.Axes`: each with its slave, its
/// CiA 402 state and statusword as the newest input frame shows them (no
/// exchange with the chip), and its methods. Returns the ids added.
pub(super) fn add_axes(
    nm: &Plant,
    space: &mut AddressSpace,
    ids: &Ids,
    master: &Arc<Master>,
    slaves: &[SlaveSummary],
) -> Vec<NodeId> {
    let axes = master.with_axes(<[_]>::to_vec);
    let mut added = Vec::new();
    if axes.is_empty() {
        return added;
    }
    let folder = ids.id("EtherCAT.Axes");
    ObjectBuilder::new(&folder, ids.browse("Axes"), "Axes")
        .is_folder()
        .component_of(ids.master())
        .has_type_definition(ObjectTypeId::FolderType)
        .description("The CiA 402 axes of [[axis]], through the chip's helper")
        .insert(&mut *space);
    added.push(folder.clone());
    for (n, a) in axes.iter().enumerate() {
        let object = ids.id(&format!("EtherCAT.Axes.{n}"));
        ObjectBuilder::new(&object, ids.browse(&format!("Axis{n}")), format!("Axis {n} (slave {})", a.slave))
            .component_of(folder.clone())
            .has_type_definition(ObjectTypeId::BaseObjectType)
            .insert(&mut *space);
        added.push(object.clone());
        let slave = ids.id(&format!("EtherCAT.Axes.{n}.Slave"));
        VariableBuilder::new(&slave, ids.browse("Slave"), "Slave")
            .data_type(DataTypeId::UInt16)
            .value(u16::from(a.slave))
            .description("The ring position of its drive")
            .property_of(object.clone())
            .has_type_definition(VariableTypeId::PropertyType)
            .insert(&mut *space);
        added.push(slave);
        // The statusword's byte in the input frame (the nodes are made
        // again when the slaves change).
        let at = slaves.get(usize::from(a.slave)).map(|s| s.tx_offset + usize::from(a.statusword_offset));
        for (name, data_type, what) in [
            ("State", DataTypeId::String, "Its CiA 402 state, decoded from the statusword"),
            ("Statusword", DataTypeId::UInt16, "Its statusword (0x6041) in the newest input frame"),
        ] {
            let id = ids.id(&format!("EtherCAT.Axes.{n}.{name}"));
            let master = Arc::clone(master);
            let read = Arc::new(move || statusword_value(&master, at, name == "State"));
            add_live(nm, space, ids, (&object, &id), (name, data_type, what), read);
            added.push(id);
        }
        let prefix = format!("EtherCAT.Axes.{n}");
        add_methods(nm, space, ids, (&object, &prefix), Target::Axis(n as u32), &Kind::AXIS, &mut added);
    }
    added
}

/// An axis' statusword (or its state, decoded) from the newest input
/// frame at byte `at`, stamped with the frame's time.
fn statusword_value(master: &Master, at: Option<usize>, as_state: bool) -> DataValue {
    let Some(frame) = master.latest_inputs() else {
        return DataValue::new_now_status(Variant::Empty, StatusCode::BadWaitingForInitialData);
    };
    let Some(sw) = at.and_then(|at| frame.data.get(at..at + 2)).map(|b| u16::from_le_bytes([b[0], b[1]])) else {
        return DataValue::new_now_status(Variant::Empty, StatusCode::BadConfigurationError);
    };
    let value = if as_state { Variant::from(Cia402State::from_statusword(sw).to_string()) } else { Variant::from(sw) };
    let at = wall_time(frame.time_ns, master.now_ns(), wall_now_ns());
    let s = master.status();
    let status = if master.verdict(&s).flowing() { StatusCode::Good } else { StatusCode::UncertainLastUsableValue };
    DataValue::new_at_status(value, at, status)
}

fn variable_said(variable: &str) -> String {
    if variable.is_empty() { String::new() } else { format!(", variable {variable}") }
}

/// Entry `i` of `image` as it is now: an input from the newest input frame,
/// stamped with that frame's time (Uncertain once it is older than the
/// flow limit: the value is the last the slave sent, not what it has); an
/// output as front ends last wrote it.
fn entry_value(master: &Master, image: &Image, i: usize) -> DataValue {
    let Some(e) = image.entries.get(i) else {
        return DataValue::new_now_status(Variant::Empty, StatusCode::BadNodeIdUnknown);
    };
    if e.output {
        let raw = read_bits(&master.output_shadow(), e.bit_offset, e.bit_length);
        return DataValue::new_now(variant(e.data_type, Value::decode(e.data_type, &raw)));
    }
    let Some(frame) = master.latest_inputs() else {
        return DataValue::new_now_status(Variant::Empty, StatusCode::BadWaitingForInitialData);
    };
    let raw = read_bits(&frame.data, e.bit_offset, e.bit_length);
    from_frame(master, frame.time_ns, variant(e.data_type, Value::decode(e.data_type, &raw)))
}

/// `value`, read from the input frame of engine time `time_ns`: stamped
/// with that time, Good while process data flows, else the last usable.
fn from_frame(master: &Master, time_ns: u64, value: Variant) -> DataValue {
    let at: DateTime = wall_time(time_ns, master.now_ns(), wall_now_ns());
    let s = master.status();
    let status = if master.verdict(&s).flowing() { StatusCode::Good } else { StatusCode::UncertainLastUsableValue };
    DataValue::new_at_status(value, at, status)
}

/// Adds the Dictionary folder of the slave at `p` with the entries of
/// `od` (see [`super::dictionary`]); returns the ids added.
pub(super) fn add_dictionary(nm: &Plant, ids: &Ids, p: u8, od: &ObjectDictionary) -> Vec<NodeId> {
    let mut space = nm.address_space().write();
    let slave = ids.slave(p);
    if !space.node_exists(&slave) {
        return Vec::new();
    }
    let (added, entries) = super::dictionary::add(&mut space, ids.ns(), &slave, p, od);
    nm.inner().read_from_device(entries);
    added
}

/// Removes what [`add_slave`] added, and what its nodes did.
pub(super) fn remove(nm: &Plant, space: &mut AddressSpace, added: &[NodeId]) {
    for id in added.iter().rev() {
        space.delete(id, true);
    }
    nm.inner().forget(added);
}
