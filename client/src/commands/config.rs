//! `config` (IgH `ethercat xml` / `cstruct`, for ecmxfd): the network the
//! daemon runs, written as a file ecmxfd takes unchanged, so scan -> edit
//! -> run is a loop.
//!
//! - `--format toml`: a whole ecmxfd configuration: the daemon's `[link]`
//!   and `[cycle]` (MasterInfo.link_toml, cycle_toml), and one
//!   `[[slave]]` per slave with its name and identity (checked against the
//!   scan when it runs), its configured ESI file (names, types and the
//!   dictionary stay the same), its DC exceptions, and its PDO assignment and
//!   mapping as read over CoE (`rx_pdos`/`tx_pdos`, which bring-up writes
//!   only where the slave does not already run it, so a fixed mapping is
//!   stated without being written; beyond PDO_CONFIG_SET's 3 PDOs of 8
//!   entries it writes them over CoE). A mapping not read over CoE is left
//!   as the slave has it, said in a comment.
//! - `--format eni`: an ETG.2100 EtherCATConfig (what `eni = FILE` takes):
//!   each slave's Info, its ProcessData (PDOs with names and types, and
//!   its Send/Recv place in the image), its DC block, the cycle, and a
//!   ProcessImage naming every entry (the entry's variable name, else
//!   SLAVE.PDO.ENTRY), which ecmxfd checks the layout against when it runs
//!   the file. A slave whose mapping was read over CoE gets it as CoE init
//!   commands at PS, in ETG.1000.6 5.6.7.4's order (0x1C12/0x1C13 emptied,
//!   each 0x16xx/0x1Axx mapping count 0, entries, count, then the
//!   assignment filled and counted), so any master rebuilds the image; the
//!   PDOs with an `Sm` say the same assignment. ecmxfd writes neither where
//!   the slave holds it already (a fixed PDO refuses a mapping write), so
//!   the file runs on the network it came from (docs/eni.md).

use std::collections::HashMap;
use std::fmt::Write as _;

use ecmxf_devices::config_file::toml_string;
use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use super::pdo::{EntryReport, LayoutReport, PdoReport, SlaveMappingReport};
use super::slaves::SlaveReport;
use crate::cli::ConfigFormat;
use crate::connect::Api;
use crate::error::CliError;
use crate::output::Report;

/// `ecmxfctl config --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct ConfigReport {
    /// "toml" or "eni".
    pub format: String,
    /// The file's text.
    pub text: String,
}

impl Report for ConfigReport {
    fn text(&self) -> String {
        self.text.clone()
    }
}

/// Everything the file is made of, read once.
struct Network {
    info: pb::MasterInfo,
    slaves: Vec<SlaveReport>,
    mappings: Vec<SlaveMappingReport>,
    layout: LayoutReport,
    /// Each slave's name in the file: the configured one, else its own,
    /// made unique (an ENI's variables start with it).
    names: Vec<String>,
}

/// Reads the network and writes it in `format`.
pub async fn fetch(api: &Api, format: ConfigFormat) -> Result<ConfigReport, CliError> {
    let info = api.master().get_info(api.req(pb::GetInfoRequest {})).await.map_err(CliError::rpc("master info"))?;
    let slaves = super::slaves::fetch(api, None, false).await?.slaves;
    let pdos = super::pdo::fetch(api, None).await?;
    let bases: Vec<String> = slaves
        .iter()
        .map(|s| {
            let configured = s.expected.as_ref().map(|e| e.name.clone()).filter(|n| !n.is_empty());
            configured
                .unwrap_or_else(|| if s.name.is_empty() { format!("Slave {}", s.position) } else { s.name.clone() })
        })
        .collect();
    let names = bases
        .iter()
        .zip(&slaves)
        .map(
            |(b, s)| {
                if bases.iter().filter(|o| *o == b).count() > 1 { format!("{b} {}", s.position) } else { b.clone() }
            },
        )
        .collect();
    let net = Network { info: info.into_inner(), slaves, mappings: pdos.slaves, layout: pdos.image, names };
    let (name, text) = match format {
        ConfigFormat::Toml => ("toml", toml(&net)),
        ConfigFormat::Eni => ("eni", eni(&net)),
    };
    Ok(ConfigReport { format: name.into(), text })
}

