//! A slave's CoE object dictionary and the SDO rules a real slave enforces
//! (ETG.1000.6 / CiA301): data types, access rights per EtherCAT state,
//! PDO-mappable flags, value ranges, complete access, and the abort codes a
//! master sees when it gets any of these wrong.

use std::collections::BTreeMap;

use ecmxf_wire::payload::sdo::SdoAbortCode;

use super::esm::AlState;

/// CoE data types (ETG.1000.6 Table 64), with their sizes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DataType {
    /// 0x0001, 1 bit.
    Bool,
    /// 0x0002.
    Int8,
    /// 0x0003.
    Int16,
    /// 0x0004.
    Int32,
    /// 0x0015.
    Int64,
    /// 0x0005.
    UInt8,
    /// 0x0006.
    UInt16,
    /// 0x0007.
    UInt32,
    /// 0x001B.
    UInt64,
    /// 0x0008.
    Real32,
    /// 0x0011.
    Real64,
    /// 0x0009, with its length in bytes.
    VisibleString(u16),
    /// 0x000A, with its length in bytes.
    OctetString(u16),
    /// BITn (ETG.1000.6 0x0030..0x0037), n = 1..=8 bits.
    Bits(u8),
}

impl DataType {
    /// Size in bits.
    pub fn bits(self) -> u32 {
        match self {
            Self::Bool => 1,
            Self::Int8 | Self::UInt8 => 8,
            Self::Int16 | Self::UInt16 => 16,
            Self::Int32 | Self::UInt32 | Self::Real32 => 32,
            Self::Int64 | Self::UInt64 | Self::Real64 => 64,
            Self::VisibleString(n) | Self::OctetString(n) => u32::from(n) * 8,
            Self::Bits(n) => u32::from(n),
        }
    }

    /// Size in whole bytes as an SDO carries it.
    pub fn bytes(self) -> usize {
        self.bits().div_ceil(8) as usize
    }

    /// The ETG type code.
    pub fn code(self) -> u16 {
        match self {
            Self::Bool => 0x01,
            Self::Int8 => 0x02,
            Self::Int16 => 0x03,
            Self::Int32 => 0x04,
            Self::UInt8 => 0x05,
            Self::UInt16 => 0x06,
            Self::UInt32 => 0x07,
            Self::Real32 => 0x08,
            Self::VisibleString(_) => 0x09,
            Self::OctetString(_) => 0x0A,
            Self::Real64 => 0x11,
            Self::Int64 => 0x15,
            Self::UInt64 => 0x1B,
            Self::Bits(n) => 0x2F + u16::from(n),
        }
    }

    /// Whether values are signed integers.
    pub fn is_signed(self) -> bool {
        matches!(self, Self::Int8 | Self::Int16 | Self::Int32 | Self::Int64)
    }

    /// Whether an SDO write must carry exactly the type's size.
    fn is_fixed_size(self) -> bool {
        !matches!(self, Self::VisibleString(_) | Self::OctetString(_))
    }
}

/// The EtherCAT states in which an entry may be read or written.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct StateSet {
    /// PRE-OP.
    pub preop: bool,
    /// SAFE-OP.
    pub safeop: bool,
    /// OP.
    pub op: bool,
}

impl StateSet {
    /// Every mailbox state.
    pub const ALL: Self = Self { preop: true, safeop: true, op: true };
    /// No state.
    pub const NONE: Self = Self { preop: false, safeop: false, op: false };
    /// PRE-OP only (PDO assignment and mapping, most configuration).
    pub const PREOP: Self = Self { preop: true, safeop: false, op: false };

    /// Whether `state` is in the set.
    pub fn contains(self, state: AlState) -> bool {
        match state {
            AlState::PreOp => self.preop,
            AlState::SafeOp => self.safeop,
            AlState::Op => self.op,
            AlState::Init | AlState::Boot => false,
        }
    }
}

/// Read and write rights of an entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Access {
    /// States in which it can be read.
    pub read: StateSet,
    /// States in which it can be written.
    pub write: StateSet,
}

