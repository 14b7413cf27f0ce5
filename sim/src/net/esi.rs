//! Simulated slaves built from an ESI description ([`ecmxf_devices::esi`]).

use ecmxf_devices::esi;
pub use ecmxf_devices::esi::*;
use ecmxf_devices::init_cmd::{CoeAccess, CoeInitCmd};
use ecmxf_wire::payload::pdo::PdoEntry;

use super::od::{Access, DataType, Entry, Object, ObjectDictionary, ObjectKind, StateSet};
use super::pdo_map::{self, RX_ASSIGN, TX_ASSIGN};
use super::profiles::{Identity, identity_objects};
use super::sii;
use super::slave::{Device, Slave};

/// A device description the simulator can make a slave of.
pub trait SimulatedDevice {
    /// A simulated slave with this description: its dictionary, PDO mapping
    /// and assignment objects (configurable as the CoE flags say), objects
    /// for PDO entries the dictionary lacks, and a generated SII image.
    fn to_slave(&self, vendor_id: u32, alias: u16) -> Slave;
}

impl SimulatedDevice for EsiDevice {
    fn to_slave(&self, vendor_id: u32, alias: u16) -> Slave {
        let mut od = self.dictionary.clone();
        od.no_complete_access = !self.complete_access;
        for (pdos, rx) in [(&self.rx_pdos, true), (&self.tx_pdos, false)] {
            let assign = EsiDevice::default_assignment(pdos);
            // The assigned PDOs make their entry objects first: an ESI may
            // list one object at two sizes in alternative PDOs (Beckhoff
            // EL1252: 0x1D09:B0 as UDINT in one, ULINT in the assigned one),
            // and the size the device runs with is the assigned PDO's.
            let (first, rest): (Vec<&EsiPdo>, Vec<&EsiPdo>) = pdos.iter().partition(|p| assign.contains(&p.index));
            for p in first.iter().chain(&rest) {
                add_entry_objects(&mut od, rx, &p.entries);
                let entries: Vec<PdoEntry> = p.entries.iter().map(|(e, _, _)| *e).collect();
                let fixed = p.fixed || !self.pdo_config;
                // A PDO numbered where another object is, or in the
                // communication area the identity object is added to
                // below (a two-channel drive's TxPDO at 0x1018): its
                // mapping is kept aside, so CoE reads the other object and
                // the process image follows the mapping.
                let standard = (0x1600..=0x17FF).contains(&p.index) || (0x1A00..=0x1BFF).contains(&p.index);
                if !standard && (od.object(p.index).is_some() || (0x1000..0x2000).contains(&p.index)) {
                    let mut scratch = ObjectDictionary::default();
                    pdo_map::add_mapping(&mut scratch, p.index, &p.name, &entries, fixed);
                    if let Some(m) = scratch.object(p.index) {
                        od.mappings_aside.insert(p.index, m.clone());
                    }
                } else {
                    pdo_map::add_mapping(&mut od, p.index, &p.name, &entries, fixed);
                }
            }
            let index = if rx { RX_ASSIGN } else { TX_ASSIGN };
            pdo_map::add_assignment(&mut od, index, &assign, pdos.len().max(assign.len()), !self.pdo_assign);
        }
        // The identity object says what the slave is (CiA301 0x1018): an
        // ESI default that disagrees (Elmo's 0x1018:01 = 0) would make the
        // slave contradict its own SII and the identity the chip reports;
        // an ESI without it (Elmo rev 1, NI 9144: no `<Dictionary>`) still
        // describes a CoE device, which has the CiA301 mandatory objects.
        if self.protocols & sii::protocol::COE != 0 {
            // CiA 301's mandatory objects, marked as added where the file's
            // dictionary lacks them; the optional device name only where
            // the file has no dictionary to say it has none.
            let described = self.dictionary.objects().next().is_some();
            let absent: Vec<u16> = [0x1000, 0x1001, 0x1018].into_iter().filter(|i| od.object(*i).is_none()).collect();
            let no_name = od.object(0x1008).is_none();
            let id = Identity { vendor_id, product_code: self.product_code, revision: self.revision, serial: 0 };
            identity_objects(&mut od, id, &self.name, 0);
            if described && no_name {
                od.remove(0x1008);
            }
            for index in absent.into_iter().filter(|_| described) {
                od.beyond_file.insert((index, 0), ecmxf_devices::od::BeyondFile::ProfileAdded);
            }
        }
        for (sub, v) in [(1, vendor_id), (2, self.product_code), (3, self.revision)] {
            od.set_int(0x1018, sub, v.into());
        }
        accept_own_init_cmds(&mut od, &self.init_cmds);
        let has_dc = self.dc_modes.iter().any(|(_, a)| *a != 0);
        super::cia402::add_profile_objects(&mut od);
        let axes = super::cia402::axes_in(&od);
        let device = if axes.is_empty() { Device::Passive } else { Device::Drive(axes) };
        let mut slave = Slave::new(self.sii_image(vendor_id), od, device, has_dc);
        if slave.name.is_empty() {
            slave.name = self.type_name.clone();
        }
        slave.notes = self.warnings.clone();
        if alias != 0 {
            slave.eeprom_write(4, alias);
        }
        slave
    }
}

