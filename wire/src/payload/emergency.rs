//! CoE emergencies: COE_EMERGENCY (83), the last n (1..=8) emergency
//! messages the chip received.
//!
//! Each record is 12 bytes (v049): slot (0..n-1, or 0xFF when empty), slave,
//! running number u16 (which emergency since the chip started), error code
//! u16, error register u8, 5 bytes of manufacturer data.

use crate::CommandCode;
use crate::bytes::{Writer, check_range, expect_range};
use crate::error::{EncodeError, PayloadError};
use crate::payload::{Reply, ReplyFields, Request, RequestFields};

/// Bytes per record.
pub const EMERGENCY_RECORD_LEN: usize = 12;
/// Most records one request can ask for.
pub const EMERGENCY_MAX: u8 = 8;

/// COE_EMERGENCY (83): parameter n = how many records (1..=8).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CoeEmergencyGet(pub u8);

impl<'a> Request<'a> for CoeEmergencyGet {
    const CODE: CommandCode = CommandCode::CoeEmergency;
    type Answer<'r> = CoeEmergencyReply<'r>;

    fn encode(&self, _data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        check_range("emergency count", self.0.into(), 1, EMERGENCY_MAX.into())?;
        Ok(RequestFields::parameter(self.0))
    }

    fn decode(fields: &RequestFields, _data: &'a [u8]) -> Result<Self, PayloadError> {
        expect_range("emergency count", fields.parameter.into(), 1, EMERGENCY_MAX.into())?;
        Ok(Self(fields.parameter))
    }
}

/// One emergency record.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct EmergencyRecord {
    /// Slot number, 0xFF when there is no emergency in this slot.
    pub slot: u8,
    /// Slave that sent it.
    pub slave: u8,
    /// Running number since the chip started.
    pub number: u16,
    /// CiA301 emergency error code.
    pub error_code: u16,
    /// Error register (0x1001).
    pub error_register: u8,
    /// Manufacturer-specific data.
    pub data: [u8; 5],
}

impl EmergencyRecord {
    /// Whether the slot holds no emergency.
    pub fn is_empty(&self) -> bool {
        self.slot == 0xFF
    }

    /// Writes the 12 bytes.
    pub fn write(&self, out: &mut [u8; EMERGENCY_RECORD_LEN]) {
        let [n0, n1] = self.number.to_le_bytes();
        let [e0, e1] = self.error_code.to_le_bytes();
        let [d0, d1, d2, d3, d4] = self.data;
        *out = [self.slot, self.slave, n0, n1, e0, e1, self.error_register, d0, d1, d2, d3, d4];
    }

    /// Reads the 12 bytes.
    pub fn read(b: &[u8; EMERGENCY_RECORD_LEN]) -> Self {
        Self {
            slot: b[0],
            slave: b[1],
            number: u16::from_le_bytes([b[2], b[3]]),
            error_code: u16::from_le_bytes([b[4], b[5]]),
            error_register: b[6],
            data: [b[7], b[8], b[9], b[10], b[11]],
        }
    }
}

/// COE_EMERGENCY's reply: 12 x n bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct CoeEmergencyReply<'a> {
    raw: &'a [u8],
}

impl<'a> CoeEmergencyReply<'a> {
    /// Wraps record bytes; their length must be a multiple of 12.
    pub fn new(raw: &'a [u8]) -> Result<Self, PayloadError> {
        if raw.len() % EMERGENCY_RECORD_LEN != 0 || raw.len() > EMERGENCY_RECORD_LEN * usize::from(EMERGENCY_MAX) {
            return Err(PayloadError::InvalidValue { field: "emergency data length", value: raw.len() as u32 });
        }
        Ok(Self { raw })
    }

    /// The records, empty slots included.
    pub fn records(&self) -> impl Iterator<Item = EmergencyRecord> + 'a {
        self.raw.chunks_exact(EMERGENCY_RECORD_LEN).map(|c| {
            let mut b = [0u8; EMERGENCY_RECORD_LEN];
            b.copy_from_slice(c);
            EmergencyRecord::read(&b)
        })
    }

    /// The raw bytes.
    pub fn as_bytes(&self) -> &'a [u8] {
        self.raw
    }
}

impl<'a> Reply<'a> for CoeEmergencyReply<'a> {
    const CODE: CommandCode = CommandCode::CoeEmergency;

    fn encode(&self, data: &mut [u8]) -> Result<ReplyFields, EncodeError> {
        let mut w = Writer::new(data);
        w.bytes(self.raw)?;
        Ok(ReplyFields { value: 0, data_len: w.len_u16() })
    }

    fn decode(_fields: &ReplyFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        Self::new(data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::request_round_trip;
    use proptest::prelude::*;
    use std::vec::Vec;

    fn record() -> impl Strategy<Value = EmergencyRecord> {
        (any::<u8>(), any::<u8>(), any::<u16>(), any::<u16>(), any::<u8>(), any::<[u8; 5]>()).prop_map(
            |(slot, slave, number, error_code, error_register, data)| EmergencyRecord {
                slot,
                slave,
                number,
                error_code,
                error_register,
                data,
            },
        )
    }

    proptest! {
        #[test]
        fn records_round_trip(recs in proptest::collection::vec(record(), 1..=8)) {
            let mut raw = Vec::new();
            for r in &recs {
                let mut b = [0u8; 12];
                r.write(&mut b);
                raw.extend_from_slice(&b);
            }
            let reply = CoeEmergencyReply::new(&raw).unwrap();
            let mut d = [0u8; 112];
            let f = reply.encode(&mut d).unwrap();
            prop_assert_eq!(usize::from(f.data_len), 12 * recs.len());
            let back = CoeEmergencyReply::decode(&f, &d[..f.data_len as usize]).unwrap();
            request_round_trip(&CoeEmergencyGet(recs.len() as u8));
            prop_assert_eq!(back.records().collect::<Vec<_>>(), recs);
        }
    }

    #[test]
    fn golden_record_and_limits() {
        let r = EmergencyRecord {
            slot: 0,
            slave: 2,
            number: 7,
            error_code: 0x7500,
            error_register: 0x11,
            data: [1, 2, 3, 4, 5],
        };
        let mut b = [0u8; 12];
        r.write(&mut b);
        assert_eq!(b, [0, 2, 7, 0, 0x00, 0x75, 0x11, 1, 2, 3, 4, 5]);
        assert!(EmergencyRecord::read(&[0xFF; 12]).is_empty());
        assert!(CoeEmergencyGet(0).encode(&mut []).is_err());
        assert!(CoeEmergencyGet(9).encode(&mut []).is_err());
        assert!(CoeEmergencyReply::new(&[0; 13]).is_err());
        assert!(CoeEmergencyReply::new(&[0; 108]).is_err());
    }
}
