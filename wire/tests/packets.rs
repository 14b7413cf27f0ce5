//! Whole-packet tests: golden packets written out by hand from the v049
//! tables (CRC-32 check words computed independently with Python's
//! `zlib.crc32`, not by this crate), corruption detection, and decoding of
//! arbitrary bytes never panicking.

use ecmxf_wire::flags::{ControlFlags, EcatState, ErrorFlags, InterruptFlags, StatusFlags};
use ecmxf_wire::framing::find_packet_start;
use ecmxf_wire::payload::control::InfoUpdate;
use ecmxf_wire::payload::pdo::{PdoConfig, PdoEntry, RX_PDO_ASSIGN};
use ecmxf_wire::payload::sdo::{SdoAccess, SdoRequest};
use ecmxf_wire::payload::state::StateReply;
use ecmxf_wire::{
    CheckType, CommandCode, CommandHeader, DecodeError, EncodeError, PayloadError, ResponseHeader, decode_command,
    decode_response, encode_command, encode_request, encode_response,
};
use proptest::prelude::*;

/// Header bytes, then 112-byte data section, then check word and end word.
fn packet(header: [u8; 24], data: &[u8], check: u32) -> Vec<u8> {
    let mut p = header.to_vec();
    let mut section = [0u8; 112];
    section[..data.len()].copy_from_slice(data);
    p.extend_from_slice(&section);
    p.extend_from_slice(&check.to_le_bytes());
    p.extend_from_slice(&[0x59, 0x58, 0x57, 0x56]);
    p
}

#[test]
fn golden_default_info_update() {
    #[rustfmt::skip]
    let header = [
        0xA4, 0xA3, 0xA2, 0xA1, // start word
        0, 0, 0, 0,             // command data 0..3
        0, 0,                   // reserved
        0x00,                   // control
        0x01,                   // index
        0x00,                   // code: INFO_UPDATE
        0x00,                   // parameter
        0, 0,                   // data length
        0, 0, 0, 0,             // interrupt clear
        0, 0, 0, 0,             // GPIO int clear, GPIO out
    ];
    let expected = packet(header, &[], 0x1234_5678);
    assert_eq!(expected.len(), 144);

    let mut buf = [0xEEu8; 144];
    encode_request(&InfoUpdate, CommandHeader::new(CommandCode::InfoUpdate, 1), CheckType::Fixed, &mut buf).unwrap();
    assert_eq!(buf.to_vec(), expected);

    let back = decode_command(&buf, CheckType::Fixed).unwrap();
    assert_eq!(back.header.index, 1);
    assert_eq!(back.parse().unwrap().code(), CommandCode::InfoUpdate);
}

#[test]
fn golden_sdo_read_request_crc32() {
    #[rustfmt::skip]
    let header = [
        0xA4, 0xA3, 0xA2, 0xA1, 0, 0, 0, 0, 0, 0,
        0x00, 0x42, 0x0A, 0x00, // control, index 0x42, SDO_REQ, parameter
        12, 0,                  // data length 12
        0, 0, 0, 0, 0, 0, 0, 0,
    ];
    #[rustfmt::skip]
    let data = [
        0x01,       // read
        0x01,       // slave 1
        0x41, 0x60, // 0x6041
        0x00,       // subindex
        0x00,       // no complete access
        0x02, 0x00, // 2 bytes expected
        0xA0, 0x86, 0x01, 0x00, // 100000 us
    ];
    let expected = packet(header, &data, 0x4A0E_6403);

    let req = SdoRequest {
        slave: 1,
        index: 0x6041,
        subindex: 0,
        complete_access: false,
        timeout_us: 100_000,
        access: SdoAccess::Read { max_len: 2 },
    };
    let mut buf = [0u8; 144];
    encode_request(&req, CommandHeader::new(CommandCode::SdoReq, 0x42), CheckType::Crc32, &mut buf).unwrap();
    assert_eq!(buf.to_vec(), expected);
    assert_eq!(decode_command(&buf, CheckType::Crc32).unwrap().request::<SdoRequest>().unwrap(), req);
}

