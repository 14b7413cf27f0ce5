//! Each slave's PDOs from the best source it has, so one slave without CoE
//! never fails the others' listing:
//! 1. CoE: the chip's PDO_CONFIG_REQ/GET (cmds 8/9) carries 3 PDOs of 8
//!    entries (v049, note under command 7); the rest of a longer assignment
//!    or mapping is read with SDO uploads of 0x1C12/0x1C13 and 0x16xx/0x1Axx.
//! 2. The SII's RxPDO/TxPDO categories (ETG.2010 categories 50/51): what a
//!    slave without a mailbox has, PDOs with their sync manager, names and
//!    entry types.
//! 3. The ESI the configuration names for the slave: its default
//!    assignment (PDOs with an `Sm`, minus those excluded).
//!
//! Entry types come from the device: the ESI dictionary, then the PDO
//! entry's own type (ESI `DataType`, SII data type code); what is left is
//! typed by the caller's table.
//!
//! Names of PDOs and entries come from the best source too, in this order
//! (`names_from` says which named any): the configured ESI, or the ENI's
//! description of the slave; else the SII's strings (its PDO categories);
//! else, for a CoE slave that does SDO Information (SII CoE details bit 1),
//! the device itself: its dictionary when the daemon has read it
//! (`device_dictionary.rs`), else only what is mapped is asked for, one Get
//! Object Description per PDO and one Get Entry Description (no value
//! information) per unnamed entry (ETG.1000.6 5.6.3.5, 5.6.3.6). That is
//! 1 + PDOs + entries mailbox exchanges once per bring-up (a 12-slave
//! mix mapping 81 entries: about 100), not a whole dictionary (hundreds
//! of objects, each with its entries). The listing is part of the process
//! image the daemon builds in its own task after each bring-up (`image.rs`,
//! `Call::daemon`), so no client's deadline ever carries it; the device's
//! names come in a second pass, after the first image is out, so they
//! never delay the first write. They only add: labels and variable names
//! where there were none; entries, offsets and types stay as they were.

use ecmxf_devices::esi::{EsiDevice, EsiPdo};
use ecmxf_devices::od::DataType;
use ecmxf_devices::sii::{self, PdoRecord, Sii, decode_text};
use ecmxf_wire::payload::pdo::{PdoEntry, RX_PDO_ASSIGN, TX_PDO_ASSIGN};

use super::device_dictionary::DictionaryError;
use super::esi::EsiRef;
use super::sii::Categories;
use super::{Call, Master};
use crate::engine::error::EngineError;

/// Where a slave's PDO list came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PdoSource {
    /// Read from the slave over CoE.
    Coe,
    /// The slave's SII PDO categories.
    Sii,
    /// The configured ESI file.
    Esi,
    /// Nothing says (no process data, or no source answered).
    None,
}

/// Where a slave's PDO and entry names came from: the first source, in
/// the order they are asked, that named any.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NameSource {
    /// The ENI's description of the slave.
    Eni,
    /// The configured ESI file.
    Esi,
    /// The slave's SII strings (PDO categories).
    Sii,
    /// The device's own SDO Information (ETG.1000.6 5.6.3).
    SdoInfo,
    /// No source named them.
    None,
}

impl NameSource {
    /// Its name in listings ("eni", "esi", "sii", "sdo_info", "none").
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Eni => "eni",
            Self::Esi => "esi",
            Self::Sii => "sii",
            Self::SdoInfo => "sdo_info",
            Self::None => "none",
        }
    }
}

/// One mapped entry.
#[derive(Clone, Debug, PartialEq)]
pub struct EntryDescription {
    /// Object index (0: a gap).
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// Size in bits.
    pub bits: u8,
    /// The device's name for it ("" when no source names it).
    pub name: String,
    /// The device's type for it, when a source gives one of this size.
    pub data_type: Option<DataType>,
}

/// One PDO.
#[derive(Clone, Debug, PartialEq)]
pub struct PdoDescription {
    /// Mapping object (0x16xx / 0x1Axx).
    pub index: u16,
    /// The device's name for it.
    pub name: String,
    /// Its sync manager, where the source says.
    pub sync_manager: Option<u8>,
    /// Entries in image order.
    pub entries: Vec<EntryDescription>,
}

