//! The SII EEPROM image of a slave (ETG.1000.6 Table 16, ETG.2010): the
//! config area and identity words, then typed categories. Built from a
//! device description for simulated slaves, parsed for real dumps.
//!
//! Word map: 0x00..0x07 ESC config area (word 4 station alias, word 7 =
//! CRC-8 poly 0x07 init 0xFF over bytes 0..14), 0x08 vendor id, 0x0A product
//! code, 0x0C revision, 0x0E serial, 0x14 bootstrap mailbox, 0x18 standard
//! mailbox (receive offset, size, send offset, size), 0x1C mailbox protocols,
//! 0x3E size in Kbit - 1 (docs/protocol.md §19; not KiB, the real dumps say Kbit:
//! SOES's 256-byte image has 1, the EK1100's 2048-byte one 15), 0x3F
//! version, 0x40 onward categories (type u16,
//! length in words u16, data), ended by type 0xFFFF.

use std::fmt;

/// Category types.
pub mod category {
    /// Strings.
    pub const STRINGS: u16 = 10;
    /// Data types.
    pub const DATATYPES: u16 = 20;
    /// General.
    pub const GENERAL: u16 = 30;
    /// FMMU usage.
    pub const FMMU: u16 = 40;
    /// SyncManagers.
    pub const SYNC_MANAGER: u16 = 41;
    /// TxPDOs.
    pub const TXPDO: u16 = 50;
    /// RxPDOs.
    pub const RXPDO: u16 = 51;
    /// Distributed clocks.
    pub const DC: u16 = 60;
    /// End.
    pub const END: u16 = 0xFFFF;
}

/// Mailbox protocol bits (word 0x1C).
pub mod protocol {
    /// ADS over EtherCAT.
    pub const AOE: u16 = 1 << 0;
    /// Ethernet over EtherCAT.
    pub const EOE: u16 = 1 << 1;
    /// CANopen over EtherCAT.
    pub const COE: u16 = 1 << 2;
    /// File access over EtherCAT.
    pub const FOE: u16 = 1 << 3;
    /// Servo over EtherCAT.
    pub const SOE: u16 = 1 << 4;
    /// Vendor specific.
    pub const VOE: u16 = 1 << 5;
}

/// SyncManager types in the SM category.
pub mod sm_type {
    /// Unused.
    pub const UNUSED: u8 = 0;
    /// Mailbox out (master to slave).
    pub const MBX_OUT: u8 = 1;
    /// Mailbox in.
    pub const MBX_IN: u8 = 2;
    /// Process data outputs.
    pub const OUTPUTS: u8 = 3;
    /// Process data inputs.
    pub const INPUTS: u8 = 4;
}

/// Why an image could not be read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SiiError {
    /// Fewer than the 128 bytes of fixed words.
    TooShort(usize),
    /// A category runs past the end of the image.
    CategoryOverrun {
        /// Category type.
        kind: u16,
        /// Its byte offset.
        offset: usize,
    },
    /// A category runs past the EEPROM's own size (word 0x3E: (n + 1) x 128
    /// bytes): found while reading it from the slave, before the image ends.
    PastEepromSize {
        /// Category type.
        kind: u16,
        /// Its byte offset.
        offset: usize,
        /// Its length in bytes, as declared.
        len: usize,
        /// The EEPROM's size in bytes.
        size: usize,
    },
    /// A category's content does not fit its declared layout.
    BadCategory {
        /// Category type.
        kind: u16,
        /// What is wrong.
        what: &'static str,
    },
}

impl fmt::Display for SiiError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooShort(n) => write!(f, "SII image of {n} bytes is shorter than its 128-byte header"),
            Self::CategoryOverrun { kind, offset } => {
                write!(f, "SII category {kind} at byte {offset:#x} runs past the end of the image")
            }
            Self::PastEepromSize { kind, offset, len, size } => write!(
                f,
                "category {kind:#06x} at byte offset {offset:#06x} is {len} bytes long and runs past the EEPROM's \
                 size of {size} bytes (word 0x3E)"
            ),
            Self::BadCategory { kind, what } => write!(f, "SII category {kind}: {what}"),
        }
    }
}

impl std::error::Error for SiiError {}

