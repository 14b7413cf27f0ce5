//! Process data: PDO configuration (7, 8, 9), working counter (4), FIFO and
//! direct process-image access (5, 6), hand-made SyncManagers, FMMUs and
//! process-data lengths (71, 72, 82).

use crate::CommandCode;
use crate::bytes::{Reader, Writer, check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Reply, ReplyFields, Request, RequestFields, bare_request, fixed_len, int_data_reply, valid};

/// Outputs' SyncManager PDO assignment object.
pub const RX_PDO_ASSIGN: u16 = 0x1C12;
/// Inputs' SyncManager PDO assignment object.
pub const TX_PDO_ASSIGN: u16 = 0x1C13;
/// Entries one PDO slot of the PDO_CONFIG commands carries (v049, note
/// under command 7): a longer mapping is for SDO writes.
pub const MAPPING_ENTRIES: usize = 8;

/// One mapped object: `index << 16 | subindex << 8 | bit length` (v049
/// PDO_CONFIG_SET, 物件 layout), as in CoE mapping objects 0x16xx/0x1Axx.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PdoEntry {
    /// Object index.
    pub index: u16,
    /// Object subindex.
    pub subindex: u8,
    /// Length in bits.
    pub bits: u8,
}

impl PdoEntry {
    /// The packed 32-bit form.
    pub const fn to_u32(self) -> u32 {
        (self.index as u32) << 16 | (self.subindex as u32) << 8 | self.bits as u32
    }

    /// From the packed 32-bit form.
    pub const fn from_u32(v: u32) -> Self {
        Self { index: (v >> 16) as u16, subindex: (v >> 8) as u8, bits: v as u8 }
    }
}

/// One PDO of a [`PdoConfig`]: its mapping object and up to eight entries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PdoMapping {
    /// Mapping object index (0x16xx outputs, 0x1Axx inputs).
    pub index: u16,
    /// Entries in use, as the chip reports it (may exceed 8 in a reply for a
    /// larger mapping; only 8 are carried).
    pub entry_count: u16,
    /// The entries; those past `entry_count` are zero.
    pub entries: [PdoEntry; MAPPING_ENTRIES],
}

impl PdoMapping {
    /// The carried entries in use.
    pub fn used(&self) -> &[PdoEntry] {
        &self.entries[..usize::from(self.entry_count).min(8)]
    }
}

/// Which of the chip's PDO-configuration layouts a packet uses. v049 gives
/// one (112 bytes for PDO_CONFIG_SET and GET's reply, 4 for PDO_CONFIG_REQ);
/// the vendor's own host driver declares and fills two others, and a chip
/// that refused them would break the vendor's PDO-configuration calls, so
/// the chip is taken to tell them apart by the declared data length
/// (docs/protocol.md §11; the vendor header's `PDO_CONFIG_HEAD`, whose size the driver
/// puts in the length field of SET and REQ alike):
///
/// | form | length | layout |
/// | --- | --- | --- |
/// | [`Manual`](Self::Manual) | 112 (REQ: 4) | slave u8, PDO count u8, assignment u16, 3 mapping indices, 3 entry counts, 3 x 8 entries |
/// | [`FourPdos`](Self::FourPdos) | 148 | the same fields with 4 PDO slots (headers before 1.52) |
/// | [`Identified`](Self::Identified) | 156 | vendor id u32, product code u32, slave, count, assignment, 4 mapping indices, 4 entry counts, then `Table[32]` packed: PDO j's entries after the earlier PDOs' (header 1.52, code 1.60) |
///
/// A REQ in a vendor form reads slave and assignment from that form's
/// offsets, and GET answers in the form its REQ used.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PdoConfigForm {
    /// v049's layout, the one ecmxfd writes.
    #[default]
    Manual,
    /// Four PDO slots, no identity prefix (148 bytes).
    FourPdos,
    /// Vendor id and product code, then four PDO slots (156 bytes).
    Identified {
        /// Vendor id (CiA301 0x1018:01).
        vendor_id: u32,
        /// Product code (0x1018:02).
        product_code: u32,
    },
}

impl PdoConfigForm {
    /// The form a declared data length selects; any length but the vendor
    /// forms' reads v049's layout (the chip takes the fields from their
    /// places whatever the length says).
    pub fn of_len(data_len: u16) -> Self {
        match usize::from(data_len) {
            PDO_CONFIG_FOUR_LEN => Self::FourPdos,
            PDO_CONFIG_IDENTIFIED_LEN => Self::Identified { vendor_id: 0, product_code: 0 },
            _ => Self::Manual,
        }
    }

