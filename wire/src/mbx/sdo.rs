//! SDO transfers in a mailbox (ETG.1000.6 5.6.2, CiA 301 7.2.4.3): the
//! initiate request and response of an upload or a download, expedited (up
//! to four bytes in the message itself) or normal (the size, then the data,
//! all in one message), and the abort. What a mailbox gateway client sends
//! to a slave, and what the simulator's slaves answer. Segmented transfers
//! (objects larger than a mailbox) are not written here; a slave reading
//! one as a request answers it with an abort.
//!
//! The command byte: bits 5..7 the command specifier (request: 1 download
//! initiate, 2 upload initiate; response: 3 download, 2 upload; 4 abort),
//! bit 4 complete access, bit 1 expedited, bit 0 size indicated, bits 2..3
//! for an expedited transfer the count of the four data bytes not used.

use crate::bytes::{Reader, Writer};
use crate::error::{EncodeError, PayloadError};
use crate::mbx::coe::{COE_HEADER_LEN, CoeHeader, CoeService};

/// Bytes of an initiate message after the CoE header: command, index,
/// subindex, four data (or size) bytes.
pub const SDO_INITIATE_LEN: usize = 8;

/// An SDO request a master sends.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SdoRequest<'a> {
    /// Write `data` to the object.
    Download {
        /// Object index.
        index: u16,
        /// Subindex.
        subindex: u8,
        /// The whole object from `subindex` on.
        complete_access: bool,
        /// The bytes.
        data: &'a [u8],
    },
    /// Read the object.
    Upload {
        /// Object index.
        index: u16,
        /// Subindex.
        subindex: u8,
        /// The whole object from `subindex` on.
        complete_access: bool,
    },
}

/// What a slave answers to an [`SdoRequest`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SdoResponse<'a> {
    /// The object's bytes.
    Uploaded {
        /// Object index.
        index: u16,
        /// Subindex.
        subindex: u8,
        /// Complete access.
        complete_access: bool,
        /// The bytes.
        data: &'a [u8],
    },
    /// The write was taken.
    Downloaded {
        /// Object index.
        index: u16,
        /// Subindex.
        subindex: u8,
    },
    /// The transfer was aborted (ETG.1000.6 Table 41 codes).
    Abort {
        /// Object index.
        index: u16,
        /// Subindex.
        subindex: u8,
        /// The abort code.
        code: u32,
    },
}

const DOWNLOAD_INITIATE: u8 = 1 << 5;
const UPLOAD_INITIATE: u8 = 2 << 5;
const DOWNLOAD_RESPONSE: u8 = 3 << 5;
const ABORT: u8 = 4 << 5;
const COMPLETE: u8 = 1 << 4;
const EXPEDITED: u8 = 1 << 1;
const SIZE: u8 = 1 << 0;

fn command(cmd: u8, complete: bool) -> u8 {
    cmd | if complete { COMPLETE } else { 0 }
}

/// Writes CoE header `service`, then the command, index and subindex.
fn initiate(w: &mut Writer<'_>, service: CoeService, cmd: u8, index: u16, subindex: u8) -> Result<(), EncodeError> {
    w.bytes(&CoeHeader::of(service).to_bytes())?;
    w.u8(cmd)?;
    w.u16(index)?;
    w.u8(subindex)
}

/// Writes data expedited (padded to four bytes) when it fits and no
/// complete access asks for more, else as size + bytes.
fn data_part(w: &mut Writer<'_>, base: u8, complete: bool, data: &[u8]) -> Result<u8, EncodeError> {
    if data.len() <= 4 && !data.is_empty() && !complete {
        let mut four = [0u8; 4];
        four[..data.len()].copy_from_slice(data);
        w.bytes(&four)?;
        Ok(base | EXPEDITED | SIZE | ((4 - data.len() as u8) << 2))
    } else {
        w.u32(data.len() as u32)?;
        w.bytes(data)?;
        Ok(command(base, complete) | SIZE)
    }
}