/// An SII string as text. ETG.2010 does not name an encoding; devices
/// write ASCII, some UTF-8, and many (Beckhoff's "1µs", byte 0xB5) Latin-1
/// or Windows-1252. Valid UTF-8 is taken as such; anything else byte by
/// byte as Windows-1252 (Latin-1 with the printable 0x80..0x9F of
/// Windows), so no string turns into replacement characters.
pub fn decode_text(bytes: &[u8]) -> String {
    if let Ok(s) = std::str::from_utf8(bytes) {
        return s.to_owned();
    }
    // Windows-1252 0x80..=0x9F; the five undefined codes stay as Latin-1.
    const HIGH: [char; 32] = [
        '€', '\u{81}', '‚', 'ƒ', '„', '…', '†', '‡', 'ˆ', '‰', 'Š', '‹', 'Œ', '\u{8D}', 'Ž', '\u{8F}', '\u{90}', '‘',
        '’', '“', '”', '•', '–', '—', '˜', '™', 'š', '›', 'œ', '\u{9D}', 'ž', 'Ÿ',
    ];
    bytes.iter().map(|&b| if (0x80..0xA0).contains(&b) { HIGH[usize::from(b - 0x80)] } else { char::from(b) }).collect()
}

/// CRC-8 of the config area (poly 0x07, init 0xFF, ETG.1000.6 Table 16).
pub fn config_checksum(bytes: &[u8]) -> u8 {
    let mut crc: u8 = 0xFF;
    for &b in bytes {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 { (crc << 1) ^ 0x07 } else { crc << 1 };
        }
    }
    crc
}

/// A mailbox's place and size.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MailboxArea {
    /// Receive (master to slave) offset.
    pub rx_offset: u16,
    /// Receive size.
    pub rx_size: u16,
    /// Send offset.
    pub tx_offset: u16,
    /// Send size.
    pub tx_size: u16,
}

/// One SyncManager record (8 bytes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SmRecord {
    /// Physical start address.
    pub start: u16,
    /// Length.
    pub length: u16,
    /// Control register.
    pub control: u8,
    /// Status register (reserved).
    pub status: u8,
    /// Enable.
    pub enable: u8,
    /// [`sm_type`].
    pub kind: u8,
}

/// One PDO entry of a PDO category (8 bytes).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PdoEntryRecord {
    /// Object index (0 = gap).
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// Name string index.
    pub name: u8,
    /// Data type code.
    pub data_type: u8,
    /// Bit length.
    pub bits: u8,
    /// Flags.
    pub flags: u16,
}

/// One PDO of a TxPDO/RxPDO category.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PdoRecord {
    /// PDO index (0x16xx / 0x1Axx).
    pub index: u16,
    /// SyncManager it is assigned to (0xFF none).
    pub sm: u8,
    /// DC sync.
    pub sync: u8,
    /// Name string index.
    pub name: u8,
    /// Flags.
    pub flags: u16,
    /// Entries.
    pub entries: Vec<PdoEntryRecord>,
}

/// The General category (32 bytes).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct General {
    /// Group string index.
    pub group: u8,
    /// Image string index.
    pub image: u8,
    /// Order string index.
    pub order: u8,
    /// Name string index.
    pub name: u8,
    /// CoE details bits.
    pub coe_details: u8,
    /// FoE details.
    pub foe_details: u8,
    /// EoE details.
    pub eoe_details: u8,
    /// Flags.
    pub flags: u8,
    /// Current drawn from the E-bus, mA (negative: supplied).
    pub ebus_current_ma: i16,
    /// Physical ports.
    pub physical_port: u16,
}

/// A parsed SII image.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Sii {
    /// Config area words 0..8.
    pub config: [u16; 8],
    /// Vendor id.
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision.
    pub revision: u32,
    /// Serial.
    pub serial: u32,
    /// Bootstrap mailbox.
    pub bootstrap_mailbox: MailboxArea,
    /// Standard mailbox.
    pub mailbox: MailboxArea,
    /// Mailbox protocols ([`protocol`] bits).
    pub protocols: u16,
    /// Size word (KiB - 1).
    pub size_word: u16,
    /// Version word.
    pub version: u16,
    /// Strings, 1-based in the image (index 0 = none).
    pub strings: Vec<Vec<u8>>,
    /// General category.
    pub general: Option<General>,
    /// FMMU usage bytes.
    pub fmmu: Vec<u8>,
    /// SyncManagers.
    pub sync_managers: Vec<SmRecord>,
    /// TxPDOs.
    pub tx_pdos: Vec<PdoRecord>,
    /// RxPDOs.
    pub rx_pdos: Vec<PdoRecord>,
    /// Raw DC category, if any.
    pub dc: Option<Vec<u8>>,
    /// Categories kept raw (type, data), including unknown ones.
    pub other: Vec<(u16, Vec<u8>)>,
}

fn u16_at(b: &[u8], i: usize) -> u16 {
    u16::from_le_bytes([b[i], b[i + 1]])
}

