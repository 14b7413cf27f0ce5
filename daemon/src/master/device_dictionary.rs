//! A slave's object dictionary as the slave itself describes it, with the
//! CoE SDO Information service (ETG.1000.6 5.6.3) over the host's mailbox
//! channel (`mailbox_channel.rs`): the list of all objects, then each
//! object's description and each entry's (data type, bit length, access
//! and mapping, default/minimum/maximum and unit where the slave gives
//! them). Fragmented answers are joined; an SDO Info error names its abort
//! code.
//!
//! Read once per identity (vendor, product, revision) and kept: in memory,
//! and as JSON under the state directory (`state_dir`, or systemd's
//! `$STATE_DIRECTORY`), reused across restarts; a device of another
//! revision is another file. The read is the daemon's work, not a
//! caller's: it runs in a task of its own, so a caller whose deadline
//! passes leaves it to finish for the next one.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use ecmxf_devices::od::{Access, DataType, Entry, Mappable, Object, ObjectDictionary, ObjectKind, StateSet};
use ecmxf_wire::mbx::MailboxType;
use ecmxf_wire::mbx::sdo_info::{
    EntryDescription, InfoFragment, InfoRequest, ListType, ObjectAccess, ObjectDescription, OdList, ValueInfo,
};
use ecmxf_wire::payload::sdo::SdoAbortCode;
use serde::{Deserialize, Serialize};
use tokio::sync::watch;

use super::mailbox_channel::{ANSWER_TIMEOUT, MailboxFailure};
use super::{Call, Identity, Master};
use crate::engine::error::EngineError;

/// Leftover answers (to questions given up on) one SDO Information
/// exchange passes over before it calls a wrong answer garbled.
const LEFTOVERS_PASSED_OVER: usize = 2;

/// One entry as the slave describes it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceEntry {
    /// Subindex.
    pub subindex: u8,
    /// Name.
    pub name: String,
    /// ETG.1000.6 data type code.
    pub data_type: u16,
    /// Size in bits.
    pub bit_length: u16,
    /// Access and mapping bits (ETG.1000.6 Table 46).
    pub access: u16,
    /// Unit type, when given.
    #[serde(default)]
    pub unit: Option<u32>,
    /// Default value, when given.
    #[serde(default)]
    pub default: Option<Vec<u8>>,
    /// Minimum, when given.
    #[serde(default)]
    pub minimum: Option<Vec<u8>>,
    /// Maximum, when given.
    #[serde(default)]
    pub maximum: Option<Vec<u8>>,
}

/// One object as the slave describes it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceObject {
    /// Index.
    pub index: u16,
    /// Name.
    pub name: String,
    /// 7 VAR, 8 ARRAY, 9 RECORD.
    pub object_code: u8,
    /// Its data type code (an array's elements'; 0 for a record).
    pub data_type: u16,
    /// Entries that answered, by subindex.
    pub entries: Vec<DeviceEntry>,
}

/// A slave's dictionary as it describes itself.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceDictionary {
    /// (vendor, product, revision).
    pub identity: Identity,
    /// Objects in index order.
    pub objects: Vec<DeviceObject>,
}

/// Why a dictionary could not be read from the device.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DictionaryError {
    /// The slave does not do SDO Information (SII CoE details bit 1).
    NotSupported(u8),
    /// The mailbox exchange failed.
    Mailbox(MailboxFailure),
    /// The slave answered a question with an SDO Info error.
    Aborted {
        /// The question.
        what: String,
        /// Its abort code.
        code: SdoAbortCode,
    },
    /// An answer does not read as SDO Information.
    Garbled(String),
    /// The engine could not do it.
    Engine(EngineError),
}

impl std::fmt::Display for DictionaryError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotSupported(s) => write!(f, "slave {s} does not describe its objects (no SDO Information)"),
            Self::Mailbox(e) => write!(f, "{e}"),
            Self::Aborted { what, code } => write!(f, "{what}: SDO Info error {code}"),
            Self::Garbled(why) => write!(f, "an SDO Information answer does not read: {why}"),
            Self::Engine(e) => write!(f, "{e}"),
        }
    }
}