/// Reads the data of an initiate message with command byte `cmd`.
fn read_data<'a>(r: &mut Reader<'a>, cmd: u8) -> Result<&'a [u8], PayloadError> {
    if cmd & EXPEDITED != 0 {
        let four = r.bytes("SDO data", 4)?;
        let unused = if cmd & SIZE != 0 { usize::from((cmd >> 2) & 0x03) } else { 0 };
        Ok(&four[..4 - unused])
    } else {
        let size = r.u32("SDO size")? as usize;
        let rest = r.rest();
        rest.get(..size).ok_or(PayloadError::TooShort { field: "SDO data", needed: size, available: rest.len() })
    }
}

fn expect_service(r: &mut Reader<'_>, want: CoeService) -> Result<(), PayloadError> {
    let header = CoeHeader::decode(r.bytes("CoE header", COE_HEADER_LEN)?)?;
    if header.service != want {
        return Err(PayloadError::InvalidValue { field: "CoE service", value: header.service.code().into() });
    }
    Ok(())
}

impl<'a> SdoRequest<'a> {
    /// Writes the CoE body; returns its length.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let mut w = Writer::new(out);
        match *self {
            Self::Upload { index, subindex, complete_access } => {
                initiate(&mut w, CoeService::SdoRequest, command(UPLOAD_INITIATE, complete_access), index, subindex)?;
                w.u32(0)?;
                Ok(usize::from(w.len_u16()))
            }
            Self::Download { index, subindex, complete_access, data } => {
                // The command byte depends on the data: written last.
                initiate(&mut w, CoeService::SdoRequest, 0, index, subindex)?;
                let cmd = data_part(&mut w, DOWNLOAD_INITIATE, complete_access, data)?;
                let n = usize::from(w.len_u16());
                out[COE_HEADER_LEN] = cmd;
                Ok(n)
            }
        }
    }

    /// Reads a CoE body. A segment request or an abort is refused as an
    /// unknown command specifier (what a slave aborts with 0x05040001).
    pub fn decode(body: &'a [u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(body);
        expect_service(&mut r, CoeService::SdoRequest)?;
        let cmd = r.u8("SDO command")?;
        let (index, subindex) = (r.u16("SDO index")?, r.u8("SDO subindex")?);
        let complete_access = cmd & COMPLETE != 0;
        match cmd & 0xE0 {
            UPLOAD_INITIATE => Ok(Self::Upload { index, subindex, complete_access }),
            DOWNLOAD_INITIATE => Ok(Self::Download { index, subindex, complete_access, data: read_data(&mut r, cmd)? }),
            other => Err(PayloadError::InvalidValue { field: "SDO command specifier", value: u32::from(other >> 5) }),
        }
    }
}