#[test]
fn golden_pdo_config_set_crc32() {
    #[rustfmt::skip]
    let header = [
        0xA4, 0xA3, 0xA2, 0xA1, 0, 0, 0, 0, 0, 0,
        0x00, 0x07, 0x07, 0x00, // index 7, PDO_CONFIG_SET
        112, 0,
        0, 0, 0, 0, 0, 0, 0, 0,
    ];
    let mut data = vec![
        0x01, 0x01, 0x12, 0x1C, // slave 1, 1 PDO, 0x1C12
        0x00, 0x16, 0x00, 0x00, 0x00, 0x00, // mapping 0x1600, 0, 0
        0x02, 0x00, 0x00, 0x00, 0x00, 0x00, // 2 entries, 0, 0
        0x10, 0x00, 0x40, 0x60, // 0x6040:00, 16 bits
        0x20, 0x00, 0x7A, 0x60, // 0x607A:00, 32 bits
    ];
    data.resize(112, 0);
    let expected = packet(header, &data, 0x86C1_B3C1);

    let entries =
        [PdoEntry { index: 0x6040, subindex: 0, bits: 16 }, PdoEntry { index: 0x607A, subindex: 0, bits: 32 }];
    let cfg = PdoConfig::new(1, RX_PDO_ASSIGN, &[(0x1600, &entries)]).unwrap();
    let mut buf = [0u8; 144];
    encode_request(&cfg, CommandHeader::new(CommandCode::PdoConfigSet, 7), CheckType::Crc32, &mut buf).unwrap();
    assert_eq!(buf.to_vec(), expected);
}

#[test]
fn golden_response_with_every_status_bit() {
    #[rustfmt::skip]
    let header = [
        0xA4, 0xA3, 0xA2, 0xA1,
        3, 4, 5, 6,             // CRC errors, WKC errors, TxFIFO, RxFIFO
        0x08, 0xFF, 0xFF,       // OP, every error bit, every status bit
        0x42, 0x0A, 0x00,       // index, SDO_REQ echoed, return value
        0, 0,
        0x00, 0x00, 0xC0, 0xA3, // interrupt flags 31, 29, 25, 24, 23, 22
        0xFF, 0xFF, 0xFF, 0x0F, // GPIO int flags, GPIO inputs
    ];
    let bytes = packet(header, &[], 0x4994_FC8F);
    let r = decode_response(&bytes, CheckType::Crc32).unwrap();
    let h = r.header;
    assert_eq!((h.crc_errors, h.wkc_errors, h.tx_fifo_count, h.rx_fifo_count), (3, 4, 5, 6));
    assert_eq!(h.ecat_state, EcatState::Op);
    assert!(h.errors.contains(ErrorFlags::all()));
    assert_eq!(h.status.check_type, CheckType::Crc32);
    assert!(h.status.flags.contains(StatusFlags::all()));
    assert!(h.is_nop() && h.blocking_busy());
    assert_eq!(h.int_flags, InterruptFlags::all());
    assert_eq!((h.gpio_int_flags, h.gpio_inputs), (0xFFFF, 0x0FFF));
    assert_eq!(h.code, CommandCode::SdoReq);
    // A NOP answers nothing, whatever code it echoes.
    assert_eq!(r.reply::<StateReply>(), Err(PayloadError::Nop));

    let mut again = [0u8; 144];
    encode_response(&h, &[], CheckType::Crc32, &mut again).unwrap();
    assert_eq!(again.to_vec(), bytes);
}

fn sample_command(check: CheckType, len: usize) -> Vec<u8> {
    let mut buf = vec![0u8; len];
    let mut header = CommandHeader::new(CommandCode::SdoReq, 9).with_gpio_output(0x0A5A);
    header.control |= ControlFlags::CLEAR_FIFO_ERROR;
    let req = SdoRequest {
        slave: 3,
        index: 0x2000,
        subindex: 1,
        complete_access: false,
        timeout_us: 5000,
        access: SdoAccess::Write(&[1, 2, 3, 4]),
    };
    encode_request(&req, header, check, &mut buf).unwrap();
    buf
}

