//! The packet check word (v049 表一/ECM_CMD_CRC_TYPE_SET; v031 for CRC-8 and
//! CRC-16, which v049 marks "undefined" but older firmware implements).
//!
//! The check word covers bytes `[0, 24 + D)`: the header and the WHOLE data
//! section, not just its valid length (v049 ECM_CMD_CRC_TYPE_SET;
//! docs/protocol.md §4). It travels little-endian like every other field;
//! the 8- and 16-bit CRCs sit in the low bits of that 32-bit word with the
//! upper bits zero (our decision: the manuals name the algorithms but not
//! the placement, and the vendor driver stores the result in a `uint32_t`).

use core::fmt;

/// The fixed check word of check type 0 (the power-up default).
pub const CHECK_FIXED: u32 = 0x1234_5678;

/// The check word the chip sends when it was clocked before it was ready.
pub const CHECK_NOT_READY: u32 = 0x8765_4321;

const CRC8: crc::Crc<u8> = crc::Crc::<u8>::new(&crc::CRC_8_SMBUS);
const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

/// How the check word is formed; the chip reports the type in force in ECM
/// status bits 1..0 and it is switched with command 25.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[repr(u8)]
pub enum CheckType {
    /// Type 0: always 0x12345678.
    #[default]
    Fixed = 0,
    /// Type 1: CRC-8, poly 0x07, init 0, no reflection, no xorout (v031).
    Crc8 = 1,
    /// Type 2: CRC-16/CCITT-FALSE, poly 0x1021, init 0xFFFF (v031).
    Crc16 = 2,
    /// Type 3: CRC-32 (IEEE/zlib): poly 0x04C11DB7 reflected, init and xorout
    /// 0xFFFFFFFF.
    Crc32 = 3,
}

impl CheckType {
    /// All four types, in code order.
    pub const ALL: [CheckType; 4] = [Self::Fixed, Self::Crc8, Self::Crc16, Self::Crc32];

    /// The type encoded in the low two bits of `bits` (ECM status bits 1..0,
    /// or command 25's parameter).
    pub const fn from_bits(bits: u8) -> Self {
        match bits & 0b11 {
            0 => Self::Fixed,
            1 => Self::Crc8,
            2 => Self::Crc16,
            _ => Self::Crc32,
        }
    }

    /// The two-bit code.
    pub const fn bits(self) -> u8 {
        self as u8
    }

    /// The check word over `covered` (header plus whole data section).
    pub fn compute(self, covered: &[u8]) -> u32 {
        match self {
            Self::Fixed => CHECK_FIXED,
            Self::Crc8 => u32::from(CRC8.checksum(covered)),
            Self::Crc16 => u32::from(CRC16.checksum(covered)),
            Self::Crc32 => crc32fast::hash(covered),
        }
    }
}

impl fmt::Display for CheckType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Fixed => "fixed",
            Self::Crc8 => "CRC-8",
            Self::Crc16 => "CRC-16/CCITT-FALSE",
            Self::Crc32 => "CRC-32",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The CRC catalogue's check values for the ASCII string "123456789".
    #[test]
    fn catalogue_check_values() {
        let s = b"123456789";
        assert_eq!(CheckType::Fixed.compute(s), 0x1234_5678);
        assert_eq!(CheckType::Crc8.compute(s), 0xF4);
        assert_eq!(CheckType::Crc16.compute(s), 0x29B1);
        assert_eq!(CheckType::Crc32.compute(s), 0xCBF4_3926);
    }

    #[test]
    fn fixed_ignores_content() {
        assert_eq!(CheckType::Fixed.compute(&[]), CHECK_FIXED);
        assert_eq!(CheckType::Fixed.compute(&[0xFF; 100]), CHECK_FIXED);
    }

    #[test]
    fn crc_changes_with_one_bit() {
        let mut a = [0u8; 136];
        let base = [CheckType::Crc8, CheckType::Crc16, CheckType::Crc32].map(|t| t.compute(&a));
        a[135] ^= 1;
        for (t, b) in [CheckType::Crc8, CheckType::Crc16, CheckType::Crc32].into_iter().zip(base) {
            assert_ne!(t.compute(&a), b, "{t}");
        }
    }

    #[test]
    fn bits_round_trip_and_mask() {
        for t in CheckType::ALL {
            assert_eq!(CheckType::from_bits(t.bits()), t);
            assert_eq!(CheckType::from_bits(t.bits() | 0xFC), t);
        }
    }
}
