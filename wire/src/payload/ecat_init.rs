//! Network bring-up and distributed clocks: ECAT_INIT (1), ECAT_RECONFIG (2),
//! ECAT_INIT_DC (3), DCSYNC (50), CONFIG_MAP (73), STATE_UPDATE (57).

use crate::CommandCode;
use crate::bytes::{Reader, Writer};
use crate::error::{EncodeError, PayloadError};
use crate::flags::HeaderOptions;
use crate::payload::{Request, RequestFields, bare_request};

/// ECAT_INIT's parameter value selecting "special slaves" (v049 ECAT_INIT 4).
pub const SPECIAL_SLAVES: u8 = 48;
/// ECAT_INIT data byte 0, fixed (v049 ECAT_INIT data table).
pub const INIT_BYTE0: u8 = 0xFF;
/// ECAT_INIT data byte 1: 0x81 in v049 (FIFO stays off until enabled in OP);
/// v031 said 0.
pub const INIT_BYTE1: u8 = 0x81;

/// DC timing shared by ECAT_INIT and DCSYNC: bytes 2..16 of their data.
///
/// The manual's table puts the shift at "0x12": a typo for 12 (0x0C), as its
/// own layout drawing shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct DcTiming {
    /// Bytes 2..4: AssignActivate word from the slave's ESI (0 = DC off).
    pub assign_activate: u16,
    /// Bytes 4..8: SYNC0 cycle in ns.
    pub sync0_ns: u32,
    /// Bytes 8..12: SYNC1 cycle in ns.
    pub sync1_ns: u32,
    /// Bytes 12..16: shift in ns.
    pub shift_ns: i32,
}

impl DcTiming {
    /// The chip's shortest DC cycle (v049 簡介: 125 us).
    pub const MIN_CYCLE_NS: u32 = 125_000;

    fn write(&self, w: &mut Writer<'_>) -> Result<(), EncodeError> {
        w.u16(self.assign_activate)?;
        w.u32(self.sync0_ns)?;
        w.u32(self.sync1_ns)?;
        w.i32(self.shift_ns)
    }

    fn read(r: &mut Reader<'_>) -> Result<Self, PayloadError> {
        Ok(Self {
            assign_activate: r.u16("DC Activate")?,
            sync0_ns: r.u32("SYNC0 Cycle Time")?,
            sync1_ns: r.u32("SYNC1 Cycle Time")?,
            shift_ns: r.i32("Shift Time")?,
        })
    }
}

/// ECAT_INIT (1): initialise the network and slaves (blocking). Data 16 bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct EcatInit {
    /// Parameter 48 ("special slaves") instead of the ordinary bring-up.
    pub special_slaves: bool,
    /// Header reserved bit12: master shift mode (else bus shift mode).
    pub master_shift: bool,
    /// Header reserved bit11: disable LRW.
    pub disable_lrw: bool,
    /// DC activation and timing applied to all slaves.
    pub dc: DcTiming,
}

impl<'a> Request<'a> for EcatInit {
    const CODE: CommandCode = CommandCode::EcatInit;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        let mut w = Writer::new(data);
        w.u8(INIT_BYTE0)?;
        w.u8(INIT_BYTE1)?;
        self.dc.write(&mut w)?;
        let mut options = HeaderOptions::empty();
        options.set(HeaderOptions::INIT_MASTER_SHIFT, self.master_shift);
        options.set(HeaderOptions::INIT_DISABLE_LRW, self.disable_lrw);
        Ok(RequestFields {
            parameter: if self.special_slaves { SPECIAL_SLAVES } else { 0 },
            param: [0; 4],
            data_len: w.len_u16(),
            options,
        })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        crate::payload::fixed_len(fields, Self::CODE, 16)?;
        let mut r = Reader::new(data);
        let _fixed: [u8; 2] = r.array("ECAT_INIT fixed bytes")?;
        Ok(Self {
            special_slaves: fields.parameter == SPECIAL_SLAVES,
            master_shift: fields.options.contains(HeaderOptions::INIT_MASTER_SHIFT),
            disable_lrw: fields.options.contains(HeaderOptions::INIT_DISABLE_LRW),
            dc: DcTiming::read(&mut r)?,
        })
    }
}

