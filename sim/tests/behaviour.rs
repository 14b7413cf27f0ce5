//! Documented chip behaviour beyond the happy path: the blocking-slot rules,
//! FIFO underrun, the WKC limit and the slaves' watchdog, emergencies, warm
//! reset, EEPROM, raw datagrams and FoE.

mod common;

use common::{Host, bring_up_to_op};
use ecmxf_sim::Network;
use ecmxf_wire::flags::{ControlFlags, ErrorFlags, StatusFlags};
use ecmxf_wire::payload::control::{
    AsyncCmdReset, AsyncReset, FwVersionGet, InfoUpdate, WkcErrorLimit, WkcErrorLimitSet,
};
use ecmxf_wire::payload::ecat_init::StateUpdate;
use ecmxf_wire::payload::ecat_init::{DcTiming, EcatInit};
use ecmxf_wire::payload::eeprom::{EepromAccess, EepromGet, EepromRequest};
use ecmxf_wire::payload::emergency::{CoeEmergencyGet, CoeEmergencyReply};
use ecmxf_wire::payload::foe::{FoeGet, FoeRequest, FoeTransfer};
use ecmxf_wire::payload::raw::{DatagramCommand, DatagramHead, RawGet, RawReply, RawRequest};
use ecmxf_wire::payload::sdo::{SdoAccess, SdoRequest};
use ecmxf_wire::payload::state::SlaveSelector;
use ecmxf_wire::{CommandCode, EcatState, Reply, ReplyFields};

fn fields(a: &common::Answer) -> ReplyFields {
    ReplyFields { value: a.header.return_value, data_len: a.header.data_len }
}

fn sdo_read(slave: u8, index: u16) -> SdoRequest<'static> {
    SdoRequest {
        slave,
        index,
        subindex: 0,
        complete_access: false,
        timeout_us: 100_000,
        access: SdoAccess::Read { max_len: 4 },
    }
}

#[test]
fn one_blocking_command_at_a_time() {
    let mut h = Host::new(Network::demo());
    h.call(&InfoUpdate);
    let dc = DcTiming { assign_activate: 0, sync0_ns: 1_000_000, sync1_ns: 0, shift_ns: 0 };
    let a = h.call(&EcatInit { special_slaves: false, master_shift: false, disable_lrw: false, dc });
    assert!(a.header.status.flags.contains(StatusFlags::BLOCKING_BUSY));
    // A second blocking command while busy: command error, not executed.
    let executed_sdo = h.call(&sdo_read(0, 0x1000));
    assert!(executed_sdo.header.errors.contains(ErrorFlags::COMMAND_ERROR));
    assert!(matches!(h.chip.pending, Some((ecmxf_sim::chip::BlockingOp::EcatInit(_), _))));
    // Non-blocking commands keep working meanwhile.
    let v = h.call(&FwVersionGet);
    assert_eq!(v.header.return_value, 0x24);
    // The clear bit clears the command error.
    h.control = ControlFlags::CLEAR_COMMAND_ERROR;
    let a = h.call(&InfoUpdate);
    assert!(!a.header.errors.contains(ErrorFlags::COMMAND_ERROR));
    // ASYNC_CMD_RESET 1 frees a stuck slot.
    let a = h.call(&AsyncCmdReset(AsyncReset::CLEAR_BUSY));
    assert!(!a.header.blocking_busy());
    assert!(!h.chip.master.inited, "the abandoned init never completed");
}

