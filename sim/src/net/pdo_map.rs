//! PDO assignment (0x1C12/0x1C13) and mapping (0x16xx/0x1Axx) objects, the
//! process-image layout they produce, and the SDO rules for changing them
//! (CiA301 / ETG.1000.6 5.6.7): writable in PRE-OP only on configurable
//! devices, entries only while subindex 0 is 0, mapped objects must exist,
//! be mappable in that direction and match in size.
//!
//! Those rules are for a host that remaps. A device's own mapping (what its
//! description gives) is taken as it stands, the way the device runs it
//! (real devices' files break the remapping rules, and a simulator that
//! refused them could not bring those devices up): entries shorter or
//! longer than their object (Beckhoff's "compact" PDOs map 16 bits of
//! UDINT objects; a BOOL mapped as 16 bits) carry the object's low bits;
//! an entry flagged for the other direction carries its object all the
//! same; an entry naming an object the dictionary lacks, or a
//! PDO-communication object itself (an open-source board mapping
//! 0x1600:01..05 as USINT), is a placeholder: its bits are in the image and
//! move no object.

use ecmxf_wire::payload::pdo::PdoEntry;
use ecmxf_wire::payload::sdo::SdoAbortCode;

use super::od::{Entry, ObjectDictionary, SdoResult};

pub use ecmxf_devices::pdo::*;

/// One mapped object in a process image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MappedEntry {
    /// Object index (0 = padding).
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// Bit offset in the slave's image.
    pub bit_offset: u32,
    /// Bit length.
    pub bits: u8,
}

/// A slave's image in one direction.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Layout {
    /// Entries in image order.
    pub entries: Vec<MappedEntry>,
    /// Total bits.
    pub bits: u32,
}

impl Layout {
    /// Image size in bytes.
    pub fn bytes(&self) -> usize {
        self.bits.div_ceil(8) as usize
    }
}

/// Computes the layout of one direction from the dictionary, as the
/// mapping stands (see the module doc). Fails with the object at fault only
/// when an assigned PDO has no mapping object.
pub fn layout(od: &ObjectDictionary, rx: bool) -> Result<Layout, u16> {
    let assign = if rx { RX_ASSIGN } else { TX_ASSIGN };
    let Some(a) = od.object(assign) else {
        return Ok(Layout::default());
    };
    let mut out = Layout::default();
    let count = a.entries.get(&0).map_or(0, Entry::int) as u8;
    for sub in 1..=count {
        let pdo = od.int(assign, sub) as u16;
        let map = od.mapping(pdo).ok_or(pdo)?;
        let n = map.entries.get(&0).map_or(0, Entry::int) as u8;
        for s in 1..=n {
            let e = PdoEntry::from_u32(map.entries.get(&s).map_or(0, Entry::int) as u32);
            out.entries.push(MappedEntry { index: e.index, subindex: e.subindex, bit_offset: out.bits, bits: e.bits });
            out.bits += u32::from(e.bits);
        }
    }
    Ok(out)
}