/// What the device's own CoE init commands write, it takes: its vendor
/// ships them (an ESI whose dictionary declares 0x6060 read-only, or lacks
/// 0x60C2, yet writes both at PS), so the real device accepts them. An
/// entry the dictionary lacks is added (typed by the data's size), one it
/// declares read-only is made writable; both are kept in
/// `beyond_file` for `ecmxf-sim check` to name. PDO objects are left
/// to the mapping's own rules.
fn accept_own_init_cmds(od: &mut ObjectDictionary, cmds: &[CoeInitCmd]) {
    use ecmxf_devices::od::BeyondFile;
    for c in cmds.iter().filter(|c| !c.disabled && !c.complete_access) {
        let CoeInitCmd { index, subindex, access: CoeAccess::Download(data), .. } = c else { continue };
        let (index, sub) = (*index, *subindex);
        if matches!(index, 0x1600..=0x17FF | 0x1A00..=0x1BFF | 0x1C12 | 0x1C13) {
            continue;
        }
        match od.entry(index, sub).map(|e| e.access.write.preop) {
            Some(true) => {}
            Some(false) => {
                if let Some(e) = od.entry_mut(index, sub) {
                    e.access.write = StateSet::ALL;
                    od.beyond_file.insert((index, sub), BeyondFile::InitCmdOpened);
                }
            }
            None => {
                let dtype = match data.len() {
                    1 => DataType::UInt8,
                    2 => DataType::UInt16,
                    4 => DataType::UInt32,
                    8 => DataType::UInt64,
                    n => DataType::OctetString(n as u16),
                };
                let entry = Entry::new(&c.comment, dtype, Access::RW);
                if sub == 0 {
                    od.insert(index, Object::var(&c.comment, entry));
                } else {
                    let mut obj = od
                        .object(index)
                        .cloned()
                        .unwrap_or_else(|| Object::record(&c.comment, ObjectKind::Record, Access::RO, Vec::new()));
                    obj.entries.insert(sub, entry);
                    let highest = obj.entries.keys().copied().max().unwrap_or(0);
                    if let Some(e0) = obj.entries.get_mut(&0) {
                        e0.set_int(highest.into());
                    }
                    od.insert(index, obj);
                }
                od.beyond_file.insert((index, sub), BeyondFile::InitCmdAdded);
            }
        }
    }
}

/// Objects for the PDO entries a dictionary lacks (a device without CoE, or
/// an ESI that lists PDO entries outside its `<Dictionary>`), and the
/// mapping flag on those it has.
pub(crate) fn add_entry_objects(od: &mut ObjectDictionary, rx: bool, entries: &[(PdoEntry, String, DataType)]) {
    for (e, name, dtype) in entries {
        if e.index == 0 || od.entry(e.index, e.subindex).is_some() {
            if od.entry(e.index, e.subindex).is_some_and(|en| !en.mappable.allows(rx)) {
                od.mapped_anyway.insert((e.index, e.subindex));
            }
            continue;
        }
        let dtype = if dtype.bits() == u32::from(e.bits) { *dtype } else { esi::data_type("", e.bits.into()) };
        let access = if rx { Access::RW } else { Access::RO };
        let entry = Entry::new(name, dtype, access).mappable(pdo_map::mappable_for(rx));
        if e.subindex == 0 {
            od.insert(e.index, Object::var(name, entry));
        } else {
            let obj = match od.object(e.index) {
                Some(o) => o.clone(),
                None => Object::record(name, ObjectKind::Record, Access::RO, Vec::new()),
            };
            let mut obj = obj;
            obj.entries.insert(e.subindex, entry);
            let highest = obj.entries.keys().copied().max().unwrap_or(0);
            if let Some(e0) = obj.entries.get_mut(&0) {
                e0.set_int(highest.into());
            }
            od.insert(e.index, obj);
        }
    }
}