#[test]
fn a_dry_rxfifo_repeats_the_last_outputs_and_flags_a_fifo_error() {
    let mut h = Host::new(Network::demo());
    let f = bring_up_to_op(&mut h, 4);
    // Push one frame with IO outputs 0x5A, then stop feeding.
    let mut frame = vec![0u8; f.rx];
    frame[f.rx - 1] = 0x5A;
    h.call(&ecmxf_wire::payload::pdo::PdoFifoOp {
        op: ecmxf_wire::payload::pdo::FifoOpFlags::WRITE,
        frames: 1,
        outputs: &frame,
    });
    h.idle(5_000_000);
    assert!(h.chip.fifo.underruns > 30);
    let a = h.call(&InfoUpdate);
    assert!(a.header.errors.contains(ErrorFlags::FIFO_ERROR));
    assert_eq!(h.chip.net.slaves[2].outputs, [0x5A], "last outputs repeat");
    assert_eq!(a.header.wkc_errors, 0, "slaves still get outputs every cycle");
    h.control = ControlFlags::CLEAR_FIFO_ERROR;
    let a = h.call(&InfoUpdate);
    // Still dry, so the error comes straight back on the next cycle.
    assert!(a.header.errors.contains(ErrorFlags::FIFO_ERROR) || h.chip.fifo.underruns > 0);
}

#[test]
fn wkc_limit_stops_exchange_and_slaves_fall_to_safeop_with_0x001b() {
    let mut h = Host::new(Network::demo());
    bring_up_to_op(&mut h, 8);
    h.call(&WkcErrorLimitSet(WkcErrorLimit(10)));
    // Unplug the IO slave: the working counter drops by 3 every cycle.
    h.chip.net.slaves[2].present = false;
    h.idle(2_000_000);
    let a = h.call(&InfoUpdate);
    assert!(a.header.wkc_errors > 10);
    assert!(h.chip.master.exchange_stopped);
    assert!(
        !a.header.status.flags.intersects(StatusFlags::PDO_CONFIGURED | StatusFlags::FIFO_ENABLED),
        "bits 4 and 6 read 0"
    );
    // Without outputs the Neuromeka drive's 50 ms watchdog fires first.
    h.idle(60_000_000);
    let s = &h.chip.net.slaves[0];
    assert_eq!((s.esm.state, s.esm.al_status), (ecmxf_sim::net::esm::AlState::SafeOp, 0x001B));
    assert_eq!(h.chip.net.slaves[1].esm.state, ecmxf_sim::net::esm::AlState::Op, "TI drive: 100 ms watchdog");
    h.idle(50_000_000);
    assert_eq!(h.chip.net.slaves[1].esm.al_status, 0x001B);
    // The chip shows it once the states are refreshed.
    h.blocking(&StateUpdate);
    let a = h.call(&InfoUpdate);
    assert_eq!(a.header.ecat_state, EcatState::Error);
    // The drives raised emergencies for the lost process data.
    let a = h.call(&CoeEmergencyGet(8));
    let r = CoeEmergencyReply::decode(&fields(&a), &a.data).unwrap();
    let codes: Vec<(u8, u16)> = r.records().filter(|r| !r.is_empty()).map(|r| (r.slave, r.error_code)).collect();
    assert!(codes.contains(&(0, 0x8700)) && codes.contains(&(1, 0x8700)), "{codes:?}");
    let _ = SlaveSelector::All;
}

#[test]
fn injected_drive_fault_reaches_the_emergency_history() {
    let mut h = Host::new(Network::demo());
    bring_up_to_op(&mut h, 16);
    assert!(h.chip.net.slaves[1].inject_drive_fault(2, 0x2310));
    h.idle(1_000_000);
    let a = h.call(&CoeEmergencyGet(2));
    assert_eq!(a.header.data_len, 24);
    let recs: Vec<_> = CoeEmergencyReply::decode(&fields(&a), &a.data).unwrap().records().collect();
    assert_eq!((recs[0].slot, recs[0].slave, recs[0].error_code, recs[0].number), (0, 1, 0x2310, 1));
    assert!(recs[1].is_empty());
}

#[test]
fn warm_reset_returns_to_power_up_state() {
    let mut h = Host::new(Network::demo());
    bring_up_to_op(&mut h, 16);
    h.send(&ecmxf_wire::payload::control::WarmReset);
    assert!(!h.chip.ready(h.now + 10_000_000), "initialising");
    h.check = ecmxf_wire::CheckType::Fixed;
    let (bytes, _) = h.send(&InfoUpdate);
    let a = h.decode(&bytes).unwrap();
    assert!(a.header.is_nop(), "first answer after reset is a NOP");
    assert_eq!(a.header.ecat_state, EcatState::None);
    let a = h.call(&InfoUpdate);
    assert!(!a.header.status.flags.contains(StatusFlags::ETHERNET_READY));
}

