//! The chip's PDO FIFOs: FIFO_ENABLE (18), FIFO_PACK_SIZE_GET (19),
//! FIFO_CLR (51), FIFO_SET/GET_TX_CNT (52/53), FIFO_SET/GET_RX_CNT (54/55),
//! FIFO_INIT (66), SET_FIFO_TH (70).
//!
//! Budget (v049 under 52/54): RxCnt x RxSize + TxCnt x TxSize <= 0x4000
//! bytes; default depth 64 each. TxFIFO full drops the oldest frame, RxFIFO
//! full drops the newest.

use crate::CommandCode;
use crate::error::{EncodeError, PayloadError};
use crate::payload::pdo::PdoDirection;
use crate::payload::{Request, RequestFields, bare_request, int_data_reply, parameter_request, value_reply};

/// The FIFOs' shared memory in bytes.
pub const FIFO_BUDGET: usize = 0x4000;
/// Default depth of each FIFO, in frames.
pub const FIFO_DEFAULT_DEPTH: u8 = 64;

/// FIFO_ENABLE (18): parameter 1 enables cyclic RxPDO output, 0 disables it
/// (frames can then be stored ahead).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct FifoEnable(pub bool);

impl<'a> Request<'a> for FifoEnable {
    const CODE: CommandCode = CommandCode::FifoEnable;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        Ok(RequestFields::parameter(u8::from(self.0)))
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        match fields.parameter {
            0 => Ok(Self(false)),
            1 => Ok(Self(true)),
            v => Err(PayloadError::InvalidValue { field: "FIFO_ENABLE parameter", value: v.into() }),
        }
    }
}

/// FIFO_PACK_SIZE_GET (19): one frame's size; parameter 0 RxPDO (outputs),
/// 1 TxPDO (inputs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FifoPackSizeGet(pub PdoDirection);

impl<'a> Request<'a> for FifoPackSizeGet {
    const CODE: CommandCode = CommandCode::FifoPackSizeGet;
    type Answer<'r> = FifoPackSize;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        Ok(RequestFields::parameter(u8::from(self.0 == PdoDirection::Inputs)))
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        match fields.parameter {
            0 => Ok(Self(PdoDirection::Outputs)),
            1 => Ok(Self(PdoDirection::Inputs)),
            v => Err(PayloadError::InvalidValue { field: "FIFO_PACK_SIZE_GET parameter", value: v.into() }),
        }
    }
}

int_data_reply! {
    /// FIFO_PACK_SIZE_GET's reply: frame size in bytes (2 bytes).
    FifoPackSize(u16) => FifoPackSizeGet;
}

/// Which FIFOs FIFO_CLR (51) clears (its parameter).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FifoClear {
    /// 0: both.
    Both,
    /// 1: TxFIFO only.
    TxOnly,
    /// 2: RxFIFO only.
    RxOnly,
}

impl<'a> Request<'a> for FifoClear {
    const CODE: CommandCode = CommandCode::FifoClear;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        Ok(RequestFields::parameter(match self {
            Self::Both => 0,
            Self::TxOnly => 1,
            Self::RxOnly => 2,
        }))
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        match fields.parameter {
            0 => Ok(Self::Both),
            1 => Ok(Self::TxOnly),
            2 => Ok(Self::RxOnly),
            v => Err(PayloadError::InvalidValue { field: "FIFO_CLR parameter", value: v.into() }),
        }
    }
}

parameter_request! {
    /// FIFO_SET_TX_CNT (52): TxFIFO depth in frames.
    FifoSetTxCount => FifoSetTxCount -> crate::payload::Done;
    /// FIFO_SET_RX_CNT (54): RxFIFO depth in frames.
    FifoSetRxCount => FifoSetRxCount -> crate::payload::Done;
}

