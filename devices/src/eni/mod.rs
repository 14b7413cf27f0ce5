//! EtherCAT Network Information files (ENI, ETG.2100 `EtherCATConfig`),
//! as configuration tools export them (TwinCAT, acontis, the EtherCAT
//! Configurator) or people write them (SOEM's sample): the slaves in ring
//! order with their identities and their CoE init commands per state
//! transition, and a record of every other element the file has, so a
//! reader can say what it does not apply.
//!
//! Numbers come decimal (TwinCAT: `<Index>7186</Index>`), C hex (`0x1c12`)
//! or ESI hex (`#x1c12`). The CoE init command's `Ccs` is the SDO client
//! command specifier: ETG.2100 and TwinCAT write 1 for a download (a
//! write). SOEM's hand-written sample writes 2 for its writes (SOEM's
//! reader takes 2 as a write): an init command with `Ccs` 2 AND data is
//! therefore read as a download too, and said so ([`CcsConvention`]); `Ccs`
//! 2 without data is an upload (a read), which nothing here replays.

use roxmltree::{Document, Node};

pub use crate::init_cmd::{CcsConvention, CoeAccess, CoeInitCmd, EniError, Transition};
pub(crate) use crate::init_cmd::{child, children, fail, number, pos_of};
use crate::init_cmd::{coe_init_cmd, hex_bytes, required, transitions};
use crate::xml::TextPos;

mod process;

pub use process::{BitRange, EniDc, EniMailbox, EniProcessData, EniVariable, SlaveVariable};

/// One register init command of a slave (`Slave/InitCmds/InitCmd`): an
/// EtherCAT datagram the configuration tool's master sends at a transition
/// (ETG.2100 5.3.5): the ESC set-up a master does (addresses, sync
/// managers, FMMUs, DC, watchdogs) and the checks it makes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RegisterInitCmd {
    /// The transitions it runs at.
    pub transitions: Vec<Transition>,
    /// Datagram command (ETG.1000.4 Table 12: 1 APRD, 2 APWR, 4 FPRD, 5
    /// FPWR, 7 BRD, 8 BWR, ...).
    pub cmd: u8,
    /// Address: position (auto-increment) or the tool's station address.
    pub adp: u16,
    /// Register.
    pub ado: u16,
    /// Data written (or the length read).
    pub data: Vec<u8>,
    /// It checks an answer (`Validate`).
    pub validates: bool,
    /// `Comment`.
    pub comment: String,
    /// Where it is in the file.
    pub at: TextPos,
}

impl RegisterInitCmd {
    /// Whether the datagram writes (APWR, FPWR, BWR, LWR, ARMW...).
    pub fn writes(&self) -> bool {
        matches!(self.cmd, 2 | 3 | 5 | 6 | 8 | 9 | 11 | 12 | 13 | 14)
    }
}

/// One slave (`Config/Slave`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EniSlave {
    /// `Info/Name`.
    pub name: String,
    /// `Info/VendorId`.
    pub vendor_id: u32,
    /// `Info/ProductCode`.
    pub product_code: u32,
    /// `Info/RevisionNo`, when given.
    pub revision: Option<u32>,
    /// `Info/PhysAddr`, when given.
    pub phys_addr: Option<u16>,
    /// CoE init commands, in file order.
    pub coe_init_cmds: Vec<CoeInitCmd>,
    /// `ProcessData`, when given.
    pub process_data: Option<EniProcessData>,
    /// `Mailbox` areas and protocols, when given.
    pub mailbox: Option<EniMailbox>,
    /// `DC`, when given.
    pub dc: Option<EniDc>,
    /// Register init commands, in file order.
    pub register_init_cmds: Vec<RegisterInitCmd>,
    /// Elements of this slave the reader's caller may not apply, with a
    /// count: `("InitCmds (register)", 49)`, `("ProcessData", 1)`, ...
    pub elements: Vec<(&'static str, usize)>,
    /// Where it is in the file.
    pub at: TextPos,
}

/// An ENI file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Eni {
    /// The slaves, in ring order.
    pub slaves: Vec<EniSlave>,
    /// Master-level elements: `("Master/InitCmds", 12)`, `("Cyclic", 1)`,
    /// `("ProcessImage", 1)`...
    pub elements: Vec<(&'static str, usize)>,
    /// `ProcessImage` variables, inputs then outputs, in file order.
    pub process_image: Vec<EniVariable>,
    /// `Cyclic/CycleTime` (us) of the first cycle, when given.
    pub cycle_us: Option<u32>,
}

/// One register init command element.
fn register_init_cmd(cmd: Node<'_, '_>, path: &str) -> Result<RegisterInitCmd, EniError> {
    let transitions = transitions(cmd, path)?;
    Ok(RegisterInitCmd {
        transitions,
        cmd: required(cmd, "Cmd", path, 0xFF)? as u8,
        adp: number(cmd, "Adp", path, 0xFFFF)?.unwrap_or(0) as u16,
        ado: required(cmd, "Ado", path, 0xFFFF)? as u16,
        data: child(cmd, "Data").map(|d| hex_bytes(d, path)).transpose()?.unwrap_or_default(),
        validates: child(cmd, "Validate").is_some(),
        comment: child(cmd, "Comment").and_then(|c| c.text()).unwrap_or("").trim().to_string(),
        at: pos_of(cmd),
    })
}

