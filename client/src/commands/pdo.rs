//! `pdos`: each slave's PDO assignment and mapping (ProcessData.GetMapping)
//! and the named process image (GetLayout) that `data`, `watch` and `top`
//! use.

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Report, Table};
use crate::values::type_name;

/// `ecmxfctl pdos --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct PdosReport {
    pub slaves: Vec<SlaveMappingReport>,
    pub image: LayoutReport,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct SlaveMappingReport {
    pub slave: u32,
    /// Where the list came from: "coe", "sii", "esi" or "none".
    pub source: String,
    /// Why a lesser source was used ("" for CoE).
    pub note: String,
    /// Where the names came from: "eni", "esi", "sii", "sdo_info" or
    /// "none" (an older daemon that does not say: "").
    pub names_from: String,
    /// RxPDOs (outputs, 0x1C12).
    pub rx_pdos: Vec<PdoReport>,
    /// TxPDOs (inputs, 0x1C13).
    pub tx_pdos: Vec<PdoReport>,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct PdoReport {
    pub index: u32,
    /// The device's name for it ("" when none).
    pub name: String,
    /// Its sync manager, where the source says.
    pub sync_manager: Option<u32>,
    pub entries: Vec<PdoEntryReport>,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct PdoEntryReport {
    /// 0: a gap.
    pub index: u32,
    pub subindex: u32,
    pub bit_length: u32,
    /// The device's name for it ("" when none).
    pub name: String,
    /// The device's type (ecmxfctl type name), "" when it gives none.
    pub data_type: String,
}

/// The process image.
#[derive(Debug, Serialize, JsonSchema, Clone)]
pub struct LayoutReport {
    pub output_bytes: u32,
    pub input_bytes: u32,
    /// DC cycle, microseconds (one frame per cycle).
    pub cycle_us: u32,
    pub entries: Vec<EntryReport>,
    /// Where the layout disagrees with the configuration (an ENI variable
    /// no entry matches); empty when all agree.
    pub notes: Vec<String>,
}

/// One named entry.
#[derive(Debug, Serialize, JsonSchema, Clone)]
pub struct EntryReport {
    /// Unique name, e.g. "1.statusword", "2.0x6000:01".
    pub name: String,
    pub slave: u32,
    pub index: u32,
    pub subindex: u32,
    /// "output" or "input".
    pub direction: String,
    /// Bits from the start of the output or input image.
    pub bit_offset: u32,
    pub bit_length: u32,
    /// ecmxfctl type name.
    pub data_type: String,
    /// The device's name for it ("" when none).
    pub label: String,
    /// Its variable name as configuration tools write it (the ENI's, else
    /// "<slave>.<PDO>.<entry>"), "" when nothing names it; `data -v` and
    /// `watch` take it as they take `name`.
    pub variable: String,
}

impl EntryReport {
    /// Whether it is an output.
    pub fn is_output(&self) -> bool {
        self.direction == "output"
    }

    /// Whether `name` is this entry's name or its variable name.
    pub fn is_named(&self, name: &str) -> bool {
        self.name == name || (!self.variable.is_empty() && self.variable == name)
    }
}

impl From<pb::ProcessImage> for LayoutReport {
    fn from(p: pb::ProcessImage) -> Self {
        Self {
            output_bytes: p.output_bytes,
            input_bytes: p.input_bytes,
            cycle_us: p.cycle_us,
            entries: p
                .entries
                .into_iter()
                .map(|e| EntryReport {
                    name: e.name,
                    slave: e.slave,
                    index: e.index,
                    subindex: e.subindex,
                    direction: if e.direction == pb::Direction::Output as i32 { "output" } else { "input" }.into(),
                    bit_offset: e.bit_offset,
                    bit_length: e.bit_length,
                    data_type: type_name(e.data_type).into(),
                    label: e.label,
                    variable: e.variable,
                })
                .collect(),
            notes: p.notes,
        }
    }
}

/// Where an entry sits: "byte 4" or "byte 4 bit 3".
fn at(bit_offset: u32) -> String {
    if bit_offset % 8 == 0 { format!("{}", bit_offset / 8) } else { format!("{}.{}", bit_offset / 8, bit_offset % 8) }
}

impl LayoutReport {
    /// The layout table.
    pub fn table(&self) -> String {
        let mut t = Table::new(&["ENTRY", "DIR", "OBJECT", "BYTE", "BITS", "TYPE", "VARIABLE"]);
        for e in &self.entries {
            t.row([
                e.name.clone(),
                if e.is_output() { "out" } else { "in" }.to_owned(),
                format!("{:#06x}:{:02x}", e.index, e.subindex),
                at(e.bit_offset),
                e.bit_length.to_string(),
                e.data_type.clone(),
                e.variable.clone(),
            ]);
        }
        let notes: String = self.notes.iter().map(|n| format!("note: {n}\n")).collect();
        format!(
            "Process image: {} bytes out, {} bytes in, cycle {} us\n{t}{notes}",
            self.output_bytes, self.input_bytes, self.cycle_us
        )
    }
}

impl Report for PdosReport {
    fn text(&self) -> String {
        let mut out = String::new();
        let quoted = |s: &str| if s.is_empty() { String::new() } else { format!(" \"{s}\"") };
        for s in &self.slaves {
            let from = match s.source.as_str() {
                "coe" => String::new(),
                src if s.note.is_empty() => format!(" (from {})", src.to_uppercase()),
                src => format!(" (from {}: {})", src.to_uppercase(), s.note),
            };
            out.push_str(&format!("Slave {}{from}\n", s.slave));
            for (dir, what, list) in [("RxPDO", "outputs", &s.rx_pdos), ("TxPDO", "inputs", &s.tx_pdos)] {
                if list.is_empty() {
                    out.push_str(&format!("  {what}: none\n"));
                }
                for p in list {
                    let sm = p.sync_manager.map_or(String::new(), |n| format!("SM{n} "));
                    out.push_str(&format!("  {sm}{what}: {dir} {:#06x}{}\n", p.index, quoted(&p.name)));
                    for e in &p.entries {
                        let t = if e.data_type.is_empty() { String::new() } else { format!(", {}", e.data_type) };
                        out.push_str(&format!(
                            "    {:#06x}:{:02x}, {} bit{t}{}\n",
                            e.index,
                            e.subindex,
                            e.bit_length,
                            quoted(&e.name)
                        ));
                    }
                }
            }
        }
        out.push('\n');
        out.push_str(&self.image.table());
        out
    }
}

/// The layout alone.
pub async fn layout(api: &Api) -> Result<LayoutReport, CliError> {
    let r =
        api.pdo().get_layout(api.req(pb::GetLayoutRequest {})).await.map_err(CliError::rpc("process image layout"))?;
    Ok(r.into_inner().into())
}

/// Mapping and layout.
pub async fn fetch(api: &Api, position: Option<u32>) -> Result<PdosReport, CliError> {
    let r = api.pdo().get_mapping(api.req(pb::GetMappingRequest { slave: position })).await;
    let r = r.map_err(CliError::rpc("PDO mapping"))?.into_inner();
    let pdos = |v: Vec<pb::Pdo>| -> Vec<PdoReport> {
        v.into_iter()
            .map(|p| PdoReport {
                index: p.index,
                name: p.name,
                sync_manager: p.sync_manager,
                entries: p
                    .entries
                    .into_iter()
                    .map(|e| PdoEntryReport {
                        index: e.index,
                        subindex: e.subindex,
                        bit_length: e.bit_length,
                        name: e.name,
                        data_type: type_name(e.data_type).into(),
                    })
                    .collect(),
            })
            .collect()
    };
    let slaves = r
        .slaves
        .into_iter()
        .map(|s| SlaveMappingReport {
            slave: s.slave,
            source: match pb::PdoSource::try_from(s.source) {
                Ok(pb::PdoSource::Coe) => "coe",
                Ok(pb::PdoSource::Sii) => "sii",
                Ok(pb::PdoSource::Esi) => "esi",
                _ => "none",
            }
            .into(),
            note: s.note,
            names_from: s.names_from,
            rx_pdos: pdos(s.rx_pdos),
            tx_pdos: pdos(s.tx_pdos),
        })
        .collect();
    let mut image = layout(api).await?;
    if let Some(p) = position {
        image.entries.retain(|e| e.slave == p);
    }
    Ok(PdosReport { slaves, image })
}