/// A slave's assigned PDOs.
#[derive(Clone, Debug, PartialEq)]
pub struct SlavePdos {
    /// Where they came from.
    pub source: PdoSource,
    /// Why a lesser source was used ("" for CoE).
    pub note: String,
    /// Where the names came from.
    pub names_from: NameSource,
    /// Entries are unnamed and the device may name them over SDO
    /// Information ([`Master::name_from_device`]): a CoE slave without
    /// ESI or ENI.
    pub device_can_name: bool,
    /// RxPDOs (outputs).
    pub rx: Vec<PdoDescription>,
    /// TxPDOs (inputs).
    pub tx: Vec<PdoDescription>,
}

impl SlavePdos {
    /// Names this slave's unnamed PDOs and entries as `twin`, a device of
    /// the same identity, names the same objects (a device's dictionary,
    /// names included, is its firmware's: the same for every device of
    /// one vendor id, product code and revision, as one ESI describes
    /// them all). True when a name was added.
    pub(crate) fn named_as(&mut self, twin: &Self) -> bool {
        let before = count_named(&self.rx, &self.tx);
        for (mine, theirs) in [(&mut self.rx, &twin.rx), (&mut self.tx, &twin.tx)] {
            for p in mine.iter_mut() {
                let Some(q) = theirs.iter().find(|q| q.index == p.index) else { continue };
                if p.name.is_empty() {
                    p.name.clone_from(&q.name);
                }
                for e in p.entries.iter_mut().filter(|e| e.index != 0 && e.name.is_empty()) {
                    if let Some(x) = q.entries.iter().find(|x| (x.index, x.subindex) == (e.index, e.subindex)) {
                        e.name.clone_from(&x.name);
                    }
                }
            }
        }
        let added = count_named(&self.rx, &self.tx) > before;
        if added && self.names_from == NameSource::None {
            self.names_from = twin.names_from;
        }
        added
    }

    /// Whether every PDO and entry (gaps left out) has a name.
    pub(crate) fn all_named(&self) -> bool {
        all_named(&self.rx, &self.tx)
    }

    /// A slave with nothing to list, and why.
    pub(crate) fn none(note: impl Into<String>) -> Self {
        Self {
            source: PdoSource::None,
            note: note.into(),
            names_from: NameSource::None,
            device_can_name: false,
            rx: Vec::new(),
            tx: Vec::new(),
        }
    }
}

/// Whether an error means "this source has nothing" (try the next) rather
/// than "the daemon cannot ask now" (pass it on).
fn source_lacks(e: &EngineError) -> bool {
    matches!(
        e,
        EngineError::Failed(_)
            | EngineError::SdoAbort { .. }
            | EngineError::Refused(_)
            | EngineError::BadDeviceData { .. }
            | EngineError::BadAnswer { .. }
            | EngineError::WrongState(crate::engine::error::WrongState::NoCoe { .. })
    )
}

fn le_u32(v: &[u8]) -> u32 {
    let mut b = [0u8; 4];
    for (o, i) in b.iter_mut().zip(v) {
        *o = *i;
    }
    u32::from_le_bytes(b)
}

