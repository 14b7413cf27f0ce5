//! The chip's SPI behaviour: NOP after power-up, one-behind answers,
//! deduplication, check words and their switching, resizing and resync,
//! readiness and the INT lines. Each test would fail on a chip that got the
//! documented behaviour wrong.

mod common;

use common::Host;
use ecmxf_sim::Network;
use ecmxf_wire::check::CHECK_NOT_READY;
use ecmxf_wire::flags::{ControlFlags, ErrorFlags, InterruptFlags, StatusFlags};
use ecmxf_wire::framing::find_packet_start;
use ecmxf_wire::payload::control::{FirmwareVersion, FwVersionGet, InfoUpdate};
use ecmxf_wire::payload::interrupt::{IntConfig, IntPolarity, IntSetEnable};
use ecmxf_wire::payload::slave_info::{SlaveCount, SlaveCountGet};
use ecmxf_wire::payload::spi::{
    CrcErrCountClear, CrcErrorsCleared, CrcTypeSet, SpiPackSize, SpiPackSizeGet, SpiReconfig,
};
use ecmxf_wire::{CheckType, CommandCode, CommandHeader, DecodeError, decode_response, encode_request};

#[test]
fn first_answer_after_power_up_is_a_nop() {
    let mut h = Host::new(Network::demo());
    let (bytes, _) = h.send(&FwVersionGet);
    let a = h.decode(&bytes).unwrap();
    assert!(a.header.is_nop());
    assert_eq!(a.header.status.check_type, CheckType::Fixed);
    // The next one answers the firmware request, not a NOP.
    let (bytes, _) = h.send(&InfoUpdate);
    let a = h.decode(&bytes).unwrap();
    assert!(!a.header.is_nop());
    assert_eq!(a.header.code, CommandCode::FwVersionGet);
    assert_eq!(a.header.return_value, 0x24);
}

#[test]
fn answers_ride_one_exchange_behind_with_index_and_code_echoed() {
    let mut h = Host::new(Network::demo());
    let (_, s1) = h.send(&SlaveCountGet);
    let (b2, s2) = h.send(&FwVersionGet);
    let (b3, _) = h.send(&InfoUpdate);
    let a2 = h.decode(&b2).unwrap();
    let a3 = h.decode(&b3).unwrap();
    assert_eq!((a2.header.index, a2.header.code, a2.header.return_value), (s1.index, CommandCode::SlaveCountGet, 3));
    assert_eq!((a3.header.index, a3.header.code, a3.header.return_value), (s2.index, CommandCode::FwVersionGet, 0x24));
}

/// Sends a packet with a bad check word and then reads the status.
fn send_corrupt(h: &mut Host) {
    let mut buf = vec![0u8; h.packet_len()];
    encode_request(&CrcErrCountClear, CommandHeader::new(CommandCode::CrcErrCountClear, 200), h.check, &mut buf)
        .unwrap();
    buf[30] ^= 0x01;
    let at = buf.len() - 8;
    buf[at] ^= 0xFF;
    h.exchange_raw(&buf);
}

#[test]
fn a_bad_check_word_is_counted_and_not_executed() {
    let mut h = Host::new(Network::demo());
    h.call(&InfoUpdate);
    let executed = h.chip.stats.executed;
    send_corrupt(&mut h);
    assert_eq!(h.chip.stats.executed, executed, "the corrupt command did not run");
    let (bytes, _) = h.send(&InfoUpdate);
    let a = h.decode(&bytes).unwrap();
    assert_eq!(a.header.crc_errors, 1);
    assert!(a.header.errors.contains(ErrorFlags::SPI_CRC_ERROR));
    assert!(a.header.int_flags.contains(InterruptFlags::CRC_ERROR));
    // The clear bits clear the error bit and the interrupt flag.
    h.control = ControlFlags::CLEAR_SPI_CRC_ERROR;
    let a = h.call(&InfoUpdate);
    assert!(!a.header.errors.contains(ErrorFlags::SPI_CRC_ERROR));
}

