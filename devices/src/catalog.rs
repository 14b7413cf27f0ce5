//! A folder of device descriptions read as one catalogue: every device of
//! every ESI file (`*.xml`) and every SII dump (`*.bin`), each with what it
//! says a slave of its kind shows on the bus — identity, name, mailbox
//! protocols, the PDO entries of its default assignment (ETG.2000 `Sm`
//! attribute / SII category 50/51 with an SM the device has), the types it
//! declares and the objects of its dictionary.
//!
//! It answers "what must a master report for this device?" without a bus,
//! so a test can hold a running master to every file that lands in the
//! folder (the conformance tests), and a tool can find the description
//! that matches a slave's identity.

use std::path::{Path, PathBuf};

use crate::esi::{EsiDevice, EsiFile, EsiPdo};
use crate::od::DataType;
use crate::sii::{self, PdoRecord, Sii};

/// Where a device's description comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Origin {
    /// One `<Device>` of an ESI file, selected by product code and revision.
    Esi {
        /// The ESI file.
        file: PathBuf,
    },
    /// An SII EEPROM dump.
    Sii {
        /// The dump.
        file: PathBuf,
    },
}

impl Origin {
    /// The file the description is in.
    pub fn file(&self) -> &Path {
        match self {
            Origin::Esi { file } | Origin::Sii { file } => file,
        }
    }

    /// The ESI file, when the description is one (what a master is
    /// configured with to name and type the slave's objects).
    pub fn esi(&self) -> Option<&Path> {
        match self {
            Origin::Esi { file } => Some(file),
            Origin::Sii { .. } => None,
        }
    }
}

/// One PDO entry of a default assignment: object, sub-index, bits, the
/// name the description gives it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CatalogEntry {
    /// Object index (0 for a gap).
    pub index: u16,
    /// Sub-index.
    pub subindex: u8,
    /// Length in bits.
    pub bits: u8,
    /// The entry's name in the description ("" when it gives none).
    pub name: String,
}

/// What a description says a slave of its kind shows.
#[derive(Debug, Clone)]
pub struct CatalogDevice {
    /// The file and how the device was read from it.
    pub origin: Origin,
    /// A label for messages: file, type, product code and revision.
    pub what: String,
    /// The device's name as its SII carries it (ESI `Name`, SII general name).
    pub name: String,
    /// Vendor id.
    pub vendor: u32,
    /// Product code.
    pub product: u32,
    /// Revision.
    pub revision: u32,
    /// The device speaks CoE (SII protocol bit 2 / ESI `<CoE>`).
    pub coe: bool,
    /// Output (RxPDO) entries of the default assignment, in PDO order.
    pub rx: Vec<CatalogEntry>,
    /// Input (TxPDO) entries of the default assignment, in PDO order.
    pub tx: Vec<CatalogEntry>,
    /// Declared types by (index, sub-index), where the description gives
    /// one whose size agrees with the mapped bits.
    pub types: Vec<((u16, u8), DataType)>,
    /// Object indices of the dictionary (ESI `<Dictionary>`; empty for an
    /// SII dump, which carries none).
    pub objects: Vec<u16>,
}

impl CatalogDevice {
    /// Bytes of process data the entries fill, rounded up.
    pub fn bytes(entries: &[CatalogEntry]) -> usize {
        entries.iter().map(|e| usize::from(e.bits)).sum::<usize>().div_ceil(8)
    }

    /// Output bytes of the default assignment.
    pub fn rx_bytes(&self) -> usize {
        Self::bytes(&self.rx)
    }

    /// Input bytes of the default assignment.
    pub fn tx_bytes(&self) -> usize {
        Self::bytes(&self.tx)
    }

    /// Whether the device exchanges any process data by default.
    pub fn has_process_data(&self) -> bool {
        !self.rx.is_empty() || !self.tx.is_empty()
    }

