//! Slaves loaded from an EtherCAT Slave Information (ESI) XML file (ETG.2000):
//! identity, SyncManagers, PDOs, mailbox protocols, DC op modes, EEPROM
//! config data, and the object dictionary with defaults and access rights.
//!
//! Real ESI files are messy: numbers come as `#x1A`, `0x1A` or decimal
//! (`RevisionNo="100"`, `ProductCode="#x00100"`), defaults as
//! `<DefaultValue>` or little-endian hex `<DefaultData>`, arrays nested in
//! records. All of those are accepted; what cannot be understood is an error
//! naming the element.

use std::collections::HashMap;
use std::fmt;

use ecmxf_wire::payload::pdo::PdoEntry;
use roxmltree::{Document, Node};

use crate::od::{Access, DataType, Entry, Mappable, Object, ObjectDictionary, ObjectKind, StateSet};
use crate::sii::{self, General, MailboxArea, PdoEntryRecord, PdoRecord, Sii, SmRecord};

/// Why an ESI file could not be loaded.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum EsiError {
    /// Not well-formed XML.
    Xml(String),
    /// A required element is missing.
    Missing(&'static str),
    /// A number could not be read.
    Number {
        /// The element or attribute.
        what: &'static str,
        /// Its text.
        text: String,
    },
    /// A PDO given only as a reference to a named PDO (`<TxPdo Ref="..."/>`,
    /// early Beckhoff catalogues) that the file does not define: its
    /// entries, and so the device's process image, are unknown.
    PdoReference {
        /// The name referred to.
        name: String,
    },
    /// No device with that product code (and revision).
    NoSuchDevice {
        /// Product code asked for.
        product_code: u32,
        /// Revision asked for.
        revision: Option<u32>,
    },
}

impl fmt::Display for EsiError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Xml(e) => write!(f, "ESI is not well-formed XML: {e}"),
            Self::Missing(what) => write!(f, "ESI has no {what}"),
            Self::Number { what, text } => write!(f, "ESI {what} {text:?} is not a number"),
            Self::PdoReference { name } => write!(
                f,
                "its PDOs are references to {name:?}, a PDO this file does not define, so its process image is unknown"
            ),
            Self::NoSuchDevice { product_code, revision: Some(r) } => {
                write!(f, "ESI has no device with product code {product_code:#010x} and revision {r:#010x}")
            }
            Self::NoSuchDevice { product_code, revision: None } => {
                write!(f, "ESI has no device with product code {product_code:#010x}")
            }
        }
    }
}

impl std::error::Error for EsiError {}

pub use crate::xml::parse_number;

fn number(what: &'static str, text: Option<&str>) -> Result<u64, EsiError> {
    let text = text.ok_or(EsiError::Missing(what))?;
    parse_number(text).ok_or_else(|| EsiError::Number { what, text: text.into() })
}

fn child<'a, 'i>(n: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    n.children().find(|c| c.has_tag_name(name))
}

fn children<'a, 'i: 'a>(n: Node<'a, 'i>, name: &'a str) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    n.children().filter(move |c| c.has_tag_name(name))
}

fn text<'a>(n: Node<'a, '_>, name: &str) -> Option<&'a str> {
    child(n, name).and_then(|c| c.text()).map(str::trim)
}

fn hex_bytes(s: &str) -> Vec<u8> {
    let clean: String = s.chars().filter(char::is_ascii_hexdigit).collect();
    (0..clean.len() / 2).filter_map(|i| u8::from_str_radix(&clean[i * 2..i * 2 + 2], 16).ok()).collect()
}

/// A SyncManager of a device.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EsiSm {
    /// [`sii::sm_type`].
    pub kind: u8,
    /// Start address.
    pub start: u16,
    /// Default size.
    pub size: u16,
    /// Control byte.
    pub control: u8,
    /// Enable.
    pub enable: u8,
}

/// A PDO of a device.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EsiPdo {
    /// Index.
    pub index: u16,
    /// Name.
    pub name: String,
    /// Default SyncManager (default assignment), if any.
    pub sm: Option<u8>,
    /// Mapping cannot change.
    pub fixed: bool,
    /// Must be assigned.
    pub mandatory: bool,
    /// PDOs this one excludes.
    pub excludes: Vec<u16>,
    /// Entries (index 0 = gap).
    pub entries: Vec<(PdoEntry, String, DataType)>,
}