fn mapping(net: &Network, position: u32) -> Option<&SlaveMappingReport> {
    net.mappings.iter().find(|m| m.slave == position)
}

/// The cycle the network runs and whether it runs DC.
fn dc_on(net: &Network) -> bool {
    net.info.dc_assign_activate != 0
}

fn toml(net: &Network) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# The network ecmxfd ran when `ecmxfctl config` read it: {} slaves. Run it with\n\
         # `ecmxfd --config FILE`; edit names, add [[slave.sdo]] start-up SDOs.\nversion = 1\n",
        net.slaves.len()
    );
    let _ = writeln!(out, "[link]\n{}", net.info.link_toml);
    let _ = writeln!(out, "[cycle]\n{}", net.info.cycle_toml);
    for (s, name) in net.slaves.iter().zip(&net.names) {
        let _ = writeln!(out, "[[slave]]  # position {}", s.position);
        let _ = writeln!(out, "name = {}", toml_string(name));
        let _ = writeln!(out, "vendor_id = {:#010x}", s.vendor_id);
        let _ = writeln!(out, "product_code = {:#010x}", s.product_code);
        let _ = writeln!(out, "revision = {:#010x}", s.revision);
        if let Some(esi) = s.expected.as_ref().map(|e| e.esi.as_str()).filter(|e| !e.is_empty()) {
            let _ = writeln!(out, "esi = {}", toml_string(esi));
        }
        if dc_on(net) && !s.dc.active {
            let _ = writeln!(out, "dc_assign_activate = 0  # runs without DC");
        } else if s.dc.active && s.dc.shift_ns != 0 {
            let _ = writeln!(out, "dc_shift_ns = {}", s.dc.shift_ns);
        }
        if let Some(m) = mapping(net, s.position) {
            toml_pdos(&mut out, m);
        }
        out.push('\n');
    }
    out
}

fn toml_pdos(out: &mut String, m: &SlaveMappingReport) {
    for (key, list) in [("rx_pdos", &m.rx_pdos), ("tx_pdos", &m.tx_pdos)] {
        if list.is_empty() {
            continue;
        }
        if m.source != "coe" {
            let why = format!("known from its {}, not read over CoE", m.source.to_uppercase());
            let pdos: Vec<String> = list.iter().map(|p| format!("{:#06x}", p.index)).collect();
            let _ = writeln!(out, "# {key}: {} as the slave has them ({why})", pdos.join(", "));
            continue;
        }
        for p in list {
            let entries: Vec<String> =
                p.entries.iter().map(|e| format!("[{:#06x}, {}, {}]", e.index, e.subindex, e.bit_length)).collect();
            let name = if p.name.is_empty() { String::new() } else { format!("  # {}", p.name) };
            let _ = writeln!(
                out,
                "  [[slave.{key}]]{name}\n  index = {:#06x}\n  entries = [{}]",
                p.index,
                entries.join(", ")
            );
        }
    }
}