impl Access {
    /// Read-only in every state.
    pub const RO: Self = Self { read: StateSet::ALL, write: StateSet::NONE };
    /// Read-write in every state.
    pub const RW: Self = Self { read: StateSet::ALL, write: StateSet::ALL };
    /// Write-only in every state.
    pub const WO: Self = Self { read: StateSet::NONE, write: StateSet::ALL };
    /// Readable always, writable in PRE-OP only.
    pub const RW_PREOP: Self = Self { read: StateSet::ALL, write: StateSet::PREOP };
}

/// Whether an entry may be mapped into a PDO, and in which direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Mappable {
    /// Not mappable.
    No,
    /// Into RxPDOs (outputs, master to slave).
    Rx,
    /// Into TxPDOs (inputs, slave to master).
    Tx,
    /// Either.
    Both,
}

impl Mappable {
    /// Whether mappable into the given direction (`true` = RxPDO).
    pub fn allows(self, rx: bool) -> bool {
        matches!((self, rx), (Self::Both, _) | (Self::Rx, true) | (Self::Tx, false))
    }
}

/// One subindex.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// Name, as an ESI would give it.
    pub name: String,
    /// Data type.
    pub dtype: DataType,
    /// Access rights.
    pub access: Access,
    /// PDO mapping.
    pub mappable: Mappable,
    /// Current value, `dtype.bytes()` long (strings: up to their length).
    pub value: Vec<u8>,
    /// Inclusive value range for integers, checked on SDO download.
    pub range: Option<(i64, i64)>,
}

impl Entry {
    /// An entry with a zero value.
    pub fn new(name: &str, dtype: DataType, access: Access) -> Self {
        Self { name: name.into(), dtype, access, mappable: Mappable::No, value: vec![0; dtype.bytes()], range: None }
    }

    /// With a PDO mapping flag.
    #[must_use]
    pub fn mappable(mut self, m: Mappable) -> Self {
        self.mappable = m;
        self
    }

    /// With a little-endian integer default.
    #[must_use]
    pub fn default_int(mut self, v: i64) -> Self {
        let n = self.dtype.bytes();
        self.value = v.to_le_bytes()[..n.min(8)].to_vec();
        self.value.resize(n, 0);
        self
    }

    /// With a byte default (strings).
    #[must_use]
    pub fn default_bytes(mut self, v: &[u8]) -> Self {
        self.value = v.to_vec();
        self
    }

    /// With an allowed range.
    #[must_use]
    pub fn range(mut self, min: i64, max: i64) -> Self {
        self.range = Some((min, max));
        self
    }

    /// The value as an integer (sign-extended for signed types).
    pub fn int(&self) -> i64 {
        let mut b = [0u8; 8];
        let n = self.value.len().min(8);
        b[..n].copy_from_slice(&self.value[..n]);
        let raw = i64::from_le_bytes(b);
        if self.dtype.is_signed() && n < 8 && n > 0 {
            let shift = 64 - 8 * n as u32;
            (raw << shift) >> shift
        } else {
            raw
        }
    }

    /// Sets the value from an integer (truncated to the type's size).
    pub fn set_int(&mut self, v: i64) {
        let n = self.dtype.bytes().min(8);
        self.value[..n].copy_from_slice(&v.to_le_bytes()[..n]);
    }
}

/// Object code (ETG.1000.6): how the subindices are organised.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ObjectKind {
    /// One value at subindex 0.
    Var,
    /// Subindex 0 = count, 1..=n of one type.
    Array,
    /// Subindex 0 = highest subindex, 1..=n of any types.
    Record,
}

/// One object: index, kind, entries by subindex.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    /// Name.
    pub name: String,
    /// Kind.
    pub kind: ObjectKind,
    /// Entries; for arrays and records `entries[0]` is subindex 0 (count).
    /// Subindices may have gaps, so they are kept by number.
    pub entries: BTreeMap<u8, Entry>,
}

impl Object {
    /// Whether a complete access starting at `sub` is possible (ETG.1000.6:
    /// only records and arrays, from subindex 0 or 1).
    fn allows_complete_access(&self, sub: u8) -> SdoResult<()> {
        if self.kind == ObjectKind::Var {
            return Err(SdoAbortCode::NO_COMPLETE_ACCESS);
        }
        if sub > 1 {
            return Err(SdoAbortCode::SUBINDEX_MISSING);
        }
        Ok(())
    }

