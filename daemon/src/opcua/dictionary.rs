//! Each slave's object dictionary as variables (docs/opcua.md,
//! "Dictionary"): `EtherCAT.Slaves.<P>.Dictionary`, one variable per
//! entry the daemon knows of the device (its own description of itself,
//! read for naming, by `ecmxfctl objects`, or kept on disk: listing it
//! costs the device nothing).
//!
//! A dictionary variable is read from the device: a Read with MaxAge 0
//! (what most clients send) is an SDO upload now; a larger MaxAge takes
//! the value last uploaded while it is that young. A write by an operator
//! is an SDO download of the entry's type. They are not sampled: a
//! monitored item gets the value read when it is created (process data
//! flows through the Inputs and Outputs folders).

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use opcua::server::address_space::{AccessLevel, AddressSpace, ObjectBuilder, VariableBuilder};
use opcua::types::{DataTypeId, DataValue, NodeId, ObjectTypeId, StatusCode, VariableTypeId, Variant};

use super::refusal::Refusal;
use super::values::{data_type_id, encode, variant};
use crate::master::value::{DataType, Value, type_name};
use crate::master::{Call, EngineError, Master};
use ecmxf_devices::od::ObjectDictionary;

/// How long an upload or a download may take.
const TRANSFER_WITHIN: Duration = Duration::from_secs(5);

/// A dictionary entry's variable: what it reads and writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct DictionaryEntry {
    slave: u8,
    index: u16,
    subindex: u8,
    data_type: DataType,
    /// Shown as text (a DI property, which is a String), whatever its type.
    as_text: bool,
}

impl DictionaryEntry {
    /// Its bits, as an SDO carries them (whole bytes).
    fn bits(&self) -> u32 {
        self.data_type.bits().max(8)
    }
}

/// The values uploaded last, by node: what a Read with a MaxAge takes.
#[derive(Default)]
pub(super) struct Uploaded(Mutex<HashMap<NodeId, (Instant, DataValue)>>);

impl Uploaded {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<NodeId, (Instant, DataValue)>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The value uploaded for `id` at most `max_age` ago.
    pub(super) fn within(&self, id: &NodeId, max_age: Duration) -> Option<DataValue> {
        self.lock().get(id).filter(|(at, _)| at.elapsed() <= max_age).map(|(_, v)| v.clone())
    }

    /// Keeps `value`, uploaded now for `id`.
    pub(super) fn store(&self, id: NodeId, value: DataValue) {
        self.lock().insert(id, (Instant::now(), value));
    }

    /// Forgets the values of nodes removed.
    pub(super) fn forget(&self, ids: &[NodeId]) {
        let mut held = self.lock();
        for id in ids {
            held.remove(id);
        }
    }
}

/// Adds the Dictionary folder of the slave at `p` (object `slave`) with
/// `od`'s entries; returns the ids added and what each variable is.
pub(super) fn add(
    space: &mut AddressSpace,
    ns: u16,
    slave: &NodeId,
    p: u8,
    od: &ObjectDictionary,
) -> (Vec<NodeId>, Vec<(NodeId, DictionaryEntry)>) {
    let id = |s: String| NodeId::new(ns, s);
    let browse = |s: &str| opcua::types::QualifiedName::new(ns, s);
    let mut added = Vec::new();
    let mut entries = Vec::new();
    let folder = id(format!("EtherCAT.Slaves.{p}.Dictionary"));
    ObjectBuilder::new(&folder, browse("Dictionary"), "Dictionary")
        .is_folder()
        .component_of(slave.clone())
        .has_type_definition(ObjectTypeId::FolderType)
        .description(
            "The device's object dictionary: each entry read (MaxAge 0: an SDO upload now) and written (operator)",
        )
        .insert(&mut *space);
    added.push(folder.clone());
    for (index, object) in od.objects() {
        // One entry: the variable is the object; more: an object holding
        // them.
        let single = object.entries.len() == 1 && object.entries.contains_key(&0);
        let parent = if single {
            folder.clone()
        } else {
            let o = id(format!("EtherCAT.Slaves.{p}.od.{index:#06x}"));
            ObjectBuilder::new(&o, browse(&format!("{index:#06x}")), format!("{index:#06x} {}", object.name))
                .component_of(folder.clone())
                .has_type_definition(ObjectTypeId::BaseObjectType)
                .insert(&mut *space);
            added.push(o.clone());
            o
        };
        for (&sub, e) in &object.entries {
            let v = id(format!("EtherCAT.Slaves.{p}.od.{index:#06x}:{sub:02x}"));
            let name = if single { object.name.as_str() } else { e.name.as_str() };
            let mut level = AccessLevel::empty();
            let readable = e.access.read.preop || e.access.read.safeop || e.access.read.op;
            let writable = e.access.write.preop || e.access.write.safeop || e.access.write.op;
            if readable {
                level |= AccessLevel::CURRENT_READ;
            }
            if writable {
                level |= AccessLevel::CURRENT_WRITE;
            }
            VariableBuilder::new(
                &v,
                browse(&format!("{index:#06x}:{sub:02x}")),
                format!("{index:#06x}:{sub:02x} {name}"),
            )
            .data_type(data_type_id(e.dtype))
            .description(format!("{} {name}: {}", type_name(e.dtype), said_access(readable, writable)))
            .component_of(parent.clone())
            .has_type_definition(VariableTypeId::BaseDataVariableType)
            .access_level(level)
            .user_access_level(level)
            .insert(&mut *space);
            added.push(v.clone());
            entries.push((v, DictionaryEntry { slave: p, index, subindex: sub, data_type: e.dtype, as_text: false }));
        }
    }
    // DI's SerialNumber and SoftwareRevision (OPC 10000-100 4.5) are what
    // CiA 301 keeps in 0x1018:04 and 0x100A: read from the device as the
    // entries are, shown as the text DI types them with.
    let identity = [
        ("SerialNumber", 0x1018, 4, "its serial number (CiA 301 0x1018:04, read from the device)"),
        ("SoftwareRevision", 0x100A, 0, "its software version (CiA 301 0x100A, read from the device)"),
    ];
    for (name, index, sub, said) in identity {
        let Some(e) = od.entry(index, sub) else { continue };
        let v = id(format!("EtherCAT.Slaves.{p}.{name}"));
        VariableBuilder::new(&v, browse(name), name)
            .data_type(DataTypeId::String)
            .description(format!("The slave's {said}"))
            .property_of(slave.clone())
            .has_type_definition(VariableTypeId::PropertyType)
            .access_level(AccessLevel::CURRENT_READ)
            .user_access_level(AccessLevel::CURRENT_READ)
            .insert(&mut *space);
        added.push(v.clone());
        entries.push((v, DictionaryEntry { slave: p, index, subindex: sub, data_type: e.dtype, as_text: true }));
    }
    (added, entries)
}

