//! CoE SDO access: SDO_REQ (10), SDO_GET (11), SDO_ABORTCODE_GET (69).
//!
//! SDO_REQ's layout comes from v031 (v049's text of it is cut short):
//!
//! | off | len | field |
//! | --- | --- | --- |
//! | 0x00 | 1 | operation: 0 write (download), 1 read (upload) |
//! | 0x01 | 1 | slave 0..=127 |
//! | 0x02 | 2 | object index |
//! | 0x04 | 1 | subindex |
//! | 0x05 | 1 | complete access flag (v031: "reserved"; the vendor driver uses it) |
//! | 0x06 | 2 | data length: bytes written, or bytes expected back |
//! | 0x08 | 4 | timeout in us (v049 revision 035 fixed the unit; v031 said ns) |
//! | 0x0C | n | bytes to write |
//!
//! The header's data length is 12 for a read and 12 + n for a write. v031's
//! table puts the data at "0x12": a typo for 12, as its drawing shows.

use core::fmt;

use crate::CommandCode;
use crate::bytes::{Reader, Writer, check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Reply, ReplyFields, Request, RequestFields, bare_request};

/// Bytes of SDO_REQ before the write data.
pub const SDO_REQ_HEADER_LEN: usize = 12;

/// Upload or download, and the data involved.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SdoAccess<'a> {
    /// Upload: read at most `max_len` bytes (fetch them with SDO_GET).
    Read {
        /// Bytes expected back.
        max_len: u16,
    },
    /// Download: write these bytes.
    Write(&'a [u8]),
}

/// SDO_REQ (10): one SDO upload or download (blocking).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SdoRequest<'a> {
    /// Slave position 0..=127.
    pub slave: u8,
    /// Object index.
    pub index: u16,
    /// Subindex (with complete access: 0 or 1, where to start).
    pub subindex: u8,
    /// Complete access: the whole object in one transfer.
    pub complete_access: bool,
    /// How long the chip waits for the slave, in microseconds.
    pub timeout_us: u32,
    /// Read or write.
    pub access: SdoAccess<'a>,
}

impl<'a> Request<'a> for SdoRequest<'a> {
    const CODE: CommandCode = CommandCode::SdoReq;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        check_range("slave", self.slave.into(), 0, 127)?;
        let mut w = Writer::new(data);
        let (op, len, bytes): (u8, u16, &[u8]) = match self.access {
            SdoAccess::Read { max_len } => (1, max_len, &[]),
            SdoAccess::Write(bytes) => {
                check_range("SDO write length", bytes.len() as u32, 0, u32::from(u16::MAX))?;
                (0, bytes.len() as u16, bytes)
            }
        };
        w.u8(op)?;
        w.u8(self.slave)?;
        w.u16(self.index)?;
        w.u8(self.subindex)?;
        w.u8(u8::from(self.complete_access))?;
        w.u16(len)?;
        w.u32(self.timeout_us)?;
        w.bytes(bytes)?;
        Ok(RequestFields { data_len: w.len_u16(), ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(data);
        let op = r.u8("SDO operation")?;
        let slave = r.u8("slave")?;
        expect_range("slave", slave.into(), 0, 127)?;
        let index = r.u16("SDO index")?;
        let subindex = r.u8("SDO subindex")?;
        let ca = r.u8("SDO complete access")?;
        expect_range("SDO complete access", ca.into(), 0, 1)?;
        let len = r.u16("SDO data length")?;
        let timeout_us = r.u32("SDO timeout")?;
        let access = match op {
            0 => {
                let declared = SDO_REQ_HEADER_LEN + usize::from(len);
                let declared = u16::try_from(declared)
                    .map_err(|_| PayloadError::InvalidValue { field: "SDO data length", value: len.into() })?;
                crate::payload::fixed_len(fields, Self::CODE, declared)?;
                SdoAccess::Write(r.bytes("SDO write data", len.into())?)
            }
            1 => {
                crate::payload::fixed_len(fields, Self::CODE, SDO_REQ_HEADER_LEN as u16)?;
                SdoAccess::Read { max_len: len }
            }
            v => return Err(PayloadError::InvalidValue { field: "SDO operation", value: v.into() }),
        };
        Ok(Self { slave, index, subindex, complete_access: ca == 1, timeout_us, access })
    }
}

