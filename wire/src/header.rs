//! The 24-byte headers (v049 圖四/圖五, 表一/表二).

use crate::command::CommandCode;
use crate::error::DecodeError;
use crate::flags::{ControlFlags, EcatState, EcmStatus, ErrorFlags, HeaderOptions, InterruptFlags};

/// The start word, first four bytes of every packet (the header's first
/// field; `framing` re-exports it with the end word).
pub const START_WORD: u32 = 0xA1A2_A3A4;

/// Header length in bytes, both directions.
pub const HEADER_LEN: usize = 24;

/// Host -> chip header (v049 表一).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CommandHeader {
    /// 0x04..0x08: command data 0..3, per-command bytes.
    pub param: [u8; 4],
    /// 0x08..0x0A: the "reserved" word (bit15 GPIO outputs valid; ECAT_INIT
    /// options).
    pub options: HeaderOptions,
    /// 0x0A: control byte.
    pub control: ControlFlags,
    /// 0x0B: index, echoed in the answer. Give every new command a fresh one:
    /// the same index and code twice in a row act as INFO_UPDATE.
    pub index: u8,
    /// 0x0C: command code.
    pub code: CommandCode,
    /// 0x0D: command parameter.
    pub parameter: u8,
    /// 0x0E..0x10: valid data length, or a per-command value.
    pub data_len: u16,
    /// 0x10..0x14: interrupt-flag clear bits.
    pub int_clear: InterruptFlags,
    /// 0x14..0x16: GPIO interrupt-flag clear, lines 0..=15.
    pub gpio_int_clear: u16,
    /// 0x16..0x18: GPIO output values, lines 0..=15 (valid only with
    /// [`HeaderOptions::GPIO_OUTPUT_VALID`]).
    pub gpio_output: u16,
}

impl Default for CommandHeader {
    fn default() -> Self {
        Self {
            param: [0; 4],
            options: HeaderOptions::empty(),
            control: ControlFlags::empty(),
            index: 0,
            code: CommandCode::InfoUpdate,
            parameter: 0,
            data_len: 0,
            int_clear: InterruptFlags::empty(),
            gpio_int_clear: 0,
            gpio_output: 0,
        }
    }
}

impl CommandHeader {
    /// A header for `code` with the given index, all else zero.
    pub fn new(code: CommandCode, index: u8) -> Self {
        Self { code, index, ..Self::default() }
    }

    /// Sets the header GPIO outputs and the two bits that make them valid
    /// (control bit0, reserved bit15: v049 表一 names both).
    #[must_use]
    pub fn with_gpio_output(mut self, value: u16) -> Self {
        self.gpio_output = value;
        self.options |= HeaderOptions::GPIO_OUTPUT_VALID;
        self.control |= ControlFlags::HEADER_GPIO_VALID;
        self
    }

    /// Whether the packet occupies the blocking slot: a blocking code, or
    /// control bit1 (refresh ECAT state).
    pub fn is_blocking(&self) -> bool {
        self.code.is_blocking() || self.control.contains(ControlFlags::REFRESH_ECAT_STATE)
    }

    /// Writes the 24 bytes, start word included.
    pub fn encode(&self, out: &mut [u8; HEADER_LEN]) {
        out[0..4].copy_from_slice(&START_WORD.to_le_bytes());
        out[4..8].copy_from_slice(&self.param);
        out[8..10].copy_from_slice(&self.options.bits().to_le_bytes());
        out[10] = self.control.bits();
        out[11] = self.index;
        out[12] = self.code.to_u8();
        out[13] = self.parameter;
        out[14..16].copy_from_slice(&self.data_len.to_le_bytes());
        out[16..20].copy_from_slice(&self.int_clear.bits().to_le_bytes());
        out[20..22].copy_from_slice(&self.gpio_int_clear.to_le_bytes());
        out[22..24].copy_from_slice(&self.gpio_output.to_le_bytes());
    }

    /// Reads the 24 bytes; only the start word can be wrong.
    pub fn decode(b: &[u8; HEADER_LEN]) -> Result<Self, DecodeError> {
        let start = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        if start != START_WORD {
            return Err(DecodeError::StartWord { found: start });
        }
        Ok(Self {
            param: [b[4], b[5], b[6], b[7]],
            options: HeaderOptions::from_bits_retain(u16::from_le_bytes([b[8], b[9]])),
            control: ControlFlags::from_bits_retain(b[10]),
            index: b[11],
            code: CommandCode::from_u8(b[12]),
            parameter: b[13],
            data_len: u16::from_le_bytes([b[14], b[15]]),
            int_clear: InterruptFlags::from_bits_retain(u32::from_le_bytes([b[16], b[17], b[18], b[19]])),
            gpio_int_clear: u16::from_le_bytes([b[20], b[21]]),
            gpio_output: u16::from_le_bytes([b[22], b[23]]),
        })
    }
}