impl From<EngineError> for DictionaryError {
    fn from(e: EngineError) -> Self {
        Self::Engine(e)
    }
}

type Outcome = Option<Result<Arc<DeviceDictionary>, DictionaryError>>;

/// Dictionaries read or being read, by identity.
#[derive(Debug, Default)]
pub struct DeviceDictionaries {
    reads: Mutex<HashMap<Identity, watch::Receiver<Outcome>>>,
}

fn data_type(code: u16, bits: u16) -> DataType {
    let bits = u32::from(bits);
    match code {
        0x09 => DataType::VisibleString((bits / 8) as u16),
        0x0A => DataType::OctetString((bits / 8) as u16),
        c => DataType::from_code(c, bits).unwrap_or(DataType::OctetString(bits.div_ceil(8) as u16)),
    }
}

impl DeviceDictionary {
    /// The dictionary in the shape device descriptions have (what an ESI
    /// gives), for listings and the value codec.
    pub fn to_od(&self) -> ObjectDictionary {
        let mut od = ObjectDictionary::new();
        for o in &self.objects {
            let kind = match o.object_code {
                8 => ObjectKind::Array,
                9 => ObjectKind::Record,
                _ => ObjectKind::Var,
            };
            let entries = o
                .entries
                .iter()
                .map(|e| {
                    let a = ObjectAccess(e.access);
                    let set = |p, s, op| StateSet { preop: a.has(p), safeop: a.has(s), op: a.has(op) };
                    let access = Access {
                        read: set(ObjectAccess::READ_PREOP, ObjectAccess::READ_SAFEOP, ObjectAccess::READ_OP),
                        write: set(ObjectAccess::WRITE_PREOP, ObjectAccess::WRITE_SAFEOP, ObjectAccess::WRITE_OP),
                    };
                    let mappable = match (a.has(ObjectAccess::RXPDO), a.has(ObjectAccess::TXPDO)) {
                        (true, true) => Mappable::Both,
                        (true, false) => Mappable::Rx,
                        (false, true) => Mappable::Tx,
                        (false, false) => Mappable::No,
                    };
                    let mut entry =
                        Entry::new(&e.name, data_type(e.data_type, e.bit_length), access).mappable(mappable);
                    if let Some(d) = &e.default {
                        entry = entry.default_bytes(d);
                    } else if !entry.dtype.is_fixed_size() {
                        entry.value = vec![0; usize::from(e.bit_length).div_ceil(8)];
                    }
                    (e.subindex, entry)
                })
                .collect();
            od.insert(o.index, Object { name: o.name.clone(), kind, entries });
        }
        od
    }

    /// The description of object `index`, if the device gave one.
    pub fn object(&self, index: u16) -> Option<&DeviceObject> {
        self.objects.binary_search_by_key(&index, |o| o.index).ok().map(|i| &self.objects[i])
    }

    /// The description of `index:subindex`, if the device gave one.
    pub fn entry(&self, index: u16, subindex: u8) -> Option<&DeviceEntry> {
        self.object(index)?.entries.iter().find(|e| e.subindex == subindex)
    }

    /// The type of `index:subindex`, if the device described it.
    pub(crate) fn data_type(&self, index: u16, subindex: u8) -> Option<DataType> {
        self.entry(index, subindex).map(|e| data_type(e.data_type, e.bit_length))
    }
}

fn text(bytes: &[u8]) -> String {
    ecmxf_devices::sii::decode_text(bytes.split(|b| *b == 0).next().unwrap_or(&[]))
}

impl Master {
    /// Where dictionaries read from devices are kept, if anywhere.
    fn dictionary_dir(&self) -> Option<PathBuf> {
        let configured = self.config.lock().unwrap_or_else(|e| e.into_inner()).state_dir.clone();
        configured.or_else(|| std::env::var_os("STATE_DIRECTORY").map(PathBuf::from)).map(|d| d.join("sdo-info"))
    }

