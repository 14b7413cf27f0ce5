//! File access over EtherCAT: FOE_FUNC_REQ (139) and FOE_FUNC_GET (140).
//!
//! The chip stages files in its own flash (offsets 0..0x40000): a download
//! first writes the file into flash in chunks of at most 256 bytes (op 4),
//! then sends it to the slave (op 2); an upload reads the file from the slave
//! into flash (op 1), then reads it back in chunks (op 3 + FOE_FUNC_GET).
//!
//! Layout (v049):
//!
//! | off | len | upload/download (op 1/2) | flash read/write (op 3/4) |
//! | --- | --- | --- | --- |
//! | 0 | 1 | slave | reserved |
//! | 1 | 1 | reserved | reserved |
//! | 2 | 1 | op | op |
//! | 3 | 1 | reserved | reserved |
//! | 4 | 4 | FoE password | reserved |
//! | 8 | 4 | file length | chunk length n (<= 256) |
//! | 12 | 4 | timeout, us | reserved |
//! | 16 | 4 | flash offset | flash offset |
//! | 20 | n | file name | data (write only) |

use crate::CommandCode;
use crate::bytes::{Reader, Writer, check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Reply, ReplyFields, Request, RequestFields, bare_request, valid};

/// The chip's staging flash size.
pub const FOE_FLASH_SIZE: u32 = 0x40000;
/// Largest flash chunk.
pub const FOE_MAX_CHUNK: u32 = 256;
/// Bytes before the name or data.
pub const FOE_HEADER_LEN: usize = 20;

/// A file transfer between a slave and the chip's staging flash.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FoeTransfer<'a> {
    /// Slave position 0..=127.
    pub slave: u8,
    /// FoE password (0 when none).
    pub password: u32,
    /// File length in bytes (download: what was staged; upload: the most to
    /// read).
    pub file_length: u32,
    /// Timeout in us.
    pub timeout_us: u32,
    /// Where the file sits in the staging flash.
    pub flash_offset: u32,
    /// File name bytes.
    pub name: &'a [u8],
}