#[test]
fn the_same_index_and_code_twice_executes_once() {
    let mut h = Host::new(Network::demo());
    send_corrupt(&mut h);
    send_corrupt(&mut h);
    let mut buf = vec![0u8; h.packet_len()];
    encode_request(&CrcErrCountClear, CommandHeader::new(CommandCode::CrcErrCountClear, 77), h.check, &mut buf)
        .unwrap();
    h.exchange_raw(&buf);
    let second = h.exchange_raw(&buf);
    let third = h.exchange_raw(&buf);
    let a = h.decode(&second).unwrap();
    let b = h.decode(&third).unwrap();
    // Both answers report the count the first execution cleared; a second
    // execution would have reported 0.
    assert_eq!((a.header.code, a.header.return_value), (CommandCode::CrcErrCountClear, 2));
    assert_eq!((b.header.index, b.header.return_value), (77, 2), "repeat answers like the original");
    assert_eq!(b.header.crc_errors, 0);
}

#[test]
fn clocking_before_ready_loses_the_command_and_says_not_ready() {
    let mut h = Host::new(Network::demo());
    h.call(&InfoUpdate);
    let (_, sent) = h.send(&FwVersionGet);
    // Immediately, while the chip is still processing.
    assert!(!h.chip.ready(h.now));
    assert!(!h.chip.int0_level(h.now), "INT0 inactive while busy");
    let mut buf = vec![0u8; h.packet_len()];
    encode_request(&SlaveCountGet, CommandHeader::new(CommandCode::SlaveCountGet, 99), h.check, &mut buf).unwrap();
    let early = h.clock(&buf);
    assert_eq!(h.decode(&early).unwrap_err(), DecodeError::ChipNotReady);
    assert_eq!(u32::from_le_bytes(early[136..140].try_into().unwrap()), CHECK_NOT_READY);
    // The pending answer to the firmware request still comes, and the lost
    // SLV_CNT never ran (its answer never shows up).
    let (bytes, _) = h.send(&InfoUpdate);
    let a = h.decode(&bytes).unwrap();
    assert_eq!((a.header.index, a.header.code), (sent.index, CommandCode::FwVersionGet));
    let (bytes, _) = h.send(&InfoUpdate);
    assert_eq!(h.decode(&bytes).unwrap().header.code, CommandCode::InfoUpdate);
    assert_eq!(h.chip.stats.not_ready, 1);
}

#[test]
fn switching_to_crc32_changes_both_directions() {
    let mut h = Host::new(Network::demo());
    h.call(&InfoUpdate);
    h.send(&CrcTypeSet(CheckType::Crc32));
    h.check = CheckType::Crc32;
    let (bytes, _) = h.send(&InfoUpdate);
    let a = h.decode(&bytes).expect("answer carries a CRC-32 check word");
    assert_eq!(a.header.code, CommandCode::CrcTypeSet);
    assert_eq!(a.header.status.check_type, CheckType::Crc32);
    // A packet with the old fixed check word is now a CRC error.
    let mut buf = vec![0u8; h.packet_len()];
    encode_request(&FwVersionGet, CommandHeader::new(CommandCode::FwVersionGet, 123), CheckType::Fixed, &mut buf)
        .unwrap();
    h.exchange_raw(&buf);
    let a = h.call(&InfoUpdate);
    assert_eq!(a.header.crc_errors, 1);
    let v: FirmwareVersion = h.get(&FwVersionGet);
    assert_eq!(v.0, 0x24);
}

/// The vendor's host driver re-sends CRC_TYPE_SET with the fixed check word
/// until the status shows the new type (and its FIFO path always sends it
/// so): the chip takes it like SPI_RECONFIG, and counts no CRC error.
#[test]
fn crc_type_set_is_taken_with_the_fixed_check_word_in_any_type() {
    let mut h = Host::new(Network::demo());
    h.call(&InfoUpdate);
    h.send(&CrcTypeSet(CheckType::Crc32));
    h.check = CheckType::Crc32;
    let before = h.call(&InfoUpdate).header.crc_errors;
    let mut buf = vec![0u8; h.packet_len()];
    encode_request(
        &CrcTypeSet(CheckType::Crc16),
        CommandHeader::new(CommandCode::CrcTypeSet, 77),
        CheckType::Fixed,
        &mut buf,
    )
    .unwrap();
    h.exchange_raw(&buf);
    h.check = CheckType::Crc16;
    let a = h.call(&InfoUpdate);
    assert_eq!(a.header.status.check_type, CheckType::Crc16, "switched");
    assert_eq!(a.header.crc_errors, before, "no CRC error counted");
    assert!(!a.header.errors.contains(ErrorFlags::SPI_CRC_ERROR));
}

