//! Chip control: INFO_UPDATE (0), FW_VERSION_GET (56), ASYNC_CMD_RESET (75),
//! WARM_RESET (127), the consecutive-WKC-error limit (130..=132) and
//! ENABLE_LRW (142).

use crate::CommandCode;
use crate::bytes::expect_range;
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Reply, ReplyFields, Request, RequestFields, bare_request, value_reply};

bare_request! {
    /// INFO_UPDATE (0): only refresh the response header. Also what a packet
    /// repeating the previous index and code turns into.
    InfoUpdate => InfoUpdate -> crate::payload::Done;
    /// FW_VERSION_GET (56).
    FwVersionGet => FwVersionGet -> FirmwareVersion;
    /// WARM_RESET (127): the chip resets to its power-up state and takes the
    /// next command only after initialising.
    WarmReset => WarmReset -> crate::payload::Done;
    /// WKC_CONTI_ERR_CNT_GET (130).
    WkcErrorCountGet => WkcContiErrCountGet -> WkcErrorCount;
    /// WKC_CONTI_ERR_MAX_GET (131).
    WkcErrorLimitGet => WkcContiErrMaxGet -> WkcErrorLimitReply;
}

value_reply! {
    /// FW_VERSION_GET's reply: the version in the return value.
    FirmwareVersion => FwVersionGet;
    /// WKC_CONTI_ERR_CNT_GET's reply: consecutive WKC errors now.
    WkcErrorCount => WkcContiErrCountGet;
}

bitflags::bitflags! {
    /// ASYNC_CMD_RESET's parameter.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
    pub struct AsyncReset: u8 {
        /// 1: clear the blocking-busy flag.
        const CLEAR_BUSY = 1 << 0;
        /// 2: skip waiting for the network initialisation.
        const SKIP_NET_INIT_WAIT = 1 << 1;
        /// 4: abandon the previous blocking command.
        const ABANDON_PREVIOUS = 1 << 2;
    }
}

/// ASYNC_CMD_RESET (75): recover a stuck blocking slot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct AsyncCmdReset(pub AsyncReset);

impl<'a> Request<'a> for AsyncCmdReset {
    const CODE: CommandCode = CommandCode::AsyncCmdReset;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        Ok(RequestFields::parameter(self.0.bits()))
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self(AsyncReset::from_bits_retain(fields.parameter)))
    }
}

/// How many consecutive WKC errors stop process-data exchange (after which
/// ECM status bit4 and bit6 read 0). 255 = never (the default).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct WkcErrorLimit(pub u8);

impl WkcErrorLimit {
    /// Never stop.
    pub const NEVER: Self = Self(255);

    /// Whether exchange never stops.
    pub const fn is_unlimited(self) -> bool {
        self.0 == 255
    }
}

impl Default for WkcErrorLimit {
    fn default() -> Self {
        Self::NEVER
    }
}

/// WKC_CONTI_ERR_MAX_SET (132): parameter 1..=254, or 255 for never.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct WkcErrorLimitSet(pub WkcErrorLimit);

impl<'a> Request<'a> for WkcErrorLimitSet {
    const CODE: CommandCode = CommandCode::WkcContiErrMaxSet;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        crate::bytes::check_range("WKC error limit", self.0.0.into(), 1, 255)?;
        Ok(RequestFields::parameter(self.0.0))
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        expect_range("WKC error limit", fields.parameter.into(), 1, 255)?;
        Ok(Self(WkcErrorLimit(fields.parameter)))
    }
}

/// WKC_CONTI_ERR_MAX_GET's reply.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct WkcErrorLimitReply(pub WkcErrorLimit);

impl<'a> Reply<'a> for WkcErrorLimitReply {
    const CODE: CommandCode = CommandCode::WkcContiErrMaxGet;

    fn encode(&self, _data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        Ok(ReplyFields { value: self.0.0, data_len: 0 })
    }

    fn decode(fields: &ReplyFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self(WkcErrorLimit(fields.value)))
    }
}

/// ENABLE_LRW (142): parameter 1 uses LRW where the slaves support it (the
/// default); 0 uses LRD + LWR instead.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct EnableLrw(pub bool);

impl<'a> Request<'a> for EnableLrw {
    const CODE: CommandCode = CommandCode::EnableLrw;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        Ok(RequestFields::parameter(u8::from(self.0)))
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        expect_range("ENABLE_LRW parameter", fields.parameter.into(), 0, 1)?;
        Ok(Self(fields.parameter == 1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn control_round_trips(v: u8, limit in 1u8..=255, on: bool) {
            request_round_trip(&AsyncCmdReset(AsyncReset::from_bits_retain(v)));
            request_round_trip(&WkcErrorLimitSet(WkcErrorLimit(limit)));
            request_round_trip(&EnableLrw(on));
            reply_round_trip(&FirmwareVersion(v));
            reply_round_trip(&WkcErrorCount(v));
            reply_round_trip(&WkcErrorLimitReply(WkcErrorLimit(v)));
        }
    }

    #[test]
    fn limits() {
        assert!(WkcErrorLimitSet(WkcErrorLimit(0)).encode(&mut []).is_err());
        assert!(WkcErrorLimitSet::decode(&RequestFields::parameter(0), &[]).is_err());
        assert!(WkcErrorLimit::default().is_unlimited());
        assert!(EnableLrw::decode(&RequestFields::parameter(2), &[]).is_err());
        assert_eq!(AsyncReset::ABANDON_PREVIOUS.bits(), 4);
    }
}
