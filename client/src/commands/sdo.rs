//! `upload`, `download`, `sdos`: CoE SDO access and the object dictionary
//! (Sdo.Upload / Download / ListObjects). Types come from `--type`, else
//! from what the daemon knows (CiA 301/402), else from the slave's ESI
//! dictionary when the configuration names one.

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::cli::{Download, Upload};
use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Report, Table};
use crate::values::{Hex, decode_le, hex, parse_value, type_name, value_json, value_text};

/// `ecmxfctl upload --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct UploadReport {
    pub slave: u32,
    pub index: u32,
    pub subindex: u32,
    /// The type used to decode ("" when unknown: `value` is then the raw hex).
    pub data_type: String,
    /// The value: a number, bool or string; raw bytes as hex.
    pub value: serde_json::Value,
    /// The bytes as the slave sent them.
    pub raw: Hex,
    #[serde(skip)]
    #[schemars(skip)]
    text: String,
}

impl Report for UploadReport {
    fn text(&self) -> String {
        self.text.clone()
    }
}

/// `ecmxfctl download --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct DownloadReport {
    pub slave: u32,
    pub index: u32,
    pub subindex: u32,
    /// The type the value was encoded as ("" when sent raw / by the daemon's knowledge).
    pub data_type: String,
    pub bytes_written: u32,
}

impl Report for DownloadReport {
    fn text(&self) -> String {
        format!(
            "wrote {} byte{} to slave {} object {:#06x}:{:02x}",
            self.bytes_written,
            if self.bytes_written == 1 { "" } else { "s" },
            self.slave,
            self.index,
            self.subindex
        )
    }
}

fn object(index: u32, subindex: u32) -> String {
    format!("{index:#06x}:{subindex:02x}")
}

/// The type the slave's dictionary (ESI) gives an object, if the daemon
/// has one for it.
async fn dictionary_type(api: &Api, slave: u32, index: u32, subindex: u32) -> Option<pb::DataType> {
    let ask = pb::ListObjectsRequest { slave, source: pb::DictionarySource::Unspecified as i32 };
    let r = api.sdo().list_objects(api.req(ask)).await.ok()?.into_inner();
    r.entries
        .into_iter()
        .find(|e| e.index == index && e.subindex == subindex)
        .and_then(|e| pb::DataType::try_from(e.data_type).ok())
        .filter(|t| *t != pb::DataType::Unspecified)
}

/// `upload`.
pub async fn upload(api: &Api, u: &Upload) -> Result<UploadReport, CliError> {
    let slave = u.slave.position;
    let action = format!("upload {} from slave {slave}", object(u.index, u.subindex));
    let req = pb::SdoUploadRequest {
        slave,
        index: u.index,
        subindex: u.subindex,
        complete_access: u.complete_access,
        data_type: u.data_type.map_or(0, |t| t as i32),
    };
    let r = api.sdo().upload(api.req(req)).await.map_err(CliError::rpc(action))?.into_inner();
    let (mut t, mut value) = (pb::DataType::try_from(r.data_type).unwrap_or_default(), r.value);
    if value.is_none() && !u.complete_access && u.data_type.is_none() {
        if let Some(dt) = dictionary_type(api, slave, u.index, u.subindex).await {
            value = decode_le(dt, &r.raw);
            if value.is_some() {
                t = dt;
            }
        }
    }
    let text = match &value {
        Some(v) => value_text(Some(v), r.raw.len()),
        None if r.raw.is_empty() => "(empty)".into(),
        None => crate::values::spaced_hex(&r.raw),
    };
    Ok(UploadReport {
        slave,
        index: u.index,
        subindex: u.subindex,
        data_type: type_name(t as i32).into(),
        value: if value.is_some() { value_json(value.as_ref()) } else { hex(&r.raw).into() },
        raw: Hex::of(&r.raw),
        text,
    })
}

