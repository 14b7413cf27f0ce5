//! GPIO: GPIO_CONFIG_SET (31) and GPIO_FUNC_OP (32), each multiplexing
//! sub-operations on its parameter (v049 ECM_GPIO_CONFIG_SET/FUNC_OP
//! sections). GPIOs power up as floating inputs.
//!
//! The "Ext" sub-operations reach lines 16..=19 on chip versions that have
//! them (firmware >= 9). Header bytes 0x16/0x17 can also drive outputs 0..=11
//! (see [`crate::CommandHeader::with_gpio_output`]).

use crate::CommandCode;
use crate::bytes::{Reader, Writer, check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::flags::GpioMask;
use crate::payload::{Reply, ReplyFields, Request, RequestFields};

/// A line's drive mode (command data 2 of SetMode).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GpioMode {
    /// 0: input.
    Input,
    /// 1: push-pull output.
    Output,
    /// 2: open drain.
    OpenDrain,
    /// 3: quasi-bidirectional.
    QuasiBidirectional,
}

/// A line's pull (command data 3 of SetMode).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GpioPull {
    /// 0: none.
    None,
    /// 1: pull-up.
    Up,
    /// 2: pull-down.
    Down,
}

/// Which edges raise a line's interrupt (command data 1 of IntEnable).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GpioTrigger {
    /// 0: off.
    Disabled,
    /// 1: both edges.
    BothEdges,
    /// 2: falling edge.
    Falling,
    /// 3: rising edge.
    Rising,
}

/// The debounce clock source (bit4 of SetDebounceClock).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DebounceSource {
    /// 0: 192 MHz.
    Clock192MHz,
    /// 1: 10 kHz.
    Clock10kHz,
}

macro_rules! small_enum_codec {
    ($ty:ident, $field:literal, [$($variant:ident = $v:literal),*]) => {
        impl $ty {
            /// The code byte.
            pub const fn to_u8(self) -> u8 {
                match self { $(Self::$variant => $v,)* }
            }

            /// From the code byte.
            pub fn from_u8(v: u8) -> Result<Self, PayloadError> {
                match v {
                    $($v => Ok(Self::$variant),)*
                    other => Err(PayloadError::InvalidValue { field: $field, value: other.into() }),
                }
            }
        }
    };
}

small_enum_codec!(GpioMode, "GPIO mode", [Input = 0, Output = 1, OpenDrain = 2, QuasiBidirectional = 3]);
small_enum_codec!(GpioPull, "GPIO pull", [None = 0, Up = 1, Down = 2]);
small_enum_codec!(GpioTrigger, "GPIO interrupt type", [Disabled = 0, BothEdges = 1, Falling = 2, Rising = 3]);
small_enum_codec!(DebounceSource, "debounce clock source", [Clock192MHz = 0, Clock10kHz = 1]);

/// GPIO_CONFIG_SET (31) sub-operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GpioConfig {
    /// Parameter 0 (ECM_GpioSetMode): mode and pull of lines 0..=15 (data 0/1
    /// = line mask).
    SetMode {
        /// Lines to configure.
        lines: u16,
        /// Mode.
        mode: GpioMode,
        /// Pull.
        pull: GpioPull,
    },
    /// Parameter 8: the same for lines 16..=19 (data 0 bits 0..3).
    SetModeExt {
        /// Bit n = line 16 + n.
        lines: u8,
        /// Mode.
        mode: GpioMode,
        /// Pull.
        pull: GpioPull,
    },
    /// Parameter 2 (ECM_GpioEnableDebounce): debounce of inputs 0..=15.
    EnableDebounce {
        /// Lines.
        lines: u16,
        /// On or off.
        enable: bool,
    },
    /// Parameter 9: the same for lines 16..=19.
    EnableDebounceExt {
        /// Bit n = line 16 + n.
        lines: u8,
        /// On or off.
        enable: bool,
    },
    /// Parameter 3 (ECM_GpioSetDebounceClock): sampling period is
    /// 2^cycles clock periods.
    SetDebounceClock {
        /// 0..=15.
        cycles: u8,
        /// Clock source.
        source: DebounceSource,
    },
    /// Parameter 1 (ECM_GpioIntEnable): one line's interrupt.
    IntEnable {
        /// Line 0..=19 (0..=15 on most chips).
        line: u8,
        /// Edges.
        trigger: GpioTrigger,
    },
    /// Parameter 4 (ECM_GpioIntClear): clear interrupt flags of lines 0..=15.
    IntClear {
        /// Lines.
        lines: u16,
    },
    /// Parameter 6: clear interrupt flags of lines 0..=19.
    IntClearExt {
        /// Lines.
        lines: GpioMask,
    },
}