    /// The form with what its prefix says (the 156-byte form's vendor id
    /// and product code), read from the front of `r`.
    fn read_prefix(self, r: &mut Reader<'_>) -> Result<Self, PayloadError> {
        Ok(match self {
            Self::Identified { .. } => {
                Self::Identified { vendor_id: r.u32("vendor id")?, product_code: r.u32("product code")? }
            }
            other => other,
        })
    }

    /// PDO slots the form carries.
    pub const fn slots(self) -> usize {
        match self {
            Self::Manual => 3,
            Self::FourPdos | Self::Identified { .. } => 4,
        }
    }

    /// The whole layout's length.
    pub const fn data_len(self) -> usize {
        match self {
            Self::Manual => PDO_CONFIG_LEN,
            Self::FourPdos => PDO_CONFIG_FOUR_LEN,
            Self::Identified { .. } => PDO_CONFIG_IDENTIFIED_LEN,
        }
    }
}

/// PDO_CONFIG_SET (7) and PDO_CONFIG_GET's reply (9): one SyncManager
/// assignment with at most three PDOs of eight entries each in v049's form.
/// Larger mappings must be written with SDOs (v049 note under command 7).
///
/// v049 layout:
///
/// | off | len | field |
/// | --- | --- | --- |
/// | 0x00 | 1 | slave |
/// | 0x01 | 1 | PDO count |
/// | 0x02 | 2 | assignment index (0x1C12 / 0x1C13) |
/// | 0x04 | 2 x 3 | mapping indices |
/// | 0x0A | 2 x 3 | entry counts |
/// | 0x10 | 4 x 8 x 3 | entries |
///
/// The vendor driver's forms are in [`PdoConfigForm`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PdoConfig {
    /// Slave position 0..=127.
    pub slave: u8,
    /// PDOs assigned (0..=127 per the manual; at most `form.slots()` are
    /// carried).
    pub pdo_count: u8,
    /// The assignment object: [`RX_PDO_ASSIGN`] or [`TX_PDO_ASSIGN`].
    pub assign_index: u16,
    /// The PDO slots; the fourth only in the vendor forms.
    pub pdos: [PdoMapping; 4],
    /// The layout on the wire.
    pub form: PdoConfigForm,
}

/// Size of the v049 [`PdoConfig`] layout.
pub const PDO_CONFIG_LEN: usize = 112;
/// Size of the vendor header's four-PDO form.
pub const PDO_CONFIG_FOUR_LEN: usize = 148;
/// Size of the vendor header 1.52's form with vendor id and product code.
pub const PDO_CONFIG_IDENTIFIED_LEN: usize = 156;
/// Entries of that form's packed table (`Table[32]`).
const PACKED_ENTRIES: usize = 32;

impl PdoConfig {
    /// A configuration from mapping indices and their entries; fails when
    /// there are more than 3 PDOs or more than 8 entries in one.
    pub fn new(slave: u8, assign_index: u16, pdos: &[(u16, &[PdoEntry])]) -> Result<Self, EncodeError> {
        check_range("slave", slave.into(), 0, 127)?;
        check_range("PDO count", pdos.len() as u32, 0, 3)?;
        let mut out = Self { slave, pdo_count: pdos.len() as u8, assign_index, ..Self::default() };
        for (slot, (index, entries)) in out.pdos.iter_mut().zip(pdos) {
            check_range("PDO entry count", entries.len() as u32, 0, 8)?;
            slot.index = *index;
            slot.entry_count = entries.len() as u16;
            slot.entries[..entries.len()].copy_from_slice(entries);
        }
        Ok(out)
    }

    /// The carried PDOs in use.
    pub fn used(&self) -> &[PdoMapping] {
        &self.pdos[..usize::from(self.pdo_count).min(self.form.slots())]
    }

