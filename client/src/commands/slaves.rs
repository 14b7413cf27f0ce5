//! `slaves`: one line per slave (Slaves.ListSlaves / Scan), `-v` for all
//! that is known about each.

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Fields, Report, Table};
use crate::values::state_name;

/// `ecmxfctl slaves --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct SlavesReport {
    pub slaves: Vec<SlaveReport>,
    /// Configured positions with no slave found.
    pub missing: Vec<u32>,
    /// Every slave matches the configuration and none is missing.
    pub matches_config: bool,
    /// Set by `-v`: the text form shows every field.
    #[serde(skip)]
    #[schemars(skip)]
    pub verbose: bool,
}

/// One slave.
#[derive(Debug, Serialize, JsonSchema)]
pub struct SlaveReport {
    /// Ring position, 0-based.
    pub position: u32,
    pub alias: u32,
    pub configured_address: u32,
    pub vendor_id: u32,
    pub product_code: u32,
    pub revision: u32,
    pub name: String,
    /// INIT, PREOP, BOOT, SAFEOP, OP, ERROR, UNKNOWN.
    pub state: String,
    /// AL status code (0: none) and its meaning.
    pub al_status_code: u32,
    pub al_status_text: String,
    pub output_bytes: u32,
    pub output_offset: u32,
    pub input_bytes: u32,
    pub input_offset: u32,
    pub dc: DcReport,
    /// What the configuration expects here (null: nothing).
    pub expected: Option<ExpectedReport>,
    /// "" when it matches; else what differs.
    pub mismatch: String,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct DcReport {
    pub supported: bool,
    pub active: bool,
    pub cycle_ns: u32,
    pub shift_ns: i32,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct ExpectedReport {
    pub name: String,
    /// 0: any.
    pub vendor_id: u32,
    pub product_code: u32,
    pub revision: u32,
    /// The ESI file configured for it ("" when none).
    pub esi: String,
}

impl From<pb::Slave> for SlaveReport {
    fn from(s: pb::Slave) -> Self {
        let dc = s.dc.unwrap_or_default();
        Self {
            position: s.position,
            alias: s.alias,
            configured_address: s.configured_address,
            vendor_id: s.vendor_id,
            product_code: s.product_code,
            revision: s.revision,
            name: s.name,
            state: state_name(s.state).into(),
            al_status_code: s.al_status_code,
            al_status_text: s.al_status_text,
            output_bytes: s.output_bytes,
            output_offset: s.output_offset,
            input_bytes: s.input_bytes,
            input_offset: s.input_offset,
            dc: DcReport { supported: dc.supported, active: dc.active, cycle_ns: dc.cycle_ns, shift_ns: dc.shift_ns },
            expected: s.expected.map(|e| ExpectedReport {
                name: e.name,
                vendor_id: e.vendor_id,
                product_code: e.product_code,
                revision: e.revision,
                esi: e.esi,
            }),
            mismatch: s.mismatch,
        }
    }
}

/// The AL status column: "-" for none, else code and text.
pub fn al_status(code: u32, text: &str) -> String {
    if code == 0 { "-".into() } else { format!("{code:#06x} {text}") }
}

impl Report for SlavesReport {
    fn text(&self) -> String {
        let mut out = String::new();
        if self.verbose {
            for s in &self.slaves {
                let mut f = Fields::default();
                f.add("Position", s.position)
                    .add("Name", &s.name)
                    .add("Vendor", format!("{:#010x}", s.vendor_id))
                    .add("Product", format!("{:#010x}", s.product_code))
                    .add("Revision", format!("{:#010x}", s.revision))
                    .add("Alias", s.alias)
                    .add("Station address", format!("{:#06x}", s.configured_address))
                    .add("State", &s.state)
                    .add("AL status", al_status(s.al_status_code, &s.al_status_text))
                    .add("Outputs", format!("{} bytes at {}", s.output_bytes, s.output_offset))
                    .add("Inputs", format!("{} bytes at {}", s.input_bytes, s.input_offset));
                let dc = if !s.dc.supported {
                    "not supported".to_owned()
                } else if s.dc.active {
                    format!("active, cycle {} ns, shift {} ns", s.dc.cycle_ns, s.dc.shift_ns)
                } else {
                    "supported, not active".to_owned()
                };
                f.add("DC", dc);
                if let Some(e) = &s.expected {
                    f.add(
                        "Expected",
                        format!("{} {:#010x}/{:#010x}/{:#010x}", e.name, e.vendor_id, e.product_code, e.revision),
                    );
                }
                if !s.mismatch.is_empty() {
                    f.add("MISMATCH", &s.mismatch);
                }
                out.push_str(&f.to_string());
                out.push('\n');
            }
        } else {
            let mut t = Table::new(&["POS", "ALIAS", "STATE", "AL STATUS", "VENDOR", "PRODUCT", "REVISION", "NAME"]);
            for s in &self.slaves {
                let name = if s.mismatch.is_empty() {
                    s.name.clone()
                } else {
                    format!("{} (MISMATCH: {})", s.name, s.mismatch)
                };
                t.row([
                    s.position.to_string(),
                    s.alias.to_string(),
                    s.state.clone(),
                    al_status(s.al_status_code, &s.al_status_text),
                    format!("{:#010x}", s.vendor_id),
                    format!("{:#010x}", s.product_code),
                    format!("{:#010x}", s.revision),
                    name,
                ]);
            }
            out.push_str(&t.to_string());
        }
        for m in &self.missing {
            out.push_str(&format!("MISSING: position {m} is configured but no slave answers there\n"));
        }
        out
    }
}

/// `rescan`: the whole bring-up again (Slaves.Scan with reinit; admin),
/// then the slaves it found, as `slaves` lists them.
pub async fn rescan(api: &Api) -> Result<SlavesReport, CliError> {
    let req = api.req_for(pb::ScanRequest { reinit: true }, std::time::Duration::from_secs(35));
    let r = api.slaves().scan(req).await.map_err(CliError::rpc("rescan"))?;
    let r = r.into_inner();
    let slaves = r.slaves.into_iter().map(Into::into).collect();
    Ok(SlavesReport { slaves, missing: r.missing, matches_config: r.matches_config, verbose: false })
}

/// Lists (or scans) the slaves; `position` keeps one.
pub async fn fetch(api: &Api, position: Option<u32>, scan: bool) -> Result<SlavesReport, CliError> {
    let (slaves, missing, matches_config) = if scan {
        let r = api.slaves().scan(api.req(pb::ScanRequest { reinit: false })).await.map_err(CliError::rpc("scan"))?;
        let r = r.into_inner();
        (r.slaves, r.missing, r.matches_config)
    } else {
        let r =
            api.slaves().list_slaves(api.req(pb::ListSlavesRequest {})).await.map_err(CliError::rpc("list slaves"))?;
        let r = r.into_inner();
        (r.slaves, r.missing, r.matches_config)
    };
    let count = slaves.len();
    let slaves: Vec<SlaveReport> =
        slaves.into_iter().filter(|s| position.is_none_or(|p| p == s.position)).map(Into::into).collect();
    if let Some(p) = position {
        if slaves.is_empty() {
            return Err(CliError::Usage(format!("no slave at position {p} ({count} found)")));
        }
    }
    Ok(SlavesReport { slaves, missing, matches_config, verbose: false })
}
