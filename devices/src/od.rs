//! A device's CoE object dictionary as its description gives it
//! (ETG.1000.6 / CiA301, ETG.2000 `<Dictionary>`): data types, access rights
//! per EtherCAT state, PDO-mappable flags, value ranges and default values.
//! What a slave does with an SDO request (the abort codes) is the
//! simulator's business; this is the description both sides read.

use std::collections::BTreeMap;

use ecmxf_wire::EcatState;

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

    /// The type of an ETG type code (what [`DataType::code`] gives), for an
    /// entry of `bits` bits: `None` for codes outside the fixed-size types
    /// and when the type's size is not `bits` (a code that contradicts its
    /// entry is not believed).
    pub fn from_code(code: u16, bits: u32) -> Option<Self> {
        let t = match code {
            0x01 => Self::Bool,
            0x02 => Self::Int8,
            0x03 => Self::Int16,
            0x04 => Self::Int32,
            0x05 => Self::UInt8,
            0x06 => Self::UInt16,
            0x07 => Self::UInt32,
            0x08 => Self::Real32,
            0x11 => Self::Real64,
            0x15 => Self::Int64,
            0x1B => Self::UInt64,
            0x30..=0x37 => Self::Bits((code - 0x2F) as u8),
            _ => return None,
        };
        (t.bits() == bits).then_some(t)
    }

    /// Whether values are signed integers.
    pub fn is_signed(self) -> bool {
        matches!(self, Self::Int8 | Self::Int16 | Self::Int32 | Self::Int64)
    }

    /// Whether an SDO write must carry exactly the type's size.
    pub fn is_fixed_size(self) -> bool {
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
    pub fn contains(self, state: EcatState) -> bool {
        match state {
            EcatState::PreOp => self.preop,
            EcatState::SafeOp => self.safeop,
            EcatState::Op => self.op,
            _ => false,
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

/// A slave's object dictionary.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjectDictionary {
    objects: BTreeMap<u16, Object>,
    /// The device does not do CoE complete access at all (ESI
    /// `<CoE CompleteAccess="0">`, SII CoE details bit 5 clear): every
    /// complete access is refused with 0x06010004.
    pub no_complete_access: bool,
    /// PDO mappings numbered where another object is (a TxPDO at 0x1018
    /// beside the identity object): the device maps with them, CoE reads
    /// the other object. See [`ObjectDictionary::mapping`].
    pub mappings_aside: BTreeMap<u16, Object>,
    /// Entries the device's own PDOs map (an ESI's `<RxPdo>`/`<TxPdo>`
    /// lists) although its dictionary does not flag them mappable: the
    /// device maps them all the same, and its description says what the
    /// file says.
    pub mapped_anyway: std::collections::BTreeSet<(u16, u8)>,
    /// Entries a simulated device has beyond its file's dictionary, and
    /// why: what its own init commands write (an ESI's
    /// `Mailbox/CoE/InitCmd`: the vendor ships those commands, so the real
    /// device takes them) where the dictionary lacks the entry or declares
    /// it read-only, and what its device profile requires (a CiA 402
    /// drive's modes of operation). Kept so the device can say so.
    pub beyond_file: std::collections::BTreeMap<(u16, u8), BeyondFile>,
}

/// Why a simulated device has an entry its file does not give it so.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BeyondFile {
    /// Written by its own init commands, not in the dictionary: added,
    /// typed by the data's size.
    InitCmdAdded,
    /// Written by its own init commands, read-only in the dictionary: made
    /// writable.
    InitCmdOpened,
    /// Required by its device profile (CiA 301 0x1000/0x1001/0x1018 of a
    /// CoE device, CiA 402 0x6060/0x6061/0x6502 of a drive), not in the
    /// dictionary: added.
    ProfileAdded,
}

impl BeyondFile {
    /// What `ecmxf-sim check` says of it.
    pub fn says(self) -> &'static str {
        match self {
            Self::InitCmdAdded => "written by its own init commands, not in its dictionary: added",
            Self::InitCmdOpened => "written by its own init commands, read-only in its dictionary: made writable",
            Self::ProfileAdded => "required by its device profile, not in its dictionary: added",
        }
    }
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

    /// Takes an object out.
    pub fn remove(&mut self, index: u16) -> Option<Object> {
        self.objects.remove(&index)
    }

    /// An object.
    pub fn object(&self, index: u16) -> Option<&Object> {
        self.objects.get(&index)
    }

    /// The PDO mapping at `index`: one kept aside for a PDO numbered where
    /// another object is, else the object there.
    pub fn mapping(&self, index: u16) -> Option<&Object> {
        self.mappings_aside.get(&index).or_else(|| self.objects.get(&index))
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_values_sign_extend() {
        let e = Entry::new("x", DataType::Int16, Access::RW).default_int(-5);
        assert_eq!(e.int(), -5);
        let e = Entry::new("x", DataType::UInt16, Access::RW).default_int(0xFFFF);
        assert_eq!(e.int(), 0xFFFF);
    }

    #[test]
    fn type_codes_round_trip_when_the_size_agrees() {
        for t in [DataType::Bool, DataType::Int32, DataType::UInt64, DataType::Real64, DataType::Bits(3)] {
            assert_eq!(DataType::from_code(t.code(), t.bits()), Some(t));
        }
        assert_eq!(DataType::from_code(0x04, 16), None, "a DINT code on 16 bits is not believed");
        assert_eq!(DataType::from_code(0x00, 8), None);
    }

    #[test]
    fn access_is_per_state() {
        assert!(Access::RW_PREOP.write.contains(EcatState::PreOp));
        assert!(!Access::RW_PREOP.write.contains(EcatState::SafeOp));
        assert!(!StateSet::ALL.contains(EcatState::Init), "no mailbox in INIT");
    }
}
