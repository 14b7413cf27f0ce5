//! Raw EtherCAT datagrams: RAW_ECAT_FUNC_REQ (137) and RAW_ECAT_FUNC_GET
//! (138). Admin territory: any datagram against any slave's ESC.
//!
//! Layout (v049), request and answer alike:
//!
//! | off | len | field |
//! | --- | --- | --- |
//! | 0 | 1 | datagram command (opcode) |
//! | 1 | 1 | reserved |
//! | 2 | 2 | datagram data length n (<= 256) |
//! | 4 | 2 | ADP (position or station address) |
//! | 6 | 2 | ADO (register offset) |
//! | 8 | 4 | logical address (LRD/LWR/LRW) |
//! | 12 | 4 | timeout, us |
//! | 16 | 4 | reserved (request) / working counter (answer) |
//! | 20 | n | data |
//!
//! The manual gives the answer's data length as "4+n" beside a drawing that
//! puts the data at 20; we follow the drawing and slice by the length field.

use crate::CommandCode;
use crate::bytes::{Reader, Writer, check_range};
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Reply, ReplyFields, Request, RequestFields, bare_request};

/// Bytes before the datagram data.
pub const RAW_HEADER_LEN: usize = 20;
/// Largest datagram data.
pub const RAW_MAX_DATA: u16 = 256;

/// An EtherCAT datagram command (ETG.1000.4; the subset the manual lists).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DatagramCommand {
    /// 1: auto-increment physical read.
    Aprd,
    /// 2: auto-increment physical write.
    Apwr,
    /// 4: configured-address physical read.
    Fprd,
    /// 5: configured-address physical write.
    Fpwr,
    /// 7: broadcast read.
    Brd,
    /// 8: broadcast write.
    Bwr,
    /// 10: logical read.
    Lrd,
    /// 11: logical write.
    Lwr,
    /// 12: logical read-write.
    Lrw,
    /// 13: auto-increment read, multiple write.
    Armw,
    /// 14: configured read, multiple write.
    Frmw,
    /// Any other opcode, kept.
    Other(u8),
}

impl DatagramCommand {
    /// From the opcode.
    pub const fn from_u8(v: u8) -> Self {
        match v {
            1 => Self::Aprd,
            2 => Self::Apwr,
            4 => Self::Fprd,
            5 => Self::Fpwr,
            7 => Self::Brd,
            8 => Self::Bwr,
            10 => Self::Lrd,
            11 => Self::Lwr,
            12 => Self::Lrw,
            13 => Self::Armw,
            14 => Self::Frmw,
            o => Self::Other(o),
        }
    }

    /// To the opcode.
    pub const fn to_u8(self) -> u8 {
        match self {
            Self::Aprd => 1,
            Self::Apwr => 2,
            Self::Fprd => 4,
            Self::Fpwr => 5,
            Self::Brd => 7,
            Self::Bwr => 8,
            Self::Lrd => 10,
            Self::Lwr => 11,
            Self::Lrw => 12,
            Self::Armw => 13,
            Self::Frmw => 14,
            Self::Other(o) => o,
        }
    }

    /// Whether the datagram carries data to the slaves.
    pub const fn writes(self) -> bool {
        matches!(self, Self::Apwr | Self::Fpwr | Self::Bwr | Self::Lwr | Self::Lrw | Self::Armw | Self::Frmw)
    }
}

/// Addressing and size of a datagram (bytes 0..16 of both directions).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct DatagramHead {
    /// Command.
    pub command: DatagramCommand,
    /// Data length n.
    pub length: u16,
    /// Position (auto-increment) or station address.
    pub adp: u16,
    /// Register offset.
    pub ado: u16,
    /// Logical address, for LRD/LWR/LRW.
    pub logical: u32,
    /// Timeout in us.
    pub timeout_us: u32,
}

impl DatagramHead {
    fn write(&self, w: &mut Writer<'_>) -> Result<(), EncodeError> {
        check_range("datagram length", self.length.into(), 0, RAW_MAX_DATA.into())?;
        w.u8(self.command.to_u8())?;
        w.u8(0)?;
        w.u16(self.length)?;
        w.u16(self.adp)?;
        w.u16(self.ado)?;
        w.u32(self.logical)?;
        w.u32(self.timeout_us)
    }

    fn read(r: &mut Reader<'_>) -> Result<Self, PayloadError> {
        let command = DatagramCommand::from_u8(r.u8("datagram command")?);
        let _ = r.u8("reserved")?;
        let length = r.u16("datagram length")?;
        if length > RAW_MAX_DATA {
            return Err(PayloadError::InvalidValue { field: "datagram length", value: length.into() });
        }
        Ok(Self {
            command,
            length,
            adp: r.u16("ADP")?,
            ado: r.u16("ADO")?,
            logical: r.u32("logical address")?,
            timeout_us: r.u32("datagram timeout")?,
        })
    }
}

/// RAW_ECAT_FUNC_REQ (137): send a datagram (blocking; fetch the answer with
/// 138). `data` is what a write sends; a read sends `head.length` zero bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RawRequest<'a> {
    /// Addressing and size.
    pub head: DatagramHead,
    /// Data sent (its length must equal `head.length` for writes; empty
    /// for reads).
    pub data: &'a [u8],
}

