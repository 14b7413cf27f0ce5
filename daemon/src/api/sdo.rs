//! `Sdo` service: typed uploads and downloads, and the object listing.

use std::sync::Arc;

use ecmxf_proto::v1 as pb;
use ecmxf_proto::v1::sdo_server::Sdo as SdoApi;
use tonic::{Request, Response, Status};

use super::Context;
use super::auth::Role;
use super::bounded;
use super::convert::{
    data_type, decode_value, domain_value, encode_known, encode_value, index, pb_type, subindex, type_size,
};
use super::status::{bad_argument, to_status};
use crate::master::Master;
use crate::master::objects::{KNOWN, axis_index, lookup};
use crate::master::value::type_name;
use crate::master::{Call, EngineError};

/// The `Sdo` service.
#[derive(Debug, Clone)]
pub(crate) struct SdoService(pub Arc<Context>);

/// The type to use for an object: the caller's, else the one the device
/// described (SDO Information, when read before), else the standard one.
fn effective_type(
    m: &Master,
    slave: u8,
    asked: pb::DataType,
    index: u16,
    subindex: u8,
    complete: bool,
) -> pb::DataType {
    if asked != pb::DataType::Unspecified || complete {
        return asked;
    }
    if let Some(t) = m.known_device_dictionary(slave).and_then(|d| d.data_type(index, subindex)) {
        return pb_type(t);
    }
    lookup(index, subindex).map_or(pb::DataType::Unspecified, |(k, _)| pb_type(k.data_type))
}

/// Complete access transfers an object from subindex 0 or 1 on
/// (ETG.1000.6, the SDO services' Complete Access flag): any other start
/// is refused before anything is sent.
fn complete_access_start(complete: bool, subindex: u8) -> Result<(), Status> {
    if complete && subindex > 1 {
        return Err(bad_argument(
            "subindex",
            format!("complete access starts at subindex 0 or 1, not {subindex} ({subindex:#04x})"),
        ));
    }
    Ok(())
}

#[tonic::async_trait]
impl SdoApi for SdoService {
    async fn upload(&self, request: Request<pb::SdoUploadRequest>) -> Result<Response<pb::SdoUploadResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let r = request.get_ref();
        let (s, i, sub) = (self.0.slave(r.slave)?, index(r.index)?, subindex(r.subindex)?);
        complete_access_start(r.complete_access, sub)?;
        let t = effective_type(&self.0.master, s, data_type(r.data_type)?, i, sub, r.complete_access);
        let started = std::time::Instant::now();
        let raw = bounded(&caller, self.0.master.sdo_read(s, i, sub, r.complete_access, caller.call)).await;
        self.0.sdo_latency.observe(started.elapsed());
        let raw = raw?;
        // A type narrower than the object would show part of it as if it
        // were the value (0x3716 read as int8 shows 22): refused, naming
        // both sizes. Complete access reads several subindices on purpose.
        if let Some(n) = type_size(t).filter(|n| r.data_type != 0 && !r.complete_access && raw.len() > *n) {
            return Err(super::status::bad_argument(
                "data_type",
                format!(
                    "object {i:#06x}:{sub:02x} of slave {s} holds {} bytes; {} is {n} byte{}",
                    raw.len(),
                    t.as_str_name(),
                    if n == 1 { "" } else { "s" }
                ),
            ));
        }
        let value = decode_value(t, &raw)
            .map_err(|e| Status::invalid_argument(format!("data_type: object {i:#06x}:{sub:02x} of slave {s}: {e}")))?;
        Ok(Response::new(pb::SdoUploadResponse { raw, value, data_type: t as i32 }))
    }

    async fn download(
        &self,
        request: Request<pb::SdoDownloadRequest>,
    ) -> Result<Response<pb::SdoDownloadResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let r = request.get_ref();
        let (s, i, sub) = (self.0.slave(r.slave)?, index(r.index)?, subindex(r.subindex)?);
        complete_access_start(r.complete_access, sub)?;
        let asked = data_type(r.data_type)?;
        let value = r.value.as_ref().ok_or_else(|| bad_argument("value", "no value given"))?;
        // Where the object's type is known, the value must be one of it:
        // nothing else is sent (a slave takes a boolean's 1 for a UDINT's
        // value). Complete access writes several subindices, as given.
        let known = if r.complete_access { None } else { self.0.master.object_type(s, i, sub).await };
        let bytes = match known {
            Some(k) => encode_known(asked, k, value).map_err(|(field, reason)| {
                let given = value.kind.as_ref().map(|k| domain_value(k).shown()).unwrap_or_default();
                let t = type_name(k);
                bad_argument(field, format!("object {i:#06x}:{sub:02x} of slave {s} is {t}, given {given}: {reason}"))
            })?,
            None => encode_value(asked, value)?,
        };
        let n = bytes.len() as u32;
        tracing::debug!(who = %caller.who, slave = s, object = format_args!("{i:#06x}:{sub:02x}"), "SDO download");
        let started = std::time::Instant::now();
        let done = bounded(&caller, self.0.master.sdo_write(s, i, sub, r.complete_access, bytes, caller.call)).await;
        self.0.sdo_latency.observe(started.elapsed());
        done?;
        Ok(Response::new(pb::SdoDownloadResponse { bytes_written: n }))
    }

    async fn list_objects(
        &self,
        request: Request<pb::ListObjectsRequest>,
    ) -> Result<Response<pb::ListObjectsResponse>, Status> {
        use pb::DictionarySource as Source;
        let caller = self.0.authorize(&request, Role::Observer)?;
        let r = request.get_ref();
        let s = self.0.slave(r.slave)?;
        let only = Source::try_from(r.source)
            .map_err(|_| super::status::bad_argument("source", format!("{} is no DictionarySource", r.source)))?;
        if usize::from(s) >= self.0.master.layout().slaves.len() {
            return Err(super::status::bad_argument("slave", format!("slave {s} does not exist")));
        }
        let wants = |source: Source| only == Source::Unspecified || only == source;
        let mut notes = Vec::new();
        if wants(Source::Device) {
            // The read is the daemon's work: a caller whose deadline passes
            // leaves it running for the next one.
            let read =
                bounded(&caller, async { Ok::<_, Status>(self.0.master.device_dictionary(s, caller.call).await) })
                    .await?;
            match read {
                Ok(d) => {
                    let entries = dictionary_objects(&d.to_od(), Some(&d));
                    let source = Source::Device as i32;
                    return Ok(Response::new(pb::ListObjectsResponse { source, entries, note: String::new() }));
                }
                Err(e) if only == Source::Device => return Err(dictionary_status(e)),
                Err(e) => notes.push(e.to_string()),
            }
        }
        // An ESI without a `<Dictionary>` (older files, e.g. NI 9144) says
        // nothing of the objects: the slave is probed as without one.
        if wants(Source::Esi) {
            match self.0.master.esi_device(s).await {
                Some(Ok(esi)) if esi.device().dictionary.objects().next().is_some() => {
                    let entries = dictionary_objects(&esi.device().dictionary, None);
                    let (source, note) = (Source::Esi as i32, notes.join("; "));
                    return Ok(Response::new(pb::ListObjectsResponse { source, entries, note }));
                }
                Some(Err(e)) if only == Source::Esi => return Err(Status::failed_precondition(e.to_string())),
                Some(Err(e)) => notes.push(e.to_string()),
                Some(Ok(_)) => notes.push(format!("slave {s}'s ESI has no Dictionary")),
                None => notes.push(format!("no ESI configured for slave {s}")),
            }
            if only == Source::Esi {
                return Err(Status::failed_precondition(notes.join("; ")));
            }
        }
        let entries = bounded(&caller, probe(&self.0.master, s, caller.call)).await?;
        let note = notes.join("; ");
        Ok(Response::new(pb::ListObjectsResponse { source: Source::Probe as i32, entries, note }))
    }
}

