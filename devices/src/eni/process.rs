//! What an ENI says a slave's process data, mailbox and distributed clock
//! are (`Slave/ProcessData`, `Slave/Mailbox`, `Slave/DC`), and the process
//! image the configuration tool laid out (`Config/ProcessImage`,
//! ETG.2100 5.4): the names and bit offsets its variables have in the
//! tool's image.
//!
//! The tool's image is not the chip's: the ECM-XF packs each slave's
//! process data one after the other (manual v049 5.2, PDO_FIFO_OP), while
//! TwinCAT leaves room between sync units. What must agree is each
//! variable's offset from the start of its slave's data (`Send`/`Recv`
//! `BitStart`), which is what [`Eni::relative_variables`] gives.

use roxmltree::Node;

use super::{Eni, EniError, child, children, fail, number, pos_of};
use crate::esi::{EsiDevice, EsiPdo, EsiSm, parse_pdo};
use crate::od::ObjectDictionary;
use crate::sii::{protocol, sm_type};

/// A range of bits in the tool's image (`BitStart`, `BitLength`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BitRange {
    /// First bit.
    pub start: u32,
    /// Length in bits.
    pub len: u32,
}

/// `Slave/ProcessData`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct EniProcessData {
    /// `Send`: the slave's outputs in the tool's output image.
    pub outputs: Option<BitRange>,
    /// `Recv`: the slave's inputs in the tool's input image.
    pub inputs: Option<BitRange>,
    /// `Sm0`..`Sm7` as (number, settings), process-data ones only.
    pub sms: Vec<(u8, EsiSm)>,
    /// `RxPdo` (outputs), all the file lists; the assigned ones carry `sm`.
    pub rx_pdos: Vec<EsiPdo>,
    /// `TxPdo` (inputs).
    pub tx_pdos: Vec<EsiPdo>,
}

/// `Slave/Mailbox`: the areas and the protocols.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EniMailbox {
    /// `Send` (master to slave, SM0): start, length.
    pub out: (u16, u16),
    /// `Recv` / `Receive` (slave to master, SM1): start, length.
    pub input: (u16, u16),
    /// [`protocol`] bits from `Protocol` elements.
    pub protocols: u16,
}

/// `Slave/DC`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EniDc {
    /// This slave is the reference clock.
    pub reference_clock: bool,
    /// SYNC0 cycle, ns.
    pub cycle_time0_ns: u32,
    /// SYNC1 cycle (offset from SYNC0), ns.
    pub cycle_time1_ns: u32,
    /// SYNC0 shift, ns.
    pub shift_time_ns: u32,
}

/// One `ProcessImage/Inputs|Outputs/Variable`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EniVariable {
    /// `Name`, e.g. "WheelRearLeft.Inputs.Status word".
    pub name: String,
    /// In the output image (else the input image).
    pub output: bool,
    /// `BitOffs` in the tool's image.
    pub bit_offset: u32,
    /// `BitSize`.
    pub bit_size: u32,
    /// `DataType`, as written ("UINT"), "" when absent.
    pub data_type: String,
    /// Where it is in the file.
    pub at: crate::xml::TextPos,
}

fn u32_of(parent: Node<'_, '_>, name: &str, path: &str) -> Result<Option<u32>, EniError> {
    Ok(number(parent, name, path, u64::from(u32::MAX))?.map(|v| v as u32))
}

fn bit_range(parent: Node<'_, '_>, name: &str, path: &str) -> Result<Option<BitRange>, EniError> {
    let Some(n) = child(parent, name) else { return Ok(None) };
    let path = format!("{path}/{name}");
    let start = u32_of(n, "BitStart", &path)?.unwrap_or(0);
    let len = u32_of(n, "BitLength", &path)?.unwrap_or(0);
    Ok(Some(BitRange { start, len }))
}