impl Master {
    /// `slave`'s assigned PDOs from the best source it has (module docs).
    /// `rx_bytes`/`tx_bytes` are its process data as bring-up found it: a
    /// direction without bytes is not asked for.
    pub async fn slave_pdos(
        &self,
        slave: u8,
        rx_bytes: usize,
        tx_bytes: usize,
        call: Call,
    ) -> Result<SlavePdos, EngineError> {
        if rx_bytes == 0 && tx_bytes == 0 {
            return Ok(SlavePdos::none("no process data"));
        }
        let esi = match self.esi_device(slave).await {
            Some(Ok(d)) => Some(d),
            Some(Err(e)) => {
                tracing::warn!(slave, "{e}");
                None
            }
            None => None,
        };
        let esi_device = esi.as_ref().map(EsiRef::device);
        // Without an ESI, an ENI entry describes the PDOs (names, types).
        let eni_device = if esi_device.is_none() { self.eni_device(slave).await } else { None };
        let mut notes = Vec::new();
        match self.coe_pdos(slave, rx_bytes, tx_bytes, call).await {
            Ok((mut rx, mut tx)) => {
                // Without an ESI, the SII's PDO categories (when it has
                // them) are what names and types the entries.
                let foreign = rx.iter().chain(&tx).any(|p| !is_mapping_index(p.index));
                if let Some(d) = esi_device.filter(|_| foreign) {
                    from_description(&mut rx, &esi_described(d.rx_pdos.iter()));
                    from_description(&mut tx, &esi_described(d.tx_pdos.iter()));
                }
                if esi_device.is_none() && eni_device.is_none() {
                    match self.sii_described(slave, PDO_CATEGORIES, call).await {
                        Ok(image) => {
                            let (all_rx, all_tx) =
                                (from_sii_all(&image, &image.rx_pdos), from_sii_all(&image, &image.tx_pdos));
                            from_description(&mut rx, &all_rx);
                            from_description(&mut tx, &all_tx);
                            complete(&mut rx, &all_rx);
                            complete(&mut tx, &all_tx);
                        }
                        Err(e) if source_lacks(&e) => tracing::debug!(slave, "PDO names from the SII: {e}"),
                        Err(e) => return Err(e),
                    }
                }
                let named_by_sii = any_named(&rx, &tx);
                let pdos = SlavePdos {
                    source: PdoSource::Coe,
                    note: String::new(),
                    names_from: if named_by_sii { NameSource::Sii } else { NameSource::None },
                    device_can_name: false,
                    rx,
                    tx,
                };
                let mut pdos = typed(pdos, esi_device.or(eni_device.as_ref()));
                if pdos.names_from == NameSource::None && any_named(&pdos.rx, &pdos.tx) {
                    pdos.names_from = if esi_device.is_some() { NameSource::Esi } else { NameSource::Eni };
                }
                // Without a description, the device can name what it maps:
                // a second pass, once the image is out (`image.rs`).
                pdos.device_can_name = esi_device.is_none() && eni_device.is_none() && !all_named(&pdos.rx, &pdos.tx);
                // Without an ESI, what the device described of itself (SDO
                // Information, when read) types the entries left untyped.
                if let Some(d) = self.known_device_dictionary(slave).filter(|_| esi_device.is_none()) {
                    for e in pdos.rx.iter_mut().chain(pdos.tx.iter_mut()).flat_map(|p| p.entries.iter_mut()) {
                        if e.data_type.is_none() {
                            e.data_type = d.data_type(e.index, e.subindex).filter(|t| t.bits() == u32::from(e.bits));
                        }
                    }
                }
                return Ok(pdos);
            }
            Err(e) if source_lacks(&e) => notes.push(format!("CoE: {e}")),
            Err(e) => return Err(e),
        }
        match self.sii_described(slave, PDO_CATEGORIES, call).await {
            Ok(image) if !image.rx_pdos.is_empty() || !image.tx_pdos.is_empty() => {
                let (rx, tx) = (from_sii(&image, &image.rx_pdos), from_sii(&image, &image.tx_pdos));
                let note = notes.join("; ");
                let names_from = if any_named(&rx, &tx) { NameSource::Sii } else { NameSource::None };
                let mut pdos = typed(
                    SlavePdos { source: PdoSource::Sii, note, names_from, device_can_name: false, rx, tx },
                    esi_device,
                );
                if pdos.names_from == NameSource::None && any_named(&pdos.rx, &pdos.tx) {
                    pdos.names_from = NameSource::Esi;
                }
                return Ok(pdos);
            }
            Ok(_) => notes.push("SII: no PDO categories".into()),
            Err(e) if source_lacks(&e) => notes.push(format!("SII: {e}")),
            Err(e) => return Err(e),
        }
        if let Some(d) = esi_device {
            let (rx, tx) = (from_esi(&d.rx_pdos), from_esi(&d.tx_pdos));
            let note = notes.join("; ");
            let names_from = if any_named(&rx, &tx) { NameSource::Esi } else { NameSource::None };
            return Ok(typed(
                SlavePdos { source: PdoSource::Esi, note, names_from, device_can_name: false, rx, tx },
                esi_device,
            ));
        }
        notes.push("no ESI configured".into());
        Ok(SlavePdos::none(notes.join("; ")))
    }