impl<'a> Request<'a> for GpioConfig {
    const CODE: CommandCode = CommandCode::GpioConfigSet;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let (parameter, param) = match *self {
            Self::SetMode { lines, mode, pull } => {
                let [lo, hi] = lines.to_le_bytes();
                (0, [lo, hi, mode.to_u8(), pull.to_u8()])
            }
            Self::SetModeExt { lines, mode, pull } => {
                check_range("extended GPIO lines", lines.into(), 0, 0x0F)?;
                (8, [lines, 0, mode.to_u8(), pull.to_u8()])
            }
            Self::EnableDebounce { lines, enable } => {
                let [lo, hi] = lines.to_le_bytes();
                (2, [lo, hi, u8::from(enable), 0])
            }
            Self::EnableDebounceExt { lines, enable } => {
                check_range("extended GPIO lines", lines.into(), 0, 0x0F)?;
                (9, [lines, 0, u8::from(enable), 0])
            }
            Self::SetDebounceClock { cycles, source } => {
                check_range("debounce cycles", cycles.into(), 0, 15)?;
                (3, [cycles | source.to_u8() << 4, 0, 0, 0])
            }
            Self::IntEnable { line, trigger } => {
                check_range("GPIO line", line.into(), 0, 19)?;
                (1, [line, trigger.to_u8(), 0, 0])
            }
            Self::IntClear { lines } => {
                let [lo, hi] = lines.to_le_bytes();
                (4, [lo, hi, 0, 0])
            }
            Self::IntClearExt { lines } => {
                check_range("GPIO lines", lines.0, 0, 0x000F_FFFF)?;
                let [a, b, c] = lines.bytes3();
                (6, [a, b, c, 0])
            }
        };
        Ok(RequestFields { parameter, param, ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        let [p0, p1, p2, p3] = fields.param;
        let lines16 = u16::from_le_bytes([p0, p1]);
        let enable = |v: u8| {
            expect_range("debounce enable", v.into(), 0, 1)?;
            Ok::<bool, PayloadError>(v == 1)
        };
        Ok(match fields.parameter {
            0 => Self::SetMode { lines: lines16, mode: GpioMode::from_u8(p2)?, pull: GpioPull::from_u8(p3)? },
            8 => {
                expect_range("extended GPIO lines", p0.into(), 0, 0x0F)?;
                Self::SetModeExt { lines: p0, mode: GpioMode::from_u8(p2)?, pull: GpioPull::from_u8(p3)? }
            }
            2 => Self::EnableDebounce { lines: lines16, enable: enable(p2)? },
            9 => {
                expect_range("extended GPIO lines", p0.into(), 0, 0x0F)?;
                Self::EnableDebounceExt { lines: p0, enable: enable(p2)? }
            }
            3 => {
                expect_range("debounce clock byte", p0.into(), 0, 0x1F)?;
                Self::SetDebounceClock { cycles: p0 & 0x0F, source: DebounceSource::from_u8(p0 >> 4)? }
            }
            1 => {
                expect_range("GPIO line", p0.into(), 0, 19)?;
                Self::IntEnable { line: p0, trigger: GpioTrigger::from_u8(p1)? }
            }
            4 => Self::IntClear { lines: lines16 },
            6 => {
                expect_range("extended GPIO lines", p2.into(), 0, 0x0F)?;
                Self::IntClearExt { lines: GpioMask(u32::from_le_bytes([p0, p1, p2, 0])) }
            }
            v => return Err(PayloadError::InvalidValue { field: "GPIO_CONFIG_SET sub-operation", value: v.into() }),
        })
    }
}

/// GPIO_FUNC_OP (32) sub-operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GpioFunc {
    /// Parameter 0 (ECM_GpioSetValue): output levels of lines 0..=15.
    SetValue {
        /// Bit n = line n high.
        values: u16,
    },
    /// Parameter 2 (ECM_GpioExtSetValue): output levels of lines 0..=19.
    ExtSetValue {
        /// Bit n = line n high.
        values: GpioMask,
    },
    /// Parameter 1 (ECM_GpioGetValue): input levels of lines 0..=15 (2 bytes
    /// back).
    GetValue,
    /// Parameter 3 (ECM_GpioExtGetValue): lines 0..=19 (4 bytes back).
    ExtGetValue,
    /// Parameter 5 (ECM_GpioGetIntFlag): interrupt flags 0..=15 (2 bytes).
    GetIntFlag,
    /// Parameter 7 (ECM_GpioExtGetIntFlag): interrupt flags 0..=19 (4 bytes).
    ExtGetIntFlag,
}