    fn write(&self, data: &mut [u8]) -> Result<u16, EncodeError> {
        check_range("slave", self.slave.into(), 0, 127)?;
        check_range("PDO count", self.pdo_count.into(), 0, 127)?;
        let mut w = Writer::new(data);
        if let PdoConfigForm::Identified { vendor_id, product_code } = self.form {
            w.u32(vendor_id)?;
            w.u32(product_code)?;
        }
        w.u8(self.slave)?;
        w.u8(self.pdo_count)?;
        w.u16(self.assign_index)?;
        let slots = &self.pdos[..self.form.slots()];
        for p in slots {
            w.u16(p.index)?;
        }
        for p in slots {
            w.u16(p.entry_count)?;
        }
        if let PdoConfigForm::Identified { .. } = self.form {
            // Packed: PDO j's entries follow the earlier PDOs' entries.
            let carried = usize::from(self.pdo_count).min(slots.len());
            let packed = slots[..carried].iter().flat_map(|p| p.used());
            let mut n = 0;
            for e in packed {
                w.u32(e.to_u32())?;
                n += 1;
            }
            check_range("PDO entries in all", n, 0, PACKED_ENTRIES as u32)?;
            for _ in n as usize..PACKED_ENTRIES {
                w.u32(0)?;
            }
            return Ok(w.len_u16());
        }
        for p in slots {
            for e in &p.entries {
                w.u32(e.to_u32())?;
            }
        }
        Ok(w.len_u16())
    }

    fn read(data: &[u8], form: PdoConfigForm) -> Result<Self, PayloadError> {
        let mut r = Reader::new(data);
        let form = form.read_prefix(&mut r)?;
        let slave = r.u8("slave")?;
        expect_range("slave", slave.into(), 0, 127)?;
        let pdo_count = r.u8("PDO count")?;
        expect_range("PDO count", pdo_count.into(), 0, 127)?;
        let assign_index = r.u16("PDO assign index")?;
        let mut pdos: [PdoMapping; 4] = Default::default();
        let slots = form.slots();
        for p in &mut pdos[..slots] {
            p.index = r.u16("PDO mapping index")?;
        }
        for p in &mut pdos[..slots] {
            p.entry_count = r.u16("PDO entry count")?;
        }
        if let PdoConfigForm::Identified { .. } = form {
            // Packed (the vendor's v1.60 code finds PDO j after the earlier
            // PDOs' entries): a table whose counts do not fit its 32
            // entries, or give a PDO more than a slot holds, cannot be read
            // one way only, and is refused rather than applied otherwise.
            let carried = usize::from(pdo_count).min(slots);
            let mut table = [PdoEntry::default(); PACKED_ENTRIES];
            for e in &mut table {
                *e = PdoEntry::from_u32(r.u32("PDO entry")?);
            }
            let mut at = 0;
            for p in &mut pdos[..carried] {
                let n = usize::from(p.entry_count);
                if n > MAPPING_ENTRIES || at + n > PACKED_ENTRIES {
                    return Err(PayloadError::InvalidValue { field: "PDO entry count", value: p.entry_count.into() });
                }
                p.entries[..n].copy_from_slice(&table[at..at + n]);
                at += n;
            }
            return Ok(Self { slave, pdo_count, assign_index, pdos, form });
        }
        for p in &mut pdos[..slots] {
            for e in &mut p.entries {
                *e = PdoEntry::from_u32(r.u32("PDO entry")?);
            }
        }
        Ok(Self { slave, pdo_count, assign_index, pdos, form })
    }
}

impl<'a> Request<'a> for PdoConfig {
    const CODE: CommandCode = CommandCode::PdoConfigSet;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        Ok(RequestFields { data_len: self.write(data)?, ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        let form = PdoConfigForm::of_len(fields.data_len);
        if form == PdoConfigForm::Manual {
            fixed_len(fields, Self::CODE, PDO_CONFIG_LEN as u16)?;
        }
        Self::read(data, form)
    }
}

/// PDO_CONFIG_GET's reply (9): the configuration requested with 8, in the
/// form the request used.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PdoConfigReply(pub PdoConfig);

impl<'a> Reply<'a> for PdoConfigReply {
    const CODE: CommandCode = CommandCode::PdoConfigGet;

    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        Ok(ReplyFields { value: 0, data_len: self.0.write(data)? })
    }

    fn decode(fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        PdoConfig::read(data, PdoConfigForm::of_len(fields.data_len)).map(Self)
    }
}

/// PDO_CONFIG_REQ (8): read a slave's assignment and mapping (blocking;
/// fetch with [`PdoConfigGet`]). v049 data, 4 bytes: slave, reserved,
/// assign index; in the vendor forms ([`PdoConfigForm`]) the same fields
/// sit where that form's [`PdoConfig`] has them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PdoConfigReq {
    /// Slave position 0..=127.
    pub slave: u8,
    /// [`RX_PDO_ASSIGN`] or [`TX_PDO_ASSIGN`].
    pub assign_index: u16,
    /// The layout of the request, and so of the answer.
    pub form: PdoConfigForm,
}