/// FOE_FUNC_REQ (139) operations (blocking).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FoeRequest<'a> {
    /// Op 1: read a file from the slave into the staging flash.
    Upload(FoeTransfer<'a>),
    /// Op 2: write a staged file to the slave.
    Download(FoeTransfer<'a>),
    /// Op 3: read n bytes of staging flash (fetch with FOE_FUNC_GET).
    ReadFlash {
        /// Flash offset.
        offset: u32,
        /// Bytes, <= 256.
        length: u16,
    },
    /// Op 4: write bytes (<= 256) into staging flash.
    WriteFlash {
        /// Flash offset.
        offset: u32,
        /// The bytes.
        data: &'a [u8],
    },
}

fn check_offset(offset: u32, len: u32) -> Result<(), EncodeError> {
    check_range("flash offset", offset, 0, FOE_FLASH_SIZE - 1)?;
    check_range("flash end", offset.saturating_add(len), 0, FOE_FLASH_SIZE)
}

impl<'a> Request<'a> for FoeRequest<'a> {
    const CODE: CommandCode = CommandCode::FoeReq;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, out: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let mut w = Writer::new(out);
        match *self {
            Self::Upload(t) | Self::Download(t) => {
                check_range("slave", t.slave.into(), 0, 127)?;
                check_offset(t.flash_offset, 0)?;
                let op = if matches!(self, Self::Upload(_)) { 1 } else { 2 };
                w.bytes(&[t.slave, 0, op, 0])?;
                w.u32(t.password)?;
                w.u32(t.file_length)?;
                w.u32(t.timeout_us)?;
                w.u32(t.flash_offset)?;
                w.bytes(t.name)?;
            }
            Self::ReadFlash { offset, length } => {
                check_range("flash chunk", length.into(), 0, FOE_MAX_CHUNK)?;
                check_offset(offset, length.into())?;
                w.bytes(&[0, 0, 3, 0])?;
                w.u32(0)?;
                w.u32(length.into())?;
                w.u32(0)?;
                w.u32(offset)?;
            }
            Self::WriteFlash { offset, data } => {
                check_range("flash chunk", data.len() as u32, 0, FOE_MAX_CHUNK)?;
                check_offset(offset, data.len() as u32)?;
                w.bytes(&[0, 0, 4, 0])?;
                w.u32(0)?;
                w.u32(data.len() as u32)?;
                w.u32(0)?;
                w.u32(offset)?;
                w.bytes(data)?;
            }
        }
        Ok(RequestFields { data_len: w.len_u16(), ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        let body = valid("FoE request", data, fields.data_len.into())?;
        let mut r = Reader::new(body);
        let [slave, _, op, _] = r.array::<4>("FoE op")?;
        let password = r.u32("FoE password")?;
        let length = r.u32("FoE length")?;
        let timeout_us = r.u32("FoE timeout")?;
        let offset = r.u32("flash offset")?;
        expect_range("flash offset", offset, 0, FOE_FLASH_SIZE - 1)?;
        let rest = r.rest();
        Ok(match op {
            1 | 2 => {
                expect_range("slave", slave.into(), 0, 127)?;
                let t =
                    FoeTransfer { slave, password, file_length: length, timeout_us, flash_offset: offset, name: rest };
                if op == 1 { Self::Upload(t) } else { Self::Download(t) }
            }
            3 => {
                expect_range("flash chunk", length, 0, FOE_MAX_CHUNK)?;
                expect_range("flash end", offset + length, 0, FOE_FLASH_SIZE)?;
                Self::ReadFlash { offset, length: length as u16 }
            }
            4 => {
                expect_range("flash chunk", length, 0, FOE_MAX_CHUNK)?;
                expect_range("flash end", offset + length, 0, FOE_FLASH_SIZE)?;
                if rest.len() != length as usize {
                    return Err(PayloadError::InvalidValue { field: "flash write length", value: rest.len() as u32 });
                }
                Self::WriteFlash { offset, data: rest }
            }
            v => return Err(PayloadError::InvalidValue { field: "FoE op", value: v.into() }),
        })
    }
}

bare_request! {
    /// FOE_FUNC_GET (140): the bytes of the last flash read.
    FoeGet => FoeGet -> FoeReply<'r>;
}

/// FOE_FUNC_GET's reply: n bytes of staging flash.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct FoeReply<'a>(pub &'a [u8]);

impl<'a> Reply<'a> for FoeReply<'a> {
    const CODE: CommandCode = CommandCode::FoeGet;

    fn encode(&self, out: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(out);
        w.bytes(self.0)?;
        Ok(ReplyFields { value: 0, data_len: w.len_u16() })
    }

    fn decode(_fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self(data))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn round_trip(req: &FoeRequest<'_>) -> RequestFields {
        let mut d = [0u8; 1408];
        let f = req.encode(&mut d).unwrap();
        assert_eq!(&FoeRequest::decode(&f, &d).unwrap(), req);
        f
    }

    proptest! {
        #[test]
        fn transfers_round_trip(
            slave in 0u8..=127, pw: u32, len: u32, t: u32, off in 0u32..0x40000,
            name in proptest::collection::vec(any::<u8>(), 0..64), up: bool,
        ) {
            let tr = FoeTransfer { slave, password: pw, file_length: len, timeout_us: t, flash_offset: off, name: &name };
            let f = round_trip(&if up { FoeRequest::Upload(tr) } else { FoeRequest::Download(tr) });
            prop_assert_eq!(usize::from(f.data_len), 20 + name.len());
        }

        #[test]
        fn flash_ops_round_trip(off in 0u32..0x3FF00, bytes in proptest::collection::vec(any::<u8>(), 0..=256)) {
            round_trip(&FoeRequest::WriteFlash { offset: off, data: &bytes });
            round_trip(&FoeRequest::ReadFlash { offset: off, length: bytes.len() as u16 });
            let mut d = [0u8; 1408];
            let f = FoeReply(&bytes).encode(&mut d).unwrap();
            prop_assert_eq!(FoeReply::decode(&f, &d[..f.data_len as usize]).unwrap(), FoeReply(&bytes));
        }
    }

    #[test]
    fn golden_download_and_limits() {
        let tr = FoeTransfer {
            slave: 1,
            password: 0,
            file_length: 1000,
            timeout_us: 5_000_000,
            flash_offset: 0x100,
            name: b"fw.bin",
        };
        let mut d = [0u8; 112];
        let f = FoeRequest::Download(tr).encode(&mut d).unwrap();
        assert_eq!(f.data_len, 26);
        assert_eq!(
            &d[..26],
            &[
                1, 0, 2, 0, 0, 0, 0, 0, 0xE8, 3, 0, 0, 0x40, 0x4B, 0x4C, 0, 0, 1, 0, 0, b'f', b'w', b'.', b'b', b'i',
                b'n'
            ]
        );
        assert!(FoeRequest::WriteFlash { offset: 0, data: &[0; 257] }.encode(&mut [0; 1408]).is_err());
        assert!(FoeRequest::ReadFlash { offset: 0x3FFFF, length: 2 }.encode(&mut [0; 1408]).is_err());
        assert!(FoeRequest::ReadFlash { offset: 0x40000, length: 0 }.encode(&mut [0; 1408]).is_err());
        d[2] = 9;
        assert!(FoeRequest::decode(&f, &d).is_err());
    }
}
