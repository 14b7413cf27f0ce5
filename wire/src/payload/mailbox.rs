//! Mailbox access: RECV_MAILBOX (143) and MBX_STAT (144).
//!
//! RECV_MAILBOX parameter 0 asks the chip to read a slave's receive mailbox
//! (command data 0..2 = slave); parameter 1 reads a window of what it got.
//! TRAP: the window is NOT two little-endian u16s: offset = data1 x 64 +
//! data0 and length = data3 x 64 + data2 (v049, RECV_MAILBOX reply note).
//!
//! MBX_STAT: parameter 0 reads, in OP, one bit per slave "receive mailbox has
//! data"; parameter 1 writes one bit per slave "master polls this mailbox"
//! (takes effect after ECAT_RECONFIG); parameter 2 reads those bits back.
//! Bitmaps are ceil(slaves / 8) bytes, bit k of byte n = slave 8n + k.

use crate::CommandCode;
use crate::bytes::{Writer, check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Reply, ReplyFields, Request, RequestFields, valid};

/// Largest offset or length the x64 encoding can carry.
pub const MAILBOX_WINDOW_MAX: u16 = 255 * 64 + 63;

/// RECV_MAILBOX (143).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RecvMailbox {
    /// Parameter 0: read the slave's receive mailbox into the chip.
    Fetch {
        /// Slave position 0..=127.
        slave: u16,
    },
    /// Parameter 1: read `length` bytes of it from `offset`.
    Read {
        /// Byte offset.
        offset: u16,
        /// Byte count.
        length: u16,
    },
}

fn split64(field: &'static str, v: u16) -> Result<[u8; 2], EncodeError> {
    check_range(field, v.into(), 0, MAILBOX_WINDOW_MAX.into())?;
    Ok([(v % 64) as u8, (v / 64) as u8])
}

impl<'a> Request<'a> for RecvMailbox {
    const CODE: CommandCode = CommandCode::RecvMailbox;
    type Answer<'r> = MailboxData<'r>;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let (parameter, param) = match *self {
            Self::Fetch { slave } => {
                check_range("slave", slave.into(), 0, 127)?;
                let [s0, s1] = slave.to_le_bytes();
                (0, [s0, s1, 0, 0])
            }
            Self::Read { offset, length } => {
                let [o0, o1] = split64("mailbox offset", offset)?;
                let [l0, l1] = split64("mailbox length", length)?;
                (1, [o0, o1, l0, l1])
            }
        };
        Ok(RequestFields { parameter, param, ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        let [p0, p1, p2, p3] = fields.param;
        match fields.parameter {
            0 => {
                let slave = u16::from_le_bytes([p0, p1]);
                expect_range("slave", slave.into(), 0, 127)?;
                Ok(Self::Fetch { slave })
            }
            1 => Ok(Self::Read {
                offset: u16::from(p1) * 64 + u16::from(p0),
                length: u16::from(p3) * 64 + u16::from(p2),
            }),
            v => Err(PayloadError::InvalidValue { field: "RECV_MAILBOX parameter", value: v.into() }),
        }
    }
}

/// RECV_MAILBOX's reply to a read: the mailbox bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct MailboxData<'a>(pub &'a [u8]);

impl<'a> Reply<'a> for MailboxData<'a> {
    const CODE: CommandCode = CommandCode::RecvMailbox;

    fn encode(&self, out: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(out);
        w.bytes(self.0)?;
        Ok(ReplyFields { value: 0, data_len: w.len_u16() })
    }

    fn decode(_fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self(data))
    }
}

/// One bit per slave, bit k of byte n = slave 8n + k (at most 128 slaves).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct SlaveBitmap<'a>(pub &'a [u8]);

impl SlaveBitmap<'_> {
    /// Bytes needed for `slaves` slaves.
    pub const fn len_for(slaves: usize) -> usize {
        slaves.div_ceil(8)
    }

    /// Whether slave `n`'s bit is set.
    pub fn contains(&self, slave: usize) -> bool {
        self.0.get(slave / 8).is_some_and(|b| b & (1 << (slave % 8)) != 0)
    }
}