#[test]
fn eeprom_raw_datagrams_and_foe() {
    let mut h = Host::new(Network::demo());
    bring_up_to_op(&mut h, 16);
    // EEPROM: the vendor id words of slave 1.
    h.blocking(&EepromRequest { slave: 1, access: EepromAccess::Read { address: 0x08 }, timeout_us: 10_000 });
    let a = h.call(&EepromGet);
    assert_eq!(a.header.return_value, 0);
    assert_eq!(&a.data[..4], &0x059Du32.to_le_bytes());
    // Write the alias word and read it back.
    h.blocking(&EepromRequest {
        slave: 1,
        access: EepromAccess::Write { address: 0x04, value: 0x0042 },
        timeout_us: 10_000,
    });
    h.blocking(&EepromRequest { slave: 1, access: EepromAccess::Read { address: 0x04 }, timeout_us: 10_000 });
    let a = h.call(&EepromGet);
    assert_eq!(&a.data[..2], &[0x42, 0x00]);

    // Raw FPRD of the AL status register of station 0x1002.
    let head = DatagramHead {
        command: DatagramCommand::Fprd,
        length: 2,
        adp: 0x1002,
        ado: 0x0130,
        logical: 0,
        timeout_us: 1000,
    };
    h.blocking(&RawRequest { head, data: &[] });
    let a = h.call(&RawGet);
    let r = RawReply::decode(&fields(&a), &a.data).unwrap();
    assert_eq!((r.working_counter, r.data), (1, &[0x08, 0x00][..]));
    // BWR to AL control: every slave to PRE-OP.
    let head =
        DatagramHead { command: DatagramCommand::Bwr, length: 2, adp: 0, ado: 0x0120, logical: 0, timeout_us: 1000 };
    h.blocking(&RawRequest { head, data: &[0x02, 0x00] });
    let a = h.call(&RawGet);
    assert_eq!(RawReply::decode(&fields(&a), &a.data).unwrap().working_counter, 3);
    assert!(h.chip.net.slaves.iter().all(|s| s.esm.state == ecmxf_sim::net::esm::AlState::PreOp));

    // FoE: stage a file in flash, download it to slave 0, upload it back.
    let file = b"firmware image v2";
    h.blocking(&FoeRequest::WriteFlash { offset: 0x100, data: file });
    let t = FoeTransfer {
        slave: 0,
        password: 0,
        file_length: file.len() as u32,
        timeout_us: 1_000_000,
        flash_offset: 0x100,
        name: b"fw.bin",
    };
    let st = h.blocking(&FoeRequest::Download(t));
    assert!(!st.errors.contains(ErrorFlags::BLOCKING_FAILED));
    assert_eq!(h.chip.net.slaves[0].files.get(b"fw.bin".as_slice()).map(Vec::as_slice), Some(&file[..]));
    let t = FoeTransfer { flash_offset: 0x2000, file_length: 256, ..t };
    h.blocking(&FoeRequest::Upload(t));
    h.blocking(&FoeRequest::ReadFlash { offset: 0x2000, length: file.len() as u16 });
    let a = h.call(&FoeGet);
    assert_eq!(a.data, file);
    // A missing file fails the blocking command.
    let t = FoeTransfer { name: b"missing", ..t };
    let st = h.blocking(&FoeRequest::Upload(t));
    assert!(st.errors.contains(ErrorFlags::BLOCKING_FAILED));
    let (bytes, _) = h.send(&InfoUpdate);
    assert_eq!(h.decode(&bytes).unwrap().header.code, CommandCode::InfoUpdate);
}

