//! The chip's own peripherals: QEI_FUNC_OP (33), DAC_FUNC_OP (34),
//! ADC_FUNC_OP (35). Each multiplexes sub-operations on its parameter; some
//! carry a 4- or 12-byte data section with fixed values the manual gives.

use crate::CommandCode;
use crate::bytes::{Reader, Writer, check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Request, RequestFields, int_data_reply};

/// Encoder counting mode (ECM_EncOpen data).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum QeiMode {
    /// 0x000: X4 free counting.
    X4Free,
    /// 0x100: X2 free counting.
    X2Free,
    /// 0x200: X4 compare counting.
    X4Compare,
    /// 0x300: X2 compare counting.
    X2Compare,
}

/// QEI_FUNC_OP (33) sub-operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum QeiOp {
    /// Parameter 4 (ECM_EncOpen): open with a mode (4 bytes data).
    Open(QeiMode),
    /// Parameter 5 (ECM_EncStart).
    Start,
    /// Parameter 6 (ECM_EncStop).
    Stop,
    /// Parameter 21 (ECM_EncGetCount): 4 bytes back.
    GetCount,
}

fn word(w: u32, data: &mut [u8]) -> Result<u16, EncodeError> {
    let mut wr = Writer::new(data);
    wr.u32(w)?;
    Ok(wr.len_u16())
}

/// The one data word some peripheral operations carry (4 bytes).
fn data_word(fields: &RequestFields, data: &[u8], field: &'static str, code: CommandCode) -> Result<u32, PayloadError> {
    crate::payload::fixed_len(fields, code, 4)?;
    Reader::new(data).u32(field)
}

impl<'a> Request<'a> for QeiOp {
    const CODE: CommandCode = CommandCode::QeiFuncOp;
    type Answer<'r> = QeiCount;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let (parameter, data_len) = match self {
            Self::Open(mode) => {
                let v = match mode {
                    QeiMode::X4Free => 0x000,
                    QeiMode::X2Free => 0x100,
                    QeiMode::X4Compare => 0x200,
                    QeiMode::X2Compare => 0x300,
                };
                (4, word(v, data)?)
            }
            Self::Start => (5, 0),
            Self::Stop => (6, 0),
            Self::GetCount => (21, 0),
        };
        Ok(RequestFields { parameter, data_len, ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(match fields.parameter {
            4 => Self::Open(match data_word(fields, data, "QEI mode", Self::CODE)? {
                0x000 => QeiMode::X4Free,
                0x100 => QeiMode::X2Free,
                0x200 => QeiMode::X4Compare,
                0x300 => QeiMode::X2Compare,
                v => return Err(PayloadError::InvalidValue { field: "QEI mode", value: v }),
            }),
            5 => Self::Start,
            6 => Self::Stop,
            21 => Self::GetCount,
            v => return Err(PayloadError::InvalidValue { field: "QEI_FUNC_OP sub-operation", value: v.into() }),
        })
    }
}

int_data_reply! {
    /// QEI GetCount's reply: the counter (4 bytes, signed).
    QeiCount(i32) => QeiFuncOp;
    /// ADC GetDataValidFlag / GetConvData reply: 4 bytes (flag, or 0..=4095
    /// for 0..3.3 V).
    AdcReply(u32) => AdcFuncOp;
}

/// What starts a DAC conversion (ECM_DacOpen data).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DacTrigger {
    /// 0x0000: SetData starts it.
    OnSetData,
    /// 0x0010: StartConv starts it.
    OnStartConv,
    /// 0x0030: DAC_ST pin low.
    PinLow,
    /// 0x1030: DAC_ST pin high.
    PinHigh,
    /// 0x2030: DAC_ST rising edge.
    PinRising,
    /// 0x3030: DAC_ST falling edge.
    PinFalling,
}

impl DacTrigger {
    const TABLE: [(Self, u32); 6] = [
        (Self::OnSetData, 0x0000),
        (Self::OnStartConv, 0x0010),
        (Self::PinLow, 0x0030),
        (Self::PinHigh, 0x1030),
        (Self::PinRising, 0x2030),
        (Self::PinFalling, 0x3030),
    ];
}