    /// A VAR object.
    pub fn var(name: &str, entry: Entry) -> Self {
        Self { name: name.into(), kind: ObjectKind::Var, entries: BTreeMap::from([(0, entry)]) }
    }

    /// A RECORD or ARRAY with subindex 0 holding the highest subindex.
    pub fn record(name: &str, kind: ObjectKind, sub0_access: Access, subs: Vec<Entry>) -> Self {
        let mut entries = BTreeMap::new();
        entries.insert(0, Entry::new("Number of entries", DataType::UInt8, sub0_access).default_int(subs.len() as i64));
        for (i, e) in subs.into_iter().enumerate() {
            entries.insert(i as u8 + 1, e);
        }
        Self { name: name.into(), kind, entries }
    }
}

/// SDO outcome: data or an abort code.
pub type SdoResult<T> = Result<T, SdoAbortCode>;

/// A slave's object dictionary.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjectDictionary {
    objects: BTreeMap<u16, Object>,
    /// The device does not do CoE complete access at all (ESI
    /// `<CoE CompleteAccess="0">`, SII CoE details bit 5 clear): every
    /// complete access is refused with 0x06010004.
    pub no_complete_access: bool,
}

impl ObjectDictionary {
    /// An empty dictionary.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds or replaces an object.
    pub fn insert(&mut self, index: u16, object: Object) {
        self.objects.insert(index, object);
    }

    /// An object.
    pub fn object(&self, index: u16) -> Option<&Object> {
        self.objects.get(&index)
    }

    /// All objects in index order.
    pub fn objects(&self) -> impl Iterator<Item = (u16, &Object)> {
        self.objects.iter().map(|(i, o)| (*i, o))
    }

    /// An entry.
    pub fn entry(&self, index: u16, sub: u8) -> Option<&Entry> {
        self.objects.get(&index)?.entries.get(&sub)
    }

    /// An entry, mutably (device models and the process image use this; it
    /// bypasses access rights).
    pub fn entry_mut(&mut self, index: u16, sub: u8) -> Option<&mut Entry> {
        self.objects.get_mut(&index)?.entries.get_mut(&sub)
    }

    /// An integer value, or 0 when the entry is missing.
    pub fn int(&self, index: u16, sub: u8) -> i64 {
        self.entry(index, sub).map_or(0, Entry::int)
    }

    /// Sets an integer value if the entry exists (device side, no checks).
    pub fn set_int(&mut self, index: u16, sub: u8, v: i64) {
        if let Some(e) = self.entry_mut(index, sub) {
            e.set_int(v);
        }
    }

    /// SDO upload as a slave answers it.
    pub fn upload(&self, index: u16, sub: u8, complete: bool, state: AlState) -> SdoResult<Vec<u8>> {
        let obj = self.objects.get(&index).ok_or(SdoAbortCode::OBJECT_MISSING)?;
        if complete {
            if self.no_complete_access {
                return Err(SdoAbortCode::NO_COMPLETE_ACCESS);
            }
            obj.allows_complete_access(sub)?;
            let count = obj.entries.get(&0).map_or(0, |e| e.int() as u8);
            let mut out = Vec::new();
            for (s, e) in obj.entries.range(sub..) {
                if *s > count && *s != 0 {
                    break;
                }
                if !e.access.read.contains(state) {
                    return Err(if e.access.read == StateSet::NONE {
                        SdoAbortCode::WRITE_ONLY
                    } else {
                        SdoAbortCode::WRONG_STATE
                    });
                }
                out.extend_from_slice(&e.value);
                // Subindex 0 travels as 16 bits in complete access
                // (ETG.1000.6 5.6.2.1).
                if *s == 0 {
                    out.push(0);
                }
            }
            return Ok(out);
        }
        let e = obj.entries.get(&sub).ok_or(SdoAbortCode::SUBINDEX_MISSING)?;
        if !e.access.read.contains(state) {
            return Err(if e.access.read == StateSet::NONE {
                SdoAbortCode::WRITE_ONLY
            } else {
                SdoAbortCode::WRONG_STATE
            });
        }
        Ok(e.value.clone())
    }

