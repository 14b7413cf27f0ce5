//! The remaining commands, each through the chip with wire packets, checked
//! against what the manual says it does.

mod common;

use common::{Answer, Host, bring_up_to_op};
use ecmxf_sim::Network;
use ecmxf_wire::flags::{ErrorFlags, InterruptFlags, StatusFlags};
use ecmxf_wire::payload::cia402::{
    Cia402ConfigSet, Cia402Control, Cia402CtlGet, Cia402CtlReply, Cia402CtlSet, Cia402GetStatusword, Cia402State,
    Cia402StateGet, Cia402StateReply, Cia402StateSet, StatuswordReply,
};
use ecmxf_wire::payload::control::{
    EnableLrw, InfoUpdate, WkcErrorCountGet, WkcErrorLimit, WkcErrorLimitGet, WkcErrorLimitReply, WkcErrorLimitSet,
};
use ecmxf_wire::payload::ecat_init::{DcSync, DcTiming, EcatInitDc};
use ecmxf_wire::payload::fifo::{
    FifoClear, FifoGetRxCount, FifoGetTxCount, FifoSetRxCount, FifoSetTxCount, RxFifoDepth, SetFifoThreshold,
    TxFifoDepth,
};
use ecmxf_wire::payload::gpio::{GpioConfig, GpioFunc, GpioMode, GpioPull, GpioReply, GpioTrigger};
use ecmxf_wire::payload::interrupt::{IntConfig, IntConfigReply, IntGetEnable, IntSetEnable, PeripheralInts};
use ecmxf_wire::payload::mailbox::{MbxStat, MbxStatReply, RecvMailbox, SlaveBitmap};
use ecmxf_wire::payload::mdio::{Mdio, MdioReply};
use ecmxf_wire::payload::pdo::{DirectAssign, PdoDataOp, PdoDataOpFlags, PdoDirection, PdoWcGet, WcQuery, WcReply};
use ecmxf_wire::payload::periph::{AdcInput, AdcOp, AdcReply, DacOp, DacTrigger, QeiCount, QeiMode, QeiOp};
use ecmxf_wire::payload::raw::{DatagramCommand, DatagramHead, RawGet, RawReply, RawRequest};
use ecmxf_wire::payload::slave_info::{SlaveInfo, SlaveInfoCode, SlaveInfoGet};
use ecmxf_wire::payload::state::{SlaveSelector, StateCheck};
use ecmxf_wire::{EcatState, GpioMask, Reply, ReplyFields};

fn parse<'a, R: Reply<'a>>(a: &'a Answer) -> R {
    R::decode(&ReplyFields { value: a.header.return_value, data_len: a.header.data_len }, &a.data).unwrap()
}