fn u32_at(b: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

fn mailbox_at(b: &[u8], word: usize) -> MailboxArea {
    MailboxArea {
        rx_offset: u16_at(b, word * 2),
        rx_size: u16_at(b, word * 2 + 2),
        tx_offset: u16_at(b, word * 2 + 4),
        tx_size: u16_at(b, word * 2 + 6),
    }
}

fn parse_pdos(kind: u16, d: &[u8]) -> Result<Vec<PdoRecord>, SiiError> {
    let mut out = Vec::new();
    let mut i = 0;
    while i + 8 <= d.len() {
        let n = usize::from(d[i + 2]);
        let mut pdo = PdoRecord {
            index: u16_at(d, i),
            sm: d[i + 3],
            sync: d[i + 4],
            name: d[i + 5],
            flags: u16_at(d, i + 6),
            entries: Vec::with_capacity(n),
        };
        i += 8;
        for _ in 0..n {
            if i + 8 > d.len() {
                return Err(SiiError::BadCategory { kind, what: "PDO entry list runs past the category" });
            }
            pdo.entries.push(PdoEntryRecord {
                index: u16_at(d, i),
                subindex: d[i + 2],
                name: d[i + 3],
                data_type: d[i + 4],
                bits: d[i + 5],
                flags: u16_at(d, i + 6),
            });
            i += 8;
        }
        out.push(pdo);
    }
    Ok(out)
}

impl Sii {
    /// Parses an image (any length from 128 bytes; categories up to 0xFFFF
    /// or the end).
    pub fn parse(b: &[u8]) -> Result<Self, SiiError> {
        if b.len() < 128 {
            return Err(SiiError::TooShort(b.len()));
        }
        let mut s = Sii {
            vendor_id: u32_at(b, 0x10),
            product_code: u32_at(b, 0x14),
            revision: u32_at(b, 0x18),
            serial: u32_at(b, 0x1C),
            bootstrap_mailbox: mailbox_at(b, 0x14),
            mailbox: mailbox_at(b, 0x18),
            protocols: u16_at(b, 0x38),
            size_word: u16_at(b, 0x7C),
            version: u16_at(b, 0x7E),
            ..Sii::default()
        };
        for (i, w) in s.config.iter_mut().enumerate() {
            *w = u16_at(b, i * 2);
        }
        let mut off = 0x80;
        while off + 4 <= b.len() {
            let kind = u16_at(b, off);
            if kind == category::END {
                break;
            }
            let len = usize::from(u16_at(b, off + 2)) * 2;
            let Some(d) = b.get(off + 4..off + 4 + len) else {
                return Err(SiiError::CategoryOverrun { kind, offset: off });
            };
            match kind {
                category::STRINGS => {
                    let count = usize::from(*d.first().unwrap_or(&0));
                    let mut i = 1;
                    for _ in 0..count {
                        let n = usize::from(*d.get(i).ok_or(SiiError::BadCategory { kind, what: "string count" })?);
                        let sbytes =
                            d.get(i + 1..i + 1 + n).ok_or(SiiError::BadCategory { kind, what: "string overruns" })?;
                        s.strings.push(sbytes.to_vec());
                        i += 1 + n;
                    }
                }
                category::GENERAL => {
                    if d.len() < 18 {
                        return Err(SiiError::BadCategory { kind, what: "general category shorter than 18 bytes" });
                    }
                    s.general = Some(General {
                        group: d[0],
                        image: d[1],
                        order: d[2],
                        name: d[3],
                        coe_details: d[5],
                        foe_details: d[6],
                        eoe_details: d[7],
                        flags: d[11],
                        ebus_current_ma: u16_at(d, 12) as i16,
                        physical_port: u16_at(d, 16),
                    });
                }
                category::FMMU => s.fmmu = d.to_vec(),
                category::SYNC_MANAGER => {
                    s.sync_managers = d
                        .chunks_exact(8)
                        .map(|c| SmRecord {
                            start: u16_at(c, 0),
                            length: u16_at(c, 2),
                            control: c[4],
                            status: c[5],
                            enable: c[6],
                            kind: c[7],
                        })
                        .collect();
                }
                category::TXPDO => s.tx_pdos.extend(parse_pdos(kind, d)?),
                category::RXPDO => s.rx_pdos.extend(parse_pdos(kind, d)?),
                category::DC => s.dc = Some(d.to_vec()),
                _ => s.other.push((kind, d.to_vec())),
            }
            off += 4 + len;
        }
        Ok(s)
    }

    /// A string by its 1-based index (0 = none).
    pub fn string(&self, index: u8) -> Option<&[u8]> {
        index.checked_sub(1).and_then(|i| self.strings.get(usize::from(i))).map(Vec::as_slice)
    }

    /// The device name from the General category.
    pub fn name(&self) -> Option<String> {
        let g = self.general.as_ref()?;
        self.string(g.name).map(decode_text)
    }

    /// The PDOs of `list` (this image's `rx_pdos` or `tx_pdos`) assigned by
    /// default: their sync manager is one the device has (ETG.2010: 0xFF,
    /// or one beyond the SM category, means none).
    pub fn default_assignment<'a>(&self, list: &'a [PdoRecord]) -> impl Iterator<Item = &'a PdoRecord> {
        let sms = self.sync_managers.len();
        list.iter().filter(move |p| p.sm != 0xFF && (sms == 0 || usize::from(p.sm) < sms))
    }

    /// Whether the config-area checksum (word 7 low byte) is right.
    pub fn checksum_ok(&self) -> bool {
        let mut bytes = [0u8; 14];
        for (i, w) in self.config[..7].iter().enumerate() {
            bytes[i * 2..i * 2 + 2].copy_from_slice(&w.to_le_bytes());
        }
        config_checksum(&bytes) == self.config[7] as u8
    }

    /// Serialises the image, `size_bytes` long (padded with 0xFF).
    pub fn to_bytes(&self, size_bytes: usize) -> Vec<u8> {
        let mut b = vec![0u8; 128];
        let put16 = |b: &mut Vec<u8>, i: usize, v: u16| b[i..i + 2].copy_from_slice(&v.to_le_bytes());
        let put32 = |b: &mut Vec<u8>, i: usize, v: u32| b[i..i + 4].copy_from_slice(&v.to_le_bytes());
        for (i, w) in self.config.iter().enumerate() {
            put16(&mut b, i * 2, *w);
        }
        let crc = config_checksum(&b[..14]);
        put16(&mut b, 14, (self.config[7] & 0xFF00) | u16::from(crc));
        put32(&mut b, 0x10, self.vendor_id);
        put32(&mut b, 0x14, self.product_code);
        put32(&mut b, 0x18, self.revision);
        put32(&mut b, 0x1C, self.serial);
        for (word, m) in [(0x14, self.bootstrap_mailbox), (0x18, self.mailbox)] {
            put16(&mut b, word * 2, m.rx_offset);
            put16(&mut b, word * 2 + 2, m.rx_size);
            put16(&mut b, word * 2 + 4, m.tx_offset);
            put16(&mut b, word * 2 + 6, m.tx_size);
        }
        put16(&mut b, 0x38, self.protocols);
        put16(&mut b, 0x7C, self.size_word);
        put16(&mut b, 0x7E, self.version);

        let cat = |b: &mut Vec<u8>, kind: u16, mut data: Vec<u8>| {
            if data.len() % 2 == 1 {
                data.push(0);
            }
            b.extend_from_slice(&kind.to_le_bytes());
            b.extend_from_slice(&((data.len() / 2) as u16).to_le_bytes());
            b.extend_from_slice(&data);
        };
        if !self.strings.is_empty() {
            let mut d = vec![self.strings.len() as u8];
            for s in &self.strings {
                d.push(s.len() as u8);
                d.extend_from_slice(s);
            }
            cat(&mut b, category::STRINGS, d);
        }
        if let Some(g) = &self.general {
            let mut d = vec![0u8; 32];
            d[0] = g.group;
            d[1] = g.image;
            d[2] = g.order;
            d[3] = g.name;
            d[5] = g.coe_details;
            d[6] = g.foe_details;
            d[7] = g.eoe_details;
            d[11] = g.flags;
            d[12..14].copy_from_slice(&g.ebus_current_ma.to_le_bytes());
            d[14] = g.group;
            d[16..18].copy_from_slice(&g.physical_port.to_le_bytes());
            cat(&mut b, category::GENERAL, d);
        }
        if !self.fmmu.is_empty() {
            cat(&mut b, category::FMMU, self.fmmu.clone());
        }
        if !self.sync_managers.is_empty() {
            let mut d = Vec::new();
            for s in &self.sync_managers {
                d.extend_from_slice(&s.start.to_le_bytes());
                d.extend_from_slice(&s.length.to_le_bytes());
                d.extend_from_slice(&[s.control, s.status, s.enable, s.kind]);
            }
            cat(&mut b, category::SYNC_MANAGER, d);
        }
        for (kind, pdos) in [(category::TXPDO, &self.tx_pdos), (category::RXPDO, &self.rx_pdos)] {
            if pdos.is_empty() {
                continue;
            }
            let mut d = Vec::new();
            for p in pdos {
                d.extend_from_slice(&p.index.to_le_bytes());
                d.extend_from_slice(&[p.entries.len() as u8, p.sm, p.sync, p.name]);
                d.extend_from_slice(&p.flags.to_le_bytes());
                for e in &p.entries {
                    d.extend_from_slice(&e.index.to_le_bytes());
                    d.extend_from_slice(&[e.subindex, e.name, e.data_type, e.bits]);
                    d.extend_from_slice(&e.flags.to_le_bytes());
                }
            }
            cat(&mut b, kind, d);
        }
        if let Some(dc) = &self.dc {
            cat(&mut b, category::DC, dc.clone());
        }
        for (kind, d) in &self.other {
            cat(&mut b, *kind, d.clone());
        }
        b.extend_from_slice(&category::END.to_le_bytes());
        b.extend_from_slice(&[0, 0]);
        if b.len() < size_bytes {
            b.resize(size_bytes, 0xFF);
        }
        // The size word (0x3E: (n + 1) x 128 bytes) covers the whole image:
        // a smaller one would have a reader stop, or call the categories
        // corrupt, before their end.
        let needed = (b.len().div_ceil(128).max(1) - 1) as u16;
        if self.size_word < needed {
            put16(&mut b, 0x7C, needed);
        }
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strings_that_are_not_utf8_are_windows_1252() {
        assert_eq!(decode_text(b"EL1008"), "EL1008");
        assert_eq!(decode_text("1µs".as_bytes()), "1µs", "valid UTF-8 stays");
        assert_eq!(decode_text(b"1\xB5s"), "1µs", "Latin-1 micro sign");
        assert_eq!(decode_text(b"\x80 5\x96"), "€ 5–", "Windows-1252 specials");
    }

    #[test]
    fn checksum_matches_the_etg_example() {
        // ETG.1000.6: config area 0x0C80 0x6E00 ... is not public; use the
        // SOES dump's own words (0x0280, zeros) and its stored 0xC6.
        let mut bytes = [0u8; 14];
        bytes[0] = 0x80;
        bytes[1] = 0x02;
        assert_eq!(config_checksum(&bytes), 0xC6);
    }

    #[test]
    fn build_parse_round_trip() {
        let s = Sii {
            config: [0x0C08, 0, 0, 0, 0x0007, 0, 0, 0],
            vendor_id: 0x89A,
            product_code: 0x3000_0000,
            revision: 0x10,
            serial: 42,
            mailbox: MailboxArea { rx_offset: 0x1000, rx_size: 128, tx_offset: 0x1080, tx_size: 128 },
            bootstrap_mailbox: MailboxArea { rx_offset: 0x1000, rx_size: 128, tx_offset: 0x1080, tx_size: 128 },
            protocols: protocol::COE | protocol::FOE,
            size_word: 1,
            version: 1,
            strings: vec![b"Drives".to_vec(), b"CORE".to_vec()],
            general: Some(General {
                group: 1,
                name: 2,
                coe_details: 0x23,
                ebus_current_ma: -2000,
                ..General::default()
            }),
            fmmu: vec![1, 2, 3, 0],
            sync_managers: vec![SmRecord {
                start: 0x1100,
                length: 13,
                control: 0x64,
                status: 0,
                enable: 1,
                kind: sm_type::OUTPUTS,
            }],
            rx_pdos: vec![PdoRecord {
                index: 0x1600,
                sm: 2,
                entries: vec![PdoEntryRecord {
                    index: 0x6040,
                    subindex: 0,
                    data_type: 6,
                    bits: 16,
                    ..Default::default()
                }],
                ..Default::default()
            }],
            ..Sii::default()
        };
        let bytes = s.to_bytes(256);
        assert_eq!(bytes.len(), 256);
        let mut back = Sii::parse(&bytes).unwrap();
        assert!(back.checksum_ok());
        back.config[7] = 0;
        assert_eq!(back, s);
        assert_eq!(Sii::parse(&bytes).unwrap().name().as_deref(), Some("CORE"));
    }

    #[test]
    fn errors_are_named() {
        assert_eq!(Sii::parse(&[0; 10]), Err(SiiError::TooShort(10)));
        let mut b = vec![0u8; 128];
        b.extend_from_slice(&[10, 0, 50, 0, 1, 2]);
        assert_eq!(Sii::parse(&b), Err(SiiError::CategoryOverrun { kind: 10, offset: 0x80 }));
    }
}