#[test]
fn an_unplugged_slave_cuts_off_the_ones_after_it() {
    use ecmxf_wire::payload::slave_info::{SlaveCount, SlaveCountGet};
    let mut h = Host::new(Network::demo());
    bring_up_to_op(&mut h, 8);
    h.chip.net.unplug(1);
    assert_eq!(h.chip.net.reachable(), 1);
    let n: SlaveCount = h.get(&SlaveCountGet);
    assert_eq!(n.0, 1, "EtherCAT is a line: slave 2 is behind the gap");
    // Configured slaves that stopped answering read as errors after a refresh.
    h.blocking(&StateUpdate);
    assert_eq!(h.call(&InfoUpdate).header.ecat_state, EcatState::Error);
    h.chip.net.replug(1);
    assert_eq!(h.chip.net.reachable(), 3);
    assert_eq!(
        h.chip.net.slaves[1].esm.state,
        ecmxf_sim::net::esm::AlState::Init,
        "a replugged slave powers up in INIT"
    );
}

/// SDO_REQ and EEPROM_REQ carry the longest wait (us, v049): a request the
/// model needs longer for fails when it is up, an SDO with abort
/// 0x05040000; within the limit it succeeds.
#[test]
fn sdo_and_eeprom_requests_fail_when_their_timeout_is_shorter_than_the_work() {
    use ecmxf_wire::payload::sdo::{SdoAbortCodeGet, SdoAbortReply};
    let mut h = Host::new(Network::demo());
    bring_up_to_op(&mut h, 8);
    let mut quick = sdo_read(0, 0x1000);
    quick.timeout_us = 100; // the model needs 600 us
    let after = h.blocking(&quick);
    assert!(after.errors.contains(ErrorFlags::BLOCKING_FAILED), "{after:?}");
    let a = h.call(&SdoAbortCodeGet);
    let code = SdoAbortReply::decode(&fields(&a), &a.data).unwrap().0;
    assert_eq!(code.0, 0x0504_0000, "SDO protocol timed out");
    h.control = ControlFlags::CLEAR_BLOCKING_ERROR;
    h.call(&InfoUpdate);
    let after = h.blocking(&sdo_read(0, 0x1000));
    assert!(!after.errors.contains(ErrorFlags::BLOCKING_FAILED), "within its timeout: {after:?}");

    let eeprom = EepromRequest { slave: 0, access: EepromAccess::Read { address: 8 }, timeout_us: 10 };
    let after = h.blocking(&eeprom);
    assert!(after.errors.contains(ErrorFlags::BLOCKING_FAILED), "EEPROM word in 10 us: {after:?}");
}

/// Sends one packet whose data section is `data` and whose header declares
/// `declared` bytes, the way a host that fills one layout and declares
/// another does; returns the answer (fetched with INFO_UPDATE).
fn send_declaring(h: &mut Host, code: CommandCode, index: u8, data: &[u8], declared: u16) -> common::Answer {
    use ecmxf_wire::{CheckType, CommandHeader};
    let mut header = CommandHeader::new(code, index);
    header.data_len = declared;
    let mut buf = vec![0u8; h.packet_len()];
    ecmxf_wire::encode_command(&header, data, CheckType::Fixed, &mut buf).unwrap();
    h.exchange_raw(&buf);
    let (bytes, _) = h.send(&InfoUpdate);
    let a = h.decode(&bytes).unwrap();
    assert_eq!(a.header.index, index, "the answer is to the request");
    a
}

/// SPI_RECONFIG to `data_size`-byte data sections (v049 command 23).
fn resize(h: &mut Host, data_size: u16) {
    use ecmxf_wire::payload::spi::SpiReconfig;
    let mut buf = vec![0u8; h.packet_len()];
    let header = ecmxf_wire::CommandHeader::new(CommandCode::SpiReconfig, 0xF0);
    ecmxf_wire::encode_request(&SpiReconfig { data_size }, header, ecmxf_wire::CheckType::Fixed, &mut buf).unwrap();
    h.exchange_raw(&buf);
    h.data_size = data_size.into();
    h.call(&InfoUpdate);
}