#[test]
fn resizing_counts_one_crc_error_and_changes_the_packet_length() {
    let mut h = Host::new(Network::demo());
    h.send(&CrcTypeSet(CheckType::Crc32));
    h.check = CheckType::Crc32;
    h.call(&InfoUpdate);
    // SPI_RECONFIG goes out with the fixed check word whatever is in force.
    let mut buf = vec![0u8; h.packet_len()];
    encode_request(
        &SpiReconfig { data_size: 1408 },
        CommandHeader::new(CommandCode::SpiReconfig, 50),
        CheckType::Fixed,
        &mut buf,
    )
    .unwrap();
    h.exchange_raw(&buf);
    h.data_size = 1408;
    let (bytes, _) = h.send(&InfoUpdate);
    assert_eq!(bytes.len(), 1440);
    let a = h.decode(&bytes).unwrap();
    assert_eq!((a.header.code, a.header.crc_errors), (CommandCode::SpiReconfig, 1));
    let size: SpiPackSize = h.get(&SpiPackSizeGet);
    assert_eq!(size.0, 1408);
    let cleared: CrcErrorsCleared = h.get(&CrcErrCountClear);
    assert_eq!(cleared.0, 1);
}

#[test]
fn a_host_finds_the_packet_size_by_clocking_single_bytes() {
    let mut h = Host::new(Network::demo());
    h.call(&InfoUpdate);
    h.send(&SpiReconfig { data_size: 256 });
    // The host forgot the size: it clocks single bytes until the end word is
    // followed by the start word, as the vendor driver does.
    let mut seen = Vec::new();
    let start = loop {
        h.now = h.now.max(h.chip.ready_at());
        seen.extend(h.clock(&[0]));
        if let Some(at) = find_packet_start(&seen) {
            break at;
        }
        assert!(seen.len() < 4000, "no boundary found");
    };
    // Bytes clocked so far belong to a packet the chip is still collecting;
    // finish it with zeros (it fails its check and is not executed), then
    // exchange whole packets of the size read back.
    let in_packet = seen.len() - start;
    h.now = h.now.max(h.chip.ready_at());
    h.clock(&vec![0u8; 288 - in_packet]);
    h.data_size = 256;
    let size: SpiPackSize = h.get(&SpiPackSizeGet);
    assert_eq!(size.0, 256);
}

#[test]
fn int_lines_follow_readiness_flags_mask_and_polarity() {
    let mut h = Host::new(Network::demo());
    assert!(h.chip.int0_level(0), "INT0 active-high and ready at power-up");
    assert!(h.chip.int1_level(), "INT1 active-low, idle high");
    // Enable the CRC interrupt, INT1 active-high, INT0 active-low.
    let cfg =
        IntConfig { polarity: IntPolarity::INT1_ACTIVE_HIGH, mask: InterruptFlags::CRC_ERROR, ..IntConfig::default() };
    h.send(&IntSetEnable(cfg));
    h.int0_active_high = false;
    assert!(h.chip.int0_level(h.now), "busy now, and INT0 is active-low: high means busy");
    h.now = h.chip.ready_at();
    assert!(!h.chip.int0_level(h.now));
    assert!(!h.chip.int1_level());
    send_corrupt(&mut h);
    assert!(h.chip.int1_level(), "CRC error flag & mask raise INT1");
    // Clearing the flag through the header lowers it.
    h.now = h.chip.ready_at();
    let mut buf = vec![0u8; h.packet_len()];
    let mut header = CommandHeader::new(CommandCode::InfoUpdate, 201);
    header.int_clear = InterruptFlags::CRC_ERROR;
    encode_request(&InfoUpdate, header, h.check, &mut buf).unwrap();
    let mut miso = vec![0u8; buf.len()];
    h.chip.transfer(h.now, &buf, &mut miso);
    assert!(!h.chip.int1_level());
}

#[test]
fn status_bits_after_power_up() {
    let mut h = Host::new(Network::demo());
    let a = h.call(&SlaveCountGet);
    assert_eq!(a.header.return_value, 3);
    assert!(!a.header.status.flags.intersects(StatusFlags::ETHERNET_READY | StatusFlags::BLOCKING_BUSY));
    let n: SlaveCount = h.get(&SlaveCountGet);
    assert_eq!(n.0, 3);
    let _ = decode_response; // used via Host
}