/// DAC_FUNC_OP (34) sub-operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DacOp {
    /// Parameter 20 (ECM_DacOpen).
    Open(DacTrigger),
    /// Parameter 21 (ECM_DacClose).
    Close,
    /// Parameter 22 (ECM_DacSetDelayTime): 0..=1023 in 1/96 us; > 768
    /// advised (a full swing takes 8 us).
    SetDelay(u16),
    /// Parameter 11 (ECM_DacSetData): 0..=4095 for 0..3.3 V.
    SetData(u16),
    /// Parameter 0 (ECM_DacStartConv).
    StartConv,
}

impl<'a> Request<'a> for DacOp {
    const CODE: CommandCode = CommandCode::DacFuncOp;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let (parameter, data_len) = match *self {
            Self::Open(t) => {
                let v = DacTrigger::TABLE.iter().find(|(x, _)| *x == t).map_or(0, |(_, v)| *v);
                (20, word(v, data)?)
            }
            Self::Close => (21, 0),
            Self::SetDelay(d) => {
                check_range("DAC delay", d.into(), 0, 1023)?;
                (22, word(d.into(), data)?)
            }
            Self::SetData(v) => {
                check_range("DAC value", v.into(), 0, 4095)?;
                (11, word(v.into(), data)?)
            }
            Self::StartConv => (0, 0),
        };
        Ok(RequestFields { parameter, data_len, ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(match fields.parameter {
            20 => {
                let v = data_word(fields, data, "DAC mode", Self::CODE)?;
                let t = DacTrigger::TABLE.iter().find(|(_, x)| *x == v);
                Self::Open(t.ok_or(PayloadError::InvalidValue { field: "DAC mode", value: v })?.0)
            }
            21 => Self::Close,
            22 => {
                let v = data_word(fields, data, "DAC delay", Self::CODE)?;
                expect_range("DAC delay", v, 0, 1023)?;
                Self::SetDelay(v as u16)
            }
            11 => {
                let v = data_word(fields, data, "DAC value", Self::CODE)?;
                expect_range("DAC value", v, 0, 4095)?;
                Self::SetData(v as u16)
            }
            0 => Self::StartConv,
            v => return Err(PayloadError::InvalidValue { field: "DAC_FUNC_OP sub-operation", value: v.into() }),
        })
    }
}

/// ADC input wiring (ECM_AdcOpen data).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AdcInput {
    /// 0x000: single-ended.
    SingleEnded,
    /// 0x100: differential.
    Differential,
}

/// ADC_FUNC_OP (35) sub-operations. The fixed data values are the manual's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AdcOp {
    /// Parameter 40 (ECM_AdcOpen).
    Open(AdcInput),
    /// Parameter 41 (ECM_AdcClose).
    Close,
    /// Parameter 42 (ECM_AdcConfigSampleModule): 12 bytes, trigger word at
    /// offset 4 = 0 (software trigger, the only one documented).
    ConfigSampleModule,
    /// Parameter 17 (ECM_AdcGetDataValidFlag): data 0x1000; 4 bytes back.
    GetDataValidFlag,
    /// Parameter 12 (ECM_AdcStartConv): data 0x1000.
    StartConv,
    /// Parameter 15 (ECM_AdcGetConvData): data 12; 4 bytes back.
    GetConvData,
}

/// The fixed data word of GetDataValidFlag and StartConv.
pub const ADC_FIXED_WORD: u32 = 0x1000;
/// The fixed data word of GetConvData.
pub const ADC_CONV_WORD: u32 = 12;

