//! The SPI link itself: SPI_PACK_SIZE_GET (20), SPI_RECONFIG (23),
//! CRC_ERR_CNT_CLR (24), CRC_TYPE_SET (25).

use crate::CommandCode;
use crate::bytes::{check_range, expect_range};
use crate::check::CheckType;
use crate::error::{EncodeError, PayloadError};
use crate::framing::{DATA_MAX, DATA_MIN};
use crate::payload::{Request, RequestFields, bare_request, int_data_reply, value_reply};

bare_request! {
    /// SPI_PACK_SIZE_GET (20): the data-section size in force.
    SpiPackSizeGet => SpiPackSizeGet -> SpiPackSize;
    /// CRC_ERR_CNT_CLR (24): clear the SPI CRC error counter.
    CrcErrCountClear => CrcErrCountClear -> CrcErrorsCleared;
}

int_data_reply! {
    /// SPI_PACK_SIZE_GET's reply: data-section size (2 bytes).
    SpiPackSize(u16) => SpiPackSizeGet;
}

value_reply! {
    /// CRC_ERR_CNT_CLR's reply: the count that was cleared.
    CrcErrorsCleared => CrcErrCountClear;
}

/// SPI_RECONFIG (23): change the data-section size (32..=1408), carried in
/// the header's data-length field. Send it with the FIXED check word: the
/// chip counts a CRC error for it, which is expected (v049 note under 23).
/// The ECM-XFU's size is fixed at 992. (v031 gave the range as whole-packet
/// sizes "66 ~ 1442"; v049's data-section range wins.)
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SpiReconfig {
    /// New data-section size.
    pub data_size: u16,
}

impl<'a> Request<'a> for SpiReconfig {
    const CODE: CommandCode = CommandCode::SpiReconfig;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        check_range("SPI data size", self.data_size.into(), DATA_MIN as u32, DATA_MAX as u32)?;
        Ok(RequestFields { data_len: self.data_size, ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        expect_range("SPI data size", fields.data_len.into(), DATA_MIN as u32, DATA_MAX as u32)?;
        Ok(Self { data_size: fields.data_len })
    }
}

/// CRC_TYPE_SET (25; v031 numbered it 3): the check type, in the parameter.
/// v049 defines only 0 (fixed) and 3 (CRC-32); 1 and 2 are v031's CRC-8 and
/// CRC-16, kept for older firmware.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CrcTypeSet(pub CheckType);

impl<'a> Request<'a> for CrcTypeSet {
    const CODE: CommandCode = CommandCode::CrcTypeSet;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        Ok(RequestFields::parameter(self.0.bits()))
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        expect_range("check type", fields.parameter.into(), 0, 3)?;
        Ok(Self(CheckType::from_bits(fields.parameter)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn reconfig_round_trips(size in 32u16..=1408) {
            let (f, _) = request_round_trip(&SpiReconfig { data_size: size });
            prop_assert_eq!(f.data_len, size);
        }

        #[test]
        fn reconfig_rejects_out_of_range(size in prop_oneof![0u16..32, 1409u16..]) {
            let req = SpiReconfig { data_size: size };
            prop_assert!(req.encode(&mut []).is_err());
            let f = RequestFields { data_len: size, ..RequestFields::default() };
            prop_assert!(SpiReconfig::decode(&f, &[]).is_err());
        }

        #[test]
        fn link_replies_round_trip(size: u16, n: u8) {
            reply_round_trip(&SpiPackSize(size));
            reply_round_trip(&CrcErrorsCleared(n));
        }
    }

    #[test]
    fn crc_type_set_all_types() {
        for t in CheckType::ALL {
            let (f, _) = request_round_trip(&CrcTypeSet(t));
            assert_eq!(f.parameter, t as u8);
        }
        assert!(CrcTypeSet::decode(&RequestFields::parameter(4), &[]).is_err());
    }
}