bare_request! {
    /// FIFO_GET_TX_CNT (53).
    FifoGetTxCount => FifoGetTxCount -> TxFifoDepth;
    /// FIFO_GET_RX_CNT (55).
    FifoGetRxCount => FifoGetRxCount -> RxFifoDepth;
    /// FIFO_INIT (66): build the FIFOs from their depths and frame sizes
    /// (blocking).
    FifoInit => FifoInit -> crate::payload::Done;
}

value_reply! {
    /// FIFO_GET_TX_CNT's reply: TxFIFO depth.
    TxFifoDepth => FifoGetTxCount;
    /// FIFO_GET_RX_CNT's reply: RxFIFO depth.
    RxFifoDepth => FifoGetRxCount;
}

/// SET_FIFO_TH (70): interrupt marks. Parameter bit0 enables the TxFIFO high
/// mark (command data 0), bit1 the RxFIFO low mark (command data 1); they
/// raise interrupt flags bit24 and bit25.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct SetFifoThreshold {
    /// TxFIFO high mark, if enabled.
    pub tx_high: Option<u8>,
    /// RxFIFO low mark, if enabled.
    pub rx_low: Option<u8>,
}

impl<'a> Request<'a> for SetFifoThreshold {
    const CODE: CommandCode = CommandCode::SetFifoThreshold;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let parameter = u8::from(self.tx_high.is_some()) | u8::from(self.rx_low.is_some()) << 1;
        Ok(RequestFields {
            parameter,
            param: [self.tx_high.unwrap_or(0), self.rx_low.unwrap_or(0), 0, 0],
            ..RequestFields::default()
        })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        if fields.parameter & !0b11 != 0 {
            return Err(PayloadError::InvalidValue { field: "SET_FIFO_TH parameter", value: fields.parameter.into() });
        }
        Ok(Self {
            tx_high: (fields.parameter & 1 != 0).then_some(fields.param[0]),
            rx_low: (fields.parameter & 2 != 0).then_some(fields.param[1]),
        })
    }
}

/// Whether depths fit the FIFO budget for the given frame sizes.
pub fn fits_budget(rx_depth: u8, rx_size: u16, tx_depth: u8, tx_size: u16) -> bool {
    usize::from(rx_depth) * usize::from(rx_size) + usize::from(tx_depth) * usize::from(tx_size) <= FIFO_BUDGET
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn fifo_requests_round_trip(n: u8, tx: Option<u8>, rx: Option<u8>, on: bool) {
            request_round_trip(&FifoSetTxCount(n));
            request_round_trip(&FifoSetRxCount(n));
            request_round_trip(&SetFifoThreshold { tx_high: tx, rx_low: rx });
            request_round_trip(&FifoEnable(on));
        }

        #[test]
        fn fifo_replies_round_trip(n: u8, size: u16) {
            reply_round_trip(&TxFifoDepth(n));
            reply_round_trip(&RxFifoDepth(n));
            let (f, _) = reply_round_trip(&FifoPackSize(size));
            prop_assert_eq!(f.data_len, 2);
        }
    }

    #[test]
    fn enumerated_parameters() {
        for c in [FifoClear::Both, FifoClear::TxOnly, FifoClear::RxOnly] {
            request_round_trip(&c);
        }
        for d in [PdoDirection::Outputs, PdoDirection::Inputs] {
            request_round_trip(&FifoPackSizeGet(d));
        }
        assert!(FifoClear::decode(&RequestFields::parameter(3), &[]).is_err());
        assert!(FifoEnable::decode(&RequestFields::parameter(2), &[]).is_err());
        assert!(FifoPackSizeGet::decode(&RequestFields::parameter(2), &[]).is_err());
        assert!(SetFifoThreshold::decode(&RequestFields::parameter(4), &[]).is_err());
    }

    #[test]
    fn budget() {
        assert!(fits_budget(64, 128, 64, 128));
        assert!(!fits_budget(64, 129, 64, 128));
        assert!(fits_budget(255, 0, 0, 0));
    }
}