impl<'a> Request<'a> for PdoConfigReq {
    const CODE: CommandCode = CommandCode::PdoConfigReq;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        check_range("slave", self.slave.into(), 0, 127)?;
        if self.form != PdoConfigForm::Manual {
            let config = PdoConfig {
                slave: self.slave,
                assign_index: self.assign_index,
                form: self.form,
                ..PdoConfig::default()
            };
            return Ok(RequestFields { data_len: config.write(data)?, ..RequestFields::default() });
        }
        let mut w = Writer::new(data);
        w.u8(self.slave)?;
        w.u8(0)?;
        w.u16(self.assign_index)?;
        Ok(RequestFields { data_len: w.len_u16(), ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        let form = PdoConfigForm::of_len(fields.data_len);
        if form == PdoConfigForm::Manual {
            fixed_len(fields, Self::CODE, 4)?;
        }
        let mut r = Reader::new(data);
        let form = form.read_prefix(&mut r)?;
        let slave = r.u8("slave")?;
        expect_range("slave", slave.into(), 0, 127)?;
        let _ = r.u8("reserved")?;
        Ok(Self { slave, assign_index: r.u16("PDO assign index")?, form })
    }
}

bare_request! {
    /// PDO_CONFIG_GET (9): fetch the configuration requested with 8.
    PdoConfigGet => PdoConfigGet -> PdoConfigReply;
}

/// What PDO_WC_GET (4) reports (its parameter).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum WcQuery {
    /// 1: slaves with inputs.
    InputSlaves,
    /// 2: slaves with outputs.
    OutputSlaves,
    /// 3: the current working counter.
    WorkingCounter,
}

/// PDO_WC_GET (4). Expected WKC = input slaves x 1 + output slaves x 2.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PdoWcGet(pub WcQuery);

impl<'a> Request<'a> for PdoWcGet {
    const CODE: CommandCode = CommandCode::PdoWcGet;
    type Answer<'r> = WcReply;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let p = match self.0 {
            WcQuery::InputSlaves => 1,
            WcQuery::OutputSlaves => 2,
            WcQuery::WorkingCounter => 3,
        };
        Ok(RequestFields::parameter(p))
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        match fields.parameter {
            1 => Ok(Self(WcQuery::InputSlaves)),
            2 => Ok(Self(WcQuery::OutputSlaves)),
            3 => Ok(Self(WcQuery::WorkingCounter)),
            v => Err(PayloadError::InvalidValue { field: "PDO_WC_GET parameter", value: v.into() }),
        }
    }
}

int_data_reply! {
    /// PDO_WC_GET's reply: the count asked for (4 bytes).
    WcReply(u32) => PdoWcGet;
}

bitflags::bitflags! {
    /// PDO_DATA_FIFO_OP's operation byte (command data 0, echoed as the
    /// return value).
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
    pub struct FifoOpFlags: u8 {
        /// bit0: push the RxPDO frames in the data section.
        const WRITE = 1 << 0;
        /// bit1: pull TxPDO frames into the response.
        const READ = 1 << 1;
    }
}

/// PDO_DATA_FIFO_OP (5): push RxPDO (output) frames into the chip's FIFO
/// and/or pull TxPDO (input) frames. Each frame is one cycle's process image
/// (sizes from FIFO_PACK_SIZE_GET).
///
/// Parameter = number of frames in the data section; data length = their
/// bytes (frames x RxPDO size: our reading of the manual's "RxPDO長度").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PdoFifoOp<'a> {
    /// Operation bits.
    pub op: FifoOpFlags,
    /// Frames carried in the data section.
    pub frames: u8,
    /// The frames' bytes, back to back.
    pub outputs: &'a [u8],
}

impl<'a> Request<'a> for PdoFifoOp<'a> {
    const CODE: CommandCode = CommandCode::PdoDataFifoOp;
    type Answer<'r> = PdoFifoReply<'r>;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let mut w = Writer::new(data);
        w.bytes(self.outputs)?;
        Ok(RequestFields {
            parameter: self.frames,
            param: [self.op.bits(), 0, 0, 0],
            data_len: w.len_u16(),
            ..RequestFields::default()
        })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self {
            op: FifoOpFlags::from_bits_retain(fields.param[0]),
            frames: fields.parameter,
            outputs: valid("RxPDO frames", data, fields.data_len.into())?,
        })
    }
}

