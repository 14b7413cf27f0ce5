//! Ready-made slaves: a Neuromeka-CORE-like drive (fixed PDO map, CST only,
//! 50 ms process-data timeout; reference document "neuromeka-core"), a
//! TI-like 3-axis drive with configurable mapping (reference document
//! "ti-ethercat-subdevice-cia402"), an 8-in/8-out digital IO slave with
//! loopback, and an EK1100-like coupler with no process data.

use ecmxf_wire::payload::pdo::PdoEntry;

use super::cia402::{self, AXIS_STRIDE, AxisSpec};
use super::od::{Access, DataType, Entry, Mappable, Object, ObjectDictionary, ObjectKind};
use super::pdo_map::{self, RX_ASSIGN, TX_ASSIGN};
use super::sii::{self, General, MailboxArea, PdoEntryRecord, PdoRecord, Sii, SmRecord};
use super::slave::{Device, Slave};

/// Identity words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Identity {
    /// Vendor id.
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision.
    pub revision: u32,
    /// Serial.
    pub serial: u32,
}

/// What goes into a generated SII image.
#[derive(Clone, Debug)]
pub struct SiiSpec<'a> {
    /// Identity.
    pub identity: Identity,
    /// Device name (also the order string).
    pub name: &'a str,
    /// Group name.
    pub group: &'a str,
    /// Mailbox, if the slave has one.
    pub mailbox: Option<MailboxArea>,
    /// Mailbox protocols.
    pub protocols: u16,
    /// Output SM length and input SM length in bytes.
    pub pd_lengths: (u16, u16),
    /// PDO records for the RxPDO/TxPDO categories (empty when only CoE
    /// describes them).
    pub rx_pdos: Vec<PdoRecord>,
    /// TxPDOs.
    pub tx_pdos: Vec<PdoRecord>,
    /// DC AssignActivate, when DC is supported.
    pub dc_assign: Option<u16>,
    /// Station alias.
    pub alias: u16,
}

/// Standard SM layout of a mailbox slave: SM0/1 mailbox, SM2 outputs at
/// 0x1100, SM3 inputs at 0x1180.
pub fn build_sii(spec: &SiiSpec<'_>) -> Vec<u8> {
    let mut s = Sii {
        config: [0x0C08, 0x0000, 0x0000, 0x0000, spec.alias, 0, 0, 0],
        vendor_id: spec.identity.vendor_id,
        product_code: spec.identity.product_code,
        revision: spec.identity.revision,
        serial: spec.identity.serial,
        protocols: spec.protocols,
        size_word: 1,
        version: 1,
        strings: vec![spec.group.as_bytes().to_vec(), spec.name.as_bytes().to_vec()],
        general: Some(General {
            group: 1,
            order: 2,
            name: 2,
            coe_details: if spec.protocols & sii::protocol::COE != 0 { 0x23 } else { 0 },
            foe_details: u8::from(spec.protocols & sii::protocol::FOE != 0),
            physical_port: 0x0011,
            ..General::default()
        }),
        ..Sii::default()
    };
    let mut sms = Vec::new();
    if let Some(m) = spec.mailbox {
        s.mailbox = m;
        s.bootstrap_mailbox = m;
        sms.push(SmRecord {
            start: m.rx_offset,
            length: m.rx_size,
            control: 0x26,
            status: 0,
            enable: 1,
            kind: sii::sm_type::MBX_OUT,
        });
        sms.push(SmRecord {
            start: m.tx_offset,
            length: m.tx_size,
            control: 0x22,
            status: 0,
            enable: 1,
            kind: sii::sm_type::MBX_IN,
        });
    }
    let (out_len, in_len) = spec.pd_lengths;
    if out_len > 0 || in_len > 0 || spec.mailbox.is_some() {
        sms.push(SmRecord {
            start: 0x1100,
            length: out_len,
            control: 0x64,
            status: 0,
            enable: u8::from(out_len > 0),
            kind: sii::sm_type::OUTPUTS,
        });
        sms.push(SmRecord {
            start: 0x1180,
            length: in_len,
            control: 0x20,
            status: 0,
            enable: u8::from(in_len > 0),
            kind: sii::sm_type::INPUTS,
        });
        s.fmmu = vec![1, 2, if spec.mailbox.is_some() { 3 } else { 0 }, 0];
    }
    s.sync_managers = sms;
    s.rx_pdos = spec.rx_pdos.clone();
    s.tx_pdos = spec.tx_pdos.clone();
    if let Some(a) = spec.dc_assign {
        let mut d = vec![0u8; 24];
        d[14..16].copy_from_slice(&a.to_le_bytes());
        s.dc = Some(d);
    }
    s.to_bytes(256)
}

