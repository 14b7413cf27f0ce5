//! The port against the in-process simulator, with the chip's faults: it
//! must get every answer and never execute a command twice.

use std::time::Duration;

use ecmxf_sim::{Chip, ChipConfig, Network};
use ecmxf_wire::payload::control::{FirmwareVersion, FwVersionGet, InfoUpdate};
use ecmxf_wire::payload::slave_info::SlaveCountGet;
use ecmxf_wire::payload::spi::SpiPackSizeGet;
use ecmxf_wire::{CheckType, CommandCode, Reply, ReplyFields};
use ecmxfd::link::Link;
use ecmxfd::link::sim::{SimHandle, SimLink};
use ecmxfd::port::{Port, PortError};

fn port() -> (Port<SimLink>, SimHandle) {
    let (link, handle) = SimLink::new(Chip::new(Network::demo(), ChipConfig::default()));
    (Port::new(link), handle)
}

#[test]
fn calls_get_their_own_answers() {
    let (mut p, h) = port();
    let a = p.call(&FwVersionGet).unwrap();
    assert_eq!((a.header.code, a.header.return_value), (CommandCode::FwVersionGet, 0x24));
    assert!(p.previous().unwrap().header.is_nop(), "the first answer after power-up was a NOP");
    let a = p.call(&SlaveCountGet).unwrap();
    assert_eq!(a.header.return_value, 3);
    let v = FirmwareVersion::decode(&ReplyFields { value: 0x24, data_len: 0 }, &[]).unwrap();
    assert_eq!(v.0, 0x24);
    assert_eq!(h.with_chip(|c| c.stats.executed), 2, "two commands, each executed once");
}

#[test]
fn bit_flips_never_execute_a_command_twice() {
    let (mut p, h) = port();
    // The power-up fixed check word covers nothing: a flipped bit in an
    // answer would pass. CRC-32 first, as bring-up does.
    p.set_check(CheckType::Crc32).unwrap();
    h.control("seed 7").unwrap();
    h.control("flip mosi 0.0005").unwrap();
    h.control("flip miso 0.0005").unwrap();
    let before = h.with_chip(|c| c.stats.executed);
    let n = 1500;
    for _ in 0..n {
        let a = p.call(&SlaveCountGet).expect("answer despite flips");
        assert_eq!((a.header.code, a.header.return_value), (CommandCode::SlaveCountGet, 3));
    }
    let executed = h.with_chip(|c| c.stats.executed) - before;
    let stats = p.stats();
    assert_eq!(executed, n, "every command ran exactly once ({stats:?})");
    assert!(stats.retries > 10 && stats.corrupt > 10, "the faults were real: {stats:?}");
    assert!(h.with_chip(|c| c.stats.crc_failures) > 5, "the chip refused corrupt packets too");
}

#[test]
fn check_type_and_size_changes() {
    let (mut p, h) = port();
    p.set_check(CheckType::Crc32).unwrap();
    assert_eq!(p.check(), CheckType::Crc32);
    assert_eq!(h.with_chip(|c| c.check), CheckType::Crc32);
    p.resize(1408).unwrap();
    assert_eq!(p.ask(&SpiPackSizeGet).unwrap().0, 1408);
    p.resize(256).unwrap();
    assert_eq!(h.with_chip(|c| c.spi.data_size), 256);
}

#[test]
fn synchronizes_with_a_chip_in_an_unknown_state() {
    let (mut setup, h) = port();
    setup.set_check(CheckType::Crc32).unwrap();
    setup.resize(600).unwrap();
    // Leave the chip mid-packet, as a crashed host would.
    let mut link = setup.into_link();
    let mut rx = [0u8; 77];
    link.wait_ready(Duration::from_millis(10)).unwrap();
    link.transfer(&[0x55; 77], &mut rx).unwrap();
    // A new port knows nothing and finds size and check type.
    let mut p = Port::new(link);
    p.synchronize().unwrap();
    assert_eq!((p.data_size(), p.check()), (600, CheckType::Crc32));
    assert_eq!(p.call(&SlaveCountGet).unwrap().header.return_value, 3);
    assert!(h.with_chip(|c| c.stats.crc_failures) >= 1);
}

#[test]
fn a_stuck_int0_is_an_error_not_a_hang() {
    let (mut p, h) = port();
    p.set_ready_timeout(Duration::from_millis(20));
    h.control("int0 stuck low").unwrap();
    assert!(matches!(p.call(&InfoUpdate), Err(PortError::NotReady(_))));
    h.control("int0 stuck off").unwrap();
    assert!(p.call(&InfoUpdate).is_ok());
}

/// A packet sent once keeps its answer whatever exchanges bring it: two
/// guarded calls after it (a FIFO exchange or two, as the running loop
/// makes them while the FIFO presses) used to leave only their own answers
/// to look at, so a read started once looked lost and ran again, and again
/// while the FIFO kept pressing (a layout read took seconds). The three
/// newest packets sent once are kept; an older one is not.
#[test]
fn answers_to_packets_sent_once_outlive_the_calls_after_them() {
    let (mut p, _h) = port();
    p.set_check(CheckType::Crc32).unwrap();
    let asked = p.send_once(&FwVersionGet).unwrap();
    for _ in 0..2 {
        p.call(&SlaveCountGet).unwrap();
    }
    assert_ne!(p.previous().map(|a| a.header.code), Some(CommandCode::FwVersionGet), "the previous answer moved on");
    let a = p.answer_to(asked, CommandCode::FwVersionGet).expect("the answer kept");
    assert_eq!(a.header.return_value, 0x24);
    assert!(p.answer_to(asked, CommandCode::SlaveCountGet).is_none(), "an index answers its own command only");

    // Only the newest packets sent once are remembered.
    let first = p.send_once(&InfoUpdate).unwrap();
    for _ in 0..ecmxfd::port::ONCE_KEPT {
        p.send_once(&InfoUpdate).unwrap();
    }
    p.call(&SlaveCountGet).unwrap();
    assert!(p.answer_to(first, CommandCode::InfoUpdate).is_none(), "pushed out by newer ones");
}