    /// Names the PDOs and entries still unnamed as the device describes
    /// them (SDO Information): from its dictionary when the daemon has read
    /// it (in memory or kept on disk), else by asking only for what is mapped, one Get Object
    /// Description per PDO and one Get Entry Description (no value
    /// information) per entry: 1 + PDOs + entries mailbox exchanges, the
    /// first (the SII's CoE details) usually cached. This is the daemon's
    /// second pass over an image it has already published (`image.rs`):
    /// its own work, never in a client's deadline, and never before the
    /// first image. Names are not worth failing a listing: a
    /// question the device refuses leaves that name empty; a failed
    /// exchange ends the naming.
    pub(crate) async fn name_from_device(&self, slave: u8, pdos: &mut SlavePdos, call: Call) {
        let before = count_named(&pdos.rx, &pdos.tx);
        if let Some(d) = self.kept_device_dictionary(slave) {
            for p in pdos.rx.iter_mut().chain(pdos.tx.iter_mut()) {
                if p.name.is_empty() {
                    if let Some(o) = d.object(p.index) {
                        p.name.clone_from(&o.name);
                    }
                }
                for e in p.entries.iter_mut().filter(|e| e.index != 0 && e.name.is_empty()) {
                    if let Some(x) = d.entry(e.index, e.subindex) {
                        e.name.clone_from(&x.name);
                    }
                }
            }
        } else {
            match self.supports_sdo_info(slave, call).await {
                Ok(true) => {}
                Ok(false) => return,
                Err(e) => {
                    tracing::debug!(slave, "PDO names from SDO Information: {e}");
                    return;
                }
            }
            // A refusal or an answer that does not read leaves one name
            // empty; anything else (mailbox, engine) ends the naming.
            let go_on =
                |e: &DictionaryError| matches!(e, DictionaryError::Aborted { .. } | DictionaryError::Garbled(_));
            'pdos: for p in pdos.rx.iter_mut().chain(pdos.tx.iter_mut()) {
                if p.name.is_empty() && is_mapping_index(p.index) {
                    match self.described_object_name(slave, p.index, call).await {
                        Ok(name) => p.name = name,
                        Err(e) => {
                            tracing::debug!(slave, "PDO name from SDO Information: {e}");
                            if !go_on(&e) {
                                break 'pdos;
                            }
                        }
                    }
                }
                for e in p.entries.iter_mut().filter(|e| e.index != 0 && e.name.is_empty()) {
                    match self.described_entry_name(slave, e.index, e.subindex, call).await {
                        Ok(name) => e.name = name,
                        Err(err) => {
                            tracing::debug!(slave, "entry name from SDO Information: {err}");
                            if !go_on(&err) {
                                break 'pdos;
                            }
                        }
                    }
                }
            }
        }
        if pdos.names_from == NameSource::None && count_named(&pdos.rx, &pdos.tx) > before {
            pdos.names_from = NameSource::SdoInfo;
        }
    }

    /// Both directions over CoE; a direction without bytes is left empty.
    async fn coe_pdos(
        &self,
        slave: u8,
        rx_bytes: usize,
        tx_bytes: usize,
        call: Call,
    ) -> Result<(Vec<PdoDescription>, Vec<PdoDescription>), EngineError> {
        let rx = if rx_bytes > 0 { self.coe_assignment(slave, RX_PDO_ASSIGN, call).await? } else { Vec::new() };
        let tx = if tx_bytes > 0 { self.coe_assignment(slave, TX_PDO_ASSIGN, call).await? } else { Vec::new() };
        Ok((rx, tx))
    }

    /// One assignment: what PDO_CONFIG_GET carries, completed with SDO
    /// uploads where it is cut (more than 3 PDOs, more than 8 entries).
    async fn coe_assignment(&self, slave: u8, assign: u16, call: Call) -> Result<Vec<PdoDescription>, EngineError> {
        let config = self.pdo_config_read(slave, assign, call).await?;
        let mut out = Vec::with_capacity(usize::from(config.pdo_count));
        for n in 0..config.pdo_count {
            let (index, count, mut entries) = match config.used().get(usize::from(n)) {
                Some(p) => (p.index, p.entry_count, p.used().to_vec()),
                None => {
                    let v = self.sdo_read(slave, assign, n + 1, false, call).await?;
                    let index = le_u32(&v) as u16;
                    let count = self.sdo_read(slave, index, 0, false, call).await?;
                    (index, u16::from(count.first().copied().unwrap_or(0)), Vec::new())
                }
            };
            for sub in entries.len() + 1..=usize::from(count).min(255) {
                let v = self.sdo_read(slave, index, sub as u8, false, call).await?;
                entries.push(PdoEntry::from_u32(le_u32(&v)));
            }
            out.push(PdoDescription {
                index,
                name: String::new(),
                // 0x1C10 + n assigns sync manager n (ETG.1000.6 5.6.7.4).
                sync_manager: Some((assign - 0x1C10) as u8),
                entries: entries
                    .into_iter()
                    .map(|e| EntryDescription {
                        index: e.index,
                        subindex: e.subindex,
                        bits: e.bits,
                        name: String::new(),
                        data_type: None,
                    })
                    .collect(),
            });
        }
        Ok(out)
    }
}

