//! Typed bit sets for the header's flag bytes, and the ECAT state.
//!
//! Every map here follows v049 表一/表二. Where v031 or the vendor header
//! disagree, v049 wins and the item's doc says what the others claim. Unknown
//! bits are kept (`from_bits_retain`), never dropped, so a value always
//! re-encodes to the byte it came from.

use core::fmt;

use crate::check::CheckType;

bitflags::bitflags! {
    /// Command header 0x0A, the control byte (v049 表一).
    ///
    /// TRAP: v031 numbers the clear bits differently (bit3 FIFO, bit4 SPI,
    /// bit5 SPI-CRC, bit6 blocking, bit7 non-blocking) and the vendor header
    /// uses bit0 for "refresh ECAT state". We follow v049.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
    pub struct ControlFlags: u8 {
        /// bit0: the header's GPIO output bytes (0x16/0x17) are valid.
        const HEADER_GPIO_VALID = 1 << 0;
        /// bit1: refresh the ECAT state from the slaves. Makes the packet a
        /// blocking operation.
        const REFRESH_ECAT_STATE = 1 << 1;
        /// bit3: clear the blocking-command error (error bit3).
        const CLEAR_BLOCKING_ERROR = 1 << 3;
        /// bit4: clear the SPI error (error bit4).
        const CLEAR_SPI_ERROR = 1 << 4;
        /// bit5: clear the FIFO error (error bit5).
        const CLEAR_FIFO_ERROR = 1 << 5;
        /// bit6: clear the SPI CRC error (error bit6).
        const CLEAR_SPI_CRC_ERROR = 1 << 6;
        /// bit7: clear the command error (error bit7).
        const CLEAR_COMMAND_ERROR = 1 << 7;
    }
}

impl ControlFlags {
    /// All clear bits together.
    pub const CLEAR_ALL_ERRORS: Self = Self::CLEAR_BLOCKING_ERROR
        .union(Self::CLEAR_SPI_ERROR)
        .union(Self::CLEAR_FIFO_ERROR)
        .union(Self::CLEAR_SPI_CRC_ERROR)
        .union(Self::CLEAR_COMMAND_ERROR);

    /// The error bits these clear bits clear (bit n of the control byte clears
    /// bit n of the error byte, for n = 3..=7).
    pub const fn cleared_errors(self) -> ErrorFlags {
        ErrorFlags::from_bits_retain(self.bits() & Self::CLEAR_ALL_ERRORS.bits())
    }
}

bitflags::bitflags! {
    /// Command header 0x08..0x0A, the "reserved" word (v049 表一 and
    /// ECM_CMD_ECAT_INIT_OP).
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
    pub struct HeaderOptions: u16 {
        /// bit11, with ECAT_INIT only: disable the LRW command (firmware >= 0x22).
        const INIT_DISABLE_LRW = 1 << 11;
        /// bit12, with ECAT_INIT only: master shift mode; clear = bus shift
        /// mode (firmware >= 0x22).
        const INIT_MASTER_SHIFT = 1 << 12;
        /// bit15: the GPIO output bytes 0x16/0x17 are valid.
        const GPIO_OUTPUT_VALID = 1 << 15;
    }
}

bitflags::bitflags! {
    /// Response header 0x09, the error byte (v049 表二).
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
    pub struct ErrorFlags: u8 {
        /// bit0: state of the LINK pin (pin 52); its polarity depends on the
        /// board.
        const LINK_PIN = 1 << 0;
        /// bit1: PHY link as seen at ECAT_INIT; polarity depends on the board.
        const PHY_LINK_AT_INIT = 1 << 1;
        /// bit3: the last blocking command returned an error.
        const BLOCKING_FAILED = 1 << 3;
        /// bit4: SPI communication error.
        const SPI_ERROR = 1 << 4;
        /// bit5: FIFO error (e.g. the RxFIFO ran dry in a cycle).
        const FIFO_ERROR = 1 << 5;
        /// bit6: a command packet failed its check word.
        const SPI_CRC_ERROR = 1 << 6;
        /// bit7: command error: a bad parameter, or a blocking command sent
        /// while another was busy (not executed).
        const COMMAND_ERROR = 1 << 7;
    }
}