#[test]
fn every_check_type_and_size_round_trips() {
    for check in CheckType::ALL {
        for len in [64, 144, 1024, 1440] {
            let buf = sample_command(check, len);
            let p = decode_command(&buf, check).unwrap();
            assert_eq!(p.header.gpio_output, 0x0A5A);
            assert!(p.header.control.contains(ControlFlags::HEADER_GPIO_VALID | ControlFlags::CLEAR_FIFO_ERROR));
            assert!(p.request::<SdoRequest>().is_ok());
        }
    }
}

#[test]
fn a_check_word_is_validated_with_the_type_asked_for() {
    let buf = sample_command(CheckType::Crc32, 144);
    for other in [CheckType::Fixed, CheckType::Crc8, CheckType::Crc16] {
        assert!(
            matches!(decode_command(&buf, other), Err(DecodeError::CheckWord { check_type, .. }) if check_type == other)
        );
    }
}

#[test]
fn not_ready_is_its_own_outcome() {
    let mut buf = sample_command(CheckType::Crc32, 144);
    buf[136..140].copy_from_slice(&0x8765_4321u32.to_le_bytes());
    assert_eq!(decode_response(&buf, CheckType::Crc32), Err(DecodeError::ChipNotReady));
    assert_eq!(decode_response(&buf, CheckType::Fixed), Err(DecodeError::ChipNotReady));
}

#[test]
fn framing_errors_are_named() {
    let good = sample_command(CheckType::Crc32, 144);
    let mut b = good.clone();
    b[0] = 0;
    assert_eq!(decode_command(&b, CheckType::Crc32), Err(DecodeError::StartWord { found: 0xA1A2_A300 }));
    let mut b = good.clone();
    b[143] = 0;
    assert_eq!(decode_command(&b, CheckType::Crc32), Err(DecodeError::EndWord { found: 0x0057_5859 }));
    // 143 bytes is a legal length (data section 111), so the cut shows up
    // as a wrong end word; 63 is too short to be a packet at all.
    assert!(matches!(decode_command(&good[..143], CheckType::Crc32), Err(DecodeError::EndWord { .. })));
    assert_eq!(decode_command(&good[..63], CheckType::Crc32), Err(DecodeError::PacketLength { len: 63 }));
    assert_eq!(decode_command(&[], CheckType::Crc32), Err(DecodeError::PacketLength { len: 0 }));
    let mut big = good.clone();
    big.resize(1441, 0);
    assert_eq!(decode_command(&big, CheckType::Crc32), Err(DecodeError::PacketLength { len: 1441 }));
}

#[test]
fn response_data_length_beyond_section_is_rejected() {
    let h = ResponseHeader { data_len: 113, ..ResponseHeader::default() };
    let mut buf = [0u8; 144];
    encode_response(&h, &[], CheckType::Crc32, &mut buf).unwrap();
    assert_eq!(decode_response(&buf, CheckType::Crc32), Err(DecodeError::DataLength { declared: 113, capacity: 112 }));
}

#[test]
fn encoding_refuses_bad_buffers() {
    let mut small = [0u8; 63];
    assert_eq!(
        encode_request(&InfoUpdate, CommandHeader::default(), CheckType::Fixed, &mut small),
        Err(EncodeError::PacketLength { len: 63 })
    );
    let mut buf = [0u8; 64];
    assert_eq!(
        encode_command(&CommandHeader::default(), &[0; 33], CheckType::Fixed, &mut buf),
        Err(EncodeError::PayloadTooLarge { needed: 33, capacity: 32 })
    );
}

#[test]
fn unused_data_section_is_zeroed_before_the_check_word() {
    let mut buf = [0xAAu8; 144];
    encode_request(&InfoUpdate, CommandHeader::default(), CheckType::Crc32, &mut buf).unwrap();
    assert!(buf[24..136].iter().all(|&b| b == 0));
}