/// How many PDO and entry names (gaps left out) the lists have.
fn count_named(rx: &[PdoDescription], tx: &[PdoDescription]) -> usize {
    rx.iter()
        .chain(tx)
        .map(|p| {
            usize::from(!p.name.is_empty()) + p.entries.iter().filter(|e| e.index != 0 && !e.name.is_empty()).count()
        })
        .sum()
}

fn any_named(rx: &[PdoDescription], tx: &[PdoDescription]) -> bool {
    count_named(rx, tx) > 0
}

/// Whether every PDO and entry (gaps left out) has a name.
fn all_named(rx: &[PdoDescription], tx: &[PdoDescription]) -> bool {
    rx.iter().chain(tx).all(|p| !p.name.is_empty() && p.entries.iter().all(|e| e.index == 0 || !e.name.is_empty()))
}

/// The SII categories that describe PDOs and name them.
const PDO_CATEGORIES: Categories<'static> = Categories::Only(&[
    sii::category::RXPDO,
    sii::category::TXPDO,
    sii::category::STRINGS,
    sii::category::SYNC_MANAGER,
]);

/// The PDOs of an SII list that are assigned by default.
fn from_sii(image: &Sii, list: &[PdoRecord]) -> Vec<PdoDescription> {
    described(image, image.default_assignment(list))
}

/// Every PDO of an SII list, assigned or not (to name what CoE assigned).
fn from_sii_all(image: &Sii, list: &[PdoRecord]) -> Vec<PdoDescription> {
    described(image, list.iter())
}

/// Whether a PDO index is where CiA 301 puts PDO mapping objects
/// (0x1600-0x17FF outputs, 0x1A00-0x1BFF inputs; ETG.1000.6 5.6.7.4).
/// Devices number PDOs elsewhere too (a two-channel drive's TxPDO at
/// 0x1018): read over CoE, such an index is the other object (the identity
/// object), not the mapping.
fn is_mapping_index(index: u16) -> bool {
    (0x1600..=0x17FF).contains(&index) || (0x1A00..=0x1BFF).contains(&index)
}

/// A PDO assigned at an index outside the mapping objects' range takes its
/// entries from the device's description (SII or ESI), which has them;
/// CoE would have read another object's values as entries (a two-channel
/// drive's TxPDO at 0x1018 once came back as the identity object's values).
fn from_description(list: &mut [PdoDescription], described: &[PdoDescription]) {
    for p in list.iter_mut().filter(|p| !is_mapping_index(p.index)) {
        match described.iter().find(|d| d.index == p.index) {
            Some(d) => p.entries.clone_from(&d.entries),
            None => tracing::warn!(
                pdo = format_args!("{:#06x}", p.index),
                "a PDO outside 0x1600-0x17FF/0x1A00-0x1BFF that no description lists: its entries as read over CoE"
            ),
        }
    }
}

/// Names of PDOs and entries, entry types and sync managers, from
/// `described` where `list` lacks them and the description's entry is the
/// same object at the same size. Gaps (object 0) are left alone: several
/// share 0:00, so which description is whose cannot be told. The entry at
/// the same position is taken first: a file may map one object twice under
/// two names (Beckhoff EL6688's 0x10F4:0F, "Control value update toggle"
/// and "Time stamp update toggle"), and each place keeps its own.
fn complete(list: &mut [PdoDescription], described: &[PdoDescription]) {
    for p in list.iter_mut() {
        let Some(known) = described.iter().find(|q| q.index == p.index) else { continue };
        if p.name.is_empty() {
            p.name.clone_from(&known.name);
        }
        p.sync_manager = p.sync_manager.or(known.sync_manager);
        for (at, e) in p.entries.iter_mut().enumerate().filter(|(_, e)| e.index != 0) {
            let same = |x: &&EntryDescription| (x.index, x.subindex, x.bits) == (e.index, e.subindex, e.bits);
            if let Some(x) = known.entries.get(at).filter(same).or_else(|| known.entries.iter().find(same)) {
                if e.name.is_empty() {
                    e.name.clone_from(&x.name);
                }
                e.data_type = e.data_type.or(x.data_type);
            }
        }
    }
}