/// The PDO configuration in the 156-byte shape of the vendor's header 1.52
/// (`PDO_CONFIG_HEAD`: vendor id u32, product code u32, then slave, PDO
/// count, assignment, 4 mapping indices, 4 entry counts and `Table[32]`
/// of `index << 16 | subindex << 8 | bits`, packed as its v1.60 code fills
/// it: PDO j's entries after the earlier PDOs' entries).
fn vendor_pdo_config(vendor: u32, product: u32, slave: u8, assign: u16, pdos: &[(u16, &[u32])]) -> Vec<u8> {
    let mut d = Vec::new();
    d.extend(vendor.to_le_bytes());
    d.extend(product.to_le_bytes());
    d.extend(pdo_fields(slave, assign, pdos, 4));
    let packed: Vec<u32> = pdos.iter().flat_map(|p| p.1.iter().copied()).collect();
    for k in 0..32 {
        d.extend(packed.get(k).copied().unwrap_or(0).to_le_bytes());
    }
    assert_eq!(d.len(), 156);
    d
}

/// Slave, PDO count, assignment, `slots` mapping indices and entry counts.
fn pdo_fields(slave: u8, assign: u16, pdos: &[(u16, &[u32])], slots: usize) -> Vec<u8> {
    let mut d = vec![slave, pdos.len() as u8];
    d.extend(assign.to_le_bytes());
    for i in 0..slots {
        d.extend(pdos.get(i).map_or(0u16, |p| p.0).to_le_bytes());
    }
    for i in 0..slots {
        d.extend(pdos.get(i).map_or(0u16, |p| p.1.len() as u16).to_le_bytes());
    }
    d
}

/// The slotted forms: v049's 112 bytes (3 slots) and the older vendor
/// headers' 148 (4 slots), each slot 8 entries wide.
fn slotted_pdo_config(slave: u8, assign: u16, pdos: &[(u16, &[u32])], slots: usize) -> Vec<u8> {
    let mut d = pdo_fields(slave, assign, pdos, slots);
    for i in 0..slots {
        for k in 0..8 {
            d.extend(pdos.get(i).and_then(|p| p.1.get(k)).copied().unwrap_or(0).to_le_bytes());
        }
    }
    d
}