/// MBX_STAT (144).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MbxStat<'a> {
    /// Parameter 0: which receive mailboxes have data (OP only).
    Status,
    /// Parameter 1: set which mailboxes the master polls.
    SetPolling(SlaveBitmap<'a>),
    /// Parameter 2: which mailboxes the master polls.
    GetPolling,
}

impl<'a> Request<'a> for MbxStat<'a> {
    const CODE: CommandCode = CommandCode::MbxStat;
    type Answer<'r> = MbxStatReply<'r>;

    fn encode(&self, out: &mut [u8]) -> Result<RequestFields, EncodeError> {
        Ok(match self {
            Self::Status => RequestFields::parameter(0),
            Self::GetPolling => RequestFields::parameter(2),
            Self::SetPolling(bits) => {
                check_range("slave bitmap bytes", bits.0.len() as u32, 0, 16)?;
                let mut w = Writer::new(out);
                w.bytes(bits.0)?;
                RequestFields { parameter: 1, data_len: w.len_u16(), ..RequestFields::default() }
            }
        })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        match fields.parameter {
            0 => Ok(Self::Status),
            2 => Ok(Self::GetPolling),
            1 => {
                expect_range("slave bitmap bytes", fields.data_len.into(), 0, 16)?;
                Ok(Self::SetPolling(SlaveBitmap(valid("slave bitmap", data, fields.data_len.into())?)))
            }
            v => Err(PayloadError::InvalidValue { field: "MBX_STAT parameter", value: v.into() }),
        }
    }
}

/// MBX_STAT's reply to parameters 0 and 2: a slave bitmap.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct MbxStatReply<'a>(pub SlaveBitmap<'a>);

impl<'a> Reply<'a> for MbxStatReply<'a> {
    const CODE: CommandCode = CommandCode::MbxStat;

    fn encode(&self, out: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(out);
        w.bytes(self.0.0)?;
        Ok(ReplyFields { value: 0, data_len: w.len_u16() })
    }

    fn decode(_fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Ok(Self(SlaveBitmap(data)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::request_round_trip;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn recv_mailbox_round_trips(slave in 0u16..=127, off in 0u16..=MAILBOX_WINDOW_MAX, len in 0u16..=MAILBOX_WINDOW_MAX) {
            request_round_trip(&RecvMailbox::Fetch { slave });
            request_round_trip(&RecvMailbox::Read { offset: off, length: len });
        }

        #[test]
        fn mbx_stat_round_trips(bits in proptest::collection::vec(any::<u8>(), 0..=16)) {
            for req in [MbxStat::Status, MbxStat::GetPolling, MbxStat::SetPolling(SlaveBitmap(&bits))] {
                let mut d = [0u8; 112];
                let f = req.encode(&mut d).unwrap();
                prop_assert_eq!(MbxStat::decode(&f, &d).unwrap(), req);
            }
            let r = MbxStatReply(SlaveBitmap(&bits));
            let mut d = [0u8; 112];
            let f = r.encode(&mut d).unwrap();
            prop_assert_eq!(MbxStatReply::decode(&f, &d[..f.data_len as usize]).unwrap(), r);
        }
    }

    #[test]
    fn window_uses_times_64_encoding() {
        let (f, _) = request_round_trip(&RecvMailbox::Read { offset: 130, length: 64 });
        assert_eq!((f.parameter, f.param), (1, [2, 2, 0, 1]));
        assert!(RecvMailbox::Read { offset: MAILBOX_WINDOW_MAX + 1, length: 0 }.encode(&mut []).is_err());
    }

    #[test]
    fn bitmap_bits() {
        let b = SlaveBitmap(&[0b0000_0101, 0b1000_0000]);
        assert!(b.contains(0) && b.contains(2) && b.contains(15));
        assert!(!b.contains(1) && !b.contains(16) && !b.contains(1000));
        assert_eq!(SlaveBitmap::len_for(9), 2);
        assert_eq!(SlaveBitmap::len_for(128), 16);
    }
}