pub(super) fn process_data(node: Node<'_, '_>, path: &str) -> Result<EniProcessData, EniError> {
    let path = format!("{path}/ProcessData");
    let mut sms = Vec::new();
    for sm in node.children().filter(|c| c.is_element()) {
        let tag = sm.tag_name().name();
        let Some(n) = tag.strip_prefix("Sm").and_then(|d| d.parse::<u8>().ok()).filter(|n| *n < 16) else {
            continue;
        };
        let p = format!("{path}/{tag}");
        let kind = match child(sm, "Type").and_then(|t| t.text()).map(str::trim) {
            Some("Outputs") => sm_type::OUTPUTS,
            Some("Inputs") => sm_type::INPUTS,
            Some("MBoxOut") => sm_type::MBX_OUT,
            Some("MBoxIn") => sm_type::MBX_IN,
            _ => sm_type::UNUSED,
        };
        let size = number(sm, "DefaultSize", &p, 0xFFFF)?.or(number(sm, "MaxSize", &p, 0xFFFF)?).unwrap_or(0);
        sms.push((
            n,
            EsiSm {
                kind,
                start: number(sm, "StartAddress", &p, 0xFFFF)?.unwrap_or(0) as u16,
                size: size as u16,
                control: number(sm, "ControlByte", &p, 0xFF)?.unwrap_or(0) as u8,
                enable: number(sm, "Enable", &p, 0xFF)?.unwrap_or(0) as u8,
            },
        ));
    }
    let pdos = |tag: &'static str| -> Result<Vec<EsiPdo>, EniError> {
        children(node, tag)
            .enumerate()
            .map(|(k, p)| parse_pdo(p).map_err(|e| fail(p, format!("{path}/{tag}[{k}]: {e}"))))
            .collect()
    };
    Ok(EniProcessData {
        outputs: bit_range(node, "Send", &path)?,
        inputs: bit_range(node, "Recv", &path)?,
        sms,
        rx_pdos: pdos("RxPdo")?,
        tx_pdos: pdos("TxPdo")?,
    })
}

pub(super) fn mailbox(node: Node<'_, '_>, path: &str) -> Result<EniMailbox, EniError> {
    let path = format!("{path}/Mailbox");
    let area = |name: &str| -> Result<(u16, u16), EniError> {
        let Some(n) = child(node, name) else { return Ok((0, 0)) };
        let p = format!("{path}/{name}");
        Ok((number(n, "Start", &p, 0xFFFF)?.unwrap_or(0) as u16, number(n, "Length", &p, 0xFFFF)?.unwrap_or(0) as u16))
    };
    let mut protocols = 0;
    for p in children(node, "Protocol") {
        protocols |= match p.text().map(str::trim) {
            Some("AoE") => protocol::AOE,
            Some("EoE") => protocol::EOE,
            Some("CoE") => protocol::COE,
            Some("FoE") => protocol::FOE,
            Some("SoE") => protocol::SOE,
            Some("VoE") => protocol::VOE,
            _ => 0,
        };
    }
    // A CoE element is CoE spoken even where no Protocol says it (SOEM's
    // sample lists both, a hand-written file may not).
    if child(node, "CoE").is_some() {
        protocols |= protocol::COE;
    }
    let input = if child(node, "Recv").is_some() { area("Recv")? } else { area("Receive")? };
    Ok(EniMailbox { out: area("Send")?, input, protocols })
}

pub(super) fn dc(node: Node<'_, '_>, path: &str) -> Result<EniDc, EniError> {
    let path = format!("{path}/DC");
    let flag = child(node, "ReferenceClock").and_then(|n| n.text()).map(str::trim);
    Ok(EniDc {
        reference_clock: matches!(flag, Some("1" | "true")),
        cycle_time0_ns: u32_of(node, "CycleTime0", &path)?.unwrap_or(0),
        cycle_time1_ns: u32_of(node, "CycleTime1", &path)?.unwrap_or(0),
        shift_time_ns: u32_of(node, "ShiftTime", &path)?.unwrap_or(0),
    })
}

pub(super) fn process_image(node: Node<'_, '_>) -> Result<Vec<EniVariable>, EniError> {
    let mut out = Vec::new();
    for (tag, output) in [("Inputs", false), ("Outputs", true)] {
        let Some(side) = child(node, tag) else { continue };
        for (k, v) in children(side, "Variable").enumerate() {
            let path = format!("ProcessImage/{tag}/Variable[{k}]");
            let name = child(v, "Name").and_then(|n| n.text()).unwrap_or("").trim().to_string();
            if name.is_empty() {
                return Err(fail(v, format!("{path} has no Name")));
            }
            let required = |what: &str| -> Result<u32, EniError> {
                u32_of(v, what, &path)?.ok_or_else(|| fail(v, format!("{path} ({name}) has no {what}")))
            };
            out.push(EniVariable {
                output,
                bit_offset: required("BitOffs")?,
                bit_size: required("BitSize")?,
                data_type: child(v, "DataType").and_then(|n| n.text()).unwrap_or("").trim().to_string(),
                at: pos_of(v),
                name,
            });
        }
    }
    Ok(out)
}

