//! The CoE header (ETG.1000.6 5.6.1, Table 29): two bytes before every CoE
//! service, bits 0..8 a number (the PDO number for PDO services, else 0),
//! bits 12..15 the service. And the emergency message (service 1, Table 50),
//! which a slave may put in its send mailbox between any two answers.

use crate::bytes::{Reader, Writer};
use crate::error::{EncodeError, PayloadError};

/// The header's length in bytes.
pub const COE_HEADER_LEN: usize = 2;

/// A CoE service (ETG.1000.6 Table 29).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CoeService {
    /// 1: emergency.
    Emergency,
    /// 2: SDO request.
    SdoRequest,
    /// 3: SDO response.
    SdoResponse,
    /// 8: SDO information.
    SdoInformation,
    /// Any other (PDO services 4..=7, reserved).
    Other(u8),
}

impl CoeService {
    /// The 4-bit code.
    pub fn code(self) -> u8 {
        match self {
            Self::Emergency => 1,
            Self::SdoRequest => 2,
            Self::SdoResponse => 3,
            Self::SdoInformation => 8,
            Self::Other(c) => c & 0x0F,
        }
    }

    /// The service of a 4-bit code.
    pub fn from_code(code: u8) -> Self {
        match code & 0x0F {
            1 => Self::Emergency,
            2 => Self::SdoRequest,
            3 => Self::SdoResponse,
            8 => Self::SdoInformation,
            c => Self::Other(c),
        }
    }
}

/// The two-byte CoE header.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CoeHeader {
    /// Bits 0..8: a PDO number, else 0.
    pub number: u16,
    /// Bits 12..15.
    pub service: CoeService,
}

impl CoeHeader {
    /// The header of `service`, number 0.
    pub fn of(service: CoeService) -> Self {
        Self { number: 0, service }
    }

    /// The two bytes.
    pub fn to_bytes(self) -> [u8; 2] {
        ((self.number & 0x01FF) | u16::from(self.service.code()) << 12).to_le_bytes()
    }

    /// Reads the header from the start of a CoE body.
    pub fn decode(body: &[u8]) -> Result<Self, PayloadError> {
        let v = Reader::new(body).u16("CoE header")?;
        Ok(Self { number: v & 0x01FF, service: CoeService::from_code((v >> 12) as u8) })
    }
}

/// A CoE emergency (ETG.1000.6 Table 50): CiA 301 error code, error
/// register, five bytes of the maker's data.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct CoeEmergency {
    /// Error code.
    pub error_code: u16,
    /// Error register (object 0x1001).
    pub error_register: u8,
    /// Manufacturer-specific data.
    pub data: [u8; 5],
}

impl CoeEmergency {
    /// The CoE body: header, then the eight bytes.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let mut w = Writer::new(out);
        w.bytes(&CoeHeader::of(CoeService::Emergency).to_bytes())?;
        w.u16(self.error_code)?;
        w.u8(self.error_register)?;
        w.bytes(&self.data)?;
        Ok(usize::from(w.len_u16()))
    }

    /// Reads the eight bytes after the CoE header.
    pub fn decode(body: &[u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(body);
        let header = CoeHeader::decode(r.bytes("CoE header", COE_HEADER_LEN)?)?;
        if header.service != CoeService::Emergency {
            return Err(PayloadError::InvalidValue { field: "CoE service", value: header.service.code().into() });
        }
        Ok(Self { error_code: r.u16("error code")?, error_register: r.u8("error register")?, data: r.array("data")? })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn headers_round_trip(number in 0u16..512, service in 0u8..16) {
            let h = CoeHeader { number, service: CoeService::from_code(service) };
            prop_assert_eq!(CoeHeader::decode(&h.to_bytes()).unwrap(), h);
        }

        #[test]
        fn emergencies_round_trip(error_code: u16, error_register: u8, data: [u8; 5]) {
            let e = CoeEmergency { error_code, error_register, data };
            let mut b = [0u8; 10];
            let n = e.encode(&mut b).unwrap();
            prop_assert_eq!(n, 10);
            prop_assert_eq!(CoeEmergency::decode(&b).unwrap(), e);
        }
    }

    #[test]
    fn an_sdo_information_header_is_0x8000() {
        assert_eq!(CoeHeader::of(CoeService::SdoInformation).to_bytes(), [0x00, 0x80]);
        assert_eq!(CoeHeader::of(CoeService::SdoRequest).to_bytes(), [0x00, 0x20]);
    }
}