/// The CiA 301 objects every CoE slave has (0x1000 device type, 0x1001
/// error register, 0x1008 name, 0x100A software version, 0x1018
/// identity), saying what it is.
pub(crate) fn identity_objects(od: &mut ObjectDictionary, id: Identity, name: &str, device_type: u32) {
    let insert_absent = |od: &mut ObjectDictionary, index: u16, object: Object| {
        if od.object(index).is_none() {
            od.insert(index, object);
        }
    };
    insert_absent(
        od,
        0x1000,
        Object::var(
            "Device type",
            Entry::new("Device type", DataType::UInt32, Access::RO).default_int(device_type.into()),
        ),
    );
    insert_absent(
        od,
        0x1001,
        Object::var("Error register", Entry::new("Error register", DataType::UInt8, Access::RO).mappable(Mappable::Tx)),
    );
    let n = name.len() as u16;
    insert_absent(
        od,
        0x1008,
        Object::var(
            "Device name",
            Entry::new("Device name", DataType::VisibleString(n), Access::RO).default_bytes(name.as_bytes()),
        ),
    );
    // What a real device's firmware says of itself: the simulator's own
    // version.
    let software = concat!("ecmxf-sim ", env!("CARGO_PKG_VERSION"));
    insert_absent(
        od,
        0x100A,
        Object::var(
            "Manufacturer software version",
            Entry::new("Manufacturer software version", DataType::VisibleString(software.len() as u16), Access::RO)
                .default_bytes(software.as_bytes()),
        ),
    );
    insert_absent(
        od,
        0x1018,
        Object::record(
            "Identity",
            ObjectKind::Record,
            Access::RO,
            vec![
                Entry::new("Vendor ID", DataType::UInt32, Access::RO).default_int(id.vendor_id.into()),
                Entry::new("Product code", DataType::UInt32, Access::RO).default_int(id.product_code.into()),
                Entry::new("Revision", DataType::UInt32, Access::RO).default_int(id.revision.into()),
                Entry::new("Serial number", DataType::UInt32, Access::RO).default_int(id.serial.into()),
            ],
        ),
    );
}

fn entries_of(pdo: &[PdoEntry], dtypes: &[u8]) -> Vec<PdoEntryRecord> {
    pdo.iter()
        .zip(dtypes)
        .map(|(e, t)| PdoEntryRecord {
            index: e.index,
            subindex: e.subindex,
            data_type: *t,
            bits: e.bits,
            ..Default::default()
        })
        .collect()
}

const MAILBOX: MailboxArea = MailboxArea { rx_offset: 0x1000, rx_size: 128, tx_offset: 0x1080, tx_size: 128 };