#[test]
fn gpio_qei_dac_adc_over_packets() {
    let mut h = Host::new(Network::demo());
    h.call(&InfoUpdate);
    h.call(&GpioConfig::SetMode { lines: 0x00FF, mode: GpioMode::Output, pull: GpioPull::None });
    h.call(&GpioConfig::SetMode { lines: 0xFF00, mode: GpioMode::Input, pull: GpioPull::Up });
    h.call(&GpioFunc::SetValue { values: 0x0081 });
    let r: GpioReply = parse(&h.call(&GpioFunc::GetValue));
    assert_eq!(r.lines.0, 0xFF81, "outputs read back, pulled-up inputs high");
    // An edge interrupt on input line 9, seen in the header's GPIO flags.
    h.call(&GpioConfig::IntEnable { line: 9, trigger: GpioTrigger::Falling });
    h.chip.periph.set_input(9, Some(false), h.now);
    let a = h.call(&InfoUpdate);
    assert_eq!(a.header.gpio_int_flags, 1 << 9);
    assert_eq!(a.header.gpio_inputs & (1 << 9), 0);
    let r: GpioReply = parse(&h.call(&GpioFunc::ExtGetIntFlag));
    assert_eq!((r.lines, r.extended), (GpioMask(1 << 9), true));
    h.call(&GpioConfig::IntClear { lines: 1 << 9 });
    assert_eq!(h.call(&InfoUpdate).header.gpio_int_flags, 0);
    // Header GPIO outputs.
    h.send(&InfoUpdate);
    h.now = h.chip.ready_at();

    h.call(&QeiOp::Open(QeiMode::X4Free));
    h.call(&QeiOp::Start);
    h.chip.periph.qei_pulses(-40);
    let c: QeiCount = parse(&h.call(&QeiOp::GetCount));
    assert_eq!(c.0, -40);

    h.call(&DacOp::Open(DacTrigger::OnSetData));
    h.call(&DacOp::SetData(4095));
    assert_eq!(h.chip.periph.dac_output, 4095);
    let refused = h.call(&InfoUpdate);
    assert!(!refused.header.errors.contains(ErrorFlags::COMMAND_ERROR));

    h.chip.periph.adc_volts = 3.3;
    h.call(&AdcOp::Open(AdcInput::SingleEnded));
    h.call(&AdcOp::ConfigSampleModule);
    h.call(&AdcOp::StartConv);
    let v: AdcReply = parse(&h.call(&AdcOp::GetDataValidFlag));
    assert_eq!(v.0, 1);
    let d: AdcReply = parse(&h.call(&AdcOp::GetConvData));
    assert_eq!(d.0, 4095);
}

#[test]
fn interrupt_mask_fifo_settings_and_thresholds() {
    let mut h = Host::new(Network::demo());
    h.call(&InfoUpdate);
    let cfg = IntConfig {
        mask: InterruptFlags::RX_FIFO_LOW,
        gpio: 0x0F,
        peripheral: PeripheralInts::QEI_INDEX,
        ..IntConfig::default()
    };
    h.call(&IntSetEnable(cfg));
    let back: IntConfigReply = parse(&h.call(&IntGetEnable));
    assert_eq!(back.0, cfg);
    h.call(&FifoSetRxCount(100));
    h.call(&FifoSetTxCount(20));
    let rx: RxFifoDepth = parse(&h.call(&FifoGetRxCount));
    let tx: TxFifoDepth = parse(&h.call(&FifoGetTxCount));
    // v049 FIFO_GET_RX_CNT/TX_CNT: the count set; FIFO_INIT puts it in use.
    assert_eq!((rx.0, tx.0), (100, 20), "the counts set");
    assert_eq!((h.chip.fifo.rx_depth, h.chip.fifo.tx_depth), (64, 64), "in use from FIFO_INIT");
    h.call(&FifoSetRxCount(64));
    h.call(&FifoSetTxCount(64));

    bring_up_to_op(&mut h, 4);
    h.call(&SetFifoThreshold { tx_high: Some(3), rx_low: Some(2) });
    h.idle(2_000_000);
    let a = h.call(&InfoUpdate);
    assert!(
        a.header
            .int_flags
            .contains(InterruptFlags::RX_FIFO_LOW | InterruptFlags::TX_FIFO_HIGH | InterruptFlags::ETHERCAT_FRAME)
    );
    assert!(!h.chip.int1_level(), "INT1 (active-low) raised by RX_FIFO_LOW & mask");
    h.call(&FifoClear::TxOnly);
    assert!(h.chip.fifo.tx.len() <= 2);
}