impl<'a> Request<'a> for GpioFunc {
    const CODE: CommandCode = CommandCode::GpioFuncOp;
    type Answer<'r> = GpioReply;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let (parameter, param) = match *self {
            Self::SetValue { values } => {
                let [lo, hi] = values.to_le_bytes();
                (0, [lo, hi, 0, 0])
            }
            Self::ExtSetValue { values } => {
                check_range("GPIO values", values.0, 0, 0x000F_FFFF)?;
                let [a, b, c] = values.bytes3();
                (2, [a, b, c, 0])
            }
            Self::GetValue => (1, [0; 4]),
            Self::ExtGetValue => (3, [0; 4]),
            Self::GetIntFlag => (5, [0; 4]),
            Self::ExtGetIntFlag => (7, [0; 4]),
        };
        Ok(RequestFields { parameter, param, ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        let [p0, p1, p2, _] = fields.param;
        Ok(match fields.parameter {
            0 => Self::SetValue { values: u16::from_le_bytes([p0, p1]) },
            2 => {
                expect_range("extended GPIO values", p2.into(), 0, 0x0F)?;
                Self::ExtSetValue { values: GpioMask(u32::from_le_bytes([p0, p1, p2, 0])) }
            }
            1 => Self::GetValue,
            3 => Self::ExtGetValue,
            5 => Self::GetIntFlag,
            7 => Self::ExtGetIntFlag,
            v => return Err(PayloadError::InvalidValue { field: "GPIO_FUNC_OP sub-operation", value: v.into() }),
        })
    }
}

/// GPIO_FUNC_OP's reply to the get operations: 2 bytes (lines 0..=15) or 4
/// (lines 0..=19).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct GpioReply {
    /// The lines' levels or flags.
    pub lines: GpioMask,
    /// Whether the answer is the 4-byte (Ext) form.
    pub extended: bool,
}