    /// Why the description gives no process data to exchange, if it gives
    /// none: a coupler or bootloader has none; an SII dump of a CoE device
    /// may leave its PDOs to the dictionary, which the dump does not carry.
    pub fn no_process_data(&self) -> Option<&'static str> {
        match (&self.origin, self.has_process_data()) {
            (_, true) => None,
            (Origin::Sii { .. }, false) if self.coe => Some("PDOs over CoE, not in the SII"),
            (_, false) => Some("no process data"),
        }
    }

    fn from_esi(file: &Path, vendor: u32, d: &EsiDevice) -> Self {
        let (rx, tx) = (EsiDevice::assigned_pdos(&d.rx_pdos), EsiDevice::assigned_pdos(&d.tx_pdos));
        let entries = |pdos: &[&EsiPdo]| -> Vec<CatalogEntry> {
            pdos.iter()
                .flat_map(|p| &p.entries)
                .map(|(e, name, _)| CatalogEntry {
                    index: e.index,
                    subindex: e.subindex,
                    bits: e.bits,
                    name: name.clone(),
                })
                .collect()
        };
        let mut types = Vec::new();
        for (e, _, t) in rx.iter().chain(&tx).flat_map(|p| &p.entries).filter(|(e, _, _)| e.index != 0) {
            let declared = d.dictionary.entry(e.index, e.subindex).map_or(*t, |x| x.dtype);
            if declared.bits() == u32::from(e.bits) {
                types.push(((e.index, e.subindex), declared));
            }
        }
        Self {
            origin: Origin::Esi { file: file.to_path_buf() },
            what: format!("{} {} ({:#010x} rev {:#010x})", file_name(file), d.type_name, d.product_code, d.revision),
            name: d.name.clone(),
            vendor,
            product: d.product_code,
            revision: d.revision,
            coe: d.protocols & sii::protocol::COE != 0,
            rx: entries(&rx),
            tx: entries(&tx),
            types,
            objects: d.dictionary.objects().map(|(i, _)| i).collect(),
        }
    }

    fn from_sii(file: &Path, image: &Sii) -> Self {
        let text = |i: u8| image.string(i).map(sii::decode_text).unwrap_or_default();
        let pick = |list: &[PdoRecord]| -> Vec<CatalogEntry> {
            image
                .default_assignment(list)
                .flat_map(|p| {
                    p.entries.iter().map(|e| CatalogEntry {
                        index: e.index,
                        subindex: e.subindex,
                        bits: e.bits,
                        name: text(e.name),
                    })
                })
                .collect()
        };
        let mut types = Vec::new();
        for p in image.default_assignment(&image.rx_pdos).chain(image.default_assignment(&image.tx_pdos)) {
            for e in p.entries.iter().filter(|e| e.index != 0) {
                if let Some(t) = DataType::from_code(u16::from(e.data_type), u32::from(e.bits)) {
                    types.push(((e.index, e.subindex), t));
                }
            }
        }
        Self {
            origin: Origin::Sii { file: file.to_path_buf() },
            what: format!("{} ({:#010x} rev {:#010x})", file_name(file), image.product_code, image.revision),
            name: image.name().unwrap_or_default(),
            vendor: image.vendor_id,
            product: image.product_code,
            revision: image.revision,
            coe: image.protocols & sii::protocol::COE != 0,
            rx: pick(&image.rx_pdos),
            tx: pick(&image.tx_pdos),
            types,
            objects: Vec::new(),
        }
    }
}

/// Every device description of a folder.
#[derive(Debug, Default)]
pub struct Catalog {
    /// The devices, ESI files first (file by file, in file order), then the
    /// SII dumps; files sorted by name.
    pub devices: Vec<CatalogDevice>,
    /// Files left out and why ("not an ESI file": an ENI or other XML).
    pub skipped: Vec<String>,
    /// Files that should describe devices and do not parse, with the error.
    pub failed: Vec<String>,
}

impl Catalog {
    /// Reads every `*.xml` and `*.bin` of `dir` (not recursive).
    pub fn scan(dir: &Path) -> std::io::Result<Self> {
        let mut out = Catalog::default();
        for file in files(dir, "xml")? {
            let text = match crate::esi::read_xml(&file) {
                Ok(t) => t,
                Err(e) => {
                    out.failed.push(format!("{}: {e}", file.display()));
                    continue;
                }
            };
            match EsiFile::parse(&text) {
                Ok(esi) => {
                    out.devices.extend(esi.devices.iter().map(|d| CatalogDevice::from_esi(&file, esi.vendor_id, d)));
                    out.skipped.extend(esi.skipped.iter().map(|why| format!("{}: {why}", file_name(&file))));
                }
                Err(e) => out.skipped.push(format!("{}: not an ESI file ({e})", file_name(&file))),
            }
        }
        for file in files(dir, "bin")? {
            match std::fs::read(&file)
                .map_err(|e| e.to_string())
                .and_then(|b| Sii::parse(&b).map_err(|e| e.to_string()))
            {
                Ok(image) => out.devices.push(CatalogDevice::from_sii(&file, &image)),
                Err(e) => out.failed.push(format!("{}: SII does not parse: {e}", file_name(&file))),
            }
        }
        Ok(out)
    }
}

impl Catalog {
    /// A fixtures folder as the tests read it: its files, then those in
    /// its `incoming/` (shapes that arrived after the others, read from
    /// the day they arrive).
    pub fn scan_with_incoming(dir: &Path) -> std::io::Result<Self> {
        let mut out = Self::scan(dir)?;
        let incoming = dir.join("incoming");
        if incoming.is_dir() {
            let more = Self::scan(&incoming)?;
            out.devices.extend(more.devices);
            out.skipped.extend(more.skipped);
            out.failed.extend(more.failed);
        }
        Ok(out)
    }
}

