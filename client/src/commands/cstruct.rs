//! `cstruct` (IgH `ethercat cstruct`): each slave's PDO configuration as
//! the C arrays IgH's application interface (`ecrt.h`) takes
//! (`ec_pdo_entry_info_t`, `ec_pdo_info_t`, `ec_sync_info_t`), in the form
//! IgH's tool prints them, so code written for IgH gets the running
//! network's mapping unchanged.
//!
//! The mapping is what the daemon runs (ProcessData.GetMapping). A PDO's
//! sync manager is the one its source names; where none does, outputs go
//! to SM2 and inputs to SM3 on a slave with a mailbox (SM0/SM1 are the
//! mailbox's), else to SM0 and SM1. The watchdog mode is `EC_WD_DEFAULT`
//! (the slave's own default): the daemon does not set it per sync manager.

use schemars::JsonSchema;
use serde::Serialize;

use super::pdo::{PdoReport, SlaveMappingReport};
use crate::connect::Api;
use crate::error::CliError;
use crate::output::Report;

/// `ecmxfctl cstruct --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct CStructReport {
    /// The C text, every slave with process data or a mailbox.
    pub c: String,
}

impl Report for CStructReport {
    fn text(&self) -> String {
        self.c.clone()
    }
}

/// The arrays of every slave (or one).
pub async fn fetch(api: &Api, position: Option<u32>) -> Result<CStructReport, CliError> {
    let slaves = super::slaves::fetch(api, position, false).await?.slaves;
    let mapping = super::pdo::fetch(api, position).await?.slaves;
    let mut c = String::new();
    for s in &slaves {
        if let Some(m) = mapping.iter().find(|m| m.slave == s.position) {
            let id = Identity {
                position: s.position,
                name: &s.name,
                vendor_id: s.vendor_id,
                product_code: s.product_code,
                revision: s.revision,
            };
            c.push_str(&slave_arrays(&id, m));
        }
    }
    Ok(CStructReport { c })
}

/// What the comment above a slave's arrays says.
struct Identity<'a> {
    position: u32,
    name: &'a str,
    vendor_id: u32,
    product_code: u32,
    revision: u32,
}

/// One sync manager as `ec_sync_info_t` lists it.
struct Sync<'a> {
    index: u32,
    output: bool,
    pdos: Vec<&'a PdoReport>,
}

/// The sync managers of a slave, with their PDOs.
fn syncs(m: &SlaveMappingReport) -> Vec<Sync<'_>> {
    let named = m.rx_pdos.iter().chain(&m.tx_pdos).any(|p| p.sync_manager.is_some_and(|s| s >= 2));
    let mailbox = m.source == "coe" || named;
    let (out_sm, in_sm) = if mailbox { (2, 3) } else { (0, 1) };
    let mut syncs: Vec<Sync<'_>> = Vec::new();
    if mailbox {
        syncs.push(Sync { index: 0, output: true, pdos: Vec::new() });
        syncs.push(Sync { index: 1, output: false, pdos: Vec::new() });
    }
    for (pdos, output, default) in [(&m.rx_pdos, true, out_sm), (&m.tx_pdos, false, in_sm)] {
        for p in pdos {
            let index = p.sync_manager.unwrap_or(default);
            match syncs.iter_mut().find(|s| s.index == index) {
                Some(s) => s.pdos.push(p),
                None => syncs.push(Sync { index, output, pdos: vec![p] }),
            }
        }
    }
    syncs.sort_by_key(|s| s.index);
    syncs
}

/// A comment's text: no `*/` inside.
fn comment(text: &str) -> String {
    if text.is_empty() { String::new() } else { format!(" /* {} */", text.replace("*/", "* /")) }
}