/// DCSYNC (50): one slave's DC activation and timing (blocking). Data 16
/// bytes: byte0 slave, byte1 reserved, then [`DcTiming`]. Follow with
/// ECAT_INIT_DC to apply.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct DcSync {
    /// Slave position 0..=127.
    pub slave: u8,
    /// Its DC settings.
    pub dc: DcTiming,
}

impl<'a> Request<'a> for DcSync {
    const CODE: CommandCode = CommandCode::DcSync;
    type Answer<'r> = crate::payload::Done;

    fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
        crate::bytes::check_range("slave", self.slave.into(), 0, 127)?;
        let mut w = Writer::new(data);
        w.u8(self.slave)?;
        w.u8(0)?;
        self.dc.write(&mut w)?;
        Ok(RequestFields { data_len: w.len_u16(), ..RequestFields::default() })
    }

    fn decode(fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
        crate::payload::fixed_len(fields, Self::CODE, 16)?;
        let mut r = Reader::new(data);
        let slave = r.u8("slave")?;
        crate::bytes::expect_range("slave", slave.into(), 0, 127)?;
        let _reserved = r.u8("reserved")?;
        Ok(Self { slave, dc: DcTiming::read(&mut r)? })
    }
}

bare_request! {
    /// ECAT_RECONFIG (2): re-plan the chip's memory after a PDO change
    /// (blocking). Slaves that reset their mapping on it need CONFIG_MAP.
    EcatReconfig => EcatReconfig -> crate::payload::Done;
    /// ECAT_INIT_DC (3): initialise distributed clocks (blocking).
    EcatInitDc => EcatInitDc -> crate::payload::Done;
    /// CONFIG_MAP (73): apply the PDO mapping (blocking).
    ConfigMap => ConfigMap -> crate::payload::Done;
    /// ECAT_STATE_UPDATE (57): refresh the slaves' states into the chip
    /// (blocking).
    StateUpdate => StateUpdate -> crate::payload::Done;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::testing::request_round_trip;
    use proptest::prelude::*;

    fn dc() -> impl Strategy<Value = DcTiming> {
        (any::<u16>(), any::<u32>(), any::<u32>(), any::<i32>()).prop_map(|(a, s0, s1, sh)| DcTiming {
            assign_activate: a,
            sync0_ns: s0,
            sync1_ns: s1,
            shift_ns: sh,
        })
    }

    proptest! {
        #[test]
        fn ecat_init_round_trips(special in any::<bool>(), ms in any::<bool>(), lrw in any::<bool>(), dc in dc()) {
            request_round_trip(&EcatInit { special_slaves: special, master_shift: ms, disable_lrw: lrw, dc });
        }

        #[test]
        fn dcsync_round_trips(slave in 0u8..=127, dc in dc()) {
            request_round_trip(&DcSync { slave, dc });
        }
    }

    #[test]
    fn ecat_init_golden_bytes() {
        let init = EcatInit {
            special_slaves: false,
            master_shift: true,
            disable_lrw: false,
            dc: DcTiming { assign_activate: 0x0300, sync0_ns: 1_000_000, sync1_ns: 0, shift_ns: -500 },
        };
        let (fields, data) = request_round_trip(&init);
        assert_eq!(fields.data_len, 16);
        assert_eq!(fields.options, HeaderOptions::INIT_MASTER_SHIFT);
        assert_eq!(fields.parameter, 0);
        assert_eq!(&data[..16], &[0xFF, 0x81, 0x00, 0x03, 0x40, 0x42, 0x0F, 0x00, 0, 0, 0, 0, 0x0C, 0xFE, 0xFF, 0xFF]);
    }

    #[test]
    fn dcsync_rejects_slave_128() {
        let mut d = [0u8; 32];
        assert!(matches!(
            DcSync { slave: 128, dc: DcTiming::default() }.encode(&mut d),
            Err(EncodeError::FieldOutOfRange { field: "slave", value: 128, .. })
        ));
        d[0] = 200;
        assert_eq!(
            DcSync::decode(&RequestFields { data_len: 16, ..RequestFields::default() }, &d),
            Err(PayloadError::InvalidValue { field: "slave", value: 200 })
        );
    }

    #[test]
    fn truncated_init_names_the_field() {
        let f = RequestFields { data_len: 16, ..RequestFields::default() };
        let err = EcatInit::decode(&f, &[0xFF, 0x81, 0, 3, 1]).unwrap_err();
        assert!(matches!(err, PayloadError::TooShort { field: "SYNC0 Cycle Time", .. }), "{err:?}");
    }
}