/// Chip -> host header (v049 表二).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ResponseHeader {
    /// 0x04: SPI CRC error count.
    pub crc_errors: u8,
    /// 0x05: working-counter error count.
    pub wkc_errors: u8,
    /// 0x06: TxPDO frames waiting in the chip for the host (inputs). Lags the
    /// truth by two exchanges.
    pub tx_fifo_count: u8,
    /// 0x07: RxPDO frames waiting in the chip to be sent (outputs). Lags the
    /// truth by two exchanges.
    pub rx_fifo_count: u8,
    /// 0x08: EtherCAT state.
    pub ecat_state: EcatState,
    /// 0x09: error byte.
    pub errors: ErrorFlags,
    /// 0x0A: ECM status (check type and flags).
    pub status: EcmStatus,
    /// 0x0B: echoed index.
    pub index: u8,
    /// 0x0C: echoed command code.
    pub code: CommandCode,
    /// 0x0D: return value.
    pub return_value: u8,
    /// 0x0E..0x10: valid data length.
    pub data_len: u16,
    /// 0x10..0x14: interrupt flags.
    pub int_flags: InterruptFlags,
    /// 0x14..0x16: GPIO interrupt flags, lines 0..=15.
    pub gpio_int_flags: u16,
    /// 0x16..0x18: GPIO input values, lines 0..=15.
    pub gpio_inputs: u16,
}

impl Default for ResponseHeader {
    fn default() -> Self {
        Self {
            crc_errors: 0,
            wkc_errors: 0,
            tx_fifo_count: 0,
            rx_fifo_count: 0,
            ecat_state: EcatState::None,
            errors: ErrorFlags::empty(),
            status: EcmStatus::default(),
            index: 0,
            code: CommandCode::InfoUpdate,
            return_value: 0,
            data_len: 0,
            int_flags: InterruptFlags::empty(),
            gpio_int_flags: 0,
            gpio_inputs: 0,
        }
    }
}

impl ResponseHeader {
    /// Whether this response is a NOP (ECM status bit5): it answers nothing,
    /// as the first response after power-up does.
    pub fn is_nop(&self) -> bool {
        self.status.flags.contains(crate::flags::StatusFlags::NOP)
    }

    /// Whether the blocking slot is busy.
    pub fn blocking_busy(&self) -> bool {
        self.status.flags.contains(crate::flags::StatusFlags::BLOCKING_BUSY)
    }

    /// Writes the 24 bytes, start word included.
    pub fn encode(&self, out: &mut [u8; HEADER_LEN]) {
        out[0..4].copy_from_slice(&START_WORD.to_le_bytes());
        out[4] = self.crc_errors;
        out[5] = self.wkc_errors;
        out[6] = self.tx_fifo_count;
        out[7] = self.rx_fifo_count;
        out[8] = self.ecat_state.to_u8();
        out[9] = self.errors.bits();
        out[10] = self.status.to_byte();
        out[11] = self.index;
        out[12] = self.code.to_u8();
        out[13] = self.return_value;
        out[14..16].copy_from_slice(&self.data_len.to_le_bytes());
        out[16..20].copy_from_slice(&self.int_flags.bits().to_le_bytes());
        out[20..22].copy_from_slice(&self.gpio_int_flags.to_le_bytes());
        out[22..24].copy_from_slice(&self.gpio_inputs.to_le_bytes());
    }

    /// Reads the 24 bytes; only the start word can be wrong.
    pub fn decode(b: &[u8; HEADER_LEN]) -> Result<Self, DecodeError> {
        let start = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        if start != START_WORD {
            return Err(DecodeError::StartWord { found: start });
        }
        Ok(Self {
            crc_errors: b[4],
            wkc_errors: b[5],
            tx_fifo_count: b[6],
            rx_fifo_count: b[7],
            ecat_state: EcatState::from_u8(b[8]),
            errors: ErrorFlags::from_bits_retain(b[9]),
            status: EcmStatus::from_byte(b[10]),
            index: b[11],
            code: CommandCode::from_u8(b[12]),
            return_value: b[13],
            data_len: u16::from_le_bytes([b[14], b[15]]),
            int_flags: InterruptFlags::from_bits_retain(u32::from_le_bytes([b[16], b[17], b[18], b[19]])),
            gpio_int_flags: u16::from_le_bytes([b[20], b[21]]),
            gpio_inputs: u16::from_le_bytes([b[22], b[23]]),
        })
    }
}
