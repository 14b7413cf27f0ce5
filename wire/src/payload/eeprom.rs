//! SII EEPROM access: EEPROM_REQ (38) and EEPROM_GET (39).
//!
//! EEPROM_REQ data (12 bytes, v049): op u16 (0 read, 1 write), slave u16,
//! word address u16, write word u16, timeout u32 in us (v031 said ns; v049
//! revision 035 fixed the unit). EEPROM_GET's return value is an error code
//! (0 = success) and its data the words read.

use crate::CommandCode;
use crate::bytes::{Reader, Writer, check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Reply, ReplyFields, Request, RequestFields, bare_request};

/// Read or write one word.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EepromAccess {
    /// Read at a word address (fetch with EEPROM_GET).
    Read {
        /// Word address.
        address: u16,
    },
    /// Write one word.
    Write {
        /// Word address.
        address: u16,
        /// The word.
        value: u16,
    },
}

/// EEPROM_REQ (38): one SII word operation (blocking).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct EepromRequest {
    /// Slave position 0..=127.
    pub slave: u16,
    /// What to do.
    pub access: EepromAccess,
    /// How long the chip waits, in us.
    pub timeout_us: u32,
}

impl<'a> Request<'a> for EepromRequest {
    const CODE: CommandCode = CommandCode::EepromReq;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        check_range("slave", self.slave.into(), 0, 127)?;
        let (op, address, value) = match self.access {
            EepromAccess::Read { address } => (0, address, 0),
            EepromAccess::Write { address, value } => (1, address, value),
        };
        let mut w = Writer::new(data);
        w.u16(op)?;
        w.u16(self.slave)?;
        w.u16(address)?;
        w.u16(value)?;
        w.u32(self.timeout_us)?;
        Ok(RequestFields { data_len: w.len_u16(), ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        crate::payload::fixed_len(fields, Self::CODE, 12)?;
        let mut r = Reader::new(data);
        let op = r.u16("EEPROM operation")?;
        let slave = r.u16("slave")?;
        expect_range("slave", slave.into(), 0, 127)?;
        let address = r.u16("EEPROM address")?;
        let value = r.u16("EEPROM write data")?;
        let timeout_us = r.u32("EEPROM timeout")?;
        let access = match op {
            0 => EepromAccess::Read { address },
            1 => EepromAccess::Write { address, value },
            v => return Err(PayloadError::InvalidValue { field: "EEPROM operation", value: v.into() }),
        };
        Ok(Self { slave, access, timeout_us })
    }
}

bare_request! {
    /// EEPROM_GET (39): fetch the result of EEPROM_REQ.
    EepromGet => EepromGet -> EepromReply<'r>;
}

/// EEPROM_GET's reply: error code (0 = ok) and the data read (ESCs read 4
/// or 8 bytes at a time; the first word is the one asked for).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct EepromReply<'a> {
    /// Return value: operation error code.
    pub error: u8,
    /// Bytes read.
    pub data: &'a [u8],
}

impl EepromReply<'_> {
    /// The word read at the requested address, if any data came back.
    pub fn word(&self) -> Option<u16> {
        (self.data.len() >= 2).then(|| u16::from_le_bytes([self.data[0], self.data[1]]))
    }
}

impl<'a> Reply<'a> for EepromReply<'a> {
    const CODE: CommandCode = CommandCode::EepromGet;

    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(data);
        w.bytes(self.data)?;
        Ok(ReplyFields { value: self.error, data_len: w.len_u16() })
    }

    fn decode(fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self { error: fields.value, data })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::request_round_trip;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn request_round_trips(slave in 0u16..=127, write: bool, address: u16, value: u16, timeout: u32) {
            let access = if write { EepromAccess::Write { address, value } } else { EepromAccess::Read { address } };
            let (f, _) = request_round_trip(&EepromRequest { slave, access, timeout_us: timeout });
            prop_assert_eq!(f.data_len, 12);
        }

        #[test]
        fn reply_round_trips(error: u8, bytes in proptest::collection::vec(any::<u8>(), 0..=8)) {
            let r = EepromReply { error, data: &bytes };
            let mut d = [0u8; 112];
            let f = r.encode(&mut d).unwrap();
            prop_assert_eq!(EepromReply::decode(&f, &d[..f.data_len as usize]).unwrap(), r);
        }
    }

    #[test]
    fn golden_write_of_alias_word() {
        let req = EepromRequest {
            slave: 2,
            access: EepromAccess::Write { address: 0x0004, value: 0x1234 },
            timeout_us: 10_000,
        };
        let (_, d) = request_round_trip(&req);
        assert_eq!(&d[..12], &[1, 0, 2, 0, 4, 0, 0x34, 0x12, 0x10, 0x27, 0, 0]);
    }

    #[test]
    fn rejects_bad_op_and_slave() {
        let mut d = [0u8; 12];
        d[0] = 2;
        assert_eq!(
            EepromRequest::decode(&RequestFields { data_len: 12, ..RequestFields::default() }, &d),
            Err(PayloadError::InvalidValue { field: "EEPROM operation", value: 2 })
        );
        assert!(
            EepromRequest { slave: 128, access: EepromAccess::Read { address: 0 }, timeout_us: 0 }
                .encode(&mut [0; 32])
                .is_err()
        );
        assert_eq!(EepromReply { error: 0, data: &[0x34] }.word(), None);
        assert_eq!(EepromReply { error: 0, data: &[0x34, 0x12, 0, 0] }.word(), Some(0x1234));
    }
}
