//! EtherCAT mailbox messages (ETG.1000.4 5.6 "Mailbox"; ETG.1000.6 5.6
//! "CoE"): what a master writes into a slave's receive mailbox (SM0) and
//! reads from its send mailbox (SM1), and what an ETG.8200 mailbox gateway
//! carries over UDP. The chip speaks CoE to the slaves itself (SDO_REQ);
//! these frames are for what it does not: the SDO Information service and
//! the gateway, sent through its raw datagrams (RAW_ECAT_FUNC_REQ 137).
//!
//! A message is a 6-byte header and `length` bytes of body:
//!
//! | bytes | field |
//! |-------|-------|
//! | 0..2  | length of the body |
//! | 2..4  | address: the station the message comes from or goes to (0 = the master) |
//! | 4     | bits 0..5 channel, bits 6..7 priority |
//! | 5     | bits 0..3 type (0 error, 2 EoE, 3 CoE, 4 FoE, 5 SoE, 15 VoE), bits 4..6 counter |
//!
//! The counter (ETG.1000.4 5.6.1) tells a slave a new request from a
//! repeated one: a master counts 1..=7 and wraps to 1; 0 means "not
//! counted" and is never sent once counting has started.

pub mod coe;
pub mod sdo;
pub mod sdo_info;

use crate::bytes::{Reader, Writer};
use crate::error::{EncodeError, PayloadError};

/// The header's length in bytes.
pub const HEADER_LEN: usize = 6;

/// A mailbox message's type (ETG.1000.4 Table 29).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MailboxType {
    /// 0: an error reply of the mailbox itself ([`MailboxError`]).
    Error,
    /// 1: ADS over EtherCAT.
    Aoe,
    /// 2: Ethernet over EtherCAT.
    Eoe,
    /// 3: CANopen over EtherCAT.
    Coe,
    /// 4: File access over EtherCAT.
    Foe,
    /// 5: Servo drive profile over EtherCAT.
    Soe,
    /// 15: vendor specific.
    Voe,
    /// Any other code.
    Other(u8),
}

impl MailboxType {
    /// The 4-bit code.
    pub fn code(self) -> u8 {
        match self {
            Self::Error => 0,
            Self::Aoe => 1,
            Self::Eoe => 2,
            Self::Coe => 3,
            Self::Foe => 4,
            Self::Soe => 5,
            Self::Voe => 15,
            Self::Other(c) => c & 0x0F,
        }
    }

    /// The type of a 4-bit code.
    pub fn from_code(code: u8) -> Self {
        match code & 0x0F {
            0 => Self::Error,
            1 => Self::Aoe,
            2 => Self::Eoe,
            3 => Self::Coe,
            4 => Self::Foe,
            5 => Self::Soe,
            15 => Self::Voe,
            c => Self::Other(c),
        }
    }
}

/// The 6-byte mailbox header.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MailboxHeader {
    /// Bytes of body after the header.
    pub length: u16,
    /// Station address of the other end (0: the master).
    pub address: u16,
    /// Channel, 0..=63 (0 for CoE).
    pub channel: u8,
    /// Priority, 0..=3.
    pub priority: u8,
    /// What the body is.
    pub kind: MailboxType,
    /// Counter, 0..=7 ([`next_counter`]).
    pub counter: u8,
}

impl MailboxHeader {
    /// A header for a body of `length` bytes of `kind`, counted `counter`.
    pub fn new(kind: MailboxType, length: u16, counter: u8) -> Self {
        Self { length, address: 0, channel: 0, priority: 0, kind, counter }
    }

    /// Writes the six bytes.
    pub fn encode(&self, out: &mut [u8]) -> Result<(), EncodeError> {
        crate::bytes::check_range("mailbox channel", self.channel.into(), 0, 63)?;
        crate::bytes::check_range("mailbox priority", self.priority.into(), 0, 3)?;
        crate::bytes::check_range("mailbox counter", self.counter.into(), 0, 7)?;
        let mut w = Writer::new(out);
        w.u16(self.length)?;
        w.u16(self.address)?;
        w.u8(self.channel | self.priority << 6)?;
        w.u8(self.kind.code() | self.counter << 4)
    }

    /// Reads the six bytes.
    pub fn decode(data: &[u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(data);
        let length = r.u16("mailbox length")?;
        let address = r.u16("mailbox address")?;
        let cp = r.u8("mailbox channel")?;
        let tc = r.u8("mailbox type")?;
        Ok(Self {
            length,
            address,
            channel: cp & 0x3F,
            priority: cp >> 6,
            kind: MailboxType::from_code(tc),
            counter: (tc >> 4) & 0x07,
        })
    }
}

/// The counter after `counter`: 1..=7, wrapping to 1 (0 is "not counted").
pub fn next_counter(counter: u8) -> u8 {
    if counter >= 7 { 1 } else { counter + 1 }
}

/// A whole message as it sits in a mailbox: header and body.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Message<'a> {
    /// The header.
    pub header: MailboxHeader,
    /// `header.length` bytes of body.
    pub body: &'a [u8],
}