/// PDO_DATA_FIFO_OP's reply: the operation echoed and the TxPDO frames pulled
/// (data length = their bytes; divide by the TxPDO size for the count).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PdoFifoReply<'a> {
    /// Echoed operation bits.
    pub op: FifoOpFlags,
    /// TxPDO frames, back to back.
    pub inputs: &'a [u8],
}

impl<'a> Reply<'a> for PdoFifoReply<'a> {
    const CODE: CommandCode = CommandCode::PdoDataFifoOp;

    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(data);
        w.bytes(self.inputs)?;
        Ok(ReplyFields { value: self.op.bits(), data_len: w.len_u16() })
    }

    fn decode(fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self { op: FifoOpFlags::from_bits_retain(fields.value), inputs: data })
    }
}

bitflags::bitflags! {
    /// PDO_DATA_OP's operation byte (command data 0).
    ///
    /// v049 lists bit1 (read) and bit2 (the bits are valid; without it the
    /// chip reads and writes); v031 also lists bit0 (write). v049 says to
    /// write outputs through the FIFO instead.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
    pub struct PdoDataOpFlags: u8 {
        /// bit0 (v031): write the outputs in the data section.
        const WRITE = 1 << 0;
        /// bit1: read the inputs.
        const READ = 1 << 1;
        /// bit2: bits 0..1 are valid.
        const VALID = 1 << 2;
    }
}

/// PDO_DATA_OP (6): read the process image directly (initial inputs; initial
/// outputs before the FIFO runs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PdoDataOp<'a> {
    /// Operation bits.
    pub op: PdoDataOpFlags,
    /// RxPDO image written when writing.
    pub outputs: &'a [u8],
}

impl<'a> Request<'a> for PdoDataOp<'a> {
    const CODE: CommandCode = CommandCode::PdoDataOp;
    type Answer<'r> = PdoDataReply<'r>;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let mut w = Writer::new(data);
        w.bytes(self.outputs)?;
        Ok(RequestFields { param: [self.op.bits(), 0, 0, 0], data_len: w.len_u16(), ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self {
            op: PdoDataOpFlags::from_bits_retain(fields.param[0]),
            outputs: valid("RxPDO image", data, fields.data_len.into())?,
        })
    }
}

/// PDO_DATA_OP's reply: the TxPDO image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PdoDataReply<'a> {
    /// The inputs.
    pub inputs: &'a [u8],
}

impl<'a> Reply<'a> for PdoDataReply<'a> {
    const CODE: CommandCode = CommandCode::PdoDataOp;

    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(data);
        w.bytes(self.inputs)?;
        Ok(ReplyFields { value: 0, data_len: w.len_u16() })
    }

    fn decode(_fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self { inputs: data })
    }
}

/// CONFIG_SM (71): configure a SyncManager by hand, where the slave's own
/// registers are wrong (blocking). Data 8 bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct ConfigSm {
    /// Byte 0: slave 0..=127.
    pub slave: u8,
    /// Byte 1: SyncManager number.
    pub sm: u8,
    /// Bytes 2..4: physical start address.
    pub start_address: u16,
    /// Bytes 4..6: length in bytes.
    pub length: u16,
    /// Byte 6: control register.
    pub control: u8,
    /// Byte 7: activate register.
    pub activate: u8,
}

impl<'a> Request<'a> for ConfigSm {
    const CODE: CommandCode = CommandCode::ConfigSm;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        check_range("slave", self.slave.into(), 0, 127)?;
        let mut w = Writer::new(data);
        w.u8(self.slave)?;
        w.u8(self.sm)?;
        w.u16(self.start_address)?;
        w.u16(self.length)?;
        w.u8(self.control)?;
        w.u8(self.activate)?;
        Ok(RequestFields { data_len: w.len_u16(), ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        fixed_len(fields, Self::CODE, 8)?;
        let mut r = Reader::new(data);
        let slave = r.u8("slave")?;
        expect_range("slave", slave.into(), 0, 127)?;
        Ok(Self {
            slave,
            sm: r.u8("SM number")?,
            start_address: r.u16("SM start address")?,
            length: r.u16("SM length")?,
            control: r.u8("SM control")?,
            activate: r.u8("SM activate")?,
        })
    }
}

/// CONFIG_FMMU (72): obsolete (the chip configures FMMUs itself and
/// overwrites these), kept so every code has a type. Data 5 bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct ConfigFmmu {
    /// Byte 0: slave.
    pub slave: u8,
    /// Bytes 1..5: FMMU0..3 functions.
    pub functions: [u8; 4],
}