#[test]
fn boundary_search_finds_the_next_packet_in_a_stream() {
    let a = sample_command(CheckType::Fixed, 144);
    let b = sample_command(CheckType::Fixed, 144);
    // A stream clocked from the middle of one packet into the next.
    let mut stream = a[57..].to_vec();
    stream.extend_from_slice(&b);
    let start = find_packet_start(&stream).unwrap();
    assert_eq!(start, 144 - 57);
    assert!(decode_command(&stream[start..start + 144], CheckType::Fixed).is_ok());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    /// Any bytes of any length decode to Ok or a typed error.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..1500), t in 0u8..4) {
        let check = CheckType::from_bits(t);
        if let Ok(p) = decode_response(&bytes, check) {
            let _ = p.reply::<StateReply>();
        }
        if let Ok(p) = decode_command(&bytes, check) {
            let _ = p.parse();
        }
    }

    /// Validly framed commands with arbitrary headers and data parse to Ok or
    /// a typed error, for every code.
    #[test]
    fn framed_garbage_commands_never_panic(
        header in proptest::array::uniform24(any::<u8>()),
        data in proptest::collection::vec(any::<u8>(), 32..=1408),
    ) {
        let mut h = header;
        h[..4].copy_from_slice(&[0xA4, 0xA3, 0xA2, 0xA1]);
        let decoded = CommandHeader::decode(&h).unwrap();
        let mut buf = vec![0u8; data.len() + 32];
        encode_command(&decoded, &data, CheckType::Crc32, &mut buf).unwrap();
        let p = decode_command(&buf, CheckType::Crc32).unwrap();
        prop_assert_eq!(p.header, decoded);
        let _ = p.parse();
    }

    /// Truncating a valid packet never yields a packet.
    #[test]
    fn truncation_is_detected(cut in 1usize..144) {
        let buf = sample_command(CheckType::Crc32, 144);
        prop_assert!(decode_command(&buf[..144 - cut], CheckType::Crc32).is_err());
    }

    /// With CRC-32, flipping any one bit anywhere is detected, and named by
    /// where it landed.
    #[test]
    fn single_bit_flips_are_detected(pos in 0usize..144, bit in 0u8..8) {
        let mut buf = sample_command(CheckType::Crc32, 144);
        buf[pos] ^= 1 << bit;
        let err = decode_command(&buf, CheckType::Crc32).unwrap_err();
        match pos {
            0..=3 => prop_assert!(matches!(err, DecodeError::StartWord { .. }), "{:?}", err),
            140..=143 => prop_assert!(matches!(err, DecodeError::EndWord { .. }), "{:?}", err),
            _ => prop_assert!(matches!(err, DecodeError::CheckWord { .. }), "{:?}", err),
        }
    }

    /// Headers round-trip through their 24 bytes.
    #[test]
    fn headers_round_trip(bytes in proptest::array::uniform24(any::<u8>())) {
        let mut b = bytes;
        b[..4].copy_from_slice(&[0xA4, 0xA3, 0xA2, 0xA1]);
        let c = CommandHeader::decode(&b).unwrap();
        let mut out = [0u8; 24];
        c.encode(&mut out);
        prop_assert_eq!(out, b);
        let r = ResponseHeader::decode(&b).unwrap();
        r.encode(&mut out);
        prop_assert_eq!(out, b);
    }
}