#[test]
fn helper_getters_state_check_dc_and_wkc_settings() {
    let mut h = Host::new(Network::demo());
    bring_up_to_op(&mut h, 8);
    h.call(&Cia402ConfigSet {
        axis: 1,
        controlword_offset: 0,
        statusword_offset: 0,
        control: Cia402Control::ENABLE,
        slave: 0,
    });
    h.call(&Cia402CtlSet {
        axis: 1,
        control: Cia402Control::ENABLE | Cia402Control::AUTO_FAULT_RESET,
        axis_count: 2,
        slave: 0,
    });
    let c: Cia402CtlReply = parse(&h.call(&Cia402CtlGet(1)));
    assert_eq!(c.0, Cia402Control::ENABLE | Cia402Control::AUTO_FAULT_RESET);
    h.call(&Cia402StateSet { axis: 1, state: Cia402State::OperationEnabled });
    // Keep the FIFO fed so the helper's outputs are sent.
    let zeros = vec![0u8; 53 * 2];
    for _ in 0..40 {
        h.call(&ecmxf_wire::payload::pdo::PdoFifoOp {
            op: ecmxf_wire::payload::pdo::FifoOpFlags::WRITE,
            frames: 2,
            outputs: &zeros,
        });
    }
    let s: Cia402StateReply = parse(&h.call(&Cia402StateGet(1)));
    assert_eq!(s.0, Cia402State::OperationEnabled);
    let sw: StatuswordReply = parse(&h.call(&Cia402GetStatusword(1)));
    assert_eq!(sw.0 & 0x6F, 0x27);
    // A drive fault is reset by the helper's automatic fault reset.
    h.chip.net.slaves[0].inject_drive_fault(0, 0x3110);
    h.chip.net.slaves[0].clear_drive_fault(0);
    for _ in 0..80 {
        h.call(&ecmxf_wire::payload::pdo::PdoFifoOp {
            op: ecmxf_wire::payload::pdo::FifoOpFlags::WRITE,
            frames: 2,
            outputs: &zeros,
        });
    }
    let s: Cia402StateReply = parse(&h.call(&Cia402StateGet(1)));
    assert_eq!(s.0, Cia402State::OperationEnabled, "faulted, reset, re-enabled by the helper");
    assert!(h.call(&Cia402StateGet(9)).header.errors.contains(ErrorFlags::COMMAND_ERROR), "unknown axis");
    // The error bit stays until a command clears it.
    assert!(h.call(&InfoUpdate).header.errors.contains(ErrorFlags::COMMAND_ERROR));
    h.control = ecmxf_wire::ControlFlags::CLEAR_COMMAND_ERROR;
    assert!(!h.call(&InfoUpdate).header.errors.contains(ErrorFlags::COMMAND_ERROR));

    let st = h.blocking(&StateCheck { target: SlaveSelector::One(2), state: EcatState::SafeOp });
    assert_eq!(st.ecat_state, EcatState::SafeOp);
    h.blocking(&DcSync {
        slave: 1,
        dc: DcTiming { assign_activate: 0x0300, sync0_ns: 250_000, sync1_ns: 0, shift_ns: 0 },
    });
    assert_eq!(h.chip.net.slaves[1].dc_cycle_ns, 250_000);
    h.blocking(&EcatInitDc);
    h.idle(10_000_000);
    assert!(h.call(&InfoUpdate).header.status.flags.contains(StatusFlags::DC_STABLE));

    let a = h.call(&WkcErrorCountGet);
    assert!(a.header.return_value > 0, "slave 2 in SAFE-OP breaks the WKC");
    let w: WcReply = parse(&h.call(&PdoWcGet(WcQuery::WorkingCounter)));
    assert_eq!(w.0, 7, "2 drives x 3 + IO inputs only");
    h.call(&WkcErrorLimitSet(WkcErrorLimit(5)));
    let l: WkcErrorLimitReply = parse(&h.call(&WkcErrorLimitGet));
    assert_eq!(l.0, WkcErrorLimit(5));
    h.idle(1_000_000);
    let w: WcReply = parse(&h.call(&PdoWcGet(WcQuery::WorkingCounter)));
    assert_eq!(w.0, 0, "exchange stopped by the limit: no datagram, no WKC");
    h.call(&EnableLrw(false));
    assert!(!h.chip.master.lrw);
}