bare_request! {
    /// SDO_GET (11): fetch the data of the last SDO read.
    SdoGet => SdoGet -> SdoGetReply<'r>;
    /// SDO_ABORTCODE_GET (69): the abort code of the last failed SDO.
    SdoAbortCodeGet => SdoAbortCodeGet -> SdoAbortReply;
}

/// SDO_GET's reply: the bytes read (data length = their count). The return
/// value's meaning is not documented; it is kept raw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct SdoGetReply<'a> {
    /// Return value byte.
    pub status: u8,
    /// The object's bytes.
    pub data: &'a [u8],
}

impl<'a> Reply<'a> for SdoGetReply<'a> {
    const CODE: CommandCode = CommandCode::SdoGet;

    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(data);
        w.bytes(self.data)?;
        Ok(ReplyFields { value: self.status, data_len: w.len_u16() })
    }

    fn decode(fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self { status: fields.value, data })
    }
}

/// A CoE SDO abort code (ETG.1000.6 Table 41; the list in v049 under
/// SDO_ABORTCODE_GET). Any u32 is kept; known ones have a meaning.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct SdoAbortCode(pub u32);

macro_rules! abort_codes {
    ($($name:ident = $v:literal, $text:literal;)*) => {
        impl SdoAbortCode {
            $(#[doc = $text] pub const $name: Self = Self($v);)*

            /// Every code with a known meaning.
            pub const KNOWN: &'static [SdoAbortCode] = &[$(Self::$name,)*];

            /// The ETG meaning, if the code is a listed one.
            pub const fn meaning(self) -> Option<&'static str> {
                match self.0 {
                    $($v => Some($text),)*
                    _ => None,
                }
            }
        }
    };
}

abort_codes! {
    NONE = 0x0000_0000, "no SDO error";
    TOGGLE_BIT = 0x0503_0000, "toggle bit not changed";
    TIMEOUT = 0x0504_0000, "SDO protocol timeout";
    COMMAND_SPECIFIER = 0x0504_0001, "client/server command specifier not valid or unknown";
    INVALID_BLOCK_SIZE = 0x0504_0002, "invalid block size";
    INVALID_SEQUENCE = 0x0504_0003, "invalid sequence number";
    CRC = 0x0504_0004, "CRC error";
    OUT_OF_MEMORY = 0x0504_0005, "out of memory";
    UNSUPPORTED_ACCESS = 0x0601_0000, "unsupported access to an object";
    WRITE_ONLY = 0x0601_0001, "attempt to read a write-only object";
    READ_ONLY = 0x0601_0002, "attempt to write a read-only object";
    SUBINDEX0_NOT_ZERO = 0x0601_0003, "subindex cannot be written, subindex 0 must be 0 for write access";
    NO_COMPLETE_ACCESS = 0x0601_0004, "object does not support complete access";
    OBJECT_TOO_LONG = 0x0601_0005, "object length exceeds mailbox size";
    MAPPED_TO_RXPDO = 0x0601_0006, "object mapped to RxPDO, SDO download blocked";
    OBJECT_MISSING = 0x0602_0000, "object does not exist in the object dictionary";
    NOT_MAPPABLE = 0x0604_0041, "object cannot be mapped into the PDO";
    PDO_TOO_LONG = 0x0604_0042, "number and length of mapped objects exceed the PDO length";
    INCOMPATIBLE_PARAMETER = 0x0604_0043, "general parameter incompatibility";
    INCOMPATIBLE_DEVICE = 0x0604_0047, "general internal incompatibility in the device";
    HARDWARE = 0x0606_0000, "access failed due to a hardware error";
    LENGTH_MISMATCH = 0x0607_0010, "data type does not match, length of service parameter does not match";
    LENGTH_TOO_HIGH = 0x0607_0012, "data type does not match, length of service parameter too high";
    LENGTH_TOO_LOW = 0x0607_0013, "data type does not match, length of service parameter too low";
    SUBINDEX_MISSING = 0x0609_0011, "subindex does not exist";
    VALUE_RANGE = 0x0609_0030, "value range of parameter exceeded (write access only)";
    VALUE_TOO_HIGH = 0x0609_0031, "value of parameter written too high";
    VALUE_TOO_LOW = 0x0609_0032, "value of parameter written too low";
    MODULE_IDENT_MISMATCH = 0x0609_0033, "detected module ident list (0xF030) and configured module ident list (0xF050) do not match";
    VALUE_BELOW_MINIMUM = 0x0609_0036, "value is less than minimum value";
    GENERAL = 0x0800_0000, "general error";
    TRANSFER = 0x0800_0020, "data cannot be transferred or stored to the application";
    LOCAL_CONTROL = 0x0800_0021, "data cannot be transferred or stored because of local control";
    WRONG_STATE = 0x0800_0022, "data cannot be transferred or stored in the present device state";
    NO_DICTIONARY = 0x0800_0023, "object dictionary dynamic generation failed or no object dictionary present";
}