impl<'a> Request<'a> for ConfigFmmu {
    const CODE: CommandCode = CommandCode::ConfigFmmu;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        check_range("slave", self.slave.into(), 0, 127)?;
        let mut w = Writer::new(data);
        w.u8(self.slave)?;
        w.bytes(&self.functions)?;
        Ok(RequestFields { data_len: w.len_u16(), ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        fixed_len(fields, Self::CODE, 5)?;
        let mut r = Reader::new(data);
        let slave = r.u8("slave")?;
        expect_range("slave", slave.into(), 0, 127)?;
        Ok(Self { slave, functions: r.array("FMMU functions")? })
    }
}

/// Which process-data direction a length applies to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PdoDirection {
    /// 0: outputs (RxPDO).
    Outputs,
    /// 1: inputs (TxPDO).
    Inputs,
}

/// DIRECT_ASSIGN (82): set a slave's process-data length by hand.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DirectAssign {
    /// Parameter 0: turn the feature on or off for a slave.
    Enable {
        /// Command data 0: slave.
        slave: u8,
        /// Command data 1.
        enable: bool,
    },
    /// Parameter 1: the length of one direction.
    Length {
        /// Command data 0: slave.
        slave: u8,
        /// Command data 1.
        direction: PdoDirection,
        /// Command data 2..4: bytes.
        bytes: u16,
    },
}