#[test]
fn slave_info_for_every_code() {
    let mut h = Host::new(Network::demo());
    bring_up_to_op(&mut h, 8);
    let mut got = Vec::new();
    for code in SlaveInfoCode::ALL {
        let a = h.call(&SlaveInfoGet { slave: 1, item: code });
        got.push(SlaveInfo::decode(code, &a.data).unwrap().code());
        let info = SlaveInfo::decode(code, &a.data).unwrap();
        match info {
            SlaveInfo::VendorId(v) => assert_eq!(v, 0x059D),
            SlaveInfo::ConfiguredAddress(a) => assert_eq!(a, 0x1002),
            SlaveInfo::Alias(a) => assert_eq!(a, 2),
            SlaveInfo::State(s) => assert_eq!(s, EcatState::Op),
            SlaveInfo::AlStatus(s) => assert_eq!(s, 0),
            SlaveInfo::OutputBytes(n) | SlaveInfo::InputBytes(n) => assert_eq!(n, 39),
            SlaveInfo::Name(n) => assert_eq!(n, b"TI CiA402 3-axis"),
            SlaveInfo::HasDc(b) | SlaveInfo::DcActive(b) => assert!(b),
            SlaveInfo::DcCycle(c) => assert_eq!(c, 125_000),
            _ => {}
        }
    }
    assert_eq!(got, SlaveInfoCode::ALL);
    assert!(
        h.call(&SlaveInfoGet { slave: 5, item: SlaveInfoCode::State })
            .header
            .errors
            .contains(ErrorFlags::COMMAND_ERROR)
    );
}

#[test]
fn mdio_mailbox_direct_assign_and_logical_datagrams() {
    let mut h = Host::new(Network::demo());
    h.call(&InfoUpdate);
    let r: MdioReply = parse(&h.call(&Mdio::Read { phy: 1, register: 1 }));
    assert_eq!(r.0 & 0x0004, 0x0004, "PHY link up");
    h.call(&Mdio::Write { phy: 1, register: 0, value: 0x2100 });
    let r: MdioReply = parse(&h.call(&Mdio::Read { phy: 1, register: 0 }));
    assert_eq!(r.0, 0x2100);

    // Direct assignment changes the frame layout at RECONFIG.
    h.call(&DirectAssign::Enable { slave: 2, enable: true });
    h.call(&DirectAssign::Length { slave: 2, direction: PdoDirection::Inputs, bytes: 4 });
    let f = bring_up_to_op(&mut h, 4);
    assert_eq!(f.tx, 13 + 39 + 4);

    // Emergencies show in MBX_STAT and can be read with RECV_MAILBOX.
    h.chip.net.slaves[1].inject_drive_fault(0, 0x7310);
    h.idle(500_000);
    let m = h.call(&MbxStat::Status);
    let bits: MbxStatReply = parse(&m);
    assert!(bits.0.contains(1) && !bits.0.contains(0));
    h.call(&RecvMailbox::Fetch { slave: 1 });
    let a = h.call(&RecvMailbox::Read { offset: 8, length: 2 });
    assert_eq!(a.data, 0x7310u16.to_le_bytes());
    h.call(&MbxStat::SetPolling(SlaveBitmap(&[0b101])));
    let a = h.call(&MbxStat::GetPolling);
    let p: MbxStatReply = parse(&a);
    assert_eq!(p.0.0, &[0b101]);

    // Logical read of the IO slave's inputs, logical write of its outputs.
    h.call(&PdoDataOp { op: PdoDataOpFlags::empty(), outputs: &[0u8; 53] });
    let head = DatagramHead { command: DatagramCommand::Lrd, length: 2, adp: 0, ado: 0, logical: 0, timeout_us: 1000 };
    h.blocking(&RawRequest { head, data: &[] });
    let a = h.call(&RawGet);
    let r: RawReply = parse(&a);
    assert_eq!(r.working_counter, 3);
    // APRD of the station address of position 2 (ADP = -2).
    let head = DatagramHead {
        command: DatagramCommand::Aprd,
        length: 2,
        adp: 0u16.wrapping_sub(2),
        ado: 0x0010,
        logical: 0,
        timeout_us: 1000,
    };
    h.blocking(&RawRequest { head, data: &[] });
    let a = h.call(&RawGet);
    let r: RawReply = parse(&a);
    assert_eq!((r.working_counter, r.data), (1, &0x1003u16.to_le_bytes()[..]));
}