/// Each form of the PDO table the evidence supports (v049's 112-byte
/// slots; the vendor headers' 148-byte slots and 156-byte packed table with
/// vendor id and product code), at 144- and 544-byte packets: applied
/// exactly, read back over CoE, or refused whole; never applied otherwise.
/// Two PDOs of 3 and 2 entries: slotted and packed readings differ.
#[test]
fn every_pdo_table_form_is_applied_exactly_or_refused() {
    use ecmxf_wire::payload::pdo::RX_PDO_ASSIGN;
    use ecmxf_wire::payload::state::StateSet;
    let first = [0x6040_0010u32, 0x607A_0020, 0x60FF_0020];
    let second = [0x6071_0010u32, 0x6060_0008];
    let pdos: [(u16, &[u32]); 2] = [(0x1600, &first), (0x1601, &second)];
    for data_size in [112u16, 512] {
        for (form, declared) in [("v049", 112u16), ("four slots", 148), ("packed", 156)] {
            let config = ecmxf_sim::ChipConfig { strict_lengths: false, ..Default::default() };
            let mut h = Host::with_config(Network::demo(), config);
            bring_up_to_op(&mut h, 4);
            resize(&mut h, data_size);
            h.blocking(&StateSet { target: SlaveSelector::All, state: EcatState::PreOp });
            let (vendor, product) = (h.chip.net.slaves[1].sii().vendor_id, h.chip.net.slaves[1].sii().product_code);
            let table = match declared {
                112 => slotted_pdo_config(1, RX_PDO_ASSIGN, &pdos, 3),
                148 => slotted_pdo_config(1, RX_PDO_ASSIGN, &pdos, 4),
                _ => vendor_pdo_config(vendor, product, 1, RX_PDO_ASSIGN, &pdos),
            };
            assert_eq!(table.len(), usize::from(declared));
            let label = format!("{form} ({declared} bytes) in {data_size}-byte data");
            let before: Vec<i64> = (0..=3).map(|k| h.chip.net.slaves[1].od.int(0x1600, k)).collect();
            // A packet carries what fits; the length still says the whole.
            let sent = &table[..table.len().min(usize::from(data_size))];
            let a = send_declaring(&mut h, CommandCode::PdoConfigSet, 90, sent, declared);
            let refused = a.header.errors.contains(ErrorFlags::COMMAND_ERROR) || {
                let after = h.wait_idle();
                after.errors.contains(ErrorFlags::BLOCKING_FAILED)
            };
            let od = &h.chip.net.slaves[1].od;
            let read = |index: u16, n: usize| (1..=n as u8).map(|k| od.int(index, k) as u32).collect::<Vec<_>>();
            if declared > data_size {
                assert!(refused, "{label}: a table longer than the packet's data");
                let now: Vec<i64> = (0..=3).map(|k| od.int(0x1600, k)).collect();
                assert_eq!(now, before, "{label}: nothing applied");
                continue;
            }
            assert!(!refused, "{label}: refused");
            assert_eq!(
                (od.int(RX_PDO_ASSIGN, 0), od.int(RX_PDO_ASSIGN, 1), od.int(RX_PDO_ASSIGN, 2)),
                (2, 0x1600, 0x1601)
            );
            assert_eq!((od.int(0x1600, 0), read(0x1600, 3)), (3, first.to_vec()), "{label}");
            assert_eq!((od.int(0x1601, 0), read(0x1601, 2)), (2, second.to_vec()), "{label}");
        }
    }
    // A packed table whose counts it cannot hold (9 entries in a PDO) is
    // refused whole, the mapping left as it was.
    let config = ecmxf_sim::ChipConfig { strict_lengths: false, ..Default::default() };
    let mut h = Host::with_config(Network::demo(), config);
    bring_up_to_op(&mut h, 4);
    resize(&mut h, 512);
    h.blocking(&StateSet { target: SlaveSelector::All, state: EcatState::PreOp });
    let mut table = vendor_pdo_config(0, 0, 1, RX_PDO_ASSIGN, &pdos);
    table[20] = 9;
    let before: Vec<i64> = (0..=3).map(|k| h.chip.net.slaves[1].od.int(0x1600, k)).collect();
    let a = send_declaring(&mut h, CommandCode::PdoConfigSet, 91, &table, 156);
    let refused = a.header.errors.contains(ErrorFlags::COMMAND_ERROR)
        || h.wait_idle().errors.contains(ErrorFlags::BLOCKING_FAILED);
    assert!(refused, "9 entries in one PDO of the packed table");
    let now: Vec<i64> = (0..=3).map(|k| h.chip.net.slaves[1].od.int(0x1600, k)).collect();
    assert_eq!(now, before);
}