impl<'a> Request<'a> for DirectAssign {
    const CODE: CommandCode = CommandCode::DirectAssign;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let (parameter, param) = match *self {
            Self::Enable { slave, enable } => {
                check_range("slave", slave.into(), 0, 127)?;
                (0, [slave, u8::from(enable), 0, 0])
            }
            Self::Length { slave, direction, bytes } => {
                check_range("slave", slave.into(), 0, 127)?;
                let [l0, l1] = bytes.to_le_bytes();
                (1, [slave, u8::from(direction == PdoDirection::Inputs), l0, l1])
            }
        };
        Ok(RequestFields { parameter, param, ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        let [slave, flag, l0, l1] = fields.param;
        expect_range("slave", slave.into(), 0, 127)?;
        expect_range("DIRECT_ASSIGN flag", flag.into(), 0, 1)?;
        match fields.parameter {
            0 => Ok(Self::Enable { slave, enable: flag == 1 }),
            1 => Ok(Self::Length {
                slave,
                direction: if flag == 1 { PdoDirection::Inputs } else { PdoDirection::Outputs },
                bytes: u16::from_le_bytes([l0, l1]),
            }),
            v => Err(PayloadError::InvalidValue { field: "DIRECT_ASSIGN parameter", value: v.into() }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    fn entry() -> impl Strategy<Value = PdoEntry> {
        any::<u32>().prop_map(PdoEntry::from_u32)
    }

    fn config() -> impl Strategy<Value = PdoConfig> {
        let mapping = (any::<u16>(), any::<u16>(), proptest::array::uniform8(entry()))
            .prop_map(|(index, entry_count, entries)| PdoMapping { index, entry_count, entries });
        (0u8..=127, 0u8..=127, any::<u16>(), proptest::array::uniform3(mapping)).prop_map(
            |(slave, pdo_count, assign_index, [a, b, c])| PdoConfig {
                slave,
                pdo_count,
                assign_index,
                pdos: [a, b, c, PdoMapping::default()],
                form: PdoConfigForm::Manual,
            },
        )
    }

    proptest! {
        #[test]
        fn entry_packs_both_ways(v in any::<u32>()) {
            prop_assert_eq!(PdoEntry::from_u32(v).to_u32(), v);
        }

        #[test]
        fn pdo_config_set_round_trips(c in config()) {
            let (fields, _) = request_round_trip(&c);
            prop_assert_eq!(fields.data_len as usize, PDO_CONFIG_LEN);
        }

        #[test]
        fn pdo_config_get_round_trips(c in config()) {
            reply_round_trip(&PdoConfigReply(c));
        }

        #[test]
        fn pdo_config_req_round_trips(slave in 0u8..=127, idx in any::<u16>()) {
            request_round_trip(&PdoConfigReq { slave, assign_index: idx, form: PdoConfigForm::Manual });
        }

        #[test]
        fn config_sm_round_trips(slave in 0u8..=127, sm: u8, start: u16, len: u16, c: u8, a: u8) {
            request_round_trip(&ConfigSm { slave, sm, start_address: start, length: len, control: c, activate: a });
        }

        #[test]
        fn config_fmmu_round_trips(slave in 0u8..=127, f: [u8; 4]) {
            request_round_trip(&ConfigFmmu { slave, functions: f });
        }

        #[test]
        fn direct_assign_round_trips(slave in 0u8..=127, on: bool, inputs: bool, bytes: u16) {
            request_round_trip(&DirectAssign::Enable { slave, enable: on });
            let direction = if inputs { PdoDirection::Inputs } else { PdoDirection::Outputs };
            request_round_trip(&DirectAssign::Length { slave, direction, bytes });
        }

        #[test]
        fn fifo_op_round_trips(op: u8, frames: u8, out in proptest::collection::vec(any::<u8>(), 0..1408)) {
            let req = PdoFifoOp { op: FifoOpFlags::from_bits_retain(op), frames, outputs: &out };
            let mut data = [0u8; 1408];
            let f = req.encode(&mut data).unwrap();
            prop_assert_eq!(PdoFifoOp::decode(&f, &data).unwrap(), req);
            let reply = PdoFifoReply { op: FifoOpFlags::from_bits_retain(op), inputs: &out };
            let mut data = [0u8; 1408];
            let f = reply.encode(&mut data).unwrap();
            prop_assert_eq!(PdoFifoReply::decode(&f, &data[..f.data_len as usize]).unwrap(), reply);
        }

        #[test]
        fn data_op_round_trips(op: u8, out in proptest::collection::vec(any::<u8>(), 0..1408)) {
            let req = PdoDataOp { op: PdoDataOpFlags::from_bits_retain(op), outputs: &out };
            let mut data = [0u8; 1408];
            let f = req.encode(&mut data).unwrap();
            prop_assert_eq!(PdoDataOp::decode(&f, &data).unwrap(), req);
            let reply = PdoDataReply { inputs: &out };
            let f = reply.encode(&mut data).unwrap();
            prop_assert_eq!(PdoDataReply::decode(&f, &data[..f.data_len as usize]).unwrap(), reply);
        }

        #[test]
        fn wc_reply_round_trips(v: u32) {
            reply_round_trip(&WcReply(v));
        }
    }

    #[test]
    fn wc_queries_round_trip_and_reject_others() {
        for q in [WcQuery::InputSlaves, WcQuery::OutputSlaves, WcQuery::WorkingCounter] {
            request_round_trip(&PdoWcGet(q));
        }
        for p in [0u8, 4, 255] {
            assert!(PdoWcGet::decode(&RequestFields::parameter(p), &[]).is_err());
        }
    }

    proptest! {
        #[test]
        fn the_vendor_forms_round_trip_by_their_length(
            c in config(),
            fourth in proptest::array::uniform8(entry()),
            vendor_id in any::<u32>(),
            product_code in any::<u32>(),
        ) {
            for form in [PdoConfigForm::FourPdos, PdoConfigForm::Identified { vendor_id, product_code }] {
                let mut c = c;
                c.form = form;
                c.pdos[3] = PdoMapping { index: 0x1603, entry_count: 8, entries: fourth };
                if form != PdoConfigForm::FourPdos {
                    // The packed table carries the used entries of the
                    // PDOs counted, at most 8 each.
                    c.pdo_count %= 5;
                    for (j, p) in c.pdos.iter_mut().enumerate() {
                        p.entry_count %= 9;
                        let used = if j < usize::from(c.pdo_count) { usize::from(p.entry_count) } else { 0 };
                        for e in &mut p.entries[used..] {
                            *e = PdoEntry::default();
                        }
                    }
                }
                let (fields, _) = request_round_trip(&c);
                prop_assert_eq!(usize::from(fields.data_len), form.data_len());
                reply_round_trip(&PdoConfigReply(c));
                let req = PdoConfigReq { slave: c.slave, assign_index: c.assign_index, form };
                let (fields, _) = request_round_trip(&req);
                prop_assert_eq!(usize::from(fields.data_len), form.data_len());
            }
        }
    }

    /// The vendor header 1.52's `PDO_CONFIG_HEAD`, byte by byte: vendor id,
    /// product code, slave, count, assignment, 4 indices, 4 counts, 32
    /// entries.
    #[test]
    fn the_identified_form_has_the_vendor_headers_offsets() {
        let e = PdoEntry { index: 0x6040, subindex: 0, bits: 16 };
        let mut c = PdoConfig::new(3, RX_PDO_ASSIGN, &[(0x1600, &[e])]).unwrap();
        c.form = PdoConfigForm::Identified { vendor_id: 0x0000_059D, product_code: 0x1234_5678 };
        let mut d = [0u8; 200];
        let f = c.encode(&mut d).unwrap();
        assert_eq!(f.data_len, 156);
        assert_eq!(&d[..12], &[0x9D, 0x05, 0, 0, 0x78, 0x56, 0x34, 0x12, 3, 1, 0x12, 0x1C]);
        assert_eq!(&d[12..14], &[0x00, 0x16], "first mapping index");
        assert_eq!(&d[20..22], &[1, 0], "first entry count");
        assert_eq!(&d[28..32], &[0x10, 0x00, 0x40, 0x60], "first entry: bits, subindex, index");
        let req = PdoConfigReq::decode(&RequestFields { data_len: 156, ..RequestFields::default() }, &d).unwrap();
        assert_eq!((req.slave, req.assign_index), (3, RX_PDO_ASSIGN));
    }

    /// The packed table: PDO 2's entries right after PDO 1's; a count a
    /// slot cannot hold, or counts beyond the 32 entries, are refused.
    #[test]
    fn the_identified_forms_table_is_packed() {
        let e = |i: u16| PdoEntry { index: 0x6000 + i, subindex: 0, bits: 8 };
        let (a, b) = ([e(1), e(2), e(3)], [e(4)]);
        let mut c = PdoConfig::new(1, TX_PDO_ASSIGN, &[(0x1A00, &a), (0x1A01, &b)]).unwrap();
        c.form = PdoConfigForm::Identified { vendor_id: 2, product_code: 3 };
        let mut d = [0u8; 200];
        c.encode(&mut d).unwrap();
        let entry = |k: usize| &d[28 + 4 * k..32 + 4 * k];
        assert_eq!(entry(2), &e(3).to_u32().to_le_bytes(), "PDO 1's third entry");
        assert_eq!(entry(3), &e(4).to_u32().to_le_bytes(), "PDO 2's first entry, packed after it");
        let fields = RequestFields { data_len: 156, ..RequestFields::default() };
        let back = PdoConfig::decode(&fields, &d).unwrap();
        assert_eq!(back.used()[1].used(), &b);
        // A count of 9: no slot holds it.
        d[22] = 9;
        assert!(matches!(
            PdoConfig::decode(&fields, &d),
            Err(PayloadError::InvalidValue { field: "PDO entry count", value: 9 })
        ));
        // Four PDOs of 8 fill the table; a fifth count would not fit.
        d[9] = 4;
        d[20..28].copy_from_slice(&[8, 0, 8, 0, 8, 0, 8, 0]);
        assert!(PdoConfig::decode(&fields, &d).is_ok());
    }

    #[test]
    fn config_new_checks_limits() {
        let e = [PdoEntry { index: 0x6040, subindex: 0, bits: 16 }; 9];
        assert!(PdoConfig::new(0, RX_PDO_ASSIGN, &[(0x1600, &e[..8])]).is_ok());
        assert!(matches!(
            PdoConfig::new(0, RX_PDO_ASSIGN, &[(0x1600, &e[..])]),
            Err(EncodeError::FieldOutOfRange { field: "PDO entry count", value: 9, .. })
        ));
        let four: [(u16, &[PdoEntry]); 4] = [(0x1600, &[]); 4];
        assert!(PdoConfig::new(0, RX_PDO_ASSIGN, &four).is_err());
        assert!(PdoConfig::new(128, RX_PDO_ASSIGN, &[]).is_err());
        let c = PdoConfig::new(1, TX_PDO_ASSIGN, &[(0x1A00, &e[..2])]).unwrap();
        assert_eq!(c.used().len(), 1);
        assert_eq!(c.used()[0].used().len(), 2);
    }

    #[test]
    fn fifo_op_data_length_beyond_section_is_an_error() {
        let f = RequestFields { data_len: 200, ..RequestFields::default() };
        assert!(matches!(PdoFifoOp::decode(&f, &[0u8; 112]), Err(PayloadError::TooShort { .. })));
    }

    #[test]
    fn fifo_op_too_big_for_section() {
        let out = [0u8; 113];
        let mut data = [0u8; 112];
        assert_eq!(
            PdoFifoOp { op: FifoOpFlags::WRITE, frames: 1, outputs: &out }.encode(&mut data),
            Err(EncodeError::PayloadTooLarge { needed: 113, capacity: 112 })
        );
    }
}