bitflags::bitflags! {
    /// Response header 0x0A bits 7..2, the ECM status flags (v049 表二). Bits
    /// 1..0 are the check type, kept apart in [`EcmStatus`].
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
    pub struct StatusFlags: u8 {
        /// bit2: the DC cycle time is stable.
        const DC_STABLE = 1 << 2;
        /// bit3: the Ethernet line is initialised.
        const ETHERNET_READY = 1 << 3;
        /// bit4: ECAT PDO configuration done.
        const PDO_CONFIGURED = 1 << 4;
        /// bit5: this response is a NOP (answers no command).
        const NOP = 1 << 5;
        /// bit6: FIFO enabled.
        const FIFO_ENABLED = 1 << 6;
        /// bit7: a blocking command is running.
        const BLOCKING_BUSY = 1 << 7;
    }
}

/// Response header 0x0A: the check type in force and the status flags.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct EcmStatus {
    /// Bits 1..0: the check type the chip uses now.
    pub check_type: CheckType,
    /// Bits 7..2.
    pub flags: StatusFlags,
}

impl EcmStatus {
    /// Splits the raw byte.
    pub const fn from_byte(b: u8) -> Self {
        Self { check_type: CheckType::from_bits(b), flags: StatusFlags::from_bits_retain(b & !0b11) }
    }

    /// Joins the raw byte.
    pub const fn to_byte(self) -> u8 {
        (self.flags.bits() & !0b11) | self.check_type.bits()
    }
}

bitflags::bitflags! {
    /// Response header 0x10 (interrupt flags), command header 0x10 (interrupt
    /// clear) and the composite mask of ECM_CMD_ECAT_INT_SET_ENABLE: one bit map
    /// for all three (v049 表一/表二 and command 58).
    ///
    /// TRAP: v049 command 58 puts the CRC error at bit23 and the WKC error at
    /// bit22; the vendor header swaps them. We follow v049.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
    pub struct InterruptFlags: u32 {
        /// bit22: EtherCAT working-counter error.
        const WKC_ERROR = 1 << 22;
        /// bit23: CRC error.
        const CRC_ERROR = 1 << 23;
        /// bit24: TxFIFO reached its high mark (command 70).
        const TX_FIFO_HIGH = 1 << 24;
        /// bit25: RxFIFO fell to its low mark (command 70).
        const RX_FIFO_LOW = 1 << 25;
        /// bit29: encoder (QEI) interrupt.
        const ENCODER = 1 << 29;
        /// bit31: an EtherCAT frame was received.
        const ETHERCAT_FRAME = 1 << 31;
    }
}

/// A set of GPIO lines, bit n = GPIOn. The header carries lines 0..=15 (two
/// bytes); the extended GPIO operations reach lines 16..=19 on chips that have
/// them (v049 ECM_GPIO_FUNC_OP).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct GpioMask(pub u32);

impl GpioMask {
    /// Lines a chip can have.
    pub const LINES: u8 = 20;

    /// Whether line `n` is in the set.
    pub const fn contains(self, line: u8) -> bool {
        line < 32 && self.0 & (1 << line) != 0
    }

    /// The set with line `n` added or removed.
    #[must_use]
    pub const fn with(self, line: u8, on: bool) -> Self {
        if line >= 32 {
            return self;
        }
        if on { Self(self.0 | (1 << line)) } else { Self(self.0 & !(1 << line)) }
    }

    /// Lines 0..=15, as the header's two GPIO bytes carry them.
    pub const fn low16(self) -> u16 {
        self.0 as u16
    }

    /// Lines 0..=7, 8..=15, 16..=19 as the three bytes of the extended
    /// operations.
    pub const fn bytes3(self) -> [u8; 3] {
        [self.0 as u8, (self.0 >> 8) as u8, (self.0 >> 16) as u8 & 0x0F]
    }
}

impl From<u16> for GpioMask {
    fn from(v: u16) -> Self {
        Self(u32::from(v))
    }
}

impl fmt::Debug for GpioMask {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "GpioMask({:#07x})", self.0)
    }
}

/// Response header 0x08, and the state argument of commands 12, 13, 41: the
/// EtherCAT state (v049 表二). Unknown values are kept, never rejected: the
/// chip reports what the slaves report.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum EcatState {
    /// 0x00: not initialised.
    #[default]
    None,
    /// 0x01 INIT.
    Init,
    /// 0x02 PRE-OP.
    PreOp,
    /// 0x03 BOOT.
    Boot,
    /// 0x04 SAFE-OP.
    SafeOp,
    /// 0x08 OP.
    Op,
    /// 0x10 error.
    Error,
    /// Any other value, kept as sent.
    Other(u8),
}