/// An entry's minimum or maximum: as the device described it, else from
/// the description's range (little-endian, the entry's size).
fn limit(
    described: Option<&crate::master::device_dictionary::DeviceDictionary>,
    index: u16,
    sub: u8,
    e: &ecmxf_devices::od::Entry,
    given: impl Fn(&crate::master::device_dictionary::DeviceEntry) -> Option<&Vec<u8>>,
    end: impl Fn((i64, i64)) -> i64,
) -> Vec<u8> {
    if let Some(d) = described {
        return d.entry(index, sub).and_then(given).cloned().unwrap_or_default();
    }
    let n = e.dtype.bytes().min(8);
    e.range.map(|r| end(r).to_le_bytes()[..n].to_vec()).unwrap_or_default()
}

/// A dictionary that could not be read from the device, as a status.
fn dictionary_status(e: crate::master::device_dictionary::DictionaryError) -> Status {
    use crate::master::device_dictionary::DictionaryError as D;
    match e {
        D::Engine(e) => to_status(e),
        D::NotSupported(_) => Status::failed_precondition(e.to_string()),
        D::Mailbox(_) | D::Aborted { .. } | D::Garbled(_) => Status::unavailable(e.to_string()),
    }
}

/// Uploads `index:subindex`; `None` when the slave aborts (the object is
/// not there), other errors pass.
async fn try_read(m: &Master, s: u8, index: u16, subindex: u8, call: Call) -> Result<Option<Vec<u8>>, Status> {
    match m.sdo_read(s, index, subindex, false, call).await {
        Ok(v) => Ok(Some(v)),
        Err(EngineError::SdoAbort { .. }) => Ok(None),
        Err(e) => Err(to_status(e)),
    }
}

fn entry(
    index: u16,
    subindex: u8,
    name: String,
    t: pb::DataType,
    bits: u32,
    access: &str,
    value: Vec<u8>,
) -> pb::ObjectEntry {
    pb::ObjectEntry {
        index: index.into(),
        subindex: subindex.into(),
        name,
        data_type: t as i32,
        bit_length: bits,
        access: access.into(),
        pdo_mappable: (0x6000..0xA000).contains(&index),
        value,
        ..pb::ObjectEntry::default()
    }
}

