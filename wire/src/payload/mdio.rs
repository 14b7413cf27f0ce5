//! PHY registers over MDIO: MDIO (81). Parameter 0 write, 1 read; command
//! data 0 = PHY register, 1 = PHY address, 2..4 = value to write. A read
//! answers 2 bytes. (The chip's PHY sits at address 1, v049 圖一.)

use crate::CommandCode;
use crate::bytes::{check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Request, RequestFields, int_data_reply};

/// MDIO (81).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Mdio {
    /// Parameter 0.
    Write {
        /// PHY address 0..=31.
        phy: u8,
        /// Register 0..=31.
        register: u8,
        /// Value.
        value: u16,
    },
    /// Parameter 1.
    Read {
        /// PHY address 0..=31.
        phy: u8,
        /// Register 0..=31.
        register: u8,
    },
}

impl<'a> Request<'a> for Mdio {
    const CODE: CommandCode = CommandCode::Mdio;
    type Answer<'r> = MdioReply;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let (parameter, phy, register, value) = match *self {
            Self::Write { phy, register, value } => (0, phy, register, value),
            Self::Read { phy, register } => (1, phy, register, 0),
        };
        check_range("PHY address", phy.into(), 0, 31)?;
        check_range("PHY register", register.into(), 0, 31)?;
        let [v0, v1] = value.to_le_bytes();
        Ok(RequestFields { parameter, param: [register, phy, v0, v1], ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        let [register, phy, v0, v1] = fields.param;
        expect_range("PHY address", phy.into(), 0, 31)?;
        expect_range("PHY register", register.into(), 0, 31)?;
        match fields.parameter {
            0 => Ok(Self::Write { phy, register, value: u16::from_le_bytes([v0, v1]) }),
            1 => Ok(Self::Read { phy, register }),
            v => Err(PayloadError::InvalidValue { field: "MDIO parameter", value: v.into() }),
        }
    }
}

int_data_reply! {
    /// MDIO read's reply: the register (2 bytes).
    MdioReply(u16) => Mdio;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::{reply_round_trip, request_round_trip};
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn round_trips(phy in 0u8..32, register in 0u8..32, value: u16) {
            let (f, _) = request_round_trip(&Mdio::Write { phy, register, value });
            prop_assert_eq!(f.parameter, 0);
            let (f, _) = request_round_trip(&Mdio::Read { phy, register });
            prop_assert_eq!(f.param[..2].to_vec(), std::vec![register, phy]);
            reply_round_trip(&MdioReply(value));
        }
    }

    #[test]
    fn ranges() {
        assert!(Mdio::Read { phy: 32, register: 0 }.encode(&mut []).is_err());
        assert!(Mdio::decode(&RequestFields::parameter(2), &[]).is_err());
    }
}