impl<'a> Request<'a> for RawRequest<'a> {
    const CODE: CommandCode = CommandCode::RawEcatReq;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, out: &mut [u8]) -> Result<RequestFields, EncodeError> {
        if !self.data.is_empty() && self.data.len() != usize::from(self.head.length) {
            return Err(EncodeError::FieldOutOfRange {
                field: "datagram data length",
                value: self.data.len() as u32,
                min: self.head.length.into(),
                max: self.head.length.into(),
            });
        }
        let mut w = Writer::new(out);
        self.head.write(&mut w)?;
        w.u32(0)?;
        w.bytes(self.data)?;
        Ok(RequestFields { data_len: w.len_u16(), ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(data);
        let head = DatagramHead::read(&mut r)?;
        let _ = r.u32("reserved")?;
        let carried = usize::from(fields.data_len).saturating_sub(RAW_HEADER_LEN);
        let data = if carried == 0 { &[][..] } else { r.bytes("datagram data", usize::from(head.length))? };
        Ok(Self { head, data })
    }
}

bare_request! {
    /// RAW_ECAT_FUNC_GET (138): fetch the answer to 137.
    RawGet => RawEcatGet -> RawReply<'r>;
}

/// RAW_ECAT_FUNC_GET's reply: the datagram as it came back.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RawReply<'a> {
    /// Addressing and size, echoed.
    pub head: DatagramHead,
    /// Working counter.
    pub working_counter: u16,
    /// Data as it returned.
    pub data: &'a [u8],
}

impl<'a> Reply<'a> for RawReply<'a> {
    const CODE: CommandCode = CommandCode::RawEcatGet;

    fn encode(&self, out: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        check_range("datagram data length", self.data.len() as u32, self.head.length.into(), self.head.length.into())?;
        let mut w = Writer::new(out);
        self.head.write(&mut w)?;
        w.u16(self.working_counter)?;
        w.u16(0)?;
        w.bytes(self.data)?;
        Ok(ReplyFields { value: 0, data_len: w.len_u16() })
    }

    fn decode(_fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(data);
        let head = DatagramHead::read(&mut r)?;
        let working_counter = r.u16("working counter")?;
        let _ = r.u16("reserved")?;
        Ok(Self { head, working_counter, data: r.bytes("datagram data", head.length.into())? })
    }
}

/// The datagram's ETG.1000.4 name ("FPRD"), for messages.
impl core::fmt::Display for DatagramCommand {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let name = match self {
            Self::Aprd => "APRD",
            Self::Apwr => "APWR",
            Self::Fprd => "FPRD",
            Self::Fpwr => "FPWR",
            Self::Brd => "BRD",
            Self::Bwr => "BWR",
            Self::Lrd => "LRD",
            Self::Lwr => "LWR",
            Self::Lrw => "LRW",
            Self::Armw => "ARMW",
            Self::Frmw => "FRMW",
            Self::Other(v) => return write!(f, "datagram command {v}"),
        };
        f.write_str(name)
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::vec;

    fn head() -> impl Strategy<Value = DatagramHead> {
        (any::<u8>(), 0u16..=256, any::<u16>(), any::<u16>(), any::<u32>(), any::<u32>()).prop_map(
            |(c, length, adp, ado, logical, t)| DatagramHead {
                command: DatagramCommand::from_u8(c),
                length,
                adp,
                ado,
                logical,
                timeout_us: t,
            },
        )
    }

    proptest! {
        #[test]
        fn request_and_reply_round_trip(h in head(), write: bool, wkc: u16, seed: u8) {
            let len = h.length;
            let bytes = vec![seed; usize::from(len)];
            let req = RawRequest { head: h, data: if write { &bytes } else { &[] } };
            let mut d = [0u8; 1408];
            let f = req.encode(&mut d).unwrap();
            prop_assert_eq!(RawRequest::decode(&f, &d).unwrap(), req);
            let reply = RawReply { head: h, working_counter: wkc, data: &bytes };
            let mut d = [0u8; 1408];
            let f = reply.encode(&mut d).unwrap();
            prop_assert_eq!(usize::from(f.data_len), 20 + usize::from(len));
            prop_assert_eq!(RawReply::decode(&f, &d[..f.data_len as usize]).unwrap(), reply);
        }

        #[test]
        fn opcodes_round_trip(v: u8) {
            prop_assert_eq!(DatagramCommand::from_u8(v).to_u8(), v);
        }
    }

    #[test]
    fn golden_fprd_of_al_status() {
        let h = DatagramHead {
            command: DatagramCommand::Fprd,
            length: 2,
            adp: 0x1001,
            ado: 0x0130,
            logical: 0,
            timeout_us: 1000,
        };
        let mut d = [0u8; 112];
        let f = RawRequest { head: h, data: &[] }.encode(&mut d).unwrap();
        assert_eq!(f.data_len, 20);
        assert_eq!(&d[..20], &[4, 0, 2, 0, 0x01, 0x10, 0x30, 0x01, 0, 0, 0, 0, 0xE8, 0x03, 0, 0, 0, 0, 0, 0]);
        assert!(!h.command.writes() && DatagramCommand::Lrw.writes());
    }

    #[test]
    fn lengths_are_checked() {
        let h = DatagramHead { command: DatagramCommand::Bwr, length: 257, adp: 0, ado: 0, logical: 0, timeout_us: 0 };
        assert!(RawRequest { head: h, data: &[] }.encode(&mut [0; 1408]).is_err());
        let h = DatagramHead { length: 4, ..h };
        assert!(RawRequest { head: h, data: &[1, 2] }.encode(&mut [0; 1408]).is_err());
        let mut d = [0u8; 24];
        d[2] = 0x01;
        d[3] = 0x02;
        assert!(RawReply::decode(&ReplyFields::default(), &d).is_err());
    }
}