fn described<'a>(image: &Sii, list: impl Iterator<Item = &'a PdoRecord>) -> Vec<PdoDescription> {
    let text = |i: u8| image.string(i).map(decode_text).unwrap_or_default();
    list.map(|p| PdoDescription {
        index: p.index,
        name: text(p.name),
        sync_manager: Some(p.sm),
        entries: p
            .entries
            .iter()
            .map(|e| EntryDescription {
                index: e.index,
                subindex: e.subindex,
                bits: e.bits,
                name: text(e.name),
                data_type: DataType::from_code(e.data_type.into(), e.bits.into()),
            })
            .collect(),
    })
    .collect()
}

/// The default assignment an ESI describes.
fn from_esi(pdos: &[EsiPdo]) -> Vec<PdoDescription> {
    esi_described(EsiDevice::assigned_pdos(pdos).into_iter())
}

fn esi_described<'a>(pdos: impl Iterator<Item = &'a EsiPdo>) -> Vec<PdoDescription> {
    pdos.map(|p| PdoDescription {
        index: p.index,
        name: p.name.clone(),
        sync_manager: p.sm,
        entries: p
            .entries
            .iter()
            .map(|(e, name, t)| EntryDescription {
                index: e.index,
                subindex: e.subindex,
                bits: e.bits,
                name: name.clone(),
                data_type: (t.bits() == u32::from(e.bits)).then_some(*t),
            })
            .collect(),
    })
    .collect()
}

/// Names and types from the ESI where the list lacks them: the dictionary's
/// type for an object (when its size is the entry's) wins over a type
/// guessed from a PDO list; then the ESI's PDOs complete the list as any
/// description does ([`complete`]), sync managers included.
fn typed(mut pdos: SlavePdos, esi: Option<&EsiDevice>) -> SlavePdos {
    let Some(d) = esi else { return pdos };
    for (list, described) in [(&mut pdos.rx, &d.rx_pdos), (&mut pdos.tx, &d.tx_pdos)] {
        for e in list.iter_mut().flat_map(|p| p.entries.iter_mut()).filter(|e| e.index != 0) {
            if let Some(t) = d.dictionary.entry(e.index, e.subindex).map(|x| x.dtype) {
                if t.bits() == u32::from(e.bits) {
                    e.data_type = Some(t);
                }
            }
        }
        complete(list, &esi_described(described.iter()));
    }
    pdos
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unassigned_and_missing_sync_managers_are_left_out() {
        let image = Sii { sync_managers: vec![Default::default(); 3], ..Sii::default() };
        let pdo = |index, sm| PdoRecord { index, sm, ..Default::default() };
        let list = [pdo(0x1A00, 2), pdo(0x1A01, 0xFF), pdo(0x1A02, 5)];
        let got: Vec<u16> = from_sii(&image, &list).iter().map(|p| p.index).collect();
        assert_eq!(got, [0x1A00]);
    }

    #[test]
    fn a_coe_listing_takes_names_and_types_from_the_sii_where_the_entry_is_the_same() {
        let entry = |index, subindex, bits, name: &str, data_type| EntryDescription {
            index,
            subindex,
            bits,
            name: name.into(),
            data_type,
        };
        let pdo = |index, name: &str, entries| PdoDescription { index, name: name.into(), sync_manager: None, entries };
        let mut coe = vec![pdo(0x1A00, "", vec![entry(0x6000, 1, 16, "", None), entry(0x6000, 2, 8, "", None)])];
        let sii = [pdo(
            0x1A00,
            "AI",
            vec![
                entry(0x6000, 1, 16, "Value", Some(DataType::Int16)),
                entry(0x6000, 2, 16, "Wide", Some(DataType::UInt16)),
            ],
        )];
        complete(&mut coe, &sii);
        assert_eq!(coe[0].name, "AI");
        assert_eq!(coe[0].entries[0], entry(0x6000, 1, 16, "Value", Some(DataType::Int16)));
        // Mapped at another size than the SII says: left as CoE gave it.
        assert_eq!(coe[0].entries[1], entry(0x6000, 2, 8, "", None));
    }
}