impl<'a> Message<'a> {
    /// Reads a message from the start of `data` (a mailbox buffer, or a
    /// gateway datagram): its body must be there in full.
    pub fn parse(data: &'a [u8]) -> Result<Self, PayloadError> {
        let header = MailboxHeader::decode(data)?;
        let end = HEADER_LEN + usize::from(header.length);
        let body = data.get(HEADER_LEN..end).ok_or(PayloadError::TooShort {
            field: "mailbox body",
            needed: end,
            available: data.len(),
        })?;
        Ok(Self { header, body })
    }

    /// Writes header and body into `out`; returns the bytes written.
    pub fn write(header: MailboxHeader, body: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
        let header = MailboxHeader { length: body.len() as u16, ..header };
        if body.len() > usize::from(u16::MAX) {
            return Err(EncodeError::PayloadTooLarge { needed: body.len(), capacity: usize::from(u16::MAX) });
        }
        let end = HEADER_LEN + body.len();
        if out.len() < end {
            return Err(EncodeError::PayloadTooLarge { needed: end, capacity: out.len() });
        }
        header.encode(&mut out[..HEADER_LEN])?;
        out[HEADER_LEN..end].copy_from_slice(body);
        Ok(end)
    }
}

/// A mailbox error reply (type 0, ETG.1000.4 Table 30): the slave could not
/// take a message at all.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MailboxError(pub u16);

impl MailboxError {
    /// 1: the syntax of the 6-byte header is wrong.
    pub const SYNTAX: Self = Self(1);
    /// 2: the mailbox protocol is not supported.
    pub const UNSUPPORTED_PROTOCOL: Self = Self(2);
    /// 3: the channel field is wrong.
    pub const INVALID_CHANNEL: Self = Self(3);
    /// 4: the service in the protocol is not supported.
    pub const SERVICE_NOT_SUPPORTED: Self = Self(4);
    /// 5: the protocol header is wrong.
    pub const INVALID_HEADER: Self = Self(5);
    /// 6: the message is too short.
    pub const SIZE_TOO_SHORT: Self = Self(6);
    /// 7: no more memory in the slave.
    pub const NO_MORE_MEMORY: Self = Self(7);
    /// 8: the length of the data is inconsistent.
    pub const INVALID_SIZE: Self = Self(8);
    /// 9: the service is already in work.
    pub const SERVICE_IN_WORK: Self = Self(9);

    /// What the code means.
    pub fn meaning(self) -> &'static str {
        match self.0 {
            1 => "mailbox header syntax error",
            2 => "mailbox protocol not supported",
            3 => "invalid mailbox channel",
            4 => "mailbox service not supported",
            5 => "invalid protocol header",
            6 => "mailbox message too short",
            7 => "no more memory in the slave",
            8 => "inconsistent data length",
            9 => "service already in work",
            _ => "unknown mailbox error",
        }
    }

    /// The error reply's body: service 0x01, then the detail code.
    pub fn body(self) -> [u8; 4] {
        let [a, b] = self.0.to_le_bytes();
        [0x01, 0x00, a, b]
    }

    /// Reads an error reply's body.
    pub fn decode(body: &[u8]) -> Result<Self, PayloadError> {
        let mut r = Reader::new(body);
        let service = r.u16("mailbox error service")?;
        if service != 0x01 {
            return Err(PayloadError::InvalidValue { field: "mailbox error service", value: service.into() });
        }
        Ok(Self(r.u16("mailbox error detail")?))
    }
}

impl core::fmt::Display for MailboxError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "mailbox error {}: {}", self.0, self.meaning())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn headers_round_trip(length: u16, address: u16, channel in 0u8..64, priority in 0u8..4, kind in 0u8..16, counter in 0u8..8) {
            let h = MailboxHeader { length, address, channel, priority, kind: MailboxType::from_code(kind), counter };
            let mut b = [0u8; HEADER_LEN];
            h.encode(&mut b).unwrap();
            prop_assert_eq!(MailboxHeader::decode(&b).unwrap(), h);
        }

        #[test]
        fn parsing_arbitrary_bytes_never_panics(data in proptest::collection::vec(any::<u8>(), 0..64)) {
            let _ = Message::parse(&data);
        }
    }

    #[test]
    fn a_message_is_its_header_then_its_body() {
        let mut out = [0u8; 16];
        let h = MailboxHeader { address: 0x1001, ..MailboxHeader::new(MailboxType::Coe, 0, 3) };
        let n = Message::write(h, &[1, 2, 3, 4], &mut out).unwrap();
        assert_eq!(&out[..n], &[4, 0, 0x01, 0x10, 0x00, 0x33, 1, 2, 3, 4]);
        let m = Message::parse(&out).unwrap();
        assert_eq!((m.header.length, m.header.counter, m.body), (4, 3, &[1u8, 2, 3, 4][..]));
        assert!(Message::parse(&out[..7]).is_err(), "a body cut short is refused");
    }

    #[test]
    fn the_counter_runs_one_to_seven() {
        let mut c = 0;
        let seen: [u8; 9] = core::array::from_fn(|_| {
            c = next_counter(c);
            c
        });
        assert_eq!(seen, [1, 2, 3, 4, 5, 6, 7, 1, 2]);
    }

    #[test]
    fn an_error_reply_names_its_cause() {
        let e = MailboxError::decode(&MailboxError::SERVICE_NOT_SUPPORTED.body()).unwrap();
        assert_eq!(e, MailboxError::SERVICE_NOT_SUPPORTED);
        assert_eq!(std::format!("{e}"), "mailbox error 4: mailbox service not supported");
    }
}