    /// SDO download as a slave answers it. `validate` sees the whole new
    /// value of an entry before it is stored, for object-specific rules (PDO
    /// mapping checks); it may refuse with an abort code.
    pub fn download(
        &mut self,
        index: u16,
        sub: u8,
        complete: bool,
        data: &[u8],
        state: AlState,
        mut validate: impl FnMut(&ObjectDictionary, u16, u8, &[u8]) -> SdoResult<()>,
    ) -> SdoResult<()> {
        let obj = self.objects.get(&index).ok_or(SdoAbortCode::OBJECT_MISSING)?;
        if complete {
            if self.no_complete_access {
                return Err(SdoAbortCode::NO_COMPLETE_ACCESS);
            }
            obj.allows_complete_access(sub)?;
            // Split the data over the entries, subindex 0 as 16 bits.
            let mut writes: Vec<(u8, Vec<u8>)> = Vec::new();
            let mut rest = data;
            for (s, e) in obj.entries.range(sub..) {
                let n = if *s == 0 { 2 } else { e.dtype.bytes() };
                if rest.len() < n {
                    if rest.is_empty() && *s != 0 {
                        break;
                    }
                    return Err(SdoAbortCode::LENGTH_TOO_LOW);
                }
                let v = if *s == 0 { vec![rest[0]] } else { rest[..n].to_vec() };
                writes.push((*s, v));
                rest = &rest[n..];
            }
            if !rest.is_empty() {
                return Err(SdoAbortCode::LENGTH_TOO_HIGH);
            }
            for (s, v) in &writes {
                self.check_write(index, *s, v, state)?;
                validate(self, index, *s, v)?;
            }
            for (s, v) in writes {
                if let Some(e) = self.entry_mut(index, s) {
                    e.value = v;
                }
            }
            return Ok(());
        }
        self.check_write(index, sub, data, state)?;
        validate(self, index, sub, data)?;
        let e = self.entry_mut(index, sub).ok_or(SdoAbortCode::SUBINDEX_MISSING)?;
        if e.dtype.is_fixed_size() {
            e.value = data.to_vec();
        } else {
            let mut v = data.to_vec();
            v.resize(e.dtype.bytes(), 0);
            e.value = v;
        }
        Ok(())
    }