/// A Neuromeka-CORE-like drive: vendor 0x89A, product 0x30000000, fixed PDO
/// map (RxPDO 0x1600 controlword, target position, target velocity, target
/// torque, mode; TxPDO 0x1A00 statusword, actual position, velocity, torque,
/// mode display), CST (mode 10) only, max torque 2048, max speed 4600 rpm,
/// 50 ms process-data timeout, CoE + FoE, DC.
pub fn neuromeka_core(serial: u32, alias: u16) -> Slave {
    let id = Identity { vendor_id: 0x0000_089A, product_code: 0x3000_0000, revision: 0x0001_0010, serial };
    let mut od = ObjectDictionary::new();
    identity_objects(&mut od, id, "CORE", 0x0002_0192);
    let spec =
        AxisSpec { modes: vec![10], default_mode: 10, max_torque: 2048, max_speed_rpm: 4600, ..AxisSpec::default() };
    cia402::add_objects(&mut od, 0, &spec);
    let e = |index, bits| PdoEntry { index, subindex: 0, bits };
    let rx = [e(0x6040, 16), e(0x607A, 32), e(0x60FF, 32), e(0x6071, 16), e(0x6060, 8)];
    let tx = [e(0x6041, 16), e(0x6064, 32), e(0x606C, 32), e(0x6077, 16), e(0x6061, 8)];
    pdo_map::add_mapping(&mut od, 0x1600, "Drive RxPDO", &rx, true);
    pdo_map::add_mapping(&mut od, 0x1A00, "Drive TxPDO", &tx, true);
    pdo_map::add_assignment(&mut od, RX_ASSIGN, &[0x1600], 1, true);
    pdo_map::add_assignment(&mut od, TX_ASSIGN, &[0x1A00], 1, true);
    let eeprom = build_sii(&SiiSpec {
        identity: id,
        name: "CORE",
        group: "Neuromeka motion device",
        mailbox: Some(MAILBOX),
        protocols: sii::protocol::COE | sii::protocol::FOE,
        pd_lengths: (13, 13),
        rx_pdos: vec![PdoRecord {
            index: 0x1600,
            sm: 2,
            entries: entries_of(&rx, &[6, 4, 4, 3, 2]),
            ..Default::default()
        }],
        tx_pdos: vec![PdoRecord {
            index: 0x1A00,
            sm: 3,
            entries: entries_of(&tx, &[6, 4, 4, 3, 2]),
            ..Default::default()
        }],
        dc_assign: Some(0x0300),
        alias,
    });
    let mut s = Slave::new(eeprom, od, Device::Drive(vec![cia402::Axis::new(0, spec)]), true);
    s.watchdog_ns = 50_000_000;
    s
}

/// A TI-like 3-axis CiA402 drive: axes at 0x6000, 0x6800, 0x7000; one RxPDO
/// (0x1600 + n) and one TxPDO (0x1A00 + n) per axis with controlword, mode,
/// target position, velocity, torque / statusword, mode display, actual
/// position, velocity, torque; mapping configurable in PRE-OP; modes 8, 9,
/// 10; CoE + FoE; DC.
pub fn ti_three_axis(serial: u32, alias: u16) -> Slave {
    let id = Identity { vendor_id: 0x0000_059D, product_code: 0x0000_0402, revision: 0x0002_0002, serial };
    let mut od = ObjectDictionary::new();
    identity_objects(&mut od, id, "TI CiA402 3-axis", 0x0302_0192);
    let spec = AxisSpec::default();
    let mut axes = Vec::new();
    let mut rx_records = Vec::new();
    let mut tx_records = Vec::new();
    for axis in 0..3u16 {
        cia402::add_objects(&mut od, axis, &spec);
        axes.push(cia402::Axis::new(axis, spec.clone()));
        let b = axis * AXIS_STRIDE;
        let e = |index: u16, bits| PdoEntry { index: index + b, subindex: 0, bits };
        let rx = [e(0x6040, 16), e(0x6060, 8), e(0x607A, 32), e(0x60FF, 32), e(0x6071, 16)];
        let tx = [e(0x6041, 16), e(0x6061, 8), e(0x6064, 32), e(0x606C, 32), e(0x6077, 16)];
        pdo_map::add_mapping(&mut od, 0x1600 + axis, &format!("RxPDO axis {}", axis + 1), &rx, false);
        pdo_map::add_mapping(&mut od, 0x1A00 + axis, &format!("TxPDO axis {}", axis + 1), &tx, false);
        rx_records.push(PdoRecord {
            index: 0x1600 + axis,
            sm: 2,
            entries: entries_of(&rx, &[6, 2, 4, 4, 3]),
            ..Default::default()
        });
        tx_records.push(PdoRecord {
            index: 0x1A00 + axis,
            sm: 3,
            entries: entries_of(&tx, &[6, 2, 4, 4, 3]),
            ..Default::default()
        });
    }
    pdo_map::add_assignment(&mut od, RX_ASSIGN, &[0x1600, 0x1601, 0x1602], 3, false);
    pdo_map::add_assignment(&mut od, TX_ASSIGN, &[0x1A00, 0x1A01, 0x1A02], 3, false);
    let eeprom = build_sii(&SiiSpec {
        identity: id,
        name: "TI CiA402 3-axis",
        group: "Drives",
        mailbox: Some(MAILBOX),
        protocols: sii::protocol::COE | sii::protocol::FOE,
        pd_lengths: (39, 39),
        rx_pdos: rx_records,
        tx_pdos: tx_records,
        dc_assign: Some(0x0300),
        alias,
    });
    Slave::new(eeprom, od, Device::Drive(axes), true)
}