/// v049 gives each command's data length ("資料長度") but never says the
/// chip refuses a packet declaring another; the vendor's own host driver
/// declares 0 for DCSYNC's filled 16 bytes and 156 (its `PDO_CONFIG_HEAD`)
/// for PDO_CONFIG_SET and PDO_CONFIG_REQ, and its calls work on the chip.
/// So the simulated chip takes the fields from their places, reads the
/// vendor's 156-byte form by its length, and counts each difference.
#[test]
fn the_vendor_drivers_declared_lengths_are_taken_as_the_chip_takes_them() {
    use ecmxf_wire::payload::pdo::{PdoConfigForm, PdoConfigGet, PdoConfigReply, RX_PDO_ASSIGN};
    use ecmxf_wire::payload::state::{StateGet, StateReply, StateSet};
    let config = ecmxf_sim::ChipConfig { strict_lengths: false, ..Default::default() };
    let mut h = Host::with_config(Network::demo(), config);
    bring_up_to_op(&mut h, 4);
    // The vendor's 156-byte form needs packets larger than the default 112.
    resize(&mut h, 256);
    h.blocking(&StateSet { target: SlaveSelector::All, state: EcatState::PreOp });
    let s: StateReply = h.get(&StateGet(SlaveSelector::All));
    assert_eq!(s.0, EcatState::PreOp);

    // DCSYNC as the vendor's ECM_EcatSetDCSync sends it: slave 1, reserved,
    // DC activate 0x0300, SYNC0 500 us, SYNC1 0, shift 0, declared as 0.
    let mut dc = vec![1u8, 0, 0x00, 0x03];
    dc.extend(500_000u32.to_le_bytes());
    dc.extend([0u8; 8]);
    let a = send_declaring(&mut h, CommandCode::DcSync, 201, &dc, 0);
    assert!(!a.header.errors.contains(ErrorFlags::COMMAND_ERROR), "{:?}", a.header);
    let after = h.wait_idle();
    assert!(!after.errors.contains(ErrorFlags::BLOCKING_FAILED), "{after:?}");
    assert_eq!(h.chip.net.slaves[1].dc_cycle_ns, 500_000, "the 16 bytes were read whatever the length said");
    assert_eq!(h.chip.stats.length_mismatches, 1);

    // PDO_CONFIG_SET in the vendor's 156-byte form: the TI drive's outputs
    // become axis 1's controlword and target position (slave 1).
    let (vendor, product) = (h.chip.net.slaves[1].sii().vendor_id, h.chip.net.slaves[1].sii().product_code);
    let entries = [0x6040_0010u32, 0x607A_0020];
    let set = vendor_pdo_config(vendor, product, 1, RX_PDO_ASSIGN, &[(0x1600, &entries)]);
    let a = send_declaring(&mut h, CommandCode::PdoConfigSet, 202, &set, 156);
    assert!(!a.header.errors.contains(ErrorFlags::COMMAND_ERROR), "{:?}", a.header);
    let after = h.wait_idle();
    assert!(!after.errors.contains(ErrorFlags::BLOCKING_FAILED), "{after:?}");
    assert_eq!(h.chip.net.slaves[1].od.int(0x1600, 0), 2);
    assert_eq!(h.chip.net.slaves[1].od.int(0x1600, 2), 0x607A_0020);

    // PDO_CONFIG_REQ the way the driver sends it (its struct with only
    // slave and assignment filled, 156 declared): GET answers in that form,
    // the slave's identity ahead of the fields.
    let req = vendor_pdo_config(0, 0, 1, RX_PDO_ASSIGN, &[]);
    let a = send_declaring(&mut h, CommandCode::PdoConfigReq, 203, &req, 156);
    assert!(!a.header.errors.contains(ErrorFlags::COMMAND_ERROR), "{:?}", a.header);
    h.wait_idle();
    let a = h.call(&PdoConfigGet);
    assert_eq!(a.header.data_len, 156, "answered in the form asked");
    assert_eq!(&a.data[..8], &[vendor.to_le_bytes(), product.to_le_bytes()].concat()[..]);
    assert_eq!(a.data[8], 1, "slave");
    let back = PdoConfigReply::decode(&fields(&a), &a.data).unwrap().0;
    assert_eq!(back.form, PdoConfigForm::Identified { vendor_id: vendor, product_code: product });
    assert_eq!(back.used().len(), 1);
    assert_eq!(back.used()[0].index, 0x1600);
    assert_eq!(back.used()[0].used().iter().map(|e| e.to_u32()).collect::<Vec<_>>(), entries);
    // Both vendor-form packets are v049-length mismatches, and counted.
    assert_eq!(h.chip.stats.length_mismatches, 3);
    let status = ecmxf_sim::control::execute(&mut h.chip, "status").unwrap();
    assert!(status.contains("length_mismatches=3"), "{status}");
}

