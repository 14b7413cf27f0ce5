//! Simulated slaves built from an SII EEPROM dump alone (a real terminal's
//! image, e.g. read with `ecmxfctl sii dump`): identity, mailbox, sync
//! managers and the PDOs of its RxPDO/TxPDO categories (ETG.2010 categories
//! 50/51) are what the chip's bring-up uses. A dump has no dictionary:
//! only the PDO entries and mapping objects are made, fixed as the SII
//! describes them, typed by the SII's data type codes; a CoE device also
//! gets the CiA 301 objects that say what it is (0x1000, 0x1001, 0x1008
//! from the SII name, 0x1018 from the SII identity), as every real one has.

use ecmxf_devices::esi;
use ecmxf_devices::sii::{PdoRecord, Sii, SiiError, decode_text, protocol};
use ecmxf_wire::payload::pdo::PdoEntry;

use super::esi::add_entry_objects;
use super::od::{DataType, ObjectDictionary};
use super::pdo_map::{self, RX_ASSIGN, TX_ASSIGN};
use super::profiles::{Identity, identity_objects};
use super::slave::{Device, Slave};

/// A slave from an SII image; the image must parse.
pub fn slave_from_sii(eeprom: Vec<u8>) -> Result<Slave, SiiError> {
    let image = Sii::parse(&eeprom)?;
    let mut od = ObjectDictionary::new();
    for (list, rx) in [(&image.rx_pdos, true), (&image.tx_pdos, false)] {
        let chosen: Vec<&PdoRecord> = image.default_assignment(list).collect();
        for p in &chosen {
            let entries: Vec<(PdoEntry, String, DataType)> = p
                .entries
                .iter()
                .map(|e| {
                    let name = image.string(e.name).map(decode_text).unwrap_or_default();
                    let entry = PdoEntry { index: e.index, subindex: e.subindex, bits: e.bits };
                    let dtype = DataType::from_code(e.data_type.into(), e.bits.into())
                        .unwrap_or_else(|| esi::data_type("", e.bits.into()));
                    (entry, name, dtype)
                })
                .collect();
            add_entry_objects(&mut od, rx, &entries);
            let name = image.string(p.name).map(decode_text).unwrap_or_default();
            let mapped: Vec<PdoEntry> = entries.iter().map(|(e, _, _)| *e).collect();
            pdo_map::add_mapping(&mut od, p.index, &name, &mapped, true);
        }
        let indices: Vec<u16> = chosen.iter().map(|p| p.index).collect();
        let assign = if rx { RX_ASSIGN } else { TX_ASSIGN };
        if !indices.is_empty() {
            pdo_map::add_assignment(&mut od, assign, &indices, indices.len(), true);
        }
    }
    if image.protocols & protocol::COE != 0 {
        let id = Identity {
            vendor_id: image.vendor_id,
            product_code: image.product_code,
            revision: image.revision,
            serial: image.serial,
        };
        identity_objects(&mut od, id, &image.name().unwrap_or_default(), 0);
    }
    let has_dc = image.dc.is_some();
    super::cia402::add_profile_objects(&mut od);
    let axes = super::cia402::axes_in(&od);
    let device = if axes.is_empty() { Device::Passive } else { Device::Drive(axes) };
    Ok(Slave::new(eeprom, od, device, has_dc))
}