fn said_access(readable: bool, writable: bool) -> &'static str {
    match (readable, writable) {
        (true, true) => "read and written over SDO",
        (true, false) => "read over SDO",
        (false, true) => "written over SDO",
        (false, false) => "not accessible",
    }
}

/// Uploads `entry` now for the session's `client`, as a value of its type.
pub(super) async fn upload(master: &Master, entry: DictionaryEntry, client: u64) -> DataValue {
    let call = Call::new(client, None).or_within(TRANSFER_WITHIN);
    let e = entry;
    match master.sdo_read(e.slave, e.index, e.subindex, false, call).await {
        Ok(raw) => {
            let value = Value::decode(e.data_type, &raw);
            DataValue::new_now(if e.as_text { Variant::from(text_of(value)) } else { variant(e.data_type, value) })
        }
        Err(err) => {
            tracing::debug!(
                slave = e.slave,
                object = format_args!("{:#06x}:{:02x}", e.index, e.subindex),
                "OPC UA read: {err}"
            );
            DataValue::new_now_status(Variant::Empty, status_of(&err))
        }
    }
}

/// A value as a DI property's text: numbers in decimal, bytes in hex.
fn text_of(value: Value) -> String {
    match value {
        Value::Bool(b) => b.to_string(),
        Value::Int(i) => i.to_string(),
        Value::UInt(u) => u.to_string(),
        Value::Real(f) => f.to_string(),
        Value::Text(s) => s,
        Value::Bytes(b) => b.iter().map(|x| format!("{x:02x}")).collect(),
    }
}

/// Downloads `value` to `entry` (the manager checked the user may write).
pub(super) async fn download(
    master: &Master,
    entry: DictionaryEntry,
    client: u64,
    value: &DataValue,
) -> Result<(), Refusal> {
    let e = entry;
    let v = value.value.as_ref().ok_or_else(|| Refusal::new(StatusCode::BadNothingToDo, "no value given"))?;
    let bytes = encode(e.data_type, e.bits(), v).map_err(|why| {
        Refusal::new(
            StatusCode::BadOutOfRange,
            format!("{:#06x}:{:02x} of slave {} is {}: {why}", e.index, e.subindex, e.slave, type_name(e.data_type)),
        )
    })?;
    let call = Call::new(client, None).or_within(TRANSFER_WITHIN);
    master
        .sdo_write(e.slave, e.index, e.subindex, false, bytes, call)
        .await
        .map_err(|err| Refusal::new(status_of(&err), err.to_string()))
}

/// An SDO transfer's failure as a status code.
fn status_of(e: &EngineError) -> StatusCode {
    match e {
        EngineError::Timeout => StatusCode::BadTimeout,
        EngineError::QueueFull => StatusCode::BadTooManyOperations,
        // The device refused: its abort code says why (in the log).
        EngineError::SdoAbort { .. } => StatusCode::BadDeviceFailure,
        _ => StatusCode::BadCommunicationError,
    }
}