    fn check_write(&self, index: u16, sub: u8, data: &[u8], state: AlState) -> SdoResult<()> {
        let e = self.entry(index, sub).ok_or(SdoAbortCode::SUBINDEX_MISSING)?;
        if e.access.write == StateSet::NONE {
            return Err(SdoAbortCode::READ_ONLY);
        }
        if !e.access.write.contains(state) {
            return Err(SdoAbortCode::WRONG_STATE);
        }
        let want = e.dtype.bytes();
        if e.dtype.is_fixed_size() {
            if data.len() > want {
                return Err(SdoAbortCode::LENGTH_TOO_HIGH);
            }
            if data.len() < want {
                return Err(SdoAbortCode::LENGTH_TOO_LOW);
            }
        } else if data.len() > want {
            return Err(SdoAbortCode::LENGTH_TOO_HIGH);
        }
        if let Some((min, max)) = e.range {
            let mut probe = e.clone();
            probe.value = data.to_vec();
            let v = probe.int();
            if v > max {
                return Err(SdoAbortCode::VALUE_TOO_HIGH);
            }
            if v < min {
                return Err(SdoAbortCode::VALUE_TOO_LOW);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn od() -> ObjectDictionary {
        let mut od = ObjectDictionary::new();
        od.insert(
            0x1000,
            Object::var(
                "Device type",
                Entry::new("Device type", DataType::UInt32, Access::RO).default_int(0x0002_0192),
            ),
        );
        od.insert(
            0x6060,
            Object::var(
                "Modes of operation",
                Entry::new("Mode", DataType::Int8, Access::RW).range(8, 10).default_int(8),
            ),
        );
        od.insert(0x2000, Object::var("Secret", Entry::new("Secret", DataType::UInt16, Access::WO)));
        od.insert(
            0x1C12,
            Object::record(
                "RxPDO assign",
                ObjectKind::Array,
                Access::RW_PREOP,
                vec![Entry::new("Subindex 001", DataType::UInt16, Access::RW_PREOP).default_int(0x1600)],
            ),
        );
        od.insert(
            0x1008,
            Object::var("Name", Entry::new("Name", DataType::VisibleString(8), Access::RO).default_bytes(b"Drive")),
        );
        od
    }

    fn ok(_: &ObjectDictionary, _: u16, _: u8, _: &[u8]) -> SdoResult<()> {
        Ok(())
    }

    #[test]
    fn upload_rules() {
        let od = od();
        assert_eq!(od.upload(0x1000, 0, false, AlState::PreOp), Ok(vec![0x92, 0x01, 0x02, 0x00]));
        assert_eq!(od.upload(0x1234, 0, false, AlState::PreOp), Err(SdoAbortCode::OBJECT_MISSING));
        assert_eq!(od.upload(0x1000, 1, false, AlState::PreOp), Err(SdoAbortCode::SUBINDEX_MISSING));
        assert_eq!(od.upload(0x2000, 0, false, AlState::PreOp), Err(SdoAbortCode::WRITE_ONLY));
        assert_eq!(od.upload(0x1000, 0, true, AlState::PreOp), Err(SdoAbortCode::NO_COMPLETE_ACCESS));
        assert_eq!(od.upload(0x1C12, 0, true, AlState::PreOp), Ok(vec![1, 0, 0x00, 0x16]));
        assert_eq!(od.upload(0x1C12, 1, true, AlState::PreOp), Ok(vec![0x00, 0x16]));
    }

    #[test]
    fn download_rules() {
        let mut od = od();
        assert_eq!(od.download(0x1000, 0, false, &[0; 4], AlState::PreOp, ok), Err(SdoAbortCode::READ_ONLY));
        assert_eq!(od.download(0x6060, 0, false, &[9, 0], AlState::Op, ok), Err(SdoAbortCode::LENGTH_TOO_HIGH));
        assert_eq!(od.download(0x6060, 0, false, &[], AlState::Op, ok), Err(SdoAbortCode::LENGTH_TOO_LOW));
        assert_eq!(od.download(0x6060, 0, false, &[11], AlState::Op, ok), Err(SdoAbortCode::VALUE_TOO_HIGH));
        assert_eq!(od.download(0x6060, 0, false, &[0xFF], AlState::Op, ok), Err(SdoAbortCode::VALUE_TOO_LOW));
        assert_eq!(od.download(0x6060, 0, false, &[9], AlState::Op, ok), Ok(()));
        assert_eq!(od.int(0x6060, 0), 9);
        assert_eq!(od.download(0x1C12, 1, false, &[0x01, 0x16], AlState::SafeOp, ok), Err(SdoAbortCode::WRONG_STATE));
        assert_eq!(od.download(0x1C12, 1, false, &[0x01, 0x16], AlState::PreOp, ok), Ok(()));
        assert_eq!(od.download(0x1C12, 0, true, &[1, 0, 0x02, 0x16], AlState::PreOp, ok), Ok(()));
        assert_eq!(od.int(0x1C12, 1), 0x1602);
        assert_eq!(
            od.download(0x1C12, 0, true, &[1, 0, 0x02, 0x16, 0], AlState::PreOp, ok),
            Err(SdoAbortCode::LENGTH_TOO_HIGH)
        );
        assert_eq!(od.download(0x1008, 0, false, b"Too long name", AlState::PreOp, ok), Err(SdoAbortCode::READ_ONLY));
        let refuse = |_: &ObjectDictionary, _: u16, _: u8, _: &[u8]| Err(SdoAbortCode::NOT_MAPPABLE);
        assert_eq!(
            od.download(0x1C12, 1, false, &[0x01, 0x16], AlState::PreOp, refuse),
            Err(SdoAbortCode::NOT_MAPPABLE)
        );
        assert_eq!(od.int(0x1C12, 1), 0x1602, "refused write changed nothing");
    }

    #[test]
    fn no_sdo_in_init() {
        let od = od();
        assert_eq!(od.upload(0x1000, 0, false, AlState::Init), Err(SdoAbortCode::WRONG_STATE));
    }

    #[test]
    fn signed_values_sign_extend() {
        let e = Entry::new("x", DataType::Int16, Access::RW).default_int(-5);
        assert_eq!(e.int(), -5);
        let e = Entry::new("x", DataType::UInt16, Access::RW).default_int(0xFFFF);
        assert_eq!(e.int(), 0xFFFF);
    }
}