fn count(parent: Node<'_, '_>, name: &str) -> usize {
    children(parent, name).count()
}

fn slave(node: Node<'_, '_>, position: usize) -> Result<EniSlave, EniError> {
    let path = format!("Slave[{position}]");
    let info = child(node, "Info").ok_or_else(|| fail(node, format!("{path} has no Info")))?;
    let info_path = format!("{path}/Info");
    let mut coe_init_cmds = Vec::new();
    let mut elements = Vec::new();
    if let Some(mailbox) = child(node, "Mailbox") {
        if let Some(cmds) = child(mailbox, "CoE").and_then(|c| child(c, "InitCmds")) {
            for (k, cmd) in children(cmds, "InitCmd").enumerate() {
                coe_init_cmds.push(coe_init_cmd(cmd, &format!("{path}/Mailbox/CoE/InitCmds/InitCmd[{k}]"), None)?);
            }
        }
        elements.push(("Mailbox (Send/Recv areas, set up by the chip)", 1));
        for (tag, what) in
            [("BootStrap", "Mailbox/BootStrap"), ("EoE", "Mailbox/EoE"), ("FoE", "Mailbox/FoE"), ("SoE", "Mailbox/SoE")]
        {
            let n = count(mailbox, tag);
            if n > 0 {
                elements.push((what, n));
            }
        }
    }
    for (tag, what) in [("InitCmds", "InitCmds (register)"), ("ProcessData", "ProcessData"), ("DC", "DC")] {
        let n = match tag {
            "InitCmds" => child(node, tag).map_or(0, |c| count(c, "InitCmd")),
            _ => count(node, tag),
        };
        if n > 0 {
            elements.push((what, n));
        }
    }
    let process_data = child(node, "ProcessData").map(|p| process::process_data(p, &path)).transpose()?;
    let mailbox = child(node, "Mailbox").map(|m| process::mailbox(m, &path)).transpose()?;
    let dc = child(node, "DC").map(|d| process::dc(d, &path)).transpose()?;
    let mut register_init_cmds = Vec::new();
    if let Some(cmds) = child(node, "InitCmds") {
        for (k, cmd) in children(cmds, "InitCmd").enumerate() {
            register_init_cmds.push(register_init_cmd(cmd, &format!("{path}/InitCmds/InitCmd[{k}]"))?);
        }
    }
    Ok(EniSlave {
        process_data,
        mailbox,
        dc,
        register_init_cmds,
        name: child(info, "Name").and_then(|n| n.text()).unwrap_or("").trim().to_string(),
        vendor_id: required(info, "VendorId", &info_path, u64::from(u32::MAX))? as u32,
        product_code: required(info, "ProductCode", &info_path, u64::from(u32::MAX))? as u32,
        revision: number(info, "RevisionNo", &info_path, u64::from(u32::MAX))?.map(|v| v as u32),
        phys_addr: number(info, "PhysAddr", &info_path, 0xFFFF)?.map(|v| v as u16),
        coe_init_cmds,
        elements,
        at: pos_of(node),
    })
}

impl Eni {
    /// Parses ENI XML.
    pub fn parse(xml: &str) -> Result<Self, EniError> {
        let doc = Document::parse(xml).map_err(|e| {
            let pos = e.pos();
            EniError { at: TextPos { line: pos.row, column: pos.col }, message: format!("not well-formed XML: {e}") }
        })?;
        let root = doc.root_element();
        if !root.has_tag_name("EtherCATConfig") {
            return Err(fail(root, format!("the root element is {}, not EtherCATConfig", root.tag_name().name())));
        }
        let config = child(root, "Config").ok_or_else(|| fail(root, "EtherCATConfig has no Config".into()))?;
        let slaves = children(config, "Slave").enumerate().map(|(i, s)| slave(s, i)).collect::<Result<Vec<_>, _>>()?;
        if slaves.is_empty() {
            return Err(fail(config, "Config has no Slave".into()));
        }
        let mut elements = Vec::new();
        if let Some(master) = child(config, "Master") {
            let n = child(master, "InitCmds").map_or(0, |c| count(c, "InitCmd"));
            if n > 0 {
                elements.push(("Master/InitCmds", n));
            }
            if child(master, "MailboxStates").is_some() {
                elements.push(("Master/MailboxStates", 1));
            }
            if child(master, "EoE").is_some() {
                elements.push(("Master/EoE", 1));
            }
        }
        for tag in ["Cyclic", "ProcessImage"] {
            let n = count(config, tag);
            if n > 0 {
                elements.push((if tag == "Cyclic" { "Cyclic" } else { "ProcessImage" }, n));
            }
        }
        let process_image = child(config, "ProcessImage").map(process::process_image).transpose()?.unwrap_or_default();
        let cycle_us = match child(config, "Cyclic") {
            Some(c) => number(c, "CycleTime", "Cyclic", u64::from(u32::MAX))?.map(|v| v as u32),
            None => None,
        };
        Ok(Self { slaves, elements, process_image, cycle_us })
    }