/// DCSYNC as the vendor's driver sends it: the 16-byte layout filled and a
/// data length of 0 declared. `parse` holds the packet to v049 and refuses
/// it; `parse_declared_len_aside` reads the fields from their places, as the
/// chip does, and hands back the difference for the caller to count.
#[test]
fn a_fixed_layout_is_read_from_its_places_whatever_the_length_declares() {
    use ecmxf_wire::AnyRequest;
    let mut data = vec![2u8, 0, 0x00, 0x03];
    data.extend(1_000_000u32.to_le_bytes());
    data.extend([0u8; 8]);
    let mut header = CommandHeader::new(CommandCode::DcSync, 9);
    header.data_len = 0;
    let mut buf = vec![0u8; 144];
    encode_command(&header, &data, CheckType::Fixed, &mut buf).unwrap();
    let cmd = decode_command(&buf, CheckType::Fixed).unwrap();
    let mismatch = PayloadError::DataLength { command: CommandCode::DcSync, expected: 16, found: 0 };
    assert_eq!(cmd.parse(), Err(mismatch));
    let (req, aside) = cmd.parse_declared_len_aside().unwrap();
    assert_eq!(aside, Some(mismatch));
    let AnyRequest::DcSync(d) = req else { panic!("{req:?}") };
    assert_eq!((d.slave, d.dc.assign_activate, d.dc.sync0_ns), (2, 0x0300, 1_000_000));

    // A packet with its own length has nothing set aside.
    header.data_len = 16;
    encode_command(&header, &data, CheckType::Fixed, &mut buf).unwrap();
    let cmd = decode_command(&buf, CheckType::Fixed).unwrap();
    assert_eq!(cmd.parse_declared_len_aside().unwrap().1, None);
}

/// An answer is read through the request that asked for it, as the type
/// that request names (`Request::Answer`): SDO_GET's bytes, SLAVE_INFO's
/// item (which only the request says), a command that only runs; another
/// command's answer and a NOP are refused, never read as this one's.
#[test]
fn an_answer_reads_as_the_type_its_request_names() {
    use ecmxf_wire::payload::sdo::{SdoGet, SdoGetReply};
    use ecmxf_wire::payload::slave_info::{SlaveInfo, SlaveInfoCode, SlaveInfoGet};
    use ecmxf_wire::{Done, encode_reply};
    let mut buf = vec![0u8; 112 + 32];
    let status = ecmxf_wire::EcmStatus { check_type: CheckType::Crc32, flags: StatusFlags::empty() };
    let base = ResponseHeader { index: 3, status, ..ResponseHeader::default() };
    encode_reply(&SdoGetReply { status: 0, data: &[1, 2, 3, 4] }, base, CheckType::Crc32, &mut buf).unwrap();
    let r = decode_response(&buf, CheckType::Crc32).unwrap();
    assert_eq!(r.answer_to(&SdoGet), Ok(SdoGetReply { status: 0, data: &[1, 2, 3, 4] }));
    assert_eq!(
        r.answer_to(&InfoUpdate),
        Err(PayloadError::WrongCommand { expected: CommandCode::InfoUpdate, found: CommandCode::SdoGet })
    );

    // The same four bytes are a vendor id or a configured address: the
    // request decides.
    let vendor = SlaveInfo::VendorId(0x0000_0a5b);
    let mut data = [0u8; 4];
    let fields = vendor.encode(&mut data).unwrap();
    let header = ResponseHeader { code: CommandCode::SlaveInfoGet, data_len: fields.data_len, ..base };
    let mut buf = vec![0u8; 112 + 32];
    encode_response(&header, &data[..usize::from(fields.data_len)], CheckType::Crc32, &mut buf).unwrap();
    let r = decode_response(&buf, CheckType::Crc32).unwrap();
    assert_eq!(r.answer_to(&SlaveInfoGet { slave: 0, item: SlaveInfoCode::VendorId }), Ok(vendor));
    assert_eq!(
        r.answer_to(&SlaveInfoGet { slave: 0, item: SlaveInfoCode::ConfiguredAddress }),
        Ok(SlaveInfo::ConfiguredAddress(0x0a5b))
    );

    let nop = ResponseHeader {
        status: ecmxf_wire::EcmStatus { check_type: CheckType::Crc32, flags: StatusFlags::NOP },
        ..ResponseHeader::default()
    };
    encode_response(&nop, &[], CheckType::Crc32, &mut buf).unwrap();
    let r = decode_response(&buf, CheckType::Crc32).unwrap();
    assert_eq!(r.answer_to(&InfoUpdate), Err(PayloadError::Nop));
    let done = ResponseHeader { code: CommandCode::InfoUpdate, ..base };
    encode_response(&done, &[], CheckType::Crc32, &mut buf).unwrap();
    assert_eq!(decode_response(&buf, CheckType::Crc32).unwrap().answer_to(&InfoUpdate), Ok(Done));
}