/// Splits devices, in order, into networks of at most `max_slaves` slaves
/// and `max_bytes` of process data each way; a device bigger than that
/// alone. (A large image leaves the SPI link little room at short cycles:
/// the chip takes one FIFO frame a packet.)
pub fn networks(devices: &[CatalogDevice], max_slaves: usize, max_bytes: usize) -> Vec<&[CatalogDevice]> {
    let mut out = Vec::new();
    let (mut start, mut rx, mut tx) = (0, 0, 0);
    for (i, d) in devices.iter().enumerate() {
        let (r, t) = (d.rx_bytes(), d.tx_bytes());
        if i > start && (i - start >= max_slaves || rx + r > max_bytes || tx + t > max_bytes) {
            out.push(&devices[start..i]);
            (start, rx, tx) = (i, 0, 0);
        }
        rx += r;
        tx += t;
    }
    if start < devices.len() {
        out.push(&devices[start..]);
    }
    out
}

fn file_name(p: &Path) -> String {
    p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// Every file of the folder with this extension (any case), sorted.
fn files(dir: &Path, ext: &str) -> std::io::Result<Vec<PathBuf>> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case(ext)))
        .collect();
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ecmxf-catalog-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    const ESI: &str = r##"<?xml version="1.0"?>
<EtherCATInfo><Vendor><Id>#x2</Id><Name>V</Name></Vendor><Descriptions><Devices>
<Device><Type ProductCode="#x10" RevisionNo="#x3">T1</Type><Name>In 2</Name>
<Sm StartAddress="#x1000" ControlByte="#x00" Enable="1">Inputs</Sm>
<TxPdo Sm="0" Fixed="1"><Index>#x1a00</Index><Name>Ch</Name>
<Entry><Index>#x6000</Index><SubIndex>1</SubIndex><BitLen>16</BitLen><Name>Value</Name><DataType>INT</DataType></Entry>
</TxPdo></Device></Devices></Descriptions></EtherCATInfo>"##;

    #[test]
    fn a_folder_gives_each_device_what_its_file_says_and_names_what_it_skips() {
        let dir = tmp("scan");
        std::fs::write(dir.join("a.xml"), ESI).unwrap();
        std::fs::write(dir.join("eni.xml"), "<EtherCATConfig/>").unwrap();
        std::fs::write(dir.join("bad.bin"), [0u8; 10]).unwrap();
        std::fs::write(dir.join("notes.txt"), "x").unwrap();
        let c = Catalog::scan(&dir).unwrap();
        assert_eq!(c.devices.len(), 1, "{c:?}");
        let d = &c.devices[0];
        assert_eq!((d.vendor, d.product, d.revision), (2, 0x10, 3));
        assert_eq!(d.name, "In 2");
        assert!(!d.coe);
        assert_eq!(d.tx, vec![CatalogEntry { index: 0x6000, subindex: 1, bits: 16, name: "Value".into() }]);
        assert_eq!((d.rx_bytes(), d.tx_bytes()), (0, 2));
        assert_eq!(d.types, vec![((0x6000, 1), DataType::Int16)]);
        assert_eq!(d.no_process_data(), None);
        assert!(c.skipped.iter().any(|s| s.starts_with("eni.xml: not an ESI file")), "{:?}", c.skipped);
        assert!(c.failed.iter().any(|s| s.starts_with("bad.bin: SII does not parse")), "{:?}", c.failed);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn an_sii_dump_lists_its_default_pdos_with_names_and_types() {
        let dir = tmp("sii");
        let esi = EsiFile::parse(ESI).unwrap();
        std::fs::write(dir.join("dump.bin"), esi.devices[0].sii_image(2)).unwrap();
        let c = Catalog::scan(&dir).unwrap();
        let d = &c.devices[0];
        assert!(matches!(d.origin, Origin::Sii { .. }));
        assert_eq!((d.vendor, d.product, d.name.as_str()), (2, 0x10, "In 2"));
        assert_eq!(d.tx, vec![CatalogEntry { index: 0x6000, subindex: 1, bits: 16, name: "Value".into() }]);
        assert_eq!(d.types, vec![((0x6000, 1), DataType::Int16)]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn networks_split_by_slaves_and_bytes_and_a_big_device_goes_alone() {
        let dev = |bits: u8| CatalogDevice {
            origin: Origin::Sii { file: PathBuf::new() },
            what: String::new(),
            name: String::new(),
            vendor: 0,
            product: 0,
            revision: 0,
            coe: false,
            rx: vec![],
            tx: vec![CatalogEntry { index: 0x6000, subindex: 1, bits, name: String::new() }],
            types: vec![],
            objects: vec![],
        };
        let devices: Vec<CatalogDevice> = [8, 8, 8, 200, 8].into_iter().map(dev).collect();
        let sizes: Vec<usize> = networks(&devices, 2, 3).iter().map(|n| n.len()).collect();
        assert_eq!(sizes, [2, 1, 1, 1]);
        let sizes: Vec<usize> = networks(&devices, 24, 20).iter().map(|n| n.len()).collect();
        assert_eq!(sizes, [3, 1, 1]);
        assert!(networks(&[], 1, 1).is_empty());
        let mut coe = dev(0);
        coe.tx.clear();
        assert_eq!(coe.no_process_data(), Some("no process data"));
        coe.coe = true;
        assert_eq!(coe.no_process_data(), Some("PDOs over CoE, not in the SII"));
    }
}