/// One device of an ESI file.
#[derive(Clone, Debug, PartialEq)]
pub struct EsiDevice {
    /// Type text (order name), e.g. "EK1100".
    pub type_name: String,
    /// Product code.
    pub product_code: u32,
    /// Revision.
    pub revision: u32,
    /// Display name.
    pub name: String,
    /// Group type.
    pub group: String,
    /// SyncManagers.
    pub sms: Vec<EsiSm>,
    /// FMMU usages.
    pub fmmus: Vec<String>,
    /// RxPDOs.
    pub rx_pdos: Vec<EsiPdo>,
    /// TxPDOs.
    pub tx_pdos: Vec<EsiPdo>,
    /// Mailbox protocol bits ([`sii::protocol`]).
    pub protocols: u16,
    /// CoE: PDO assignment configurable.
    pub pdo_assign: bool,
    /// CoE: PDO mapping configurable.
    pub pdo_config: bool,
    /// CoE: complete access supported (`CompleteAccess`, absent: yes).
    pub complete_access: bool,
    /// CoE: SDO information service (`SdoInfo`).
    pub sdo_info: bool,
    /// Mailbox data link layer (`<Mailbox DataLinkLayer>`).
    pub data_link_layer: bool,
    /// Port physics, one letter a port (`Physics="YY"`: Y/H = MII,
    /// K = E-bus).
    pub physics: String,
    /// DC op modes (name, AssignActivate).
    pub dc_modes: Vec<(String, u16)>,
    /// EEPROM size in bytes.
    pub eeprom_bytes: usize,
    /// EEPROM config data (words 0.. of the SII).
    pub config_data: Vec<u8>,
    /// Bootstrap mailbox bytes.
    pub bootstrap: Vec<u8>,
    /// Raw SII categories given in the ESI.
    pub categories: Vec<(u16, Vec<u8>)>,
    /// Object dictionary.
    pub dictionary: ObjectDictionary,
    /// CoE init commands (`Mailbox/CoE/InitCmd`): what a configuration
    /// tool writes into an ENI for this device (e.g. the mode of operation
    /// at PRE-OP -> SAFE-OP).
    pub init_cmds: Vec<crate::init_cmd::CoeInitCmd>,
    /// What the loader had to leave out or correct, in words a user can
    /// act on (a PDO listed twice, a PDO on a sync manager the device does
    /// not have).
    pub warnings: Vec<String>,
}

/// A parsed ESI file.
#[derive(Clone, Debug, PartialEq)]
pub struct EsiFile {
    /// Vendor id.
    pub vendor_id: u32,
    /// Vendor name.
    pub vendor_name: String,
    /// Devices.
    pub devices: Vec<EsiDevice>,
    /// Device entries that could not be read, each named (its `Type`
    /// text, else its `Name`, else its place in the file) with the reason:
    /// family files list passive terminals without a ProductCode, and one
    /// such entry must not make the file's other devices unusable.
    pub skipped: Vec<String>,
}

/// An ESI file's text, as every reader of one takes it: vendors' files are
/// not always UTF-8 (Latin-1 umlauts in names), and a byte that is not is
/// replaced, never a reason to refuse the file.
pub fn read_xml(path: &std::path::Path) -> std::io::Result<String> {
    std::fs::read(path).map(|b| String::from_utf8_lossy(&b).into_owned())
}

impl EsiFile {
    /// Parses ESI XML.
    pub fn parse(xml: &str) -> Result<Self, EsiError> {
        let doc = Document::parse(xml).map_err(|e| EsiError::Xml(e.to_string()))?;
        let root = doc.root_element();
        let vendor = child(root, "Vendor").ok_or(EsiError::Missing("Vendor"))?;
        let vendor_id = number("Vendor/Id", text(vendor, "Id"))? as u32;
        let vendor_name = text(vendor, "Name").unwrap_or_default().to_string();
        let devices_node = child(root, "Descriptions")
            .and_then(|d| child(d, "Devices"))
            .ok_or(EsiError::Missing("Descriptions/Devices"))?;
        let (mut devices, mut skipped, mut first_error) = (Vec::new(), Vec::new(), None);
        for (n, node) in children(devices_node, "Device").enumerate() {
            match parse_device(node) {
                Ok(d) => devices.push(d),
                Err(e) => {
                    let named = text(node, "Type").or_else(|| text(node, "Name")).filter(|t| !t.is_empty());
                    let label = named.map_or_else(|| format!("device #{}", n + 1), |t| format!("device {t:?}"));
                    skipped.push(format!("{label} skipped: {e}"));
                    first_error.get_or_insert(e);
                }
            }
        }
        // A file none of whose devices can be read is an error: its first.
        if let (true, Some(e)) = (devices.is_empty(), first_error) {
            return Err(e);
        }
        Ok(Self { vendor_id, vendor_name, devices, skipped })
    }

    /// The device with this product code and revision (the highest revision
    /// when none is given). Devices the file lists but could not be read
    /// ([`EsiFile::skipped`]) are not found.
    pub fn device(&self, product_code: u32, revision: Option<u32>) -> Result<&EsiDevice, EsiError> {
        self.devices
            .iter()
            .filter(|d| d.product_code == product_code && revision.is_none_or(|r| d.revision == r))
            .max_by_key(|d| d.revision)
            .ok_or(EsiError::NoSuchDevice { product_code, revision })
    }

    /// The device a slave reporting this product code and revision runs
    /// as: of that product's devices, the one with the [`nearest_revision`].
    /// `None` when the file has no device of that product (devices it could
    /// not read, e.g. without a ProductCode, match nothing).
    pub fn for_identity(&self, product_code: u32, revision: u32) -> Option<&EsiDevice> {
        let of_product = || self.devices.iter().filter(move |d| d.product_code == product_code);
        let chosen = nearest_revision(of_product().map(|d| d.revision), revision)?;
        of_product().find(|d| d.revision == chosen)
    }
}