impl<'a> SdoResponse<'a> {
    /// Writes the CoE body; returns its length.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let mut w = Writer::new(out);
        match *self {
            Self::Downloaded { index, subindex } => {
                initiate(&mut w, CoeService::SdoResponse, DOWNLOAD_RESPONSE, index, subindex)?;
                w.u32(0)?;
            }
            Self::Abort { index, subindex, code } => {
                initiate(&mut w, CoeService::SdoRequest, ABORT, index, subindex)?;
                w.u32(code)?;
            }
            Self::Uploaded { index, subindex, complete_access, data } => {
                initiate(&mut w, CoeService::SdoResponse, 0, index, subindex)?;
                let cmd = data_part(&mut w, UPLOAD_INITIATE, complete_access, data)?;
                let n = usize::from(w.len_u16());
                out[COE_HEADER_LEN] = cmd;
                return Ok(n);
            }
        }
        Ok(usize::from(w.len_u16()))
    }

    /// Reads a CoE body (an abort comes as an SDO request or response,
    /// ETG.1000.6 Table 40).
    pub fn decode(body: &'a [u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(body);
        let header = CoeHeader::decode(r.bytes("CoE header", COE_HEADER_LEN)?)?;
        let cmd = r.u8("SDO command")?;
        let (index, subindex) = (r.u16("SDO index")?, r.u8("SDO subindex")?);
        match (header.service, cmd & 0xE0) {
            (CoeService::SdoRequest | CoeService::SdoResponse, ABORT) => {
                Ok(Self::Abort { index, subindex, code: r.u32("SDO abort code")? })
            }
            (CoeService::SdoResponse, DOWNLOAD_RESPONSE) => Ok(Self::Downloaded { index, subindex }),
            (CoeService::SdoResponse, UPLOAD_INITIATE) => Ok(Self::Uploaded {
                index,
                subindex,
                complete_access: cmd & COMPLETE != 0,
                data: read_data(&mut r, cmd)?,
            }),
            (CoeService::SdoResponse, other) => {
                Err(PayloadError::InvalidValue { field: "SDO command specifier", value: u32::from(other >> 5) })
            }
            (service, _) => Err(PayloadError::InvalidValue { field: "CoE service", value: service.code().into() }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn requests_round_trip(index: u16, subindex: u8, complete_access: bool, upload: bool,
                               data in proptest::collection::vec(any::<u8>(), 1..40)) {
            let r = if upload {
                SdoRequest::Upload { index, subindex, complete_access }
            } else {
                SdoRequest::Download { index, subindex, complete_access, data: &data }
            };
            let mut b = [0u8; 64];
            let n = r.encode(&mut b).unwrap();
            prop_assert_eq!(SdoRequest::decode(&b[..n]).unwrap(), r);
        }

        #[test]
        fn responses_round_trip(index: u16, subindex: u8, complete_access: bool, kind in 0u8..3, code: u32,
                                data in proptest::collection::vec(any::<u8>(), 1..40)) {
            let r = match kind {
                0 => SdoResponse::Uploaded { index, subindex, complete_access, data: &data },
                1 => SdoResponse::Downloaded { index, subindex },
                _ => SdoResponse::Abort { index, subindex, code },
            };
            let mut b = [0u8; 64];
            let n = r.encode(&mut b).unwrap();
            prop_assert_eq!(SdoResponse::decode(&b[..n]).unwrap(), r);
        }

        #[test]
        fn decoding_arbitrary_bytes_never_panics(data in proptest::collection::vec(any::<u8>(), 0..24)) {
            let _ = SdoRequest::decode(&data);
            let _ = SdoResponse::decode(&data);
        }
    }

    #[test]
    fn golden_expedited_messages() {
        // Upload 0x1018:01 (CiA 301: 0x40, index LE, subindex, 4 zero bytes).
        let mut b = [0u8; 16];
        let n = SdoRequest::Upload { index: 0x1018, subindex: 1, complete_access: false }.encode(&mut b).unwrap();
        assert_eq!(&b[..n], &[0x00, 0x20, 0x40, 0x18, 0x10, 0x01, 0, 0, 0, 0]);
        // Its answer: 4 bytes expedited, 0x43.
        let n = SdoResponse::Uploaded { index: 0x1018, subindex: 1, complete_access: false, data: &[2, 0, 0, 0] }
            .encode(&mut b)
            .unwrap();
        assert_eq!(&b[..n], &[0x00, 0x30, 0x43, 0x18, 0x10, 0x01, 2, 0, 0, 0]);
        // Download of one byte: 0x2F.
        let n = SdoRequest::Download { index: 0x6060, subindex: 0, complete_access: false, data: &[8] }
            .encode(&mut b)
            .unwrap();
        assert_eq!(&b[..n], &[0x00, 0x20, 0x2F, 0x60, 0x60, 0x00, 8, 0, 0, 0]);
        // An abort: 0x80 and the code.
        let n = SdoResponse::Abort { index: 0x6060, subindex: 0, code: 0x0602_0000 }.encode(&mut b).unwrap();
        assert_eq!(&b[..n], &[0x00, 0x20, 0x80, 0x60, 0x60, 0x00, 0x00, 0x00, 0x02, 0x06]);
    }
}