/// Object-specific SDO download checks for assignment and mapping objects.
pub fn validate_write(od: &ObjectDictionary, index: u16, sub: u8, data: &[u8]) -> SdoResult<()> {
    let value = |n: usize| data.iter().take(n).enumerate().fold(0u32, |acc, (i, b)| acc | u32::from(*b) << (8 * i));
    if index == RX_ASSIGN || index == TX_ASSIGN {
        let rx = index == RX_ASSIGN;
        let obj = od.object(index).ok_or(SdoAbortCode::OBJECT_MISSING)?;
        let capacity = obj.entries.len() - 1;
        if sub == 0 {
            let n = value(1) as usize;
            if n > capacity {
                return Err(SdoAbortCode::VALUE_TOO_HIGH);
            }
            for s in 1..=n as u8 {
                let p = od.int(index, s) as u16;
                if od.object(p).is_none() || (rx && !is_rx_mapping(p)) || (!rx && !is_tx_mapping(p)) {
                    return Err(SdoAbortCode::VALUE_RANGE);
                }
            }
        } else {
            if od.int(index, 0) != 0 {
                return Err(SdoAbortCode::SUBINDEX0_NOT_ZERO);
            }
            let p = value(2) as u16;
            let ok = p == 0 || (od.object(p).is_some() && if rx { is_rx_mapping(p) } else { is_tx_mapping(p) });
            if !ok {
                return Err(SdoAbortCode::VALUE_RANGE);
            }
        }
    } else if is_rx_mapping(index) || is_tx_mapping(index) {
        let rx = is_rx_mapping(index);
        let obj = od.object(index).ok_or(SdoAbortCode::OBJECT_MISSING)?;
        if sub == 0 {
            let n = value(1) as usize;
            if n > obj.entries.len() - 1 {
                return Err(SdoAbortCode::VALUE_TOO_HIGH);
            }
            let mut bits = 0usize;
            for s in 1..=n as u8 {
                bits += (od.int(index, s) as u32 & 0xFF) as usize;
            }
            if bits > MAX_IMAGE_BYTES * 8 {
                return Err(SdoAbortCode::PDO_TOO_LONG);
            }
        } else {
            if od.int(index, 0) != 0 {
                return Err(SdoAbortCode::SUBINDEX0_NOT_ZERO);
            }
            let e = PdoEntry::from_u32(value(4));
            if e.index != 0 {
                let target = od.entry(e.index, e.subindex).ok_or(SdoAbortCode::NOT_MAPPABLE)?;
                if !target.mappable.allows(rx) && !od.mapped_anyway.contains(&(e.index, e.subindex)) {
                    return Err(SdoAbortCode::NOT_MAPPABLE);
                }
                if target.dtype.bits() != u32::from(e.bits) {
                    return Err(SdoAbortCode::LENGTH_MISMATCH);
                }
            }
        }
    }
    Ok(())
}

/// Copies `bits` bits from `src` at bit `from` to `dst` at bit `to`
/// (LSB-first, as EtherCAT process images are). Bits beyond the end of
/// `src` are 0 (an entry wider than its object); the copy stops at the end
/// of `dst` (an entry narrower than its object's value).
pub fn copy_bits(src: &[u8], from: u32, dst: &mut [u8], to: u32, bits: u32) {
    if from % 8 == 0 && to % 8 == 0 && bits % 8 == 0 {
        let (f, t, n) = ((from / 8) as usize, (to / 8) as usize, (bits / 8) as usize);
        let Some(out) = dst.get_mut(t..(t + n).min(dst.len())) else { return };
        let have = src.get(f..).unwrap_or(&[]);
        for (i, o) in out.iter_mut().enumerate() {
            *o = have.get(i).copied().unwrap_or(0);
        }
        return;
    }
    for i in 0..bits {
        let (sb, db) = (from + i, to + i);
        let (si, di) = ((sb / 8) as usize, (db / 8) as usize);
        if di >= dst.len() {
            return;
        }
        let bit = src.get(si).map_or(0, |b| (b >> (sb % 8)) & 1);
        dst[di] = (dst[di] & !(1 << (db % 8))) | (bit << (db % 8));
    }
}

/// Whether a mapped entry moves no object: padding, or a PDO-communication
/// object (mapping 0x1600-0x1BFF, assignment and SM objects 0x1C00-0x1C3F),
/// which process data must never overwrite.
fn placeholder(m: &MappedEntry) -> bool {
    m.index == 0 || (0x1600..0x1C40).contains(&m.index)
}

/// Moves an output image into the mapped objects.
pub fn image_to_od(od: &mut ObjectDictionary, layout: &Layout, image: &[u8]) {
    for m in &layout.entries {
        if placeholder(m) {
            continue;
        }
        if let Some(e) = od.entry_mut(m.index, m.subindex) {
            copy_bits(image, m.bit_offset, &mut e.value, 0, m.bits.into());
        }
    }
}

