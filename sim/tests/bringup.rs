//! Power-up to OP with cyclic FIFO exchange, using only `ecmxf-wire`
//! packets, in the bring-up order of the manual's figure 7 (v049
//! "ECM-XF 初始化EtherCAT網路及從站配置說明"): init network (1, DC) ->
//! states (12/13) -> PDO mapping (7/8/9, then 2) -> SDO parameters (10/11)
//! -> CiA402 helper (26) -> 402 states (27/28) -> FIFO sizes and first images
//! (19, 4, 6) -> OP and cyclic FIFO exchange (5), at a 125 us DC cycle,
//! without RxFIFO underruns.

mod common;

use common::Host;
use ecmxf_sim::Network;
use ecmxf_wire::flags::{ErrorFlags, StatusFlags};
use ecmxf_wire::payload::cia402::{Cia402ConfigSet, Cia402Control, Cia402State, Cia402StateSet};
use ecmxf_wire::payload::ecat_init::{DcTiming, EcatInit, EcatReconfig};
use ecmxf_wire::payload::fifo::{FifoEnable, FifoInit, FifoPackSize, FifoPackSizeGet, FifoSetRxCount, FifoSetTxCount};
use ecmxf_wire::payload::pdo::{
    FifoOpFlags, PdoConfig, PdoConfigGet, PdoConfigReply, PdoConfigReq, PdoDataOp, PdoDataOpFlags, PdoDataReply,
    PdoDirection, PdoEntry, PdoFifoOp, PdoFifoReply, PdoWcGet, RX_PDO_ASSIGN, TX_PDO_ASSIGN, WcQuery, WcReply,
};
use ecmxf_wire::payload::sdo::{
    SdoAbortCode, SdoAbortCodeGet, SdoAbortReply, SdoAccess, SdoGet, SdoGetReply, SdoRequest,
};
use ecmxf_wire::payload::slave_info::{SlaveCount, SlaveCountGet, SlaveInfo, SlaveInfoCode, SlaveInfoGet};
use ecmxf_wire::payload::spi::{CrcTypeSet, SpiReconfig};
use ecmxf_wire::payload::state::{SlaveSelector, StateGet, StateReply, StateSet};
use ecmxf_wire::{CheckType, EcatState, Reply, ReplyFields};

const TI: u8 = 1;

/// Runs one SDO transfer on the blocking slot; a failure is answered with
/// its abort code (cmd 69).
fn sdo(h: &mut Host, slave: u8, index: u16, subindex: u8, access: SdoAccess<'_>) -> Result<(), SdoAbortCode> {
    let status =
        h.blocking(&SdoRequest { slave, index, subindex, complete_access: false, timeout_us: 100_000, access });
    if status.errors.contains(ErrorFlags::BLOCKING_FAILED) {
        h.control = ecmxf_wire::ControlFlags::CLEAR_BLOCKING_ERROR;
        let code: SdoAbortReply = h.get(&SdoAbortCodeGet);
        return Err(code.0);
    }
    Ok(())
}

fn sdo_read(h: &mut Host, slave: u8, index: u16, subindex: u8) -> Result<Vec<u8>, SdoAbortCode> {
    sdo(h, slave, index, subindex, SdoAccess::Read { max_len: 64 })?;
    let a = h.call(&SdoGet);
    let r = SdoGetReply::decode(&ReplyFields { value: a.header.return_value, data_len: a.header.data_len }, &a.data)
        .unwrap();
    Ok(r.data.to_vec())
}

fn sdo_write(h: &mut Host, slave: u8, index: u16, subindex: u8, data: &[u8]) -> Result<(), SdoAbortCode> {
    sdo(h, slave, index, subindex, SdoAccess::Write(data))
}

fn info(h: &mut Host, slave: u8, item: SlaveInfoCode) -> u32 {
    let a = h.call(&SlaveInfoGet { slave, item });
    match SlaveInfo::decode(item, &a.data).unwrap() {
        SlaveInfo::OutputBytes(n) | SlaveInfo::InputBytes(n) => n.into(),
        SlaveInfo::VendorId(v) | SlaveInfo::ProductCode(v) => v,
        other => panic!("unexpected {other:?}"),
    }
}