impl fmt::Debug for SdoAbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "SdoAbortCode({:#010x})", self.0)
    }
}

impl fmt::Display for SdoAbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.meaning() {
            Some(m) => write!(f, "{:#010x} ({m})", self.0),
            None => write!(f, "{:#010x} (unknown abort code)", self.0),
        }
    }
}

/// SDO_ABORTCODE_GET's reply: 4 bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct SdoAbortReply(pub SdoAbortCode);

impl<'a> Reply<'a> for SdoAbortReply {
    const CODE: CommandCode = CommandCode::SdoAbortCodeGet;

    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(data);
        w.u32(self.0.0)?;
        Ok(ReplyFields { value: 0, data_len: w.len_u16() })
    }

    fn decode(_fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self(SdoAbortCode(Reader::new(data).u32("SDO abort code")?)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::reply_round_trip;
    use proptest::prelude::*;
    use std::format;

    proptest! {
        #[test]
        fn sdo_request_round_trips(
            slave in 0u8..=127, index: u16, subindex: u8, ca: bool, timeout: u32,
            read: bool, max_len: u16, bytes in proptest::collection::vec(any::<u8>(), 0..=1396),
        ) {
            let access = if read { SdoAccess::Read { max_len } } else { SdoAccess::Write(&bytes) };
            let req = SdoRequest { slave, index, subindex, complete_access: ca, timeout_us: timeout, access };
            let mut data = [0u8; 1408];
            let f = req.encode(&mut data).unwrap();
            let expect_len = if read { 12 } else { 12 + bytes.len() };
            prop_assert_eq!(usize::from(f.data_len), expect_len);
            prop_assert_eq!(SdoRequest::decode(&f, &data).unwrap(), req);
        }

        #[test]
        fn sdo_get_reply_round_trips(status: u8, bytes in proptest::collection::vec(any::<u8>(), 0..=1408)) {
            let r = SdoGetReply { status, data: &bytes };
            let mut data = [0u8; 1408];
            let f = r.encode(&mut data).unwrap();
            prop_assert_eq!(SdoGetReply::decode(&f, &data[..f.data_len as usize]).unwrap(), r);
        }

        #[test]
        fn abort_reply_round_trips(code: u32) {
            reply_round_trip(&SdoAbortReply(SdoAbortCode(code)));
        }
    }

    /// An SDO read of 0x6041:00 (statusword) from slave 1, timeout 100 ms,
    /// written out by hand from the v031 table.
    #[test]
    fn sdo_read_golden() {
        let req = SdoRequest {
            slave: 1,
            index: 0x6041,
            subindex: 0,
            complete_access: false,
            timeout_us: 100_000,
            access: SdoAccess::Read { max_len: 2 },
        };
        let mut data = [0u8; 112];
        let f = req.encode(&mut data).unwrap();
        assert_eq!(f.data_len, 12);
        assert_eq!(&data[..12], &[0x01, 0x01, 0x41, 0x60, 0x00, 0x00, 0x02, 0x00, 0xA0, 0x86, 0x01, 0x00]);
    }

    #[test]
    fn sdo_write_complete_access_golden() {
        let payload = [0x02, 0x00, 0x10, 0x16, 0x11, 0x16];
        let req = SdoRequest {
            slave: 3,
            index: 0x1C12,
            subindex: 0,
            complete_access: true,
            timeout_us: 0x0102_0304,
            access: SdoAccess::Write(&payload),
        };
        let mut data = [0u8; 112];
        let f = req.encode(&mut data).unwrap();
        assert_eq!(f.data_len, 18);
        assert_eq!(
            &data[..18],
            &[
                0x00, 0x03, 0x12, 0x1C, 0x00, 0x01, 0x06, 0x00, 0x04, 0x03, 0x02, 0x01, 0x02, 0x00, 0x10, 0x16, 0x11,
                0x16
            ]
        );
    }

    #[test]
    fn sdo_decode_rejects_inconsistent_lengths_and_ops() {
        let mut data = [0u8; 112];
        let req = SdoRequest {
            slave: 0,
            index: 1,
            subindex: 0,
            complete_access: false,
            timeout_us: 0,
            access: SdoAccess::Write(&[1, 2]),
        };
        let mut f = req.encode(&mut data).unwrap();
        f.data_len = 13;
        assert_eq!(
            SdoRequest::decode(&f, &data),
            Err(PayloadError::DataLength { command: CommandCode::SdoReq, expected: 14, found: 13 })
        );
        f.data_len = 14;
        data[0] = 2;
        assert_eq!(SdoRequest::decode(&f, &data), Err(PayloadError::InvalidValue { field: "SDO operation", value: 2 }));
        data[0] = 0;
        data[5] = 7;
        assert!(SdoRequest::decode(&f, &data).is_err());
        data[5] = 0;
        data[1] = 128;
        assert!(SdoRequest::decode(&f, &data).is_err());
    }

    #[test]
    fn write_too_large_for_section() {
        let bytes = [0u8; 101];
        let req = SdoRequest {
            slave: 0,
            index: 1,
            subindex: 0,
            complete_access: false,
            timeout_us: 0,
            access: SdoAccess::Write(&bytes),
        };
        assert_eq!(req.encode(&mut [0u8; 112]), Err(EncodeError::PayloadTooLarge { needed: 113, capacity: 112 }));
    }

    #[test]
    fn abort_codes_have_their_etg_meaning() {
        assert_eq!(SdoAbortCode(0x0602_0000).meaning(), Some("object does not exist in the object dictionary"));
        assert_eq!(SdoAbortCode::READ_ONLY.0, 0x0601_0002);
        assert_eq!(SdoAbortCode(0x1234_5678).meaning(), None);
        assert_eq!(format!("{}", SdoAbortCode::SUBINDEX_MISSING), "0x06090011 (subindex does not exist)");
        // Every code the v049 manual lists is known.
        for c in [
            0x0000_0000u32,
            0x0503_0000,
            0x0504_0000,
            0x0504_0001,
            0x0504_0005,
            0x0601_0000,
            0x0601_0001,
            0x0601_0002,
            0x0601_0003,
            0x0601_0004,
            0x0602_0000,
            0x0604_0041,
            0x0604_0042,
            0x0604_0043,
            0x0604_0047,
            0x0606_0000,
            0x0607_0010,
            0x0607_0012,
            0x0607_0013,
            0x0609_0011,
            0x0609_0030,
            0x0609_0031,
            0x0609_0032,
            0x0609_0033,
            0x0609_0036,
            0x0800_0000,
            0x0800_0020,
            0x0800_0021,
            0x0800_0022,
            0x0800_0023,
        ] {
            assert!(SdoAbortCode(c).meaning().is_some(), "{c:#x}");
        }
        let mut seen = std::collections::HashSet::new();
        assert!(SdoAbortCode::KNOWN.iter().all(|c| seen.insert(c.0)), "duplicate code");
    }
}