impl EcatState {
    /// From the raw byte.
    pub const fn from_u8(v: u8) -> Self {
        match v {
            0x00 => Self::None,
            0x01 => Self::Init,
            0x02 => Self::PreOp,
            0x03 => Self::Boot,
            0x04 => Self::SafeOp,
            0x08 => Self::Op,
            0x10 => Self::Error,
            other => Self::Other(other),
        }
    }

    /// To the raw byte.
    pub const fn to_u8(self) -> u8 {
        match self {
            Self::None => 0x00,
            Self::Init => 0x01,
            Self::PreOp => 0x02,
            Self::Boot => 0x03,
            Self::SafeOp => 0x04,
            Self::Op => 0x08,
            Self::Error => 0x10,
            Self::Other(v) => v,
        }
    }

    /// Whether this is one of the four states a slave can be asked to enter
    /// (commands 12 and 41).
    pub const fn is_requestable(self) -> bool {
        matches!(self, Self::Init | Self::PreOp | Self::Boot | Self::SafeOp | Self::Op)
    }
}

impl From<u8> for EcatState {
    fn from(v: u8) -> Self {
        Self::from_u8(v)
    }
}

impl From<EcatState> for u8 {
    fn from(s: EcatState) -> Self {
        s.to_u8()
    }
}

impl fmt::Display for EcatState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::None => f.write_str("NONE"),
            Self::Init => f.write_str("INIT"),
            Self::PreOp => f.write_str("PREOP"),
            Self::Boot => f.write_str("BOOT"),
            Self::SafeOp => f.write_str("SAFEOP"),
            Self::Op => f.write_str("OP"),
            Self::Error => f.write_str("ERROR"),
            Self::Other(v) => write!(f, "state {v:#04x}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ecat_state_keeps_every_byte() {
        for b in 0..=255u8 {
            assert_eq!(EcatState::from_u8(b).to_u8(), b);
        }
        assert_eq!(EcatState::from_u8(0x14), EcatState::Other(0x14));
        assert_eq!(EcatState::from_u8(8), EcatState::Op);
    }

    #[test]
    fn ecm_status_keeps_every_byte() {
        for b in 0..=255u8 {
            assert_eq!(EcmStatus::from_byte(b).to_byte(), b);
        }
        let s = EcmStatus::from_byte(0b1010_0011);
        assert_eq!(s.check_type, CheckType::Crc32);
        assert!(s.flags.contains(StatusFlags::BLOCKING_BUSY | StatusFlags::NOP));
        assert!(!s.flags.contains(StatusFlags::FIFO_ENABLED));
    }

    #[test]
    fn v049_bit_positions() {
        assert_eq!(ControlFlags::REFRESH_ECAT_STATE.bits(), 0x02);
        assert_eq!(ControlFlags::CLEAR_COMMAND_ERROR.bits(), 0x80);
        assert_eq!(ControlFlags::CLEAR_ALL_ERRORS.bits(), 0xF8);
        assert_eq!(ErrorFlags::FIFO_ERROR.bits(), 0x20);
        assert_eq!(InterruptFlags::CRC_ERROR.bits(), 1 << 23);
        assert_eq!(InterruptFlags::WKC_ERROR.bits(), 1 << 22);
        assert_eq!(HeaderOptions::GPIO_OUTPUT_VALID.bits(), 0x8000);
    }

    #[test]
    fn clear_bits_map_onto_error_bits() {
        let c = ControlFlags::CLEAR_FIFO_ERROR | ControlFlags::CLEAR_COMMAND_ERROR | ControlFlags::HEADER_GPIO_VALID;
        assert_eq!(c.cleared_errors(), ErrorFlags::FIFO_ERROR | ErrorFlags::COMMAND_ERROR);
        assert_eq!(ControlFlags::CLEAR_ALL_ERRORS.cleared_errors().bits(), 0xF8);
    }

    #[test]
    fn gpio_mask_lines() {
        let m = GpioMask::default().with(0, true).with(13, true).with(19, true);
        assert!(m.contains(13) && m.contains(19) && !m.contains(12));
        assert_eq!(m.low16(), 0x2001);
        assert_eq!(m.bytes3(), [0x01, 0x20, 0x08]);
        assert_eq!(m.with(13, false).low16(), 0x0001);
        assert_eq!(m.with(40, true), m);
    }
}