/// An 8-in/8-out digital IO slave: outputs 0x7000:01 (USINT) looped back to
/// inputs 0x6000:01 (USINT), RxPDO 0x1600, TxPDO 0x1A00, CoE, no DC.
pub fn digital_io(serial: u32, alias: u16) -> Slave {
    let id = Identity { vendor_id: 0x0000_1337, product_code: 0x0000_0808, revision: 1, serial };
    let mut od = ObjectDictionary::new();
    identity_objects(&mut od, id, "8io", 0x0000_0191);
    od.insert(
        0x6000,
        Object::record(
            "Inputs",
            ObjectKind::Array,
            Access::RO,
            vec![Entry::new("Inputs 1-8", DataType::UInt8, Access::RO).mappable(Mappable::Tx)],
        ),
    );
    od.insert(
        0x7000,
        Object::record(
            "Outputs",
            ObjectKind::Array,
            Access::RO,
            vec![Entry::new("Outputs 1-8", DataType::UInt8, Access::RW).mappable(Mappable::Rx)],
        ),
    );
    let rx = [PdoEntry { index: 0x7000, subindex: 1, bits: 8 }];
    let tx = [PdoEntry { index: 0x6000, subindex: 1, bits: 8 }];
    pdo_map::add_mapping(&mut od, 0x1600, "Outputs", &rx, false);
    pdo_map::add_mapping(&mut od, 0x1A00, "Inputs", &tx, false);
    pdo_map::add_assignment(&mut od, RX_ASSIGN, &[0x1600], 1, false);
    pdo_map::add_assignment(&mut od, TX_ASSIGN, &[0x1A00], 1, false);
    let eeprom = build_sii(&SiiSpec {
        identity: id,
        name: "8io",
        group: "IO",
        mailbox: Some(MAILBOX),
        protocols: sii::protocol::COE,
        pd_lengths: (1, 1),
        rx_pdos: vec![PdoRecord { index: 0x1600, sm: 2, entries: entries_of(&rx, &[5]), ..Default::default() }],
        tx_pdos: vec![PdoRecord { index: 0x1A00, sm: 3, entries: entries_of(&tx, &[5]), ..Default::default() }],
        dc_assign: None,
        alias,
    });
    Slave::new(eeprom, od, Device::DigitalIo { forced_inputs: 0 }, false)
}