/// A variable of one slave, placed from the start of that slave's data.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SlaveVariable<'a> {
    /// The slave's position in the file (0-based).
    pub slave: usize,
    /// The variable.
    pub variable: &'a EniVariable,
    /// Bits from the start of the slave's outputs or inputs.
    pub relative_bit: u32,
}

impl Eni {
    /// The image's variables that belong to a slave (the name's first part
    /// is the slave's name and the offset falls in its `Send`/`Recv`
    /// range), each placed relative to that slave's data. The tool's own
    /// variables (`Inputs.Frm0State`, working-counter states, `DevState`)
    /// belong to none and are left out.
    pub fn relative_variables(&self) -> Vec<SlaveVariable<'_>> {
        let mut out = Vec::new();
        for v in &self.process_image {
            let owner = self.slaves.iter().enumerate().find_map(|(i, s)| {
                let prefix = v.name.strip_prefix(s.name.as_str())?.strip_prefix('.')?;
                let pd = s.process_data.as_ref()?;
                let range = if v.output { pd.outputs } else { pd.inputs }?;
                let inside = v.bit_offset >= range.start && v.bit_offset + v.bit_size <= range.start + range.len;
                (inside && !prefix.is_empty()).then_some((i, v.bit_offset - range.start))
            });
            if let Some((slave, relative_bit)) = owner {
                out.push(SlaveVariable { slave, variable: v, relative_bit });
            }
        }
        out
    }
}

impl super::EniSlave {
    /// The device this slave's entry describes, as an ESI would: identity,
    /// mailbox and process-data sync managers, PDOs with their default
    /// assignment (the ones the file puts on a sync manager), protocols.
    /// No dictionary: an ENI carries none. The simulator makes a slave of
    /// it (a device known only from an ENI, like the TwinCAT fixture's
    /// IMU), the daemon names process data from it.
    pub fn device(&self) -> EsiDevice {
        let mailbox = self.mailbox.unwrap_or_default();
        let mut sms = Vec::new();
        if mailbox.out.1 > 0 && mailbox.input.1 > 0 {
            // ETG.1000.4 control bytes: mailbox out (write, mailbox mode,
            // interrupt) and in (read).
            for (kind, (start, size), control) in
                [(sm_type::MBX_OUT, mailbox.out, 0x26), (sm_type::MBX_IN, mailbox.input, 0x22)]
            {
                sms.push(EsiSm { kind, start, size, control, enable: 1 });
            }
        }
        let pd = self.process_data.clone().unwrap_or_default();
        for (n, sm) in &pd.sms {
            let n = usize::from(*n);
            while sms.len() < n {
                sms.push(EsiSm { kind: sm_type::UNUSED, start: 0, size: 0, control: 0, enable: 0 });
            }
            if sms.len() == n {
                sms.push(sm.clone());
            }
        }
        let coe = mailbox.protocols & protocol::COE != 0;
        EsiDevice {
            type_name: self.name.clone(),
            product_code: self.product_code,
            revision: self.revision.unwrap_or(0),
            name: self.name.clone(),
            group: String::new(),
            sms,
            fmmus: Vec::new(),
            rx_pdos: pd.rx_pdos,
            tx_pdos: pd.tx_pdos,
            protocols: mailbox.protocols,
            pdo_assign: coe,
            pdo_config: coe,
            complete_access: true,
            sdo_info: false,
            data_link_layer: false,
            physics: String::new(),
            dc_modes: match self.dc {
                Some(_) => vec![("DC".to_string(), 0x300)],
                None => Vec::new(),
            },
            eeprom_bytes: 2048,
            config_data: Vec::new(),
            bootstrap: Vec::new(),
            categories: Vec::new(),
            dictionary: ObjectDictionary::default(),
            init_cmds: self.coe_init_cmds.clone(),
            warnings: Vec::new(),
        }
    }
}