/// Moves the mapped objects into an input image.
pub fn od_to_image(od: &ObjectDictionary, layout: &Layout, image: &mut [u8]) {
    for m in &layout.entries {
        if placeholder(m) {
            continue;
        }
        if let Some(e) = od.entry(m.index, m.subindex) {
            copy_bits(&e.value, 0, image, m.bit_offset, m.bits.into());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net::esm::AlState;
    use crate::net::od::{Access, DataType, Mappable, Object, SdoServer};

    fn od(fixed: bool) -> ObjectDictionary {
        let mut od = ObjectDictionary::new();
        od.insert(0x6040, Object::var("cw", Entry::new("cw", DataType::UInt16, Access::RW).mappable(Mappable::Rx)));
        od.insert(0x6041, Object::var("sw", Entry::new("sw", DataType::UInt16, Access::RO).mappable(Mappable::Tx)));
        od.insert(0x6060, Object::var("mode", Entry::new("mode", DataType::Int8, Access::RW).mappable(Mappable::Rx)));
        od.insert(0x1000, Object::var("type", Entry::new("type", DataType::UInt32, Access::RO)));
        add_mapping(&mut od, 0x1600, "RxPDO", &[PdoEntry { index: 0x6040, subindex: 0, bits: 16 }], fixed);
        add_mapping(&mut od, 0x1601, "RxPDO 2", &[], fixed);
        add_mapping(&mut od, 0x1A00, "TxPDO", &[PdoEntry { index: 0x6041, subindex: 0, bits: 16 }], fixed);
        add_assignment(&mut od, RX_ASSIGN, &[0x1600], 2, fixed);
        add_assignment(&mut od, TX_ASSIGN, &[0x1A00], 2, fixed);
        od
    }

    #[test]
    fn a_devices_own_mapping_is_taken_as_it_stands() {
        let mut od = od(true);
        od.insert(
            0x6010,
            Object::var("count", Entry::new("count", DataType::UInt32, Access::RO).mappable(Mappable::Tx)),
        );
        od.insert(0x6020, Object::var("flag", Entry::new("flag", DataType::Bool, Access::RO).mappable(Mappable::Rx)));
        let entries = [
            PdoEntry { index: 0x6010, subindex: 0, bits: 16 }, // compact: 16 bits of a UDINT
            PdoEntry { index: 0x6020, subindex: 0, bits: 16 }, // a BOOL as 16 bits, flagged for outputs
            PdoEntry { index: 0x1A00, subindex: 1, bits: 8 },  // the mapping object itself
            PdoEntry { index: 0x7777, subindex: 1, bits: 8 },  // not in the dictionary
        ];
        add_mapping(&mut od, 0x1A00, "TxPDO", &entries, true);
        let tx = layout(&od, false).unwrap();
        assert_eq!(tx.bits, 48);
        od.entry_mut(0x6010, 0).unwrap().value = 0x0012_3456u32.to_le_bytes().to_vec();
        od.entry_mut(0x6020, 0).unwrap().value = vec![1];
        let mut image = vec![0xAA; 6];
        od_to_image(&od, &tx, &mut image);
        assert_eq!(&image[..2], &[0x56, 0x34], "the object's low 16 bits");
        assert_eq!(image[2], 1, "the BOOL's byte");
        assert_eq!(&image[4..], &[0xAA, 0xAA], "placeholders move nothing");
        // Outputs never overwrite a mapping object.
        add_mapping(&mut od, 0x1600, "RxPDO", &[PdoEntry { index: 0x1600, subindex: 1, bits: 32 }], true);
        let rx = layout(&od, true).unwrap();
        let before = od.int(0x1600, 1);
        image_to_od(&mut od, &rx, &[0xFF; 4]);
        assert_eq!(od.int(0x1600, 1), before);
    }

    fn write(od: &mut ObjectDictionary, index: u16, sub: u8, data: &[u8], state: AlState) -> SdoResult<()> {
        od.download(index, sub, false, data, state, validate_write)
    }

    #[test]
    fn layout_follows_mapping() {
        let od = od(false);
        let rx = layout(&od, true).unwrap();
        assert_eq!(rx.bytes(), 2);
        assert_eq!(rx.entries[0], MappedEntry { index: 0x6040, subindex: 0, bit_offset: 0, bits: 16 });
    }

    #[test]
    fn remapping_in_preop_follows_the_rules() {
        let mut od = od(false);
        let mode = PdoEntry { index: 0x6060, subindex: 0, bits: 8 }.to_u32().to_le_bytes();
        assert_eq!(write(&mut od, 0x1600, 2, &mode, AlState::PreOp), Err(SdoAbortCode::SUBINDEX0_NOT_ZERO));
        assert_eq!(write(&mut od, 0x1600, 0, &[0], AlState::SafeOp), Err(SdoAbortCode::WRONG_STATE));
        write(&mut od, 0x1600, 0, &[0], AlState::PreOp).unwrap();
        let sw = PdoEntry { index: 0x6041, subindex: 0, bits: 16 }.to_u32().to_le_bytes();
        assert_eq!(write(&mut od, 0x1600, 2, &sw, AlState::PreOp), Err(SdoAbortCode::NOT_MAPPABLE));
        let bad_len = PdoEntry { index: 0x6060, subindex: 0, bits: 16 }.to_u32().to_le_bytes();
        assert_eq!(write(&mut od, 0x1600, 2, &bad_len, AlState::PreOp), Err(SdoAbortCode::LENGTH_MISMATCH));
        let unmappable = PdoEntry { index: 0x1000, subindex: 0, bits: 32 }.to_u32().to_le_bytes();
        assert_eq!(write(&mut od, 0x1600, 2, &unmappable, AlState::PreOp), Err(SdoAbortCode::NOT_MAPPABLE));
        write(&mut od, 0x1600, 2, &mode, AlState::PreOp).unwrap();
        write(&mut od, 0x1600, 0, &[2], AlState::PreOp).unwrap();
        let rx = layout(&od, true).unwrap();
        // sub 1 still holds 0x6040 from before, sub 2 is the mode.
        assert_eq!(rx.bits, 24);
        // Assignment: only existing Rx mapping objects.
        write(&mut od, RX_ASSIGN, 0, &[0], AlState::PreOp).unwrap();
        assert_eq!(write(&mut od, RX_ASSIGN, 1, &[0x00, 0x1A], AlState::PreOp), Err(SdoAbortCode::VALUE_RANGE));
        write(&mut od, RX_ASSIGN, 2, &[0x01, 0x16], AlState::PreOp).unwrap();
        assert_eq!(write(&mut od, RX_ASSIGN, 0, &[3], AlState::PreOp), Err(SdoAbortCode::VALUE_TOO_HIGH));
        write(&mut od, RX_ASSIGN, 0, &[2], AlState::PreOp).unwrap();
        assert_eq!(layout(&od, true).unwrap().bits, 24);
    }

    #[test]
    fn fixed_mapping_is_read_only() {
        let mut od = od(true);
        assert_eq!(write(&mut od, 0x1600, 0, &[0], AlState::PreOp), Err(SdoAbortCode::READ_ONLY));
        assert_eq!(write(&mut od, RX_ASSIGN, 0, &[0], AlState::PreOp), Err(SdoAbortCode::READ_ONLY));
    }

    #[test]
    fn bit_copies() {
        let src = [0b1010_1100u8, 0xFF];
        let mut dst = [0u8; 2];
        copy_bits(&src, 2, &mut dst, 5, 4);
        assert_eq!(dst, [0b0110_0000, 0b0000_0001]);
        let mut dst = [0u8; 2];
        copy_bits(&src, 0, &mut dst, 0, 16);
        assert_eq!(dst, src);
    }
}