    /// The dictionary of the device at `slave` as read before (in memory
    /// or on disk): never a mailbox exchange. For the value codec.
    pub(crate) fn known_device_dictionary(&self, slave: u8) -> Option<Arc<DeviceDictionary>> {
        let identity = self.identity(slave)?;
        let reads = self.dictionaries.reads.lock().unwrap_or_else(|e| e.into_inner());
        match &*reads.get(&identity)?.borrow() {
            Some(Ok(d)) => Some(Arc::clone(d)),
            _ => None,
        }
    }

    /// The dictionary of the device at `slave`, as the device describes it:
    /// from the cache, else read from the device by a task of the daemon's
    /// own that this call waits for. `call`'s deadline ends the wait
    /// ([`EngineError::Timeout`]), never the read, which the next caller
    /// finds done or under way.
    pub async fn device_dictionary(
        self: &Arc<Self>,
        slave: u8,
        call: Call,
    ) -> Result<Arc<DeviceDictionary>, DictionaryError> {
        self.check_slave(slave, "slave").map_err(DictionaryError::Engine)?;
        let identity = self.identity(slave).ok_or_else(|| {
            DictionaryError::Engine(EngineError::BadArgument {
                field: "slave",
                reason: format!("slave {slave} does not exist"),
            })
        })?;
        let mut rx = {
            let mut reads = self.dictionaries.reads.lock().unwrap_or_else(|e| e.into_inner());
            // A failed read is tried again by the next caller; a device
            // that does not do SDO Information is not asked again.
            let retry = reads.get(&identity).is_some_and(
                |r| matches!(&*r.borrow(), Some(Err(e)) if !matches!(e, DictionaryError::NotSupported(_))),
            );
            match reads.get(&identity) {
                Some(rx) if !retry => rx.clone(),
                _ => {
                    let (tx, rx) = watch::channel(None);
                    reads.insert(identity, rx.clone());
                    let master = Arc::clone(self);
                    tokio::spawn(async move {
                        let started = std::time::Instant::now();
                        // No caller's: the read outlives the call that
                        // started it, each request with the default time.
                        let reader = Call::anonymous(None);
                        let outcome = master.load_device_dictionary(slave, identity, reader).await.map(Arc::new);
                        match &outcome {
                            Ok(d) => tracing::info!(
                                slave,
                                objects = d.objects.len(),
                                ms = started.elapsed().as_millis() as u64,
                                "object dictionary read from the device"
                            ),
                            Err(e) => tracing::warn!(slave, "object dictionary not read from the device: {e}"),
                        }
                        tx.send_replace(Some(outcome));
                    });
                    rx
                }
            }
        };
        let outcome = async {
            let done = rx.wait_for(Option::is_some).await.map_err(|_| {
                DictionaryError::Engine(EngineError::Unavailable(crate::engine::error::NotRunning::Stopped))
            })?;
            done.clone().unwrap_or_else(|| Err(DictionaryError::Garbled("no outcome".into())))
        };
        match call.deadline {
            None => outcome.await,
            Some(end) => tokio::time::timeout_at(end.into(), outcome)
                .await
                .unwrap_or(Err(DictionaryError::Engine(EngineError::Timeout))),
        }
    }

    /// The dictionary of the device at `slave` as read before, in memory
    /// or kept on disk: never a mailbox exchange.
    pub(crate) fn kept_device_dictionary(&self, slave: u8) -> Option<Arc<DeviceDictionary>> {
        self.known_device_dictionary(slave).or_else(|| self.dictionary_on_disk(self.identity(slave)?).map(Arc::new))
    }

    /// Where the dictionary of a device is kept, if anywhere.
    fn dictionary_file(&self, identity: Identity) -> Option<PathBuf> {
        let (vendor, product, revision) = identity;
        self.dictionary_dir().map(|d| d.join(format!("{vendor:08x}-{product:08x}-{revision:08x}.json")))
    }