/// `download`.
pub async fn download(api: &Api, d: &Download) -> Result<DownloadReport, CliError> {
    let slave = d.slave.position;
    let action = format!("download {} to slave {slave}", object(d.index, d.subindex));
    let mut t = d.data_type.unwrap_or(pb::DataType::Unspecified);
    if d.complete_access && d.data_type.is_none() {
        t = pb::DataType::OctetString;
    }
    let mut req = pb::SdoDownloadRequest {
        slave,
        index: d.index,
        subindex: d.subindex,
        complete_access: d.complete_access,
        data_type: t as i32,
        value: Some(parse_value(&d.value, t)?),
    };
    let first = api.sdo().download(api.req(req.clone())).await;
    let r = match first {
        // The daemon does not know the type: ask the slave's dictionary.
        Err(s) if s.code() == tonic::Code::InvalidArgument && t == pb::DataType::Unspecified => {
            let Some(dt) = dictionary_type(api, slave, d.index, d.subindex).await else {
                return Err(CliError::Usage(format!(
                    "{action}: the type of {} is not known (not a standard object, no ESI); give --type",
                    object(d.index, d.subindex)
                )));
            };
            t = dt;
            req.data_type = dt as i32;
            req.value = Some(parse_value(&d.value, dt)?);
            api.sdo().download(api.req(req)).await
        }
        other => other,
    };
    let r = r.map_err(CliError::rpc(action))?.into_inner();
    Ok(DownloadReport {
        slave,
        index: d.index,
        subindex: d.subindex,
        data_type: type_name(t as i32).into(),
        bytes_written: r.bytes_written,
    })
}

/// `ecmxfctl sdos --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct SdosReport {
    pub slave: u32,
    /// Where the list comes from: DEVICE (the slave's own description, CoE
    /// SDO Information), ESI (the slave's ESI file) or PROBE (standard
    /// objects probed).
    pub source: String,
    /// Why a better source was not used ("" when none was passed over).
    pub note: String,
    pub objects: Vec<ObjectReport>,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct ObjectReport {
    pub index: u32,
    pub subindex: u32,
    pub name: String,
    /// ecmxfctl type name ("" unknown).
    pub data_type: String,
    pub bit_length: u32,
    /// "ro", "rw", "wo" or "".
    pub access: String,
    pub pdo_mappable: bool,
    /// The value read while probing (PROBE only; else null), as hex.
    pub value: Option<Hex>,
    #[serde(skip)]
    #[schemars(skip)]
    value_text: String,
}

impl Report for SdosReport {
    fn text(&self) -> String {
        let mut t = Table::new(&["OBJECT", "TYPE", "BITS", "ACCESS", "PDO", "NAME", "VALUE"]);
        for o in &self.objects {
            t.row([
                object(o.index, o.subindex),
                o.data_type.clone(),
                o.bit_length.to_string(),
                o.access.clone(),
                if o.pdo_mappable { "yes" } else { "" }.to_owned(),
                o.name.clone(),
                o.value_text.clone(),
            ]);
        }
        let from = match self.source.as_str() {
            "DEVICE" => "from the device",
            "ESI" => "from its ESI",
            "PROBE" => "probed",
            other => other,
        };
        let note = if self.note.is_empty() { String::new() } else { format!("\n({})", self.note) };
        format!("slave {} object dictionary ({from}, {} entries):{note}\n{t}", self.slave, self.objects.len())
    }
}

/// `sdos`.
pub async fn sdos(api: &Api, slave: u32, only: Option<crate::cli::DictionarySource>) -> Result<SdosReport, CliError> {
    use crate::cli::DictionarySource as S;
    let source = match only {
        None => pb::DictionarySource::Unspecified,
        Some(S::Device) => pb::DictionarySource::Device,
        Some(S::Esi) => pb::DictionarySource::Esi,
        Some(S::Probe) => pb::DictionarySource::Probe,
    } as i32;
    // Probing uploads every standard object, and a device describing a
    // large dictionary the first time takes a while: give it time.
    let req = api.req_for(pb::ListObjectsRequest { slave, source }, std::time::Duration::from_secs(60));
    let r = api.sdo().list_objects(req).await.map_err(CliError::rpc(format!("object dictionary of slave {slave}")))?;
    let r = r.into_inner();
    let source = crate::values::enum_name(r.source, pb::DictionarySource::as_str_name, "DICTIONARY_SOURCE_");
    Ok(SdosReport {
        slave,
        source: source.into(),
        note: r.note,
        objects: r
            .entries
            .into_iter()
            .map(|e| ObjectReport {
                value_text: match pb::DataType::try_from(e.data_type).ok().and_then(|t| decode_le(t, &e.value)) {
                    _ if source != "PROBE" => String::new(),
                    Some(v) => value_text(Some(&v), e.value.len()),
                    None => crate::values::spaced_hex(&e.value),
                },
                index: e.index,
                subindex: e.subindex,
                name: e.name,
                data_type: type_name(e.data_type).into(),
                bit_length: e.bit_length,
                access: e.access,
                pdo_mappable: e.pdo_mappable,
                value: (source == "PROBE").then(|| Hex::of(&e.value)),
            })
            .collect(),
    })
}
