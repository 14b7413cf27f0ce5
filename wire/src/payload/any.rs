//! [`AnyRequest`]: any command, parsed by its code. This is how the chip's
//! side (the simulator) reads what a host sent.

use crate::command::CommandCode;
use crate::error::{EncodeError, PayloadError};
use crate::payload::{
    Request, RequestFields, cia402, control, ecat_init, eeprom, emergency, fifo, foe, gpio, interrupt, mailbox, mdio,
    pdo, periph, raw, sdo, slave_info, spi, state,
};

macro_rules! any_request {
    ($($variant:ident($ty:ty),)*) => {
        /// A parsed command of any code; each variant is named after its
        /// [`CommandCode`].
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        #[allow(missing_docs)]
        pub enum AnyRequest<'a> {
            $($variant($ty),)*
        }

        impl<'a> AnyRequest<'a> {
            /// Parses the payload of a command with this code.
            pub fn decode(code: CommandCode, fields: &RequestFields, data: &'a [u8]) -> Result<Self, PayloadError> {
                match code {
                    $(CommandCode::$variant => <$ty as Request<'a>>::decode(fields, data).map(Self::$variant),)*
                    CommandCode::Other(code) => Err(PayloadError::UnknownCommand { code }),
                }
            }

            /// The command code.
            pub fn code(&self) -> CommandCode {
                match self {
                    $(Self::$variant(_) => CommandCode::$variant,)*
                }
            }

            /// Writes the data section and returns the header fields.
            pub fn encode(&self, data: &mut [u8]) -> Result<RequestFields, EncodeError> {
                match self {
                    $(Self::$variant(r) => r.encode(data),)*
                }
            }
        }
    };
}