/// The three arrays of one slave, as IgH's `cstruct` writes them; nothing
/// for a slave without sync managers (a coupler).
fn slave_arrays(slave: &Identity<'_>, m: &SlaveMappingReport) -> String {
    let syncs = syncs(m);
    if syncs.is_empty() {
        return String::new();
    }
    let id = format!("slave_{}_", slave.position);
    let mut c = format!("/* Master 0, Slave {}", slave.position);
    if !slave.name.is_empty() {
        c.push_str(&format!(", \"{}\"", slave.name.replace('"', "'").replace("*/", "* /")));
    }
    c.push_str(&format!(
        "\n * Vendor ID:       {:#010x}\n * Product code:    {:#010x}\n * Revision number: {:#010x}\n */\n\n",
        slave.vendor_id, slave.product_code, slave.revision
    ));
    let ordered: Vec<&PdoReport> = syncs.iter().flat_map(|s| s.pdos.iter().copied()).collect();
    if !ordered.is_empty() {
        c.push_str(&format!("ec_pdo_entry_info_t {id}pdo_entries[] = {{\n"));
        for e in ordered.iter().flat_map(|p| &p.entries) {
            c.push_str(&format!(
                "    {{0x{:04x}, 0x{:02x}, {}}},{}\n",
                e.index,
                e.subindex,
                e.bit_length,
                comment(&e.name)
            ));
        }
        c.push_str("};\n\n");
        c.push_str(&format!("ec_pdo_info_t {id}pdos[] = {{\n"));
        let mut first_entry = 0;
        for p in &ordered {
            c.push_str(&format!(
                "    {{0x{:04x}, {}, {id}pdo_entries + {first_entry}}},{}\n",
                p.index,
                p.entries.len(),
                comment(&p.name)
            ));
            first_entry += p.entries.len();
        }
        c.push_str("};\n\n");
    }
    c.push_str(&format!("ec_sync_info_t {id}syncs[] = {{\n"));
    let mut first_pdo = 0;
    for s in &syncs {
        let dir = if s.output { "EC_DIR_OUTPUT" } else { "EC_DIR_INPUT" };
        let pdos = if s.pdos.is_empty() { "NULL".to_owned() } else { format!("{id}pdos + {first_pdo}") };
        c.push_str(&format!("    {{{}, {dir}, {}, {pdos}, EC_WD_DEFAULT}},\n", s.index, s.pdos.len()));
        first_pdo += s.pdos.len();
    }
    c.push_str("    {0xff}\n};\n\n");
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::commands::pdo::PdoEntryReport;

    fn pdo(index: u32, sm: Option<u32>, entries: &[(u32, u32, u32, &str)]) -> PdoReport {
        PdoReport {
            index,
            name: format!("PDO {index:#x}"),
            sync_manager: sm,
            entries: entries
                .iter()
                .map(|&(index, subindex, bit_length, name)| PdoEntryReport {
                    index,
                    subindex,
                    bit_length,
                    name: name.into(),
                    data_type: String::new(),
                })
                .collect(),
        }
    }

    fn mapping(source: &str, rx: Vec<PdoReport>, tx: Vec<PdoReport>) -> SlaveMappingReport {
        SlaveMappingReport {
            slave: 1,
            source: source.into(),
            note: String::new(),
            names_from: String::new(),
            rx_pdos: rx,
            tx_pdos: tx,
        }
    }

    fn slave() -> Identity<'static> {
        Identity { position: 1, name: "Drive", vendor_id: 0x59d, product_code: 0x402, revision: 1 }
    }

    #[test]
    fn a_coe_drive_is_written_as_igh_writes_it() {
        let m = mapping(
            "coe",
            vec![pdo(0x1600, None, &[(0x6040, 0, 16, "Controlword")])],
            vec![pdo(0x1a00, None, &[(0x6041, 0, 16, "Statusword"), (0x6064, 0, 32, "Position actual */")])],
        );
        let c = slave_arrays(&slave(), &m);
        let want = "/* Master 0, Slave 1, \"Drive\"
 * Vendor ID:       0x0000059d
 * Product code:    0x00000402
 * Revision number: 0x00000001
 */

ec_pdo_entry_info_t slave_1_pdo_entries[] = {
    {0x6040, 0x00, 16}, /* Controlword */
    {0x6041, 0x00, 16}, /* Statusword */
    {0x6064, 0x00, 32}, /* Position actual * / */
};

ec_pdo_info_t slave_1_pdos[] = {
    {0x1600, 1, slave_1_pdo_entries + 0}, /* PDO 0x1600 */
    {0x1a00, 2, slave_1_pdo_entries + 1}, /* PDO 0x1a00 */
};

ec_sync_info_t slave_1_syncs[] = {
    {0, EC_DIR_OUTPUT, 0, NULL, EC_WD_DEFAULT},
    {1, EC_DIR_INPUT, 0, NULL, EC_WD_DEFAULT},
    {2, EC_DIR_OUTPUT, 1, slave_1_pdos + 0, EC_WD_DEFAULT},
    {3, EC_DIR_INPUT, 1, slave_1_pdos + 1, EC_WD_DEFAULT},
    {0xff}
};

";
        assert_eq!(c, want);
    }

    #[test]
    fn an_io_terminal_without_mailbox_uses_its_own_sync_managers() {
        let m = mapping("sii", Vec::new(), vec![pdo(0x1a00, Some(0), &[(0x6000, 1, 1, "Input 1")])]);
        let c = slave_arrays(&slave(), &m);
        assert!(c.contains("    {0, EC_DIR_INPUT, 1, slave_1_pdos + 0, EC_WD_DEFAULT},\n    {0xff}"), "{c}");
        assert!(!c.contains("{1, "), "{c}");
        // A coupler (no PDOs, no mailbox) has no arrays.
        assert_eq!(slave_arrays(&slave(), &mapping("none", Vec::new(), Vec::new())), "");
    }
}