#[test]
fn power_up_to_op_with_cyclic_fifo_exchange_at_125_us() {
    let mut h = Host::new(Network::demo());

    // Link set-up: CRC-32 on, bigger packets for several frames each.
    h.call(&ecmxf_wire::payload::control::InfoUpdate);
    h.send(&CrcTypeSet(CheckType::Crc32));
    h.check = CheckType::Crc32;
    let mut buf = vec![0u8; h.packet_len()];
    let header = ecmxf_wire::CommandHeader::new(ecmxf_wire::CommandCode::SpiReconfig, 0xF0);
    ecmxf_wire::encode_request(&SpiReconfig { data_size: 512 }, header, CheckType::Fixed, &mut buf).unwrap();
    h.exchange_raw(&buf);
    h.data_size = 512;

    // 1. Init network with DC: SYNC0 125 us.
    let dc = DcTiming { assign_activate: 0x0300, sync0_ns: 125_000, sync1_ns: 0, shift_ns: 0 };
    let status = h.blocking(&EcatInit { special_slaves: false, master_shift: false, disable_lrw: false, dc });
    assert!(status.status.flags.contains(StatusFlags::ETHERNET_READY));
    assert!(!status.errors.contains(ErrorFlags::BLOCKING_FAILED));
    let n: SlaveCount = h.get(&SlaveCountGet);
    assert_eq!(n.0, 3);
    assert_eq!(info(&mut h, TI, SlaveInfoCode::VendorId), 0x059D);

    // 2. States: PRE-OP.
    h.blocking(&StateSet { target: SlaveSelector::All, state: EcatState::PreOp });
    let s: StateReply = h.get(&StateGet(SlaveSelector::All));
    assert_eq!(s.0, EcatState::PreOp);

    // 3. PDO mapping: shrink the TI drive's outputs to axis 1's controlword,
    // mode and target position; read it back; the fixed-mapping drive
    // refuses, with the abort code of a read-only object.
    let entries = [
        PdoEntry { index: 0x6040, subindex: 0, bits: 16 },
        PdoEntry { index: 0x6060, subindex: 0, bits: 8 },
        PdoEntry { index: 0x607A, subindex: 0, bits: 32 },
    ];
    let cfg = PdoConfig::new(TI, RX_PDO_ASSIGN, &[(0x1600, &entries)]).unwrap();
    let st = h.blocking(&cfg);
    assert!(!st.errors.contains(ErrorFlags::BLOCKING_FAILED));
    h.blocking(&PdoConfigReq { slave: TI, assign_index: RX_PDO_ASSIGN, ..Default::default() });
    let back: PdoConfigReply = h.get(&PdoConfigGet);
    assert_eq!(back.0, cfg);
    let fixed = PdoConfig::new(0, RX_PDO_ASSIGN, &[(0x1600, &entries)]).unwrap();
    let st = h.blocking(&fixed);
    assert!(st.errors.contains(ErrorFlags::BLOCKING_FAILED));
    h.control = ecmxf_wire::ControlFlags::CLEAR_BLOCKING_ERROR;
    let code: SdoAbortReply = h.get(&SdoAbortCodeGet);
    assert_eq!(code.0, SdoAbortCode::READ_ONLY);
    h.blocking(&EcatReconfig);

    // 4. SDO parameters: CSP mode on axis 1; identity read back; a missing
    // object aborts with its ETG code.
    sdo_write(&mut h, TI, 0x6060, 0, &[8]).unwrap();
    assert_eq!(sdo_read(&mut h, TI, 0x6060, 0).unwrap(), [8]);
    assert_eq!(sdo_read(&mut h, TI, 0x1018, 1).unwrap(), 0x059Du32.to_le_bytes());
    assert_eq!(sdo_read(&mut h, TI, 0x5555, 0), Err(SdoAbortCode::OBJECT_MISSING));
    assert_eq!(sdo_write(&mut h, TI, 0x6060, 0, &[3]), Err(SdoAbortCode::VALUE_TOO_LOW));

    // 5. CiA402 helper for axis 0 = TI axis 1 (controlword and statusword at
    // offset 0 of the slave's images), 6. target state: operation enabled.
    h.call(&Cia402ConfigSet {
        axis: 0,
        controlword_offset: 0,
        statusword_offset: 0,
        control: Cia402Control::ENABLE,
        slave: TI,
    });
    h.call(&Cia402StateSet { axis: 0, state: Cia402State::OperationEnabled });

    // 7. FIFO sizes and first images.
    let rx: FifoPackSize = h.get(&FifoPackSizeGet(PdoDirection::Outputs));
    let tx: FifoPackSize = h.get(&FifoPackSizeGet(PdoDirection::Inputs));
    assert_eq!((rx.0, tx.0), (13 + 7 + 1, 13 + 39 + 1));
    let outs: WcReply = h.get(&PdoWcGet(WcQuery::OutputSlaves));
    let ins: WcReply = h.get(&PdoWcGet(WcQuery::InputSlaves));
    let expected_wkc = ins.0 + 2 * outs.0;
    assert_eq!(expected_wkc, 9);
    let rx_size = usize::from(rx.0);
    let tx_size = usize::from(tx.0);
    let offsets: Vec<usize> = (0..3u8)
        .scan(0usize, |acc, s| {
            let at = *acc;
            *acc += info(&mut h, s, SlaveInfoCode::OutputBytes) as usize;
            Some(at)
        })
        .collect();
    let ti_in = info(&mut h, 0, SlaveInfoCode::InputBytes) as usize;
    let a = h.call(&PdoDataOp { op: PdoDataOpFlags::READ | PdoDataOpFlags::VALID, outputs: &[] });
    assert_eq!(a.data.len(), tx_size);
    // The vendor driver copies the inputs only when the op bits come back.
    assert_eq!(a.header.return_value, 0x06, "PDO_DATA_OP echoes its operation bits (v031)");
    h.call(&FifoSetRxCount(32));
    h.call(&FifoSetTxCount(32));
    h.blocking(&FifoInit);

    // The output frame: TI axis 1 in CSP towards 5000 counts; IO outputs.
    let mut frame = vec![0u8; rx_size];
    frame[offsets[1] + 2] = 8;
    frame[offsets[1] + 3..offsets[1] + 7].copy_from_slice(&5000i32.to_le_bytes());
    frame[offsets[2]] = 0xA5;

    // 8. SAFE-OP, prefill the RxFIFO, OP, FIFO on.
    h.blocking(&StateSet { target: SlaveSelector::All, state: EcatState::SafeOp });
    let prefill: Vec<u8> = frame.repeat(16);
    h.call(&PdoFifoOp { op: FifoOpFlags::WRITE, frames: 16, outputs: &prefill });
    let st = h.blocking(&StateSet { target: SlaveSelector::All, state: EcatState::Op });
    assert!(!st.errors.contains(ErrorFlags::BLOCKING_FAILED), "{st:?}");
    assert_eq!(st.ecat_state, EcatState::Op);
    h.call(&FifoEnable(true));

    // Cyclic exchange for one second of simulated time: keep the RxFIFO
    // near 16 frames using the header's count. The count is two exchanges
    // (about four cycles) late, so frames pushed in the last two exchanges
    // count as in flight, and the target leaves room for what was consumed
    // meanwhile.
    let underruns_before = h.chip.fifo.underruns;
    let per_packet = h.data_size / rx_size;
    let mut in_flight = [0usize; 2];
    let mut last_inputs = Vec::new();
    let mut inputs_seen = 0usize;
    let end = h.now + 1_000_000_000;
    let mut min_level = usize::MAX;
    while h.now < end {
        let (bytes, _) = {
            let level = h.chip.fifo.rx.len();
            min_level = min_level.min(level);
            let reported = last_header_rx(&h);
            let believed = reported + in_flight[0] + in_flight[1];
            let push = 16usize.saturating_sub(believed).min(per_packet);
            in_flight = [in_flight[1], push];
            let outputs = frame.repeat(push);
            h.send(&PdoFifoOp { op: FifoOpFlags::WRITE | FifoOpFlags::READ, frames: push as u8, outputs: &outputs })
        };
        let a = h.decode(&bytes).expect("cyclic answer decodes");
        h.last_rx_count = a.header.rx_fifo_count;
        if a.header.code == ecmxf_wire::CommandCode::PdoDataFifoOp {
            let r = PdoFifoReply::decode(
                &ReplyFields { value: a.header.return_value, data_len: a.header.data_len },
                &a.data,
            )
            .unwrap();
            assert_eq!(r.inputs.len() % tx_size, 0);
            inputs_seen += r.inputs.len() / tx_size;
            if r.inputs.len() >= tx_size {
                last_inputs = r.inputs[r.inputs.len() - tx_size..].to_vec();
            }
        }
        assert_eq!(a.header.wkc_errors, 0, "no working-counter errors in OP");
    }

    assert_eq!(h.chip.fifo.underruns - underruns_before, 0, "RxFIFO never ran dry");
    assert!(min_level >= 1, "RxFIFO level stayed above zero (min {min_level})");
    assert!(inputs_seen >= 7_900, "about one input frame per 125 us cycle: {inputs_seen}");
    assert!(h.chip.stats.cycles >= 8_000);
    // The helper enabled TI axis 1 and it reached its target.
    let sw = u16::from_le_bytes([last_inputs[ti_in], last_inputs[ti_in + 1]]);
    assert_eq!(Cia402State::from_statusword(sw), Cia402State::OperationEnabled, "statusword {sw:#06x}");
    let pos = i32::from_le_bytes(last_inputs[ti_in + 3..ti_in + 7].try_into().unwrap());
    assert_eq!(pos, 5000);
    // The IO slave loops its outputs back.
    assert_eq!(last_inputs[tx_size - 1], 0xA5);
    let st = h.wait_idle();
    assert!(!st.errors.contains(ErrorFlags::FIFO_ERROR));
    assert_eq!(st.ecat_state, EcatState::Op);
    let _ = TX_PDO_ASSIGN;
    let _ = PdoDataReply { inputs: &[] };
}

fn last_header_rx(h: &Host) -> usize {
    usize::from(h.last_rx_count)
}