impl<'a> Request<'a> for AdcOp {
    const CODE: CommandCode = CommandCode::AdcFuncOp;
    type Answer<'r> = AdcReply;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let (parameter, data_len) = match self {
            Self::Open(AdcInput::SingleEnded) => (40, word(0x000, data)?),
            Self::Open(AdcInput::Differential) => (40, word(0x100, data)?),
            Self::Close => (41, 0),
            Self::ConfigSampleModule => {
                let mut w = Writer::new(data);
                w.u32(0)?;
                w.u32(0)?;
                w.u32(0)?;
                (42, w.len_u16())
            }
            Self::GetDataValidFlag => (17, word(ADC_FIXED_WORD, data)?),
            Self::StartConv => (12, word(ADC_FIXED_WORD, data)?),
            Self::GetConvData => (15, word(ADC_CONV_WORD, data)?),
        };
        Ok(RequestFields { parameter, data_len, ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        let fixed = |want: u32, field: &'static str| -> Result<(), PayloadError> {
            let v = data_word(fields, data, field, Self::CODE)?;
            if v == want { Ok(()) } else { Err(PayloadError::InvalidValue { field, value: v }) }
        };
        Ok(match fields.parameter {
            40 => match data_word(fields, data, "ADC input mode", Self::CODE)? {
                0x000 => Self::Open(AdcInput::SingleEnded),
                0x100 => Self::Open(AdcInput::Differential),
                v => return Err(PayloadError::InvalidValue { field: "ADC input mode", value: v }),
            },
            41 => Self::Close,
            42 => {
                let mut r = Reader::new(data);
                let _ = r.u32("ADC sample module")?;
                let trigger = r.u32("ADC trigger source")?;
                expect_range("ADC trigger source", trigger, 0, 0)?;
                Self::ConfigSampleModule
            }
            17 => {
                fixed(ADC_FIXED_WORD, "ADC valid-flag word")?;
                Self::GetDataValidFlag
            }
            12 => {
                fixed(ADC_FIXED_WORD, "ADC start word")?;
                Self::StartConv
            }
            15 => {
                fixed(ADC_CONV_WORD, "ADC data word")?;
                Self::GetConvData
            }
            v => return Err(PayloadError::InvalidValue { field: "ADC_FUNC_OP sub-operation", value: v.into() }),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    #[test]
    fn every_sub_operation_round_trips() {
        for m in [QeiMode::X4Free, QeiMode::X2Free, QeiMode::X4Compare, QeiMode::X2Compare] {
            request_round_trip(&QeiOp::Open(m));
        }
        for op in [QeiOp::Start, QeiOp::Stop, QeiOp::GetCount] {
            request_round_trip(&op);
        }
        for (t, _) in DacTrigger::TABLE {
            request_round_trip(&DacOp::Open(t));
        }
        for op in [DacOp::Close, DacOp::StartConv, DacOp::SetDelay(1023), DacOp::SetData(4095), DacOp::SetData(0)] {
            request_round_trip(&op);
        }
        for op in [
            AdcOp::Open(AdcInput::SingleEnded),
            AdcOp::Open(AdcInput::Differential),
            AdcOp::Close,
            AdcOp::ConfigSampleModule,
            AdcOp::GetDataValidFlag,
            AdcOp::StartConv,
            AdcOp::GetConvData,
        ] {
            request_round_trip(&op);
        }
    }

    #[test]
    fn golden_fields() {
        let (f, d) = request_round_trip(&QeiOp::Open(QeiMode::X2Compare));
        assert_eq!((f.parameter, f.data_len, &d[..4]), (4, 4, &[0x00, 0x03, 0, 0][..]));
        let (f, d) = request_round_trip(&DacOp::Open(DacTrigger::PinRising));
        assert_eq!((f.parameter, &d[..4]), (20, &[0x30, 0x20, 0, 0][..]));
        let (f, d) = request_round_trip(&AdcOp::GetConvData);
        assert_eq!((f.parameter, f.data_len, &d[..4]), (15, 4, &[12, 0, 0, 0][..]));
        let (f, _) = request_round_trip(&AdcOp::ConfigSampleModule);
        assert_eq!((f.parameter, f.data_len), (42, 12));
    }

    #[test]
    fn ranges_are_enforced() {
        assert!(DacOp::SetData(4096).encode(&mut [0; 32]).is_err());
        assert!(DacOp::SetDelay(1024).encode(&mut [0; 32]).is_err());
        let f = RequestFields { parameter: 11, data_len: 4, ..RequestFields::default() };
        assert_eq!(
            DacOp::decode(&f, &[0x00, 0x10, 0, 0]),
            Err(PayloadError::InvalidValue { field: "DAC value", value: 4096 })
        );
        let f = RequestFields { parameter: 17, data_len: 4, ..RequestFields::default() };
        assert!(AdcOp::decode(&f, &[0, 0, 0, 0]).is_err());
        let f = RequestFields { parameter: 4, data_len: 0, ..RequestFields::default() };
        assert!(matches!(QeiOp::decode(&f, &[0; 4]), Err(PayloadError::DataLength { expected: 4, found: 0, .. })));
        let f = RequestFields { parameter: 99, ..RequestFields::default() };
        assert!(QeiOp::decode(&f, &[]).is_err() && DacOp::decode(&f, &[]).is_err() && AdcOp::decode(&f, &[]).is_err());
    }

    proptest! {
        #[test]
        fn replies_round_trip(c: i32, v: u32) {
            reply_round_trip(&QeiCount(c));
            reply_round_trip(&AdcReply(v));
        }
    }
}
