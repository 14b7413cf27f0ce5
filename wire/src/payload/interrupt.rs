//! INT0/INT1 configuration: INT_SET_ENABLE (58) and INT_GET_ENABLE (59).
//!
//! Parameter (and 59's return value): bit0 INT1 active-high (default 0, i.e.
//! active-low), bit1 INT0 active-high (default 1). Data (6 bytes): u32
//! composite mask (same map as [`InterruptFlags`]), u8 GPIO0..7 interrupt
//! enable, u8 GPIO8..11 and QEI enables. INT1 is active while
//! `flags & mask != 0`. (v031 had a 4-byte mask and a one-bit polarity;
//! v049 wins.)

use crate::CommandCode;
use crate::bytes::{Reader, Writer};
use crate::error::{EncodeError, PayloadError};
use crate::flags::InterruptFlags;
use crate::payload::{Reply, ReplyFields, Request, RequestFields, bare_request};

bitflags::bitflags! {
    /// Line polarities.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub struct IntPolarity: u8 {
        /// bit0: INT1 is active-high.
        const INT1_ACTIVE_HIGH = 1 << 0;
        /// bit1: INT0 is active-high.
        const INT0_ACTIVE_HIGH = 1 << 1;
    }
}

impl Default for IntPolarity {
    /// Power-up: INT0 active-high, INT1 active-low.
    fn default() -> Self {
        Self::INT0_ACTIVE_HIGH
    }
}

bitflags::bitflags! {
    /// The sixth data byte: GPIO8..11 and QEI interrupt enables.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
    pub struct PeripheralInts: u8 {
        /// GPIO8.
        const GPIO8 = 1 << 0;
        /// GPIO9.
        const GPIO9 = 1 << 1;
        /// GPIO10.
        const GPIO10 = 1 << 2;
        /// GPIO11.
        const GPIO11 = 1 << 3;
        /// QEI index.
        const QEI_INDEX = 1 << 4;
        /// QEI compare.
        const QEI_COMPARE = 1 << 5;
        /// QEI over/underflow.
        const QEI_OVERFLOW = 1 << 6;
    }
}

/// The whole INT configuration.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct IntConfig {
    /// Polarities of INT0 and INT1.
    pub polarity: IntPolarity,
    /// Composite sources of INT1.
    pub mask: InterruptFlags,
    /// GPIO0..7 sources.
    pub gpio: u8,
    /// GPIO8..11 and QEI sources.
    pub peripheral: PeripheralInts,
}

/// Length of the INT configuration data.
pub const INT_CONFIG_LEN: u16 = 6;

impl IntConfig {
    fn write(&self, data: &mut [u8]) -> Result<u16, EncodeError> {
        let mut w = Writer::new(data);
        w.u32(self.mask.bits())?;
        w.u8(self.gpio)?;
        w.u8(self.peripheral.bits())?;
        Ok(w.len_u16())
    }

    fn read(polarity: u8, data: &[u8]) -> Result<Self, PayloadError> {
        if polarity & !0b11 != 0 {
            return Err(PayloadError::InvalidValue { field: "INT polarity", value: polarity.into() });
        }
        let mut r = Reader::new(data);
        Ok(Self {
            polarity: IntPolarity::from_bits_retain(polarity),
            mask: InterruptFlags::from_bits_retain(r.u32("INT composite mask")?),
            gpio: r.u8("GPIO INT enable")?,
            peripheral: PeripheralInts::from_bits_retain(r.u8("peripheral INT enable")?),
        })
    }
}

/// INT_SET_ENABLE (58).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct IntSetEnable(pub IntConfig);

impl<'a> Request<'a> for IntSetEnable {
    const CODE: CommandCode = CommandCode::IntSetEnable;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let data_len = self.0.write(data)?;
        Ok(RequestFields { parameter: self.0.polarity.bits(), data_len, ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        crate::payload::fixed_len(fields, Self::CODE, INT_CONFIG_LEN)?;
        IntConfig::read(fields.parameter, data).map(Self)
    }
}

bare_request! {
    /// INT_GET_ENABLE (59).
    IntGetEnable => IntGetEnable -> IntConfigReply;
}

/// INT_GET_ENABLE's reply: polarity in the return value, masks in the data.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct IntConfigReply(pub IntConfig);

impl<'a> Reply<'a> for IntConfigReply {
    const CODE: CommandCode = CommandCode::IntGetEnable;

    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        Ok(ReplyFields { value: self.0.polarity.bits(), data_len: self.0.write(data)? })
    }

    fn decode(fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        IntConfig::read(fields.value, data).map(Self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn int_config_round_trips(pol in 0u8..4, mask: u32, gpio: u8, per: u8) {
            let c = IntConfig {
                polarity: IntPolarity::from_bits_retain(pol),
                mask: InterruptFlags::from_bits_retain(mask),
                gpio,
                peripheral: PeripheralInts::from_bits_retain(per),
            };
            let (f, _) = request_round_trip(&IntSetEnable(c));
            prop_assert_eq!(f.data_len, INT_CONFIG_LEN);
            reply_round_trip(&IntConfigReply(c));
        }
    }

    #[test]
    fn golden_and_defaults() {
        assert_eq!(IntPolarity::default().bits(), 0b10);
        let c = IntConfig {
            polarity: IntPolarity::INT0_ACTIVE_HIGH | IntPolarity::INT1_ACTIVE_HIGH,
            mask: InterruptFlags::RX_FIFO_LOW | InterruptFlags::WKC_ERROR,
            gpio: 0x81,
            peripheral: PeripheralInts::QEI_INDEX,
        };
        let (f, d) = request_round_trip(&IntSetEnable(c));
        assert_eq!(f.parameter, 3);
        assert_eq!(&d[..6], &[0x00, 0x00, 0x40, 0x02, 0x81, 0x10]);
        assert!(IntSetEnable::decode(&RequestFields::parameter(4), &d).is_err());
    }
}