    /// The dictionary kept on disk for a device, if one is and reads.
    fn dictionary_on_disk(&self, identity: Identity) -> Option<DeviceDictionary> {
        let f = self.dictionary_file(identity)?;
        let text = std::fs::read_to_string(&f).ok()?;
        match serde_json::from_str::<DeviceDictionary>(&text) {
            Ok(d) if d.identity == identity => Some(d),
            _ => {
                tracing::warn!(file = %f.display(), "a kept object dictionary does not read; reading it again");
                None
            }
        }
    }

    /// From disk when kept there, else from the device (then kept).
    async fn load_device_dictionary(
        &self,
        slave: u8,
        identity: Identity,
        call: Call,
    ) -> Result<DeviceDictionary, DictionaryError> {
        if let Some(d) = self.dictionary_on_disk(identity) {
            return Ok(d);
        }
        let file = self.dictionary_file(identity);
        let d = self.read_device_dictionary(slave, identity, call).await?;
        if let Some(f) = &file {
            let kept = f
                .parent()
                .map_or(Ok(()), std::fs::create_dir_all)
                .and_then(|()| serde_json::to_vec(&d).map_err(std::io::Error::other))
                .and_then(|bytes| {
                    let tmp = f.with_extension("json.tmp");
                    std::fs::write(&tmp, bytes)?;
                    std::fs::rename(&tmp, f)
                });
            if let Err(e) = kept {
                tracing::warn!(file = %f.display(), "the object dictionary read is not kept on disk: {e}");
            }
        }
        Ok(d)
    }

    /// Whether the slave says (SII General, CoE details bit 1) that it
    /// answers SDO Information.
    pub(crate) async fn supports_sdo_info(&self, slave: u8, call: Call) -> Result<bool, EngineError> {
        let general = super::sii::Categories::Only(&[ecmxf_devices::sii::category::GENERAL]);
        let sii = self.sii(slave, general, call).await?;
        Ok(sii.general.is_some_and(|g| g.coe_details & 0x02 != 0))
    }

    async fn read_device_dictionary(
        &self,
        slave: u8,
        identity: Identity,
        call: Call,
    ) -> Result<DeviceDictionary, DictionaryError> {
        if !self.supports_sdo_info(slave, call).await? {
            return Err(DictionaryError::NotSupported(slave));
        }
        let payload = self.sdo_info(slave, InfoRequest::OdList(ListType::All), "the object list", call).await?;
        let list = OdList::decode(&payload).map_err(|e| DictionaryError::Garbled(e.to_string()))?;
        let mut indices: Vec<u16> = list.indices().collect();
        indices.sort_unstable();
        indices.dedup();
        let mut objects = Vec::with_capacity(indices.len());
        for index in indices {
            let what = format!("object {index:#06x}");
            let payload = self.sdo_info(slave, InfoRequest::Object { index }, &what, call).await?;
            let o = ObjectDescription::decode(&payload).map_err(|e| DictionaryError::Garbled(e.to_string()))?;
            let subs = if o.object_code == 7 { 0..=0 } else { 0..=o.max_subindex };
            let mut entries = Vec::new();
            for subindex in subs {
                let ask = InfoRequest::Entry { index, subindex, value_info: ValueInfo::ALL };
                let what = format!("entry {index:#06x}:{subindex:02x}");
                let payload = match self.sdo_info(slave, ask, &what, call).await {
                    // A record may skip subindices.
                    Err(DictionaryError::Aborted { code, .. }) if code == SdoAbortCode::SUBINDEX_MISSING => continue,
                    other => other?,
                };
                let e = EntryDescription::decode(&payload).map_err(|e| DictionaryError::Garbled(e.to_string()))?;
                entries.push(DeviceEntry {
                    subindex,
                    name: text(e.name),
                    data_type: e.data_type,
                    bit_length: e.bit_length,
                    access: e.access.0,
                    unit: e.unit,
                    default: e.default.map(<[u8]>::to_vec),
                    minimum: e.minimum.map(<[u8]>::to_vec),
                    maximum: e.maximum.map(<[u8]>::to_vec),
                });
            }
            objects.push(DeviceObject {
                index,
                name: text(o.name),
                object_code: o.object_code,
                data_type: o.data_type,
                entries,
            });
        }
        Ok(DeviceDictionary { identity, objects })
    }