/// A known object's size in bits: its type's, or for a string what the
/// slave answered.
fn known_bits(t: ecmxf_devices::od::DataType, value: &[u8]) -> u32 {
    use ecmxf_devices::od::DataType as D;
    match t {
        D::VisibleString(_) | D::OctetString(_) => (value.len() * 8) as u32,
        t => t.bits(),
    }
}

/// Lists the standard objects a slave answers: CiA 301 identity and
/// communication objects, the PDO assignment and every assigned PDO's
/// mapping, and the CiA 402 objects of each axis found (axis n exists when
/// its statusword does).
async fn probe(m: &Master, s: u8, call: Call) -> Result<Vec<pb::ObjectEntry>, Status> {
    let mut out = Vec::new();
    for k in KNOWN.iter().filter(|k| !k.per_axis) {
        if let Some(v) = try_read(m, s, k.index, k.subindex, call).await? {
            let bits = known_bits(k.data_type, &v);
            out.push(entry(k.index, k.subindex, k.name.into(), pb_type(k.data_type), bits, k.access, v));
        }
    }
    for assign in [0x1C12u16, 0x1C13] {
        let Some(count) = try_read(m, s, assign, 0, call).await? else { continue };
        for sub in 1..=count.first().copied().unwrap_or(0) {
            let Some(pdo) = try_read(m, s, assign, sub, call).await? else { continue };
            let pdo_index = u16::from_le_bytes([pdo[0], *pdo.get(1).unwrap_or(&0)]);
            let name = format!("{}.{sub}", if assign == 0x1C12 { "rx_pdo_assign" } else { "tx_pdo_assign" });
            out.push(entry(assign, sub, name, pb::DataType::Unsigned16, 16, "rw", pdo.clone()));
            let Some(n) = try_read(m, s, pdo_index, 0, call).await? else { continue };
            out.push(entry(
                pdo_index,
                0,
                format!("pdo_{pdo_index:#06x}.count"),
                pb::DataType::Unsigned8,
                8,
                "rw",
                n.clone(),
            ));
            for e in 1..=n.first().copied().unwrap_or(0) {
                if let Some(v) = try_read(m, s, pdo_index, e, call).await? {
                    let name = format!("pdo_{pdo_index:#06x}.entry{e}");
                    out.push(entry(pdo_index, e, name, pb::DataType::Unsigned32, 32, "rw", v));
                }
            }
        }
    }
    for axis in 0..8u8 {
        if try_read(m, s, axis_index(0x6041, axis), 0, call).await?.is_none() {
            break;
        }
        for k in KNOWN.iter().filter(|k| k.per_axis) {
            let i = axis_index(k.index, axis);
            if let Some(v) = try_read(m, s, i, 0, call).await? {
                let bits = known_bits(k.data_type, &v);
                let name = if axis == 0 { k.name.to_string() } else { format!("axis{axis}.{}", k.name) };
                out.push(entry(i, 0, name, pb_type(k.data_type), bits, k.access, v));
            }
        }
    }
    Ok(out)
}

/// A dictionary's entries as listed: an ESI device's, or a device's own
/// (`described`: its minimum, maximum and unit where it gave them).
fn dictionary_objects(
    dictionary: &ecmxf_devices::od::ObjectDictionary,
    described: Option<&crate::master::device_dictionary::DeviceDictionary>,
) -> Vec<pb::ObjectEntry> {
    let mut out = Vec::new();
    for (index, object) in dictionary.objects() {
        for (sub, e) in &object.entries {
            let read = e.access.read.preop || e.access.read.safeop || e.access.read.op;
            let write = e.access.write.preop || e.access.write.safeop || e.access.write.op;
            let access = match (read, write) {
                (true, true) => "rw",
                (true, false) => "ro",
                (false, true) => "wo",
                (false, false) => "",
            };
            let name =
                if object.entries.len() == 1 { object.name.clone() } else { format!("{}.{}", object.name, e.name) };
            out.push(pb::ObjectEntry {
                index: index.into(),
                subindex: (*sub).into(),
                name,
                data_type: super::convert::pb_type(e.dtype) as i32,
                // Strings have no fixed size: their default value's.
                bit_length: if e.dtype.bits() == 0 { e.value.len() as u32 * 8 } else { e.dtype.bits() },
                access: access.into(),
                pdo_mappable: e.mappable != ecmxf_devices::od::Mappable::No,
                value: e.value.clone(),
                minimum: limit(described, index, *sub, e, |d| d.minimum.as_ref(), |(lo, _)| lo),
                maximum: limit(described, index, *sub, e, |d| d.maximum.as_ref(), |(_, hi)| hi),
                unit: described.and_then(|d| d.entry(index, *sub)).and_then(|d| d.unit).unwrap_or(0),
            });
        }
    }
    out
}