impl<'a> Reply<'a> for GpioReply {
    const CODE: CommandCode = CommandCode::GpioFuncOp;

    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(data);
        if self.extended {
            w.u32(self.lines.0)?;
        } else {
            check_range("GPIO lines", self.lines.0, 0, 0xFFFF)?;
            w.u16(self.lines.0 as u16)?;
        }
        Ok(ReplyFields { value: 0, data_len: w.len_u16() })
    }

    fn decode(_fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(data);
        if data.len() >= 4 {
            Ok(Self { lines: GpioMask(r.u32("GPIO lines")?), extended: true })
        } else {
            Ok(Self { lines: GpioMask(r.u16("GPIO lines")?.into()), extended: false })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    fn mode() -> impl Strategy<Value = GpioMode> {
        (0u8..4).prop_map(|v| GpioMode::from_u8(v).unwrap())
    }
    fn pull() -> impl Strategy<Value = GpioPull> {
        (0u8..3).prop_map(|v| GpioPull::from_u8(v).unwrap())
    }
    fn trigger() -> impl Strategy<Value = GpioTrigger> {
        (0u8..4).prop_map(|v| GpioTrigger::from_u8(v).unwrap())
    }

    proptest! {
        #[test]
        fn config_ops_round_trip(
            lines: u16, ext in 0u8..16, mode in mode(), pull in pull(), on: bool,
            cycles in 0u8..16, src: bool, line in 0u8..20, trig in trigger(), mask in 0u32..0x10_0000,
        ) {
            let source = if src { DebounceSource::Clock10kHz } else { DebounceSource::Clock192MHz };
            for op in [
                GpioConfig::SetMode { lines, mode, pull },
                GpioConfig::SetModeExt { lines: ext, mode, pull },
                GpioConfig::EnableDebounce { lines, enable: on },
                GpioConfig::EnableDebounceExt { lines: ext, enable: on },
                GpioConfig::SetDebounceClock { cycles, source },
                GpioConfig::IntEnable { line, trigger: trig },
                GpioConfig::IntClear { lines },
                GpioConfig::IntClearExt { lines: GpioMask(mask) },
            ] {
                request_round_trip(&op);
            }
        }

        #[test]
        fn func_ops_round_trip(values: u16, mask in 0u32..0x10_0000) {
            for op in [
                GpioFunc::SetValue { values },
                GpioFunc::ExtSetValue { values: GpioMask(mask) },
                GpioFunc::GetValue, GpioFunc::ExtGetValue, GpioFunc::GetIntFlag, GpioFunc::ExtGetIntFlag,
            ] {
                request_round_trip(&op);
            }
        }

        #[test]
        fn replies_round_trip(narrow: u16, wide: u32) {
            let (f, _) = reply_round_trip(&GpioReply { lines: GpioMask(narrow.into()), extended: false });
            prop_assert_eq!(f.data_len, 2);
            let (f, _) = reply_round_trip(&GpioReply { lines: GpioMask(wide), extended: true });
            prop_assert_eq!(f.data_len, 4);
        }
    }

    #[test]
    fn set_mode_golden_fields() {
        let (f, _) =
            request_round_trip(&GpioConfig::SetMode { lines: 0x0103, mode: GpioMode::Output, pull: GpioPull::Down });
        assert_eq!((f.parameter, f.param), (0, [0x03, 0x01, 1, 2]));
        let (f, _) =
            request_round_trip(&GpioConfig::SetDebounceClock { cycles: 7, source: DebounceSource::Clock10kHz });
        assert_eq!((f.parameter, f.param), (3, [0x17, 0, 0, 0]));
    }

    #[test]
    fn out_of_range_values_are_refused_both_ways() {
        assert!(GpioConfig::IntEnable { line: 20, trigger: GpioTrigger::Rising }.encode(&mut []).is_err());
        assert!(
            GpioConfig::SetDebounceClock { cycles: 16, source: DebounceSource::Clock10kHz }.encode(&mut []).is_err()
        );
        assert!(
            GpioConfig::SetModeExt { lines: 0x10, mode: GpioMode::Input, pull: GpioPull::None }
                .encode(&mut [])
                .is_err()
        );
        let f = RequestFields { parameter: 0, param: [0, 0, 4, 0], ..RequestFields::default() };
        assert_eq!(GpioConfig::decode(&f, &[]), Err(PayloadError::InvalidValue { field: "GPIO mode", value: 4 }));
        let f = RequestFields { parameter: 5, ..RequestFields::default() };
        assert!(GpioConfig::decode(&f, &[]).is_err());
        let f = RequestFields { parameter: 4, ..RequestFields::default() };
        assert!(GpioFunc::decode(&f, &[]).is_err());
    }
}