/// Text safe in XML character data and attribute values.
fn xml(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// An IEC 61131-3 type name for an ecmxfctl type (ETG.2100 `DataType`).
fn iec_type(t: &str, bits: u32) -> String {
    match t {
        // A few bits of a byte (a 2-bit sync mode): ETG.1000.6's BITn.
        "uint8" | "int8" if (2..8).contains(&bits) => format!("BIT{bits}"),
        "bool" => "BOOL".into(),
        "int8" => "SINT".into(),
        "int16" => "INT".into(),
        "int32" => "DINT".into(),
        "int64" => "LINT".into(),
        "uint8" => "USINT".into(),
        "uint16" => "UINT".into(),
        "uint32" => "UDINT".into(),
        "uint64" => "ULINT".into(),
        "float" => "REAL".into(),
        "double" => "LREAL".into(),
        "string" => format!("STRING({})", bits / 8),
        _ => format!("BIT{bits}"),
    }
}

/// The ProcessImage name of an entry: SLAVE.REST, SLAVE the slave's name
/// in this file (a reader gives a variable to the slave its name starts
/// with, ETG.2100) and REST its variable's name without the daemon's
/// prefix (the slave's configured name or its position), else PDO.ENTRY
/// from the mapping's names (or numbers where unnamed).
fn variable_names(net: &Network) -> HashMap<(bool, u32), String> {
    let mut out = HashMap::new();
    let mut taken: Vec<String> = Vec::new();
    for e in &net.layout.entries {
        if e.index == 0 {
            continue;
        }
        let slave = net.names.get(e.slave as usize).cloned().unwrap_or_else(|| e.slave.to_string());
        let name = if !e.variable.is_empty() {
            let configured = net.slaves.get(e.slave as usize).and_then(|s| s.expected.as_ref()).map(|x| &x.name);
            let rest = [configured.cloned().unwrap_or_default(), e.slave.to_string()]
                .iter()
                .filter(|p| !p.is_empty())
                .find_map(|p| e.variable.strip_prefix(p.as_str())?.strip_prefix('.'))
                .unwrap_or(&e.variable);
            format!("{slave}.{rest}")
        } else {
            let (pdo, entry) = described(net, e);
            format!("{slave}.{pdo}.{entry}")
        };
        let mut unique = name.clone();
        let mut n = 2;
        while taken.contains(&unique) {
            unique = format!("{name} #{n}");
            n += 1;
        }
        taken.push(unique.clone());
        out.insert((e.is_output(), e.bit_offset), unique);
    }
    out
}

/// The PDO and entry names of a layout entry, from the mapping.
fn described(net: &Network, e: &EntryReport) -> (String, String) {
    let list = mapping(net, e.slave).map(|m| if e.is_output() { &m.rx_pdos } else { &m.tx_pdos });
    let hit = list
        .into_iter()
        .flatten()
        .find_map(|p| p.entries.iter().find(|x| (x.index, x.subindex) == (e.index, e.subindex)).map(|x| (p, x)));
    let object = format!("{:#06x}:{:02x}", e.index, e.subindex);
    match hit {
        Some((p, x)) => (
            if p.name.is_empty() { format!("{:#06x}", p.index) } else { p.name.clone() },
            if x.name.is_empty() { object } else { x.name.clone() },
        ),
        None => (if e.is_output() { "Outputs" } else { "Inputs" }.into(), object),
    }
}

fn eni_pdos(out: &mut String, tag: &str, sm: u8, list: &[PdoReport]) {
    for p in list {
        let _ = writeln!(out, "\t\t\t\t<{tag} Sm=\"{}\">", p.sync_manager.unwrap_or(u32::from(sm)));
        let _ = writeln!(out, "\t\t\t\t\t<Index>#x{:04x}</Index>", p.index);
        let _ = writeln!(out, "\t\t\t\t\t<Name>{}</Name>", xml(&p.name));
        for e in &p.entries {
            let _ = writeln!(out, "\t\t\t\t\t<Entry>");
            let _ = writeln!(out, "\t\t\t\t\t\t<Index>#x{:04x}</Index>", e.index);
            if e.index != 0 {
                let _ = writeln!(out, "\t\t\t\t\t\t<SubIndex>{}</SubIndex>", e.subindex);
            }
            let _ = writeln!(out, "\t\t\t\t\t\t<BitLen>{}</BitLen>", e.bit_length);
            if e.index != 0 {
                let _ = writeln!(out, "\t\t\t\t\t\t<Name>{}</Name>", xml(&e.name));
                let _ = writeln!(out, "\t\t\t\t\t\t<DataType>{}</DataType>", iec_type(&e.data_type, e.bit_length));
            }
            let _ = writeln!(out, "\t\t\t\t\t</Entry>");
        }
        let _ = writeln!(out, "\t\t\t\t</{tag}>");
    }
}

/// One CoE init command at PS (ETG.2100 `InitCmd`, `Ccs` 1: a download),
/// numbers in decimal as TwinCAT writes them, data as hex bytes.
fn init_cmd(comment: &str, index: u32, subindex: u32, data: &[u8]) -> String {
    let hex: String = data.iter().map(|b| format!("{b:02x}")).collect();
    format!(
        "\t\t\t\t\t\t<InitCmd>\n\t\t\t\t\t\t\t<Transition>PS</Transition>\n\t\t\t\t\t\t\t<Comment>{}</Comment>\n\
         \t\t\t\t\t\t\t<Timeout>0</Timeout>\n\t\t\t\t\t\t\t<Ccs>1</Ccs>\n\t\t\t\t\t\t\t<Index>{index}</Index>\n\
         \t\t\t\t\t\t\t<SubIndex>{subindex}</SubIndex>\n\t\t\t\t\t\t\t<Data>{hex}</Data>\n\t\t\t\t\t\t</InitCmd>\n",
        xml(comment)
    )
}

/// The init commands that give a slave its assignment and mapping over CoE
/// (ETG.1000.6 5.6.7.4): per direction, the assignment emptied, each PDO's
/// mapping (count 0, entries, count), the PDOs assigned, their count.
fn pdo_init_cmds(m: &SlaveMappingReport) -> Vec<String> {
    let mut out = Vec::new();
    for (assign, list) in [(0x1C12u32, &m.rx_pdos), (0x1C13, &m.tx_pdos)] {
        if list.is_empty() {
            continue;
        }
        out.push(init_cmd(&format!("clear pdo {assign:#06x} entries"), assign, 0, &[0]));
        for p in list {
            out.push(init_cmd(&format!("clear pdo {:#06x} entries", p.index), p.index, 0, &[0]));
            for (k, e) in p.entries.iter().enumerate() {
                let value = e.index << 16 | (e.subindex & 0xFF) << 8 | (e.bit_length & 0xFF);
                let comment = format!("download pdo {:#06x} entry {}", p.index, k + 1);
                out.push(init_cmd(&comment, p.index, k as u32 + 1, &value.to_le_bytes()));
            }
            let count = [p.entries.len() as u8];
            out.push(init_cmd(&format!("download pdo {:#06x} entry count", p.index), p.index, 0, &count));
        }
        for (k, p) in list.iter().enumerate() {
            let comment = format!("download pdo {assign:#06x}:{:02x} index", k + 1);
            out.push(init_cmd(&comment, assign, k as u32 + 1, &(p.index as u16).to_le_bytes()));
        }
        out.push(init_cmd(&format!("download pdo {assign:#06x} count"), assign, 0, &[list.len() as u8]));
    }
    out
}

fn eni(net: &Network) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<!-- The network ecmxfd ran when `ecmxfctl config` read it as an ENI \
         ({} slaves; ETG.2100, decimal numbers as TwinCAT writes them). ecmxfd writes the assignment \
         ProcessData gives, and the CoE InitCmds at PS, where a slave does not hold them already. -->\n<EtherCATConfig Version=\"1.3\">\n\t<Config>\n\
         \t\t<Master>\n\t\t\t<Info>\n\t\t\t\t<Name>ecmxfd</Name>\n\t\t\t</Info>\n\t\t</Master>",
        net.slaves.len()
    );
    let reference = net.slaves.iter().find(|s| s.dc.active).map(|s| s.position);
    for (s, name) in net.slaves.iter().zip(&net.names) {
        let _ = writeln!(out, "\t\t<Slave>\n\t\t\t<Info>");
        let _ = writeln!(out, "\t\t\t\t<Name>{}</Name>", xml(name));
        let _ = writeln!(out, "\t\t\t\t<PhysAddr>{}</PhysAddr>", s.configured_address);
        let _ = writeln!(out, "\t\t\t\t<AutoIncAddr>{}</AutoIncAddr>", (s.position as u16).wrapping_neg());
        let _ = writeln!(out, "\t\t\t\t<VendorId>{}</VendorId>", s.vendor_id);
        let _ = writeln!(out, "\t\t\t\t<ProductCode>{}</ProductCode>", s.product_code);
        let _ = writeln!(out, "\t\t\t\t<RevisionNo>{}</RevisionNo>", s.revision);
        let _ = writeln!(out, "\t\t\t</Info>");
        if s.output_bytes > 0 || s.input_bytes > 0 {
            let _ = writeln!(out, "\t\t\t<ProcessData>");
            for (tag, bytes, offset) in
                [("Send", s.output_bytes, s.output_offset), ("Recv", s.input_bytes, s.input_offset)]
            {
                if bytes > 0 {
                    let _ = writeln!(
                        out,
                        "\t\t\t\t<{tag}>\n\t\t\t\t\t<BitStart>{}</BitStart>\n\t\t\t\t\t<BitLength>{}</BitLength>\n\t\t\t\t</{tag}>",
                        offset * 8,
                        bytes * 8
                    );
                }
            }
            if let Some(m) = mapping(net, s.position) {
                eni_pdos(&mut out, "RxPdo", 2, &m.rx_pdos);
                eni_pdos(&mut out, "TxPdo", 3, &m.tx_pdos);
            }
            let _ = writeln!(out, "\t\t\t</ProcessData>");
        }
        // Its mapping was read over CoE: it speaks CoE (the mailbox areas
        // are the chip's to set up from the SII), and its init commands
        // write that mapping.
        if let Some(m) = mapping(net, s.position).filter(|m| m.source == "coe") {
            let _ =
                writeln!(out, "\t\t\t<Mailbox>\n\t\t\t\t<Protocol>CoE</Protocol>\n\t\t\t\t<CoE>\n\t\t\t\t\t<InitCmds>");
            for cmd in pdo_init_cmds(m) {
                let _ = write!(out, "{cmd}");
            }
            let _ = writeln!(out, "\t\t\t\t\t</InitCmds>\n\t\t\t\t</CoE>\n\t\t\t</Mailbox>");
        }
        if s.dc.active {
            let _ = writeln!(
                out,
                "\t\t\t<DC>\n\t\t\t\t<ReferenceClock>{}</ReferenceClock>\n\t\t\t\t<CycleTime0>{}</CycleTime0>\n\
                 \t\t\t\t<CycleTime1>0</CycleTime1>\n\t\t\t\t<ShiftTime>{}</ShiftTime>\n\t\t\t</DC>",
                reference == Some(s.position),
                net.info.sync0_us * 1000,
                s.dc.shift_ns.max(0)
            );
        }
        let _ = writeln!(out, "\t\t</Slave>");
    }
    let _ = writeln!(out, "\t\t<Cyclic>\n\t\t\t<CycleTime>{}</CycleTime>\n\t\t</Cyclic>", net.info.sync0_us);
    let names = variable_names(net);
    let _ = writeln!(out, "\t\t<ProcessImage>");
    for (tag, output, bytes) in [("Inputs", false, net.layout.input_bytes), ("Outputs", true, net.layout.output_bytes)]
    {
        let _ = writeln!(out, "\t\t\t<{tag}>\n\t\t\t\t<ByteSize>{bytes}</ByteSize>");
        for e in net.layout.entries.iter().filter(|e| e.is_output() == output && e.index != 0) {
            let Some(name) = names.get(&(output, e.bit_offset)) else { continue };
            let _ = writeln!(
                out,
                "\t\t\t\t<Variable>\n\t\t\t\t\t<Name>{}</Name>\n\t\t\t\t\t<DataType>{}</DataType>\n\
                 \t\t\t\t\t<BitSize>{}</BitSize>\n\t\t\t\t\t<BitOffs>{}</BitOffs>\n\t\t\t\t</Variable>",
                xml(name),
                iec_type(&e.data_type, e.bit_length),
                e.bit_length,
                e.bit_offset
            );
        }
        let _ = writeln!(out, "\t\t\t</{tag}>");
    }
    let _ = writeln!(out, "\t\t</ProcessImage>\n\t</Config>\n</EtherCATConfig>");
    out
}