/// Which of a product's described revisions a device reporting `scanned`
/// runs as, the way TwinCAT and the IgH master match a scanned slave to
/// its description: the same revision; else the highest one below it (a
/// newer revision keeps what older ones offered: ETG.2000's
/// `CheckRevisionNo="EQ_OR_G"` says a description applies to that revision
/// and later ones); else, a device older than every description, the
/// highest one (the file's current device).
pub fn nearest_revision(described: impl Iterator<Item = u32> + Clone, scanned: u32) -> Option<u32> {
    if described.clone().any(|r| r == scanned) {
        return Some(scanned);
    }
    described.clone().filter(|&r| r < scanned).max().or_else(|| described.max())
}

/// The CoE type of an ESI type name (`DINT`, `UINT`, `BIT3`, `STRING(8)`),
/// from its size when the name is not a standard one.
pub fn data_type(name: &str, bits: u32) -> DataType {
    match name.trim() {
        "BOOL" | "BIT" | "BIT1" => DataType::Bool,
        "SINT" => DataType::Int8,
        "INT" => DataType::Int16,
        "DINT" => DataType::Int32,
        "LINT" => DataType::Int64,
        "USINT" | "BYTE" => DataType::UInt8,
        "UINT" | "WORD" => DataType::UInt16,
        "UDINT" | "DWORD" => DataType::UInt32,
        "ULINT" => DataType::UInt64,
        "REAL" => DataType::Real32,
        "LREAL" => DataType::Real64,
        t if t.starts_with("BIT") && t[3..].parse::<u8>().is_ok_and(|n| (2..=8).contains(&n)) => {
            DataType::Bits(t[3..].parse().unwrap_or(8))
        }
        t if t.starts_with("STRING") => DataType::VisibleString((bits / 8) as u16),
        _ => match bits {
            1 => DataType::Bool,
            8 => DataType::UInt8,
            16 => DataType::UInt16,
            32 => DataType::UInt32,
            64 => DataType::UInt64,
            n if n < 8 => DataType::Bits(n as u8),
            n => DataType::OctetString(n.div_ceil(8) as u16),
        },
    }
}

pub(crate) fn parse_pdo(n: Node<'_, '_>) -> Result<EsiPdo, EsiError> {
    if let (Some(name), None) = (n.attribute("Ref"), child(n, "Index")) {
        return Err(EsiError::PdoReference { name: name.to_string() });
    }
    let flag = |a: &str| n.attribute(a).is_some_and(|v| v == "1" || v.eq_ignore_ascii_case("true"));
    let mut entries = Vec::new();
    for e in children(n, "Entry") {
        let index = number("PDO Entry/Index", text(e, "Index"))? as u16;
        let bits = number("PDO Entry/BitLen", text(e, "BitLen"))? as u8;
        let subindex =
            if index == 0 { 0 } else { number("PDO Entry/SubIndex", text(e, "SubIndex")).unwrap_or(0) as u8 };
        let dtype = data_type(text(e, "DataType").unwrap_or(""), bits.into());
        entries.push((PdoEntry { index, subindex, bits }, text(e, "Name").unwrap_or_default().to_string(), dtype));
    }
    Ok(EsiPdo {
        index: number("PDO Index", text(n, "Index"))? as u16,
        name: text(n, "Name").unwrap_or_default().to_string(),
        sm: n.attribute("Sm").and_then(parse_number).map(|v| v as u8),
        fixed: flag("Fixed"),
        mandatory: flag("Mandatory"),
        excludes: children(n, "Exclude").filter_map(|x| x.text().and_then(parse_number)).map(|v| v as u16).collect(),
        entries,
    })
}