    /// The device's name for object `index` (Get Object Description):
    /// one SDO Information exchange, no whole dictionary. For naming PDOs.
    pub(crate) async fn described_object_name(
        &self,
        slave: u8,
        index: u16,
        call: Call,
    ) -> Result<String, DictionaryError> {
        let what = format!("object {index:#06x}");
        let payload = self.sdo_info(slave, InfoRequest::Object { index }, &what, call).await?;
        let o = ObjectDescription::decode(&payload).map_err(|e| DictionaryError::Garbled(e.to_string()))?;
        Ok(text(o.name))
    }

    /// The device's name for entry `index:subindex` (Get Entry Description
    /// without value information): one SDO Information exchange. For
    /// naming mapped entries.
    pub(crate) async fn described_entry_name(
        &self,
        slave: u8,
        index: u16,
        subindex: u8,
        call: Call,
    ) -> Result<String, DictionaryError> {
        let ask = InfoRequest::Entry { index, subindex, value_info: ValueInfo(0) };
        let what = format!("entry {index:#06x}:{subindex:02x}");
        let payload = self.sdo_info(slave, ask, &what, call).await?;
        let e = EntryDescription::decode(&payload).map_err(|e| DictionaryError::Garbled(e.to_string()))?;
        Ok(text(e.name))
    }

    /// One SDO Information question and its whole answer (fragments
    /// joined), under the slave's mailbox lock.
    async fn sdo_info(
        &self,
        slave: u8,
        request: InfoRequest,
        what: &str,
        call: Call,
    ) -> Result<Vec<u8>, DictionaryError> {
        let mut body = [0u8; 16];
        let n = request.encode(&mut body).map_err(|e| DictionaryError::Garbled(e.to_string()))?;
        let want = request.answer_opcode();
        let _lock = self.mailbox_lock(slave).await;
        let mut answer = self.mailbox_exchange(slave, MailboxType::Coe, &body[..n], ANSWER_TIMEOUT, call).await?;
        let mut joined = Vec::new();
        let mut expected_left: Option<u16> = None;
        let mut passed_over = 0;
        loop {
            let (_, message) = answer.map_err(DictionaryError::Mailbox)?;
            let f = InfoFragment::decode(&message).map_err(|e| DictionaryError::Garbled(format!("{what}: {e}")))?;
            if let Some(code) = f.abort_code() {
                return Err(DictionaryError::Aborted { what: what.to_string(), code: SdoAbortCode(code) });
            }
            // An answer to another question, left in the mailbox by an
            // exchange given up on (a deadline, a re-init meanwhile): its
            // own answer follows it. Passed over, a few at most: one
            // leftover must not make every later answer one behind.
            if f.header.opcode != want && expected_left.is_none() && passed_over < LEFTOVERS_PASSED_OVER {
                tracing::debug!(
                    slave,
                    opcode = f.header.opcode.code(),
                    "{what}: a leftover SDO Information answer passed over"
                );
                passed_over += 1;
                answer = self.mailbox_next(slave, ANSWER_TIMEOUT, call).await?;
                continue;
            }
            if f.header.opcode != want {
                return Err(DictionaryError::Garbled(format!("{what}: opcode {} answers it", f.header.opcode.code())));
            }
            if expected_left.is_some_and(|left| f.header.fragments_left + 1 != left) {
                return Err(DictionaryError::Garbled(format!("{what}: a fragment is missing")));
            }
            joined.extend_from_slice(f.payload);
            if !f.header.incomplete {
                return Ok(joined);
            }
            expected_left = Some(f.header.fragments_left);
            answer = self.mailbox_next(slave, ANSWER_TIMEOUT, call).await?;
        }
    }
}
