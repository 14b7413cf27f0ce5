//! PDO descriptions: the assignment (0x1C12/0x1C13) and mapping
//! (0x16xx/0x1Axx) objects of CiA301 / ETG.1000.6 5.6.7 as a device's
//! dictionary holds them, built from the PDO lists of an ESI or a profile.

use ecmxf_wire::payload::pdo::PdoEntry;

use crate::od::{Access, DataType, Entry, Mappable, Object, ObjectDictionary, ObjectKind};

/// Outputs' assignment object.
pub const RX_ASSIGN: u16 = 0x1C12;
/// Inputs' assignment object.
pub const TX_ASSIGN: u16 = 0x1C13;
/// Most entries one mapping object holds here.
pub const MAX_ENTRIES: usize = 16;
/// Largest process image of one direction, bytes (SM length limit we model).
pub const MAX_IMAGE_BYTES: usize = 512;

/// Whether `index` is an RxPDO mapping object.
pub fn is_rx_mapping(index: u16) -> bool {
    (0x1600..=0x17FF).contains(&index)
}

/// Whether `index` is a TxPDO mapping object.
pub fn is_tx_mapping(index: u16) -> bool {
    (0x1A00..=0x1BFF).contains(&index)
}

/// Sets an existing object's values to `values` (subindex 1 on, and the
/// count in subindex 0), keeping its names and access as described: an
/// ESI's `<Dictionary>` that has the object says how the device describes
/// it. Subindices it lacks are added as `make` builds them.
fn fill_described(object: &mut Object, values: &[i64], make: impl Fn(usize) -> Entry) {
    for (i, v) in values.iter().enumerate() {
        let fresh = make(i + 1);
        let e = object.entries.entry(i as u8 + 1).or_insert_with(|| fresh.clone());
        // A subindex described at another size cannot hold the value: the
        // device's own layout wins, under the described name.
        if e.dtype.bits() != fresh.dtype.bits() {
            *e = Entry { name: e.name.clone(), ..fresh };
        }
        e.set_int(*v);
    }
    if let Some(e0) = object.entries.get_mut(&0) {
        e0.set_int(values.len() as i64);
    }
}

/// Adds a mapping object with `entries`; `fixed` makes it read-only. One
/// the dictionary already describes keeps its names and access.
pub fn add_mapping(od: &mut ObjectDictionary, index: u16, name: &str, entries: &[PdoEntry], fixed: bool) {
    let access = if fixed { Access::RO } else { Access::RW_PREOP };
    if let Some(described) = od.object(index).filter(|o| o.kind != ObjectKind::Var) {
        let mut object = described.clone();
        let values: Vec<i64> = entries.iter().map(|e| e.to_u32().into()).collect();
        fill_described(&mut object, &values, |i| Entry::new(&format!("SubIndex {i:03}"), DataType::UInt32, access));
        od.insert(index, object);
        return;
    }
    let mut subs: Vec<Entry> = entries
        .iter()
        .enumerate()
        .map(|(i, e)| {
            Entry::new(&format!("SubIndex {:03}", i + 1), DataType::UInt32, access).default_int(e.to_u32().into())
        })
        .collect();
    if !fixed {
        while subs.len() < MAX_ENTRIES {
            subs.push(Entry::new(&format!("SubIndex {:03}", subs.len() + 1), DataType::UInt32, access));
        }
    }
    let mut obj = Object::record(name, ObjectKind::Record, access, subs);
    obj.entries.get_mut(&0).expect("sub0").set_int(entries.len() as i64);
    od.insert(index, obj);
}

/// Adds an assignment object listing `pdos`; `fixed` makes it read-only.
pub fn add_assignment(od: &mut ObjectDictionary, index: u16, pdos: &[u16], capacity: usize, fixed: bool) {
    let access = if fixed { Access::RO } else { Access::RW_PREOP };
    if let Some(described) = od.object(index).filter(|o| o.kind != ObjectKind::Var) {
        let mut object = described.clone();
        let values: Vec<i64> = pdos.iter().map(|p| i64::from(*p)).collect();
        // Unused subindices hold 0.
        for e in object.entries.range_mut(1..).map(|(_, e)| e) {
            e.set_int(0);
        }
        fill_described(&mut object, &values, |i| Entry::new(&format!("SubIndex {i:03}"), DataType::UInt16, access));
        od.insert(index, object);
        return;
    }
    let mut subs: Vec<Entry> = pdos
        .iter()
        .enumerate()
        .map(|(i, p)| Entry::new(&format!("SubIndex {:03}", i + 1), DataType::UInt16, access).default_int((*p).into()))
        .collect();
    while subs.len() < capacity.max(pdos.len()) {
        subs.push(Entry::new(&format!("SubIndex {:03}", subs.len() + 1), DataType::UInt16, access));
    }
    let name = if index == RX_ASSIGN { "Sync manager 2 PDO assignment" } else { "Sync manager 3 PDO assignment" };
    let mut obj = Object::record(name, ObjectKind::Array, access, subs);
    obj.entries.get_mut(&0).expect("sub0").set_int(pdos.len() as i64);
    od.insert(index, obj);
}

/// An object mappable in the given direction, for ESI-built dictionaries.
pub fn mappable_for(rx: bool) -> Mappable {
    if rx { Mappable::Rx } else { Mappable::Tx }
}