any_request! {
    InfoUpdate(control::InfoUpdate),
    EcatInit(ecat_init::EcatInit),
    EcatReconfig(ecat_init::EcatReconfig),
    EcatInitDc(ecat_init::EcatInitDc),
    PdoWcGet(pdo::PdoWcGet),
    PdoDataFifoOp(pdo::PdoFifoOp<'a>),
    PdoDataOp(pdo::PdoDataOp<'a>),
    PdoConfigSet(pdo::PdoConfig),
    PdoConfigReq(pdo::PdoConfigReq),
    PdoConfigGet(pdo::PdoConfigGet),
    SdoReq(sdo::SdoRequest<'a>),
    SdoGet(sdo::SdoGet),
    StateSet(state::StateSet),
    StateGet(state::StateGet),
    SlaveInfoGet(slave_info::SlaveInfoGet),
    SlaveCountGet(slave_info::SlaveCountGet),
    FifoEnable(fifo::FifoEnable),
    FifoPackSizeGet(fifo::FifoPackSizeGet),
    SpiPackSizeGet(spi::SpiPackSizeGet),
    SpiReconfig(spi::SpiReconfig),
    CrcErrCountClear(spi::CrcErrCountClear),
    CrcTypeSet(spi::CrcTypeSet),
    Cia402ConfigSet(cia402::Cia402ConfigSet),
    Cia402StateSet(cia402::Cia402StateSet),
    Cia402StateGet(cia402::Cia402StateGet),
    Cia402CtlSet(cia402::Cia402CtlSet),
    Cia402CtlGet(cia402::Cia402CtlGet),
    GpioConfigSet(gpio::GpioConfig),
    GpioFuncOp(gpio::GpioFunc),
    QeiFuncOp(periph::QeiOp),
    DacFuncOp(periph::DacOp),
    AdcFuncOp(periph::AdcOp),
    EepromReq(eeprom::EepromRequest),
    EepromGet(eeprom::EepromGet),
    StateCheck(state::StateCheck),
    DcSync(ecat_init::DcSync),
    FifoClear(fifo::FifoClear),
    FifoSetTxCount(fifo::FifoSetTxCount),
    FifoGetTxCount(fifo::FifoGetTxCount),
    FifoSetRxCount(fifo::FifoSetRxCount),
    FifoGetRxCount(fifo::FifoGetRxCount),
    FwVersionGet(control::FwVersionGet),
    StateUpdate(ecat_init::StateUpdate),
    IntSetEnable(interrupt::IntSetEnable),
    IntGetEnable(interrupt::IntGetEnable),
    FifoInit(fifo::FifoInit),
    SdoAbortCodeGet(sdo::SdoAbortCodeGet),
    SetFifoThreshold(fifo::SetFifoThreshold),
    ConfigSm(pdo::ConfigSm),
    ConfigFmmu(pdo::ConfigFmmu),
    ConfigMap(ecat_init::ConfigMap),
    Cia402GetStatusword(cia402::Cia402GetStatusword),
    AsyncCmdReset(control::AsyncCmdReset),
    Mdio(mdio::Mdio),
    DirectAssign(pdo::DirectAssign),
    CoeEmergency(emergency::CoeEmergencyGet),
    WarmReset(control::WarmReset),
    WkcContiErrCountGet(control::WkcErrorCountGet),
    WkcContiErrMaxGet(control::WkcErrorLimitGet),
    WkcContiErrMaxSet(control::WkcErrorLimitSet),
    RawEcatReq(raw::RawRequest<'a>),
    RawEcatGet(raw::RawGet),
    FoeReq(foe::FoeRequest<'a>),
    FoeGet(foe::FoeGet),
    EnableLrw(control::EnableLrw),
    RecvMailbox(mailbox::RecvMailbox),
    MbxStat(mailbox::MbxStat<'a>),
}

#[cfg(test)]
pub(crate) mod samples {
    //! One non-trivial request per command code.
    use super::*;
    use crate::check::CheckType;
    use crate::flags::{EcatState, GpioMask, InterruptFlags};
    use crate::payload::pdo::PdoEntry;
    use std::vec::Vec;

    /// A sample of every command code, in code order.
    pub fn every_code() -> Vec<AnyRequest<'static>> {
        use AnyRequest as A;
        let dc = ecat_init::DcTiming { assign_activate: 0x0300, sync0_ns: 125_000, sync1_ns: 0, shift_ns: 0 };
        let entries: &'static [PdoEntry] =
            &[PdoEntry { index: 0x6040, subindex: 0, bits: 16 }, PdoEntry { index: 0x607A, subindex: 0, bits: 32 }];
        let sel = state::SlaveSelector::One(1);
        vec_of(&[
            A::InfoUpdate(control::InfoUpdate),
            A::EcatInit(ecat_init::EcatInit { special_slaves: false, master_shift: false, disable_lrw: true, dc }),
            A::EcatReconfig(ecat_init::EcatReconfig),
            A::EcatInitDc(ecat_init::EcatInitDc),
            A::PdoWcGet(pdo::PdoWcGet(pdo::WcQuery::WorkingCounter)),
            A::PdoDataFifoOp(pdo::PdoFifoOp { op: pdo::FifoOpFlags::all(), frames: 2, outputs: &[1, 2, 3, 4] }),
            A::PdoDataOp(pdo::PdoDataOp { op: pdo::PdoDataOpFlags::READ | pdo::PdoDataOpFlags::VALID, outputs: &[] }),
            A::PdoConfigSet(pdo::PdoConfig::new(1, pdo::RX_PDO_ASSIGN, &[(0x1600, entries)]).unwrap()),
            A::PdoConfigReq(pdo::PdoConfigReq {
                slave: 1,
                assign_index: pdo::TX_PDO_ASSIGN,
                form: pdo::PdoConfigForm::Manual,
            }),
            A::PdoConfigGet(pdo::PdoConfigGet),
            A::SdoReq(sdo::SdoRequest {
                slave: 1,
                index: 0x6060,
                subindex: 0,
                complete_access: false,
                timeout_us: 100_000,
                access: sdo::SdoAccess::Write(&[8]),
            }),
            A::SdoGet(sdo::SdoGet),
            A::StateSet(state::StateSet { target: state::SlaveSelector::All, state: EcatState::Op }),
            A::StateGet(state::StateGet(sel)),
            A::SlaveInfoGet(slave_info::SlaveInfoGet { slave: 2, item: slave_info::SlaveInfoCode::Name }),
            A::SlaveCountGet(slave_info::SlaveCountGet),
            A::FifoEnable(fifo::FifoEnable(true)),
            A::FifoPackSizeGet(fifo::FifoPackSizeGet(pdo::PdoDirection::Inputs)),
            A::SpiPackSizeGet(spi::SpiPackSizeGet),
            A::SpiReconfig(spi::SpiReconfig { data_size: 1408 }),
            A::CrcErrCountClear(spi::CrcErrCountClear),
            A::CrcTypeSet(spi::CrcTypeSet(CheckType::Crc32)),
            A::Cia402ConfigSet(cia402::Cia402ConfigSet {
                axis: 0,
                controlword_offset: 0,
                statusword_offset: 0,
                control: cia402::Cia402Control::ENABLE,
                slave: 1,
            }),
            A::Cia402StateSet(cia402::Cia402StateSet { axis: 0, state: cia402::Cia402State::OperationEnabled }),
            A::Cia402StateGet(cia402::Cia402StateGet(0)),
            A::Cia402CtlSet(cia402::Cia402CtlSet {
                axis: 1,
                control: cia402::Cia402Control::AUTO_FAULT_RESET,
                axis_count: 2,
                slave: 1,
            }),
            A::Cia402CtlGet(cia402::Cia402CtlGet(1)),
            A::GpioConfigSet(gpio::GpioConfig::IntEnable { line: 3, trigger: gpio::GpioTrigger::Rising }),
            A::GpioFuncOp(gpio::GpioFunc::ExtSetValue { values: GpioMask(0x8_0001) }),
            A::QeiFuncOp(periph::QeiOp::Open(periph::QeiMode::X4Free)),
            A::DacFuncOp(periph::DacOp::SetData(2048)),
            A::AdcFuncOp(periph::AdcOp::GetConvData),
            A::EepromReq(eeprom::EepromRequest {
                slave: 0,
                access: eeprom::EepromAccess::Read { address: 8 },
                timeout_us: 10_000,
            }),
            A::EepromGet(eeprom::EepromGet),
            A::StateCheck(state::StateCheck { target: sel, state: EcatState::SafeOp }),
            A::DcSync(ecat_init::DcSync { slave: 1, dc }),
            A::FifoClear(fifo::FifoClear::RxOnly),
            A::FifoSetTxCount(fifo::FifoSetTxCount(32)),
            A::FifoGetTxCount(fifo::FifoGetTxCount),
            A::FifoSetRxCount(fifo::FifoSetRxCount(96)),
            A::FifoGetRxCount(fifo::FifoGetRxCount),
            A::FwVersionGet(control::FwVersionGet),
            A::StateUpdate(ecat_init::StateUpdate),
            A::IntSetEnable(interrupt::IntSetEnable(interrupt::IntConfig {
                mask: InterruptFlags::RX_FIFO_LOW,
                ..Default::default()
            })),
            A::IntGetEnable(interrupt::IntGetEnable),
            A::FifoInit(fifo::FifoInit),
            A::SdoAbortCodeGet(sdo::SdoAbortCodeGet),
            A::SetFifoThreshold(fifo::SetFifoThreshold { tx_high: Some(48), rx_low: Some(8) }),
            A::ConfigSm(pdo::ConfigSm {
                slave: 1,
                sm: 2,
                start_address: 0x1100,
                length: 6,
                control: 0x64,
                activate: 1,
            }),
            A::ConfigFmmu(pdo::ConfigFmmu { slave: 1, functions: [1, 2, 3, 0] }),
            A::ConfigMap(ecat_init::ConfigMap),
            A::Cia402GetStatusword(cia402::Cia402GetStatusword(0)),
            A::AsyncCmdReset(control::AsyncCmdReset(control::AsyncReset::CLEAR_BUSY)),
            A::Mdio(mdio::Mdio::Read { phy: 1, register: 1 }),
            A::DirectAssign(pdo::DirectAssign::Length { slave: 1, direction: pdo::PdoDirection::Inputs, bytes: 12 }),
            A::CoeEmergency(emergency::CoeEmergencyGet(8)),
            A::WarmReset(control::WarmReset),
            A::WkcContiErrCountGet(control::WkcErrorCountGet),
            A::WkcContiErrMaxGet(control::WkcErrorLimitGet),
            A::WkcContiErrMaxSet(control::WkcErrorLimitSet(control::WkcErrorLimit(3))),
            A::RawEcatReq(raw::RawRequest {
                head: raw::DatagramHead {
                    command: raw::DatagramCommand::Fpwr,
                    length: 2,
                    adp: 0x1001,
                    ado: 0x0120,
                    logical: 0,
                    timeout_us: 1000,
                },
                data: &[0x02, 0x00],
            }),
            A::RawEcatGet(raw::RawGet),
            A::FoeReq(foe::FoeRequest::WriteFlash { offset: 0, data: b"firmware" }),
            A::FoeGet(foe::FoeGet),
            A::EnableLrw(control::EnableLrw(false)),
            A::RecvMailbox(mailbox::RecvMailbox::Read { offset: 0, length: 128 }),
            A::MbxStat(mailbox::MbxStat::SetPolling(mailbox::SlaveBitmap(&[0x03]))),
        ])
    }

    fn vec_of(items: &[AnyRequest<'static>]) -> Vec<AnyRequest<'static>> {
        items.to_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::samples::every_code;
    use super::*;
    use std::vec::Vec;

    #[test]
    fn samples_cover_every_code_once() {
        let codes: Vec<CommandCode> = every_code().iter().map(AnyRequest::code).collect();
        assert_eq!(codes, CommandCode::ALL);
    }

    #[test]
    fn every_code_round_trips_through_any_request() {
        for req in every_code() {
            let mut data = [0u8; 1408];
            let fields = req.encode(&mut data).unwrap_or_else(|e| panic!("{:?}: {e}", req.code()));
            let back =
                AnyRequest::decode(req.code(), &fields, &data).unwrap_or_else(|e| panic!("{:?}: {e}", req.code()));
            assert_eq!(back, req);
        }
    }

    /// Commands with a data layout of a fixed length (v049 "資料長度"): a
    /// packet declaring any other length is refused whole, so the chip never
    /// reads its fields from the wrong offsets (as it would the vendor
    /// driver's PDO_CONFIG_REQ, which declares 156 bytes where v049's layout
    /// has 4).
    #[test]
    fn a_declared_length_that_does_not_fit_the_layout_is_refused() {
        use CommandCode as C;
        let fixed = [
            (C::EcatInit, 16),
            (C::PdoConfigSet, 112),
            (C::PdoConfigReq, 4),
            (C::EepromReq, 12),
            (C::DcSync, 16),
            (C::ConfigSm, 8),
            (C::ConfigFmmu, 5),
            (C::IntSetEnable, 6),
        ];
        for req in every_code() {
            let mut data = [0u8; 1408];
            let fields = req.encode(&mut data).unwrap();
            let Some(&(code, len)) = fixed.iter().find(|(c, _)| *c == req.code()) else { continue };
            assert_eq!(fields.data_len, len, "{code:?} encodes its layout's length");
            // 148 and 156 are the vendor driver's PDO-configuration forms
            // (pdo::PdoConfigForm), layouts of their own.
            let vendor_form = matches!(code, C::PdoConfigSet | C::PdoConfigReq);
            for wrong in [0, len - 1, len + 1, 156].into_iter().filter(|&w| !(vendor_form && w == 156)) {
                let f = RequestFields { data_len: wrong, ..fields };
                assert_eq!(
                    AnyRequest::decode(code, &f, &data),
                    Err(PayloadError::DataLength { command: code, expected: len, found: wrong }),
                    "{code:?} with {wrong} bytes"
                );
            }
        }
        // SDO_REQ: 12 bytes to read, 12 + the bytes to write.
        let read = sdo::SdoRequest {
            slave: 1,
            index: 0x6040,
            subindex: 0,
            complete_access: false,
            timeout_us: 0,
            access: sdo::SdoAccess::Read { max_len: 4 },
        };
        let mut data = [0u8; 64];
        let f = read.encode(&mut data).unwrap();
        assert_eq!(f.data_len, 12);
        let err = AnyRequest::decode(C::SdoReq, &RequestFields { data_len: 16, ..f }, &data);
        assert_eq!(err, Err(PayloadError::DataLength { command: C::SdoReq, expected: 12, found: 16 }));
        // A peripheral operation's data word.
        let f = RequestFields { parameter: 4, data_len: 8, ..RequestFields::default() };
        assert!(matches!(AnyRequest::decode(C::QeiFuncOp, &f, &data), Err(PayloadError::DataLength { .. })));
    }

    #[test]
    fn unknown_codes_are_named() {
        for c in [14u8, 17, 100, 255] {
            assert_eq!(
                AnyRequest::decode(CommandCode::from_u8(c), &RequestFields::default(), &[]),
                Err(PayloadError::UnknownCommand { code: c })
            );
        }
    }
}