/// An EK1100-like coupler: vendor 2, product 0x044C2C52, revision
/// 0x00120000, no mailbox, no process data.
pub fn coupler(serial: u32) -> Slave {
    let id = Identity { vendor_id: 2, product_code: 0x044C_2C52, revision: 0x0012_0000, serial };
    let eeprom = build_sii(&SiiSpec {
        identity: id,
        name: "EK1100",
        group: "SystemBk",
        mailbox: None,
        protocols: 0,
        pd_lengths: (0, 0),
        rx_pdos: Vec::new(),
        tx_pdos: Vec::new(),
        dc_assign: None,
        alias: 0,
    });
    Slave::new(eeprom, ObjectDictionary::new(), Device::Passive, false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::net::esm::AlState;
    use ecmxf_devices::sii::protocol;
    use ecmxf_wire::payload::sdo::SdoAbortCode;

    #[test]
    fn a_slave_whose_sii_lists_no_coe_never_answers_coe() {
        let mut drive = ti_three_axis(1, 1);
        drive.esm.state = AlState::PreOp;
        assert!(drive.sdo_upload(0x1018, 1, false).is_ok());
        // The same device with FoE and SoE only in its SII (word 0x1C).
        let mut eeprom = drive.eeprom.clone();
        eeprom[0x38..0x3A].copy_from_slice(&(protocol::FOE | protocol::SOE).to_le_bytes());
        let mut other = Slave::new(eeprom, drive.od.clone(), drive.device.clone(), drive.has_dc);
        other.esm.state = AlState::PreOp;
        assert!(other.has_mailbox && !other.has_coe);
        assert_eq!(other.sdo_upload(0x1018, 1, false), Err(SdoAbortCode::TIMEOUT));
    }
}

#[cfg(test)]
mod sdo_information_through_the_esc {
    use ecmxf_wire::mbx::sdo_info::{InfoFragment, InfoRequest, ListType, OdList};
    use ecmxf_wire::mbx::{MailboxHeader, MailboxType, Message};

    use super::ti_three_axis;
    use crate::net::esm::AlState;

    /// A request written into the receive mailbox by datagrams is answered
    /// in the send mailbox, in fragments when the list is long; an empty
    /// send mailbox is not counted; a slave without SDO Info refuses the
    /// service with a mailbox error.
    #[test]
    fn an_od_list_comes_back_in_fragments_through_the_mailboxes() {
        let mut s = ti_three_axis(1, 1);
        s.esm.state = AlState::PreOp;
        s.sdo_info = true;
        // A small send mailbox, so the list comes in fragments.
        let area = ecmxf_devices::sii::MailboxArea { tx_size: 32, ..s.mailboxes.area };
        s.mailboxes = crate::net::mailbox::Mailboxes::new(area);
        let mut body = [0u8; 16];
        let n = InfoRequest::OdList(ListType::All).encode(&mut body).unwrap();
        let mut request = vec![0u8; usize::from(area.rx_size)];
        Message::write(MailboxHeader::new(MailboxType::Coe, 0, 0), &body[..n], &mut request).unwrap();
        s.esc_write(area.rx_offset, &request);
        let mut joined = Vec::new();
        loop {
            let mut out = vec![0u8; usize::from(area.tx_size)];
            assert_eq!(s.esc_read(area.tx_offset, &mut out), Some(true), "an answer waits");
            let m = Message::parse(&out).unwrap();
            let f = InfoFragment::decode(m.body).unwrap();
            joined.extend_from_slice(f.payload);
            if !f.header.incomplete {
                break;
            }
        }
        let mut out = vec![0u8; usize::from(area.tx_size)];
        assert_eq!(s.esc_read(area.tx_offset, &mut out), Some(false), "empty now");
        let listed: Vec<u16> = OdList::decode(&joined).unwrap().indices().collect();
        let expected: Vec<u16> = s.od.objects().map(|(i, _)| i).collect();
        assert_eq!(listed, expected);
        assert!(expected.len() * 2 > usize::from(area.tx_size), "the list needed fragments");

        s.sdo_info = false;
        s.esc_write(area.rx_offset, &request);
        assert_eq!(s.esc_read(area.tx_offset, &mut out), Some(true));
        assert_eq!(Message::parse(&out).unwrap().header.kind, MailboxType::Error);
    }
}