    /// Reads and parses a file (lossy UTF-8, as ESI files are read).
    pub fn load(path: &std::path::Path) -> Result<Self, EniError> {
        let text = crate::esi::read_xml(path)
            .map_err(|e| EniError { at: TextPos::default(), message: format!("{}: {e}", path.display()) })?;
        Self::parse(&text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = r#"<?xml version="1.0"?>
<EtherCATConfig Version="1.3"><Config>
  <Slave><Info><Name>A</Name><VendorId>#x9a</VendorId><ProductCode>0x30924</ProductCode><RevisionNo>66592</RevisionNo></Info>
    <Mailbox><CoE><InitCmds>
      <InitCmd><Transition>PS</Transition><Ccs>1</Ccs><Index>24672</Index><SubIndex>0</SubIndex><Data>08</Data></InitCmd>
      <InitCmd CompleteAccess="1"><Transition>PS</Transition><Ccs>2</Ccs><Index>0x1c12</Index><Data>0100001a</Data></InitCmd>
      <InitCmd><Transition>SO</Transition><Ccs>1</Ccs><Index>0x6060</Index><Data>09</Data><Disabled>true</Disabled></InitCmd>
    </InitCmds></CoE></Mailbox>
  </Slave>
</Config></EtherCATConfig>"#;

    #[test]
    fn numbers_in_every_notation_and_both_ccs_conventions() {
        let eni = Eni::parse(SMALL).unwrap();
        let s = &eni.slaves[0];
        assert_eq!((s.vendor_id, s.product_code, s.revision), (0x9A, 0x30924, Some(0x10420)));
        let c = &s.coe_init_cmds;
        assert_eq!(
            (c[0].index, c[0].access.clone(), c[0].ccs),
            (0x6060, CoeAccess::Download(vec![8]), CcsConvention::Etg)
        );
        assert_eq!(c[1].ccs, CcsConvention::Soem);
        assert!(c[1].complete_access);
        assert_eq!(c[1].access, CoeAccess::Download(vec![1, 0, 0, 0x1A]));
        assert_eq!(c[2].transitions, vec![Transition::SafeOpOp]);
        assert!(c[2].disabled);
        assert_eq!(c[2].at.line, 7);
    }

    #[test]
    fn mistakes_name_the_element_and_the_line() {
        let e = Eni::parse(&SMALL.replace("<Ccs>1</Ccs><Index>24672", "<Ccs>7</Ccs><Index>24672")).unwrap_err();
        assert_eq!(e.at.line, 5, "{e}");
        assert!(e.message.contains("InitCmd[0]/Ccs 7"), "{e}");
        let e = Eni::parse(&SMALL.replace("#x9a", "#xZZ")).unwrap_err();
        assert!(e.to_string().contains("line 3") && e.message.contains("Info/VendorId \"#xZZ\""), "{e}");
        let e = Eni::parse(&SMALL.replace("<Data>08</Data>", "<Data>080</Data>")).unwrap_err();
        assert!(e.message.contains("odd number of hex digits"), "{e}");
        let e = Eni::parse(&SMALL.replace("<SubIndex>0</SubIndex>", "<SubIndex>300</SubIndex>")).unwrap_err();
        assert!(e.message.contains("SubIndex \"300\" is above 255"), "{e}");
        let e = Eni::parse(&SMALL[..SMALL.len() / 2]).unwrap_err();
        assert!(e.message.contains("not well-formed"), "{e}");
        let e = Eni::parse(&SMALL.replace("<Transition>SO</Transition>", "<Transition>XY</Transition>")).unwrap_err();
        assert!(e.message.contains("Transition \"XY\"") && e.at.line == 7, "{e}");
    }

    /// Exports often hold the whole file on one line: the column tells
    /// the element apart.
    #[test]
    fn a_one_line_file_names_the_column() {
        let one_line: String = SMALL.lines().map(str::trim).collect();
        let e = Eni::parse(&one_line.replace("<Ccs>1</Ccs><Index>24672", "<Ccs>7</Ccs><Index>24672")).unwrap_err();
        assert_eq!(e.at.line, 1, "{e}");
        let bad = one_line.replace("<Ccs>1</Ccs><Index>24672", "<Ccs>7</Ccs><Index>24672");
        let column = bad.find("<Ccs>7").unwrap() as u32 + 1;
        assert_eq!(e.at.column, column, "{e}");
        assert!(e.to_string().starts_with(&format!("line 1:{column}: ")), "{e}");
        let eni = Eni::parse(&one_line).unwrap();
        let c = &eni.slaves[0].coe_init_cmds;
        assert!(c[0].at < c[1].at && c[1].at < c[2].at && c[2].at.line == 1, "file order by column");
    }
}