fn parse_device(d: Node<'_, '_>) -> Result<EsiDevice, EsiError> {
    let ty = child(d, "Type").ok_or(EsiError::Missing("Device/Type"))?;
    let product_code = number("ProductCode", ty.attribute("ProductCode"))? as u32;
    let revision = number("RevisionNo", ty.attribute("RevisionNo").or(Some("0")))? as u32;
    let mut sms = Vec::new();
    for sm in children(d, "Sm") {
        let kind = match sm.text().map(str::trim) {
            Some("MBoxOut") => sii::sm_type::MBX_OUT,
            Some("MBoxIn") => sii::sm_type::MBX_IN,
            Some("Outputs") => sii::sm_type::OUTPUTS,
            Some("Inputs") => sii::sm_type::INPUTS,
            _ => sii::sm_type::UNUSED,
        };
        let attr = |a: &'static str| sm.attribute(a).map(|t| number(a, Some(t))).transpose();
        sms.push(EsiSm {
            kind,
            start: attr("StartAddress")?.unwrap_or(0) as u16,
            size: attr("DefaultSize")?.unwrap_or(0) as u16,
            control: attr("ControlByte")?.unwrap_or(0) as u8,
            enable: attr("Enable")?.unwrap_or(0) as u8,
        });
    }
    let mut protocols = 0;
    let (mut pdo_assign, mut pdo_config, mut complete_access, mut sdo_info) = (false, false, true, false);
    let yes = |v: &str| v == "1" || v.eq_ignore_ascii_case("true");
    let mut data_link_layer = false;
    let mut init_cmds = Vec::new();
    let mut init_warnings = Vec::new();
    if let Some(mb) = child(d, "Mailbox") {
        data_link_layer = mb.attribute("DataLinkLayer").is_some_and(yes);
        for (name, bit) in [
            ("AoE", sii::protocol::AOE),
            ("EoE", sii::protocol::EOE),
            ("CoE", sii::protocol::COE),
            ("FoE", sii::protocol::FOE),
            ("SoE", sii::protocol::SOE),
            ("VoE", sii::protocol::VOE),
        ] {
            if let Some(p) = child(mb, name) {
                protocols |= bit;
                if name == "CoE" {
                    let on = |a: &str| p.attribute(a).is_some_and(|v| v == "1" || v.eq_ignore_ascii_case("true"));
                    pdo_assign = on("PdoAssign");
                    pdo_config = on("PdoConfig");
                    sdo_info = on("SdoInfo");
                    // Absent means the device does not say; only an
                    // explicit "0"/"false" turns complete access off.
                    complete_access =
                        p.attribute("CompleteAccess").is_none_or(|v| v == "1" || v.eq_ignore_ascii_case("true"));
                    for (k, cmd) in children(p, "InitCmd").enumerate() {
                        match crate::init_cmd::coe_init_cmd(cmd, &format!("Mailbox/CoE/InitCmd[{k}]"), Some(1)) {
                            Ok(c) => init_cmds.push(c),
                            Err(e) => init_warnings.push(format!("init command left out: {e}")),
                        }
                    }
                }
            }
        }
    }
    let dc_modes = child(d, "Dc")
        .map(|dc| {
            children(dc, "OpMode")
                .map(|m| {
                    (
                        text(m, "Name").unwrap_or_default().to_string(),
                        text(m, "AssignActivate").and_then(parse_number).unwrap_or(0) as u16,
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    let eeprom = child(d, "Eeprom");
    let eeprom_bytes = eeprom.and_then(|e| text(e, "ByteSize")).and_then(parse_number).unwrap_or(256) as usize;
    let config_data = eeprom.and_then(|e| text(e, "ConfigData")).map(hex_bytes).unwrap_or_default();
    let bootstrap = eeprom.and_then(|e| text(e, "BootStrap")).map(hex_bytes).unwrap_or_default();
    let categories = eeprom
        .map(|e| {
            children(e, "Category")
                .filter_map(|c| Some((text(c, "CatNo").and_then(parse_number)? as u16, hex_bytes(text(c, "Data")?))))
                .collect()
        })
        .unwrap_or_default();
    let dictionary =
        child(d, "Profile").and_then(|p| child(p, "Dictionary")).map(parse_dictionary).transpose()?.unwrap_or_default();
    let mut warnings = Vec::new();
    let mut rx_pdos: Vec<EsiPdo> = children(d, "RxPdo").map(parse_pdo).collect::<Result<_, _>>()?;
    let mut tx_pdos: Vec<EsiPdo> = children(d, "TxPdo").map(parse_pdo).collect::<Result<_, _>>()?;
    for (kind, list) in [("RxPdo", &mut rx_pdos), ("TxPdo", &mut tx_pdos)] {
        check_pdos(kind, list, sms.len(), &mut warnings);
    }
    Ok(EsiDevice {
        type_name: ty.text().unwrap_or_default().trim().to_string(),
        product_code,
        revision,
        name: text(d, "Name").unwrap_or_default().to_string(),
        group: text(d, "GroupType").unwrap_or_default().to_string(),
        sms,
        fmmus: children(d, "Fmmu").filter_map(|f| f.text()).map(|t| t.trim().to_string()).collect(),
        rx_pdos,
        tx_pdos,
        protocols,
        pdo_assign,
        pdo_config,
        complete_access,
        sdo_info,
        data_link_layer,
        physics: d.attribute("Physics").unwrap_or_default().to_string(),
        dc_modes,
        eeprom_bytes,
        config_data,
        bootstrap,
        categories,
        dictionary,
        init_cmds,
        warnings: {
            warnings.append(&mut init_warnings);
            warnings
        },
    })
}

/// ETG.2000 gives each PDO one index and, for a default assignment, a sync
/// manager of the device. A PDO listed again under the same index (Beckhoff
/// EL2252 lists 0x1602 twice) keeps its first description; a PDO on a sync
/// manager the device does not have is not assigned. Both are said.
fn check_pdos(kind: &str, list: &mut Vec<EsiPdo>, sms: usize, warnings: &mut Vec<String>) {
    let mut seen = Vec::new();
    list.retain(|p| {
        if seen.contains(&p.index) {
            warnings.push(format!("{kind} {:#06x} is listed twice; the first description is used", p.index));
            return false;
        }
        seen.push(p.index);
        true
    });
    for p in list.iter_mut() {
        if let Some(sm) = p.sm.filter(|sm| sms > 0 && usize::from(*sm) >= sms) {
            warnings.push(format!(
                "{kind} {:#06x} is assigned to sync manager {sm}, and the device has {sms}: not assigned",
                p.index
            ));
            p.sm = None;
        }
    }
}

/// A `<DataType>` of the dictionary: a base type with array bounds, or
/// sub-items.
struct EsiType {
    base: Option<String>,
    subs: Vec<SubItem>,
    /// (lower bound, elements) of an array type.
    array: Option<(u8, u8)>,
}

/// A sub-item of a data type.
struct SubItem {
    subindex: Option<u8>,
    name: String,
    type_name: String,
    bits: u32,
    access: Access,
    mappable: Mappable,
}

fn access_of(flags: Option<Node<'_, '_>>) -> (Access, Mappable) {
    let Some(f) = flags else { return (Access::RO, Mappable::No) };
    let acc = child(f, "Access");
    let text = acc.and_then(|a| a.text()).unwrap_or("ro").trim().to_ascii_lowercase();
    let restrict = |attr: &str| -> StateSet {
        match acc.and_then(|a| a.attribute(attr)).map(str::to_ascii_lowercase).as_deref() {
            Some("preop") => StateSet::PREOP,
            Some("preop_safeop") => StateSet { preop: true, safeop: true, op: false },
            Some("preop_op") => StateSet { preop: true, safeop: false, op: true },
            Some("safeop_op") => StateSet { preop: false, safeop: true, op: true },
            _ => StateSet::ALL,
        }
    };
    let read = if text.contains('r') { restrict("ReadRestrictions") } else { StateSet::NONE };
    let write = if text.contains('w') { restrict("WriteRestrictions") } else { StateSet::NONE };
    let mapping = match child(f, "PdoMapping").and_then(|m| m.text()).map(|t| t.trim().to_ascii_uppercase()).as_deref()
    {
        Some("R") => Mappable::Rx,
        Some("T") => Mappable::Tx,
        Some("RT" | "TR") => Mappable::Both,
        _ => Mappable::No,
    };
    (Access { read, write }, mapping)
}

fn default_of(info: Option<Node<'_, '_>>, dtype: DataType) -> Option<Vec<u8>> {
    let info = info?;
    let n = dtype.bytes();
    if let Some(v) = text(info, "DefaultValue").and_then(parse_number) {
        let mut b = v.to_le_bytes().to_vec();
        b.resize(n.max(1), 0);
        b.truncate(n);
        return Some(b);
    }
    if let Some(d) = text(info, "DefaultData") {
        let mut b = hex_bytes(d);
        b.resize(n, 0);
        return Some(b);
    }
    text(info, "DefaultString").map(|s| s.as_bytes().to_vec())
}

fn parse_dictionary(dict: Node<'_, '_>) -> Result<ObjectDictionary, EsiError> {
    let mut types: HashMap<String, EsiType> = HashMap::new();
    if let Some(dts) = child(dict, "DataTypes") {
        for dt in children(dts, "DataType") {
            let name = text(dt, "Name").unwrap_or_default().to_string();
            let base = text(dt, "BaseType").map(str::to_string);
            let array = child(dt, "ArrayInfo").map(|a| {
                (
                    text(a, "LBound").and_then(parse_number).unwrap_or(1) as u8,
                    text(a, "Elements").and_then(parse_number).unwrap_or(0) as u8,
                )
            });
            let subs = children(dt, "SubItem")
                .map(|s| {
                    let (access, mappable) = access_of(child(s, "Flags"));
                    SubItem {
                        subindex: text(s, "SubIdx").and_then(parse_number).map(|v| v as u8),
                        name: text(s, "Name").unwrap_or_default().to_string(),
                        type_name: text(s, "Type").unwrap_or_default().to_string(),
                        bits: text(s, "BitSize").and_then(parse_number).unwrap_or(0) as u32,
                        access,
                        mappable,
                    }
                })
                .collect();
            types.insert(name, EsiType { base, subs, array });
        }
    }
    let mut od = ObjectDictionary::new();
    let Some(objects) = child(dict, "Objects") else { return Ok(od) };
    for o in children(objects, "Object") {
        let index = number("Object/Index", text(o, "Index"))? as u16;
        let name = text(o, "Name").unwrap_or_default().to_string();
        let type_name = text(o, "Type").unwrap_or_default().to_string();
        let bits = text(o, "BitSize").and_then(parse_number).unwrap_or(0) as u32;
        let (access, mappable) = access_of(child(o, "Flags"));
        let info = child(o, "Info");
        match types.get(&type_name) {
            Some(EsiType { subs, .. }) if !subs.is_empty() => {
                // A record (or an array described by sub-items).
                let defaults: Vec<Node<'_, '_>> = info.map(|i| children(i, "SubItem").collect()).unwrap_or_default();
                let mut entries = std::collections::BTreeMap::new();
                let mut next_sub = 0u8;
                // Whether the ESI gives subindex 0 a value of its own.
                let mut sub0_given = false;
                for (k, s) in subs.iter().enumerate() {
                    if let Some(EsiType { base: Some(base), array: Some((lbound, count)), .. }) =
                        types.get(&s.type_name)
                    {
                        // An array type inside the record: one subindex per
                        // element.
                        let each = s.bits / u32::from((*count).max(1));
                        for e in 0..*count {
                            let sub = lbound + e;
                            let dtype = data_type(base, each);
                            let dflt =
                                defaults.get(usize::from(sub)).and_then(|n| default_of(child(*n, "Info"), dtype));
                            let mut en =
                                Entry::new(&format!("{} {}", s.name, e + 1), dtype, s.access).mappable(s.mappable);
                            if let Some(v) = dflt {
                                en.value = v;
                            }
                            entries.insert(sub, en);
                            next_sub = sub + 1;
                        }
                        continue;
                    }
                    let sub = s.subindex.unwrap_or(next_sub);
                    next_sub = sub.wrapping_add(1);
                    let dtype = data_type(&s.type_name, s.bits);
                    let dflt = defaults.get(k).and_then(|n| default_of(child(*n, "Info"), dtype));
                    let mut en = Entry::new(&s.name, dtype, s.access).mappable(s.mappable);
                    if let Some(v) = dflt {
                        en.value = v;
                        sub0_given |= sub == 0;
                    }
                    entries.insert(sub, en);
                }
                // Subindex 0 without a value in the ESI counts the entries;
                // one the ESI sets (0x1003:0 = 0: no errors logged yet) is
                // kept as written.
                if let Some(e0) = entries.get_mut(&0).filter(|_| !sub0_given) {
                    if e0.int() == 0 {
                        let highest = entries.keys().copied().max().unwrap_or(0);
                        if let Some(e0) = entries.get_mut(&0) {
                            e0.set_int(highest.into());
                        }
                    }
                }
                od.insert(index, Object { name, kind: ObjectKind::Record, entries });
            }
            _ => {
                let base = types.get(&type_name).and_then(|t| t.base.clone()).unwrap_or(type_name.clone());
                let dtype = data_type(&base, bits);
                let mut e = Entry::new(&name, dtype, access).mappable(mappable);
                if let Some(v) = default_of(info, dtype) {
                    e.value = v;
                }
                od.insert(index, Object::var(&name, e));
            }
        }
    }
    Ok(od)
}

impl EsiDevice {
    /// The SII image generated from this description.
    pub fn sii_image(&self, vendor_id: u32) -> Vec<u8> {
        let mut config = [0u16; 8];
        for (i, w) in config.iter_mut().enumerate().take(7) {
            let lo = self.config_data.get(i * 2).copied().unwrap_or(0);
            let hi = self.config_data.get(i * 2 + 1).copied().unwrap_or(0);
            *w = u16::from_le_bytes([lo, hi]);
        }
        let out = self.sms.iter().find(|s| s.kind == sii::sm_type::MBX_OUT);
        let inp = self.sms.iter().find(|s| s.kind == sii::sm_type::MBX_IN);
        let mailbox = match (out, inp) {
            (Some(o), Some(i)) => {
                MailboxArea { rx_offset: o.start, rx_size: o.size, tx_offset: i.start, tx_size: i.size }
            }
            _ => MailboxArea::default(),
        };
        let bootstrap = if self.bootstrap.len() >= 8 {
            let w = |i: usize| u16::from_le_bytes([self.bootstrap[i], self.bootstrap[i + 1]]);
            MailboxArea { rx_offset: w(0), rx_size: w(2), tx_offset: w(4), tx_size: w(6) }
        } else {
            mailbox
        };
        // Strings (ETG.2010 category 10): the device's, then every PDO and
        // PDO entry name, each once; at most 255 (a string index is a byte).
        let mut strings: Vec<Vec<u8>> = Vec::new();
        let mut intern = |text: &str| -> u8 {
            if text.is_empty() {
                return 0;
            }
            if let Some(p) = strings.iter().position(|x| x == text.as_bytes()) {
                return p as u8 + 1;
            }
            if strings.len() >= 255 {
                return 0;
            }
            strings.push(text.as_bytes().to_vec());
            strings.len() as u8
        };
        let (group, order, name) = (intern(&self.group), intern(&self.type_name), intern(&self.name));
        let coe = self.protocols & sii::protocol::COE != 0;
        let mut pdo_records = |pdos: &[EsiPdo]| -> Vec<PdoRecord> {
            pdos.iter()
                .map(|p| PdoRecord {
                    index: p.index,
                    sm: p.sm.unwrap_or(0xFF),
                    name: intern(&p.name),
                    flags: u16::from(p.fixed) << 4 | u16::from(p.mandatory),
                    entries: p
                        .entries
                        .iter()
                        .map(|(e, n, t)| PdoEntryRecord {
                            index: e.index,
                            subindex: e.subindex,
                            name: intern(n),
                            data_type: t.code() as u8,
                            bits: e.bits,
                            ..Default::default()
                        })
                        .collect(),
                    ..Default::default()
                })
                .collect()
        };
        // PDOs described by CoE objects are not repeated in the SII.
        let (rx_pdos, tx_pdos) =
            if coe { (Vec::new(), Vec::new()) } else { (pdo_records(&self.rx_pdos), pdo_records(&self.tx_pdos)) };
        // Physical ports (ETG.2010 General): 4 bits a port, 1 = MII, 3 = E-bus.
        let physical_port = self.physics.chars().take(4).enumerate().fold(0u16, |w, (i, c)| {
            let code = match c {
                'Y' | 'H' => 1,
                'K' => 3,
                _ => 0,
            };
            w | code << (4 * i)
        });
        let mut s = Sii {
            config,
            vendor_id,
            product_code: self.product_code,
            revision: self.revision,
            serial: 0,
            bootstrap_mailbox: bootstrap,
            mailbox,
            protocols: self.protocols,
            size_word: (self.eeprom_bytes * 8 / 1024).saturating_sub(1) as u16,
            version: 1,
            general: Some(General {
                group,
                order,
                name,
                // CoE details (ETG.2010 General): bit0 SDO, bit1 SDO info,
                // bit2 PDO assign, bit3 PDO config, bit5 complete access.
                coe_details: if coe {
                    0x01 | u8::from(self.sdo_info) << 1
                        | u8::from(self.pdo_assign) << 2
                        | u8::from(self.pdo_config) << 3
                        | u8::from(self.complete_access) << 5
                } else {
                    0
                },
                foe_details: u8::from(self.protocols & sii::protocol::FOE != 0),
                eoe_details: u8::from(self.protocols & sii::protocol::EOE != 0),
                // Flags bit2: mailbox data link layer.
                flags: u8::from(self.data_link_layer) << 2,
                physical_port: if self.physics.is_empty() { 0x0011 } else { physical_port },
                ..General::default()
            }),
            strings,
            fmmu: self
                .fmmus
                .iter()
                .map(|f| match f.as_str() {
                    "Outputs" => 1,
                    "Inputs" => 2,
                    "MBoxState" => 3,
                    _ => 0,
                })
                .collect(),
            sync_managers: self
                .sms
                .iter()
                .map(|m| SmRecord {
                    start: m.start,
                    length: m.size,
                    control: m.control,
                    status: 0,
                    enable: m.enable,
                    kind: m.kind,
                })
                .collect(),
            rx_pdos,
            tx_pdos,
            ..Sii::default()
        };
        for (cat, data) in &self.categories {
            match *cat {
                sii::category::GENERAL | sii::category::STRINGS => {}
                sii::category::DC => s.dc = Some(data.clone()),
                other => s.other.push((other, data.clone())),
            }
        }
        // The size word (Kbit - 1) must cover the image: an ESI's ByteSize
        // can be smaller than what its categories take.
        let first = s.to_bytes(self.eeprom_bytes.max(128));
        let bytes = first.len().max(self.eeprom_bytes).div_ceil(128) * 128;
        let size_word = (bytes * 8 / 1024).saturating_sub(1) as u16;
        if size_word == s.size_word && first.len() == bytes {
            return first;
        }
        s.size_word = size_word;
        s.to_bytes(bytes)
    }

    /// The default assignment: PDOs with a SyncManager, skipping those
    /// excluded by ones already chosen.
    pub fn default_assignment(pdos: &[EsiPdo]) -> Vec<u16> {
        let mut chosen: Vec<u16> = Vec::new();
        for p in pdos.iter().filter(|p| p.sm.is_some()) {
            let excluded = chosen.iter().any(|c| pdos.iter().any(|q| q.index == *c && q.excludes.contains(&p.index)));
            if !excluded {
                chosen.push(p.index);
            }
        }
        chosen
    }

    /// The PDOs of the default assignment, in assignment order.
    pub fn assigned_pdos(pdos: &[EsiPdo]) -> Vec<&EsiPdo> {
        let chosen = Self::default_assignment(pdos);
        chosen.iter().filter_map(|i| pdos.iter().find(|p| p.index == *i)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messy_numbers() {
        assert_eq!(parse_number("#x00100"), Some(0x100));
        assert_eq!(parse_number("100"), Some(100));
        assert_eq!(parse_number(" 0x1A "), Some(0x1A));
        assert_eq!(parse_number("#X1a"), Some(0x1A));
        assert_eq!(parse_number("-1"), Some(u64::MAX));
        assert_eq!(parse_number("x12"), None);
    }

    #[test]
    fn a_pdo_listed_twice_or_on_a_missing_sync_manager_is_said() {
        let pdo = |index, sm| EsiPdo {
            index,
            name: String::new(),
            sm,
            fixed: true,
            mandatory: false,
            excludes: Vec::new(),
            entries: Vec::new(),
        };
        let mut list = vec![pdo(0x1A00, Some(3)), pdo(0x1A00, Some(3)), pdo(0x1A01, Some(5))];
        let mut warnings = Vec::new();
        check_pdos("TxPdo", &mut list, 4, &mut warnings);
        assert_eq!(list.iter().map(|p| (p.index, p.sm)).collect::<Vec<_>>(), [(0x1A00, Some(3)), (0x1A01, None)]);
        assert!(warnings[0].contains("0x1a00 is listed twice"), "{warnings:?}");
        assert!(warnings[1].contains("sync manager 5, and the device has 4"), "{warnings:?}");
    }

    const TERMINAL: &str = r##"<EtherCATInfo><Vendor><Id>2</Id></Vendor><Descriptions><Devices>
        <Device Physics="YK"><Type ProductCode="#x1" RevisionNo="1">T1</Type><Name>Terminal</Name>
          <Sm ControlByte="#x26" Enable="1" StartAddress="#x1000" DefaultSize="128">MBoxOut</Sm>
          <Sm ControlByte="#x22" Enable="1" StartAddress="#x1080" DefaultSize="128">MBoxIn</Sm>
          <Sm ControlByte="#x00" Enable="1" StartAddress="#x1100">Inputs</Sm>
          <TxPdo Sm="2"><Index>#x1a00</Index><Name>Channel 1</Name>
            <Entry><Index>#x6000</Index><SubIndex>1</SubIndex><BitLen>32</BitLen><Name>Counter</Name><DataType>DINT</DataType></Entry>
          </TxPdo>
          <Mailbox DataLinkLayer="true"><CoE SdoInfo="true" PdoAssign="false" PdoConfig="true" CompleteAccess="false"/></Mailbox>
          <Eeprom><ByteSize>128</ByteSize><ConfigData>0C0D</ConfigData></Eeprom>
        </Device></Devices></Descriptions></EtherCATInfo>"##;

    #[test]
    fn a_device_entry_without_a_product_code_is_skipped_by_name_and_the_rest_stays_usable() {
        // Beckhoff family files list passive terminals with no ProductCode.
        let family = TERMINAL.replace(
            "<Devices>",
            "<Devices><Device><Type>EL9011</Type><Name>End terminal</Name></Device>\
             <Device><Name>nameless</Name></Device><Device/>",
        );
        let f = EsiFile::parse(&family).unwrap();
        assert_eq!(f.devices.len(), 1);
        assert_eq!(f.device(1, Some(1)).unwrap().type_name, "T1");
        assert_eq!(f.skipped.len(), 3, "{:?}", f.skipped);
        assert!(f.skipped[0].contains("\"EL9011\"") && f.skipped[0].contains("ProductCode"), "{:?}", f.skipped);
        assert!(f.skipped[1].contains("\"nameless\""), "{:?}", f.skipped);
        assert!(f.skipped[2].contains("device #3"), "{:?}", f.skipped);
        // Only unreadable devices: the file is an error, the first one's.
        let none = r#"<EtherCATInfo><Vendor><Id>2</Id></Vendor><Descriptions><Devices>
            <Device><Type>EL9011</Type></Device></Devices></Descriptions></EtherCATInfo>"#;
        assert_eq!(EsiFile::parse(none), Err(EsiError::Missing("ProductCode")));
    }

    /// Early Beckhoff catalogues (incoming/esi_beckhoff_EtherCAT_Terminals)
    /// give PDOs as `<TxPdo Ref="DigInputBit"/>` to names they never
    /// define: such a device is skipped with that reason, the rest loads.
    #[test]
    fn a_device_whose_pdos_are_references_the_file_does_not_define_is_skipped_saying_so() {
        let family = TERMINAL.replace(
            "<Devices>",
            r##"<Devices><Device><Type ProductCode="#x3ea3052" RevisionNo="#x270b0000">EL1002</Type>
              <TxPdo Ref="DigInputBit" Chn="0" Fixed="1" Mandatory="1" Sm="0"/></Device>"##,
        );
        let f = EsiFile::parse(&family).unwrap();
        assert_eq!(f.devices.len(), 1);
        assert_eq!(f.skipped.len(), 1, "{:?}", f.skipped);
        let why = &f.skipped[0];
        assert!(why.contains("\"EL1002\"") && why.contains("references to \"DigInputBit\""), "{why}");
        assert!(why.contains("does not define"), "{why}");
    }

    #[test]
    fn the_sii_an_esi_implies_keeps_names_details_physics_and_its_size() {
        let f = EsiFile::parse(TERMINAL).unwrap();
        let mut d = f.devices[0].clone();
        let image = Sii::parse(&d.sii_image(2)).unwrap();
        let g = image.general.clone().unwrap();
        assert_eq!(g.coe_details, 0x01 | 0x02 | 0x08, "SDO, SDO info, PDO config; no assign, no complete access");
        assert_eq!(g.flags & 0x04, 0x04, "data link layer");
        assert_eq!(g.physical_port, 0x0031, "Y = MII on port 0, K = E-bus on port 1");
        // Without CoE the PDOs are in the SII, with their names and types.
        d.protocols = 0;
        let bytes = d.sii_image(2);
        let image = Sii::parse(&bytes).unwrap();
        let pdo = &image.tx_pdos[0];
        assert_eq!(image.string(pdo.name), Some(&b"Channel 1"[..]));
        assert_eq!(image.string(pdo.entries[0].name), Some(&b"Counter"[..]));
        assert_eq!(pdo.entries[0].data_type, 0x04, "DINT");
        // ByteSize 128 is too small for the categories: the size word
        // covers the image instead.
        assert!(bytes.len() > 128);
        assert_eq!((usize::from(image.size_word) + 1) * 128, bytes.len());
    }

    #[test]
    fn a_scanned_revision_picks_its_own_description_else_the_nearest_lower_else_the_highest() {
        let revisions = [0x0010_0000u32, 0x0012_0000, 0x0014_0000];
        let pick = |scanned| nearest_revision(revisions.iter().copied(), scanned);
        assert_eq!(pick(0x0012_0000), Some(0x0012_0000), "the same revision");
        assert_eq!(pick(0x0013_0005), Some(0x0012_0000), "the nearest lower");
        assert_eq!(pick(0x0020_0000), Some(0x0014_0000), "newer than every description");
        assert_eq!(pick(0x0001_0000), Some(0x0014_0000), "older than every description: the highest");
        assert_eq!(nearest_revision(std::iter::empty(), 1), None);
        let f = EsiFile::parse(TERMINAL).unwrap();
        assert_eq!(f.for_identity(1, 7).map(|d| d.revision), Some(1));
        assert!(f.for_identity(2, 1).is_none(), "another product");
    }

    #[test]
    fn errors_name_what_is_wrong() {
        assert!(matches!(EsiFile::parse("<EtherCATInfo>"), Err(EsiError::Xml(_))));
        assert_eq!(EsiFile::parse("<EtherCATInfo/>"), Err(EsiError::Missing("Vendor")));
        let bad = "<EtherCATInfo><Vendor><Id>#xZZ</Id></Vendor></EtherCATInfo>";
        assert_eq!(EsiFile::parse(bad), Err(EsiError::Number { what: "Vendor/Id", text: "#xZZ".into() }));
    }
}