/// With strict lengths (the daemon's tests), the same packets are refused
/// whole (error bit7) and nothing runs: ecmxfd's packets must be v049-exact.
#[test]
fn strict_lengths_refuse_a_declared_length_that_is_not_the_layouts() {
    use ecmxf_wire::payload::pdo::{PdoConfigReq, TX_PDO_ASSIGN};
    use ecmxf_wire::{CheckType, CommandHeader, encode_request};
    let config = ecmxf_sim::ChipConfig { strict_lengths: true, ..Default::default() };
    let mut h = Host::with_config(Network::demo(), config);
    h.call(&InfoUpdate);
    resize(&mut h, 256);
    let req = PdoConfigReq { slave: 0, assign_index: TX_PDO_ASSIGN, ..Default::default() };
    for (index, len, refused) in [(101u8, 156u16, true), (102, 3, true), (103, 5, true), (104, 4, false)] {
        let executed = h.chip.stats.executed;
        let mut buf = vec![0u8; h.packet_len()];
        encode_request(&req, CommandHeader::new(CommandCode::PdoConfigReq, index), CheckType::Fixed, &mut buf).unwrap();
        buf[14..16].copy_from_slice(&len.to_le_bytes());
        if len == 156 {
            // The vendor's form, its fields where it has them: read fine,
            // and still not v049's length.
            let mut header = CommandHeader::new(CommandCode::PdoConfigReq, index);
            header.data_len = len;
            let form = vendor_pdo_config(0, 0, 0, TX_PDO_ASSIGN, &[]);
            ecmxf_wire::encode_command(&header, &form, CheckType::Fixed, &mut buf).unwrap();
        }
        h.exchange_raw(&buf);
        let (bytes, _) = h.send(&InfoUpdate);
        let a = h.decode(&bytes).unwrap();
        assert_eq!(a.header.index, index, "the answer is to the request");
        assert_eq!(a.header.errors.contains(ErrorFlags::COMMAND_ERROR), refused, "{len} bytes: {:?}", a.header);
        assert_eq!(h.chip.pending.is_some(), !refused, "{len} bytes: the read runs only with a layout's length");
        assert_eq!(h.chip.stats.executed, executed + 2, "the packet was taken (and answered)");
        h.control = ControlFlags::CLEAR_COMMAND_ERROR;
        h.wait_idle();
    }
    assert_eq!(h.chip.stats.length_mismatches, 0, "a refused packet is not also counted as taken");
}

/// v049: EEPROM_GET's return value is the operation's error code. After a
/// request that failed or timed out, GET says so and hands back no data,
/// never the previous read's word as if it were this one's.
#[test]
fn a_failed_request_is_never_answered_with_the_previous_ones_data() {
    use ecmxf_sim::chip::result_code::{RESULT_FAILED, RESULT_TIMED_OUT};
    use ecmxf_wire::payload::eeprom::EepromReply;
    use ecmxf_wire::payload::sdo::{SdoGet, SdoGetReply};
    let mut h = Host::new(Network::demo());
    bring_up_to_op(&mut h, 8);
    h.blocking(&EepromRequest { slave: 0, access: EepromAccess::Read { address: 8 }, timeout_us: 100_000 });
    let a = h.call(&EepromGet);
    let ok = EepromReply::decode(&fields(&a), &a.data).unwrap();
    assert_eq!((ok.error, ok.data.len() >= 2), (0, true));

    let timed_out = EepromRequest { slave: 0, access: EepromAccess::Read { address: 0x0A }, timeout_us: 10 };
    let after = h.blocking(&timed_out);
    assert!(after.errors.contains(ErrorFlags::BLOCKING_FAILED));
    let a = h.call(&EepromGet);
    let r = EepromReply::decode(&fields(&a), &a.data).unwrap();
    assert_eq!((r.error, r.data), (RESULT_TIMED_OUT, &[][..]), "no stale word with error 0");

    h.control = ControlFlags::CLEAR_BLOCKING_ERROR;
    h.blocking(&sdo_read(0, 0x1000));
    let a = h.call(&SdoGet);
    let good = SdoGetReply::decode(&fields(&a), &a.data).unwrap();
    assert_eq!((good.status, good.data.len()), (0, 4));
    h.control = ControlFlags::CLEAR_BLOCKING_ERROR;
    h.blocking(&sdo_read(0, 0x5555));
    let a = h.call(&SdoGet);
    assert_eq!(
        (a.header.return_value, a.data.len()),
        (RESULT_FAILED, 0),
        "a failed read's GET is empty, with its code"
    );
}
