//! Every ECM-XF command code, in v049 numbering (表三 and each command's
//! section), with its name and whether it occupies the chip's single blocking
//! slot.
//!
//! TRAP: v031 gives code 3 to CRC_TYPE_SET; v049 moved it to 25 and gave 3 to
//! ECAT_INIT_DC. We follow v049.
//!
//! Blocking commands (v049 表三 plus the ones the vendor driver waits on as
//! such, docs/protocol.md §8): only one may run at a
//! time; a second one while busy sets error bit7 and is not executed. Their
//! results are fetched with the matching GET command. Any packet whose control
//! byte has bit1 set is blocking as well (see [`crate::ControlFlags`]).

use core::fmt;

macro_rules! command_codes {
    ($($(#[$doc:meta])* $variant:ident = $code:literal, $name:literal, $blocking:literal;)*) => {
        /// A command code (command header 0x0C, echoed at response 0x0C).
        /// Codes the manual does not list are kept as [`CommandCode::Other`].
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum CommandCode {
            $($(#[$doc])* $variant,)*
            /// A code the manual does not list.
            Other(u8),
        }

        impl CommandCode {
            /// Every listed code, in ascending order.
            pub const ALL: &'static [CommandCode] = &[$(Self::$variant,)*];

            /// From the raw byte.
            pub const fn from_u8(v: u8) -> Self {
                match v {
                    $($code => Self::$variant,)*
                    other => Self::Other(other),
                }
            }

            /// To the raw byte.
            pub const fn to_u8(self) -> u8 {
                match self {
                    $(Self::$variant => $code,)*
                    Self::Other(v) => v,
                }
            }

            /// The manual's name, without the `ECM_CMD_` prefix.
            pub const fn name(self) -> &'static str {
                match self {
                    $(Self::$variant => $name,)*
                    Self::Other(_) => "UNKNOWN",
                }
            }

            /// Whether the command runs in the chip's single blocking slot.
            pub const fn is_blocking(self) -> bool {
                match self {
                    $(Self::$variant => $blocking,)*
                    Self::Other(_) => false,
                }
            }
        }
    };
}

command_codes! {
    /// 0: refresh the response header only.
    InfoUpdate = 0, "INFO_UPDATE_OP", false;
    /// 1: initialise the EtherCAT network and slaves, with DC settings.
    EcatInit = 1, "ECAT_INIT_OP", true;
    /// 2: re-plan the chip's memory after a PDO change.
    EcatReconfig = 2, "ECAT_RECONFIG_OP", true;
    /// 3: initialise distributed clocks (v049; v031 had CRC_TYPE_SET here).
    EcatInitDc = 3, "ECAT_INIT_DC_OP", true;
    /// 4: slaves with inputs, slaves with outputs, or the working counter.
    PdoWcGet = 4, "ECAT_PDO_WC_GET", false;
    /// 5: push RxPDO frames into / pull TxPDO frames from the FIFO.
    PdoDataFifoOp = 5, "ECAT_PDO_DATA_FIFO_OP", false;
    /// 6: read the current process image (initial outputs / inputs).
    PdoDataOp = 6, "ECAT_PDO_DATA_OP", false;
    /// 7: configure one slave's PDO assignment and mapping.
    PdoConfigSet = 7, "ECAT_PDO_CONFIG_SET", true;
    /// 8: request a slave's PDO configuration (fetch with 9).
    PdoConfigReq = 8, "ECAT_PDO_CONFIG_REQ", true;
    /// 9: fetch the configuration requested with 8.
    PdoConfigGet = 9, "ECAT_PDO_CONFIG_GET", false;
    /// 10: SDO upload/download request (fetch reads with 11).
    SdoReq = 10, "ECAT_SDO_REQ", true;
    /// 11: fetch the data of the last SDO read.
    SdoGet = 11, "ECAT_SDO_GET", false;
    /// 12: request an EtherCAT state.
    StateSet = 12, "ECAT_STATE_SET", true;
    /// 13: the EtherCAT state held in the chip.
    StateGet = 13, "ECAT_STATE_GET", false;
    /// 15: one item of a slave's information.
    SlaveInfoGet = 15, "ECAT_SLV_INFO_GET", false;
    /// 16: the number of slaves found.
    SlaveCountGet = 16, "ECAT_SLV_CNT_GET", false;
    /// 18: enable/disable cyclic RxPDO FIFO output.
    FifoEnable = 18, "FIFO_ENABLE", false;
    /// 19: one FIFO frame's size (RxPDO or TxPDO).
    FifoPackSizeGet = 19, "FIFO_PACK_SIZE_GET", false;
    /// 20: the SPI packet's data-section size.
    SpiPackSizeGet = 20, "SPI_PACK_SIZE_GET", false;
    /// 23: change the SPI packet's data-section size.
    SpiReconfig = 23, "SPI_RECONFIG_OP", false;
    /// 24: clear the SPI CRC error counter.
    CrcErrCountClear = 24, "CRC_ERR_CNT_CLR", false;
    /// 25: set the check type (v049; v031 numbered it 3).
    CrcTypeSet = 25, "CRC_TYPE_SET", false;
    /// 26: configure the internal CiA402 helper for an axis.
    Cia402ConfigSet = 26, "402_CONFIG_SET", false;
    /// 27: drive an axis to a CiA402 state.
    Cia402StateSet = 27, "402_STATE_SET", false;
    /// 28: an axis' CiA402 state.
    Cia402StateGet = 28, "402_STATE_GET", false;
    /// 29: set the CiA402 helper's control byte.
    Cia402CtlSet = 29, "402_CTL_SET", false;
    /// 30: the CiA402 helper's control byte.
    Cia402CtlGet = 30, "402_CTL_GET", false;
    /// 31: GPIO configuration sub-operations.
    GpioConfigSet = 31, "GPIO_CONFIG_SET", false;
    /// 32: GPIO value and interrupt-flag sub-operations.
    GpioFuncOp = 32, "GPIO_FUNC_OP", false;
    /// 33: quadrature encoder sub-operations.
    QeiFuncOp = 33, "QEI_FUNC_OP", false;
    /// 34: DAC sub-operations.
    DacFuncOp = 34, "DAC_FUNC_OP", false;
    /// 35: ADC sub-operations.
    AdcFuncOp = 35, "ADC_FUNC_OP", false;
    /// 38: SII EEPROM word read/write request (fetch with 39).
    EepromReq = 38, "EEPROM_REQ", true;
    /// 39: fetch the result of 38.
    EepromGet = 39, "EEPROM_GET", false;
    /// 41: set, refresh and check a state in one blocking step.
    StateCheck = 41, "ECAT_STATE_CHECK", true;
    /// 50: one slave's DC activation, cycle and shift.
    DcSync = 50, "ECAT_DCSYNC", true;
    /// 51: clear the FIFOs.
    FifoClear = 51, "FIFO_CLR_OP", false;
    /// 52: TxFIFO depth.
    FifoSetTxCount = 52, "FIFO_SET_TX_CNT", false;
    /// 53: TxFIFO depth.
    FifoGetTxCount = 53, "FIFO_GET_TX_CNT", false;
    /// 54: RxFIFO depth.
    FifoSetRxCount = 54, "FIFO_SET_RX_CNT", false;
    /// 55: RxFIFO depth.
    FifoGetRxCount = 55, "FIFO_GET_RX_CNT", false;
    /// 56: firmware version.
    FwVersionGet = 56, "FW_VERSION_GET", false;
    /// 57: refresh the slaves' states into the chip.
    StateUpdate = 57, "ECAT_STATE_UPDATE", true;
    /// 58: INT0/INT1 polarity and the INT1 enable mask.
    IntSetEnable = 58, "ECAT_INT_SET_ENABLE", false;
    /// 59: INT0/INT1 polarity and the INT1 enable mask.
    IntGetEnable = 59, "ECAT_INT_GET_ENABLE", false;
    /// 66: build the FIFOs from their depths and the frame sizes.
    FifoInit = 66, "FIFO_INIT", true;
    /// 69: the abort code of the last failed SDO.
    SdoAbortCodeGet = 69, "ECAT_SDO_ABORTCODE_GET", false;
    /// 70: TxFIFO high / RxFIFO low interrupt marks.
    SetFifoThreshold = 70, "ECAT_SET_FIFO_TH", false;
    /// 71: configure a SyncManager by hand.
    ConfigSm = 71, "ECAT_CONFIG_SM", true;
    /// 72: configure FMMUs (obsolete: the chip overwrites them).
    ConfigFmmu = 72, "ECAT_CONFIG_FMMU", false;
    /// 73: apply PDO mapping (instead of 2 for slaves that reset theirs).
    ConfigMap = 73, "ECAT_CONFIG_MAP", true;
    /// 74: an axis' statusword.
    Cia402GetStatusword = 74, "402_GET_STATUSWORD", false;
    /// 75: reset the blocking-command machinery.
    AsyncCmdReset = 75, "ASYNC_CMD_RESET", false;
    /// 81: PHY register access over MDIO.
    Mdio = 81, "MDIO", false;
    /// 82: set a slave's process-data length by hand.
    DirectAssign = 82, "DIRECT_ASSIGN", false;
    /// 83: the last n CoE emergency messages.
    CoeEmergency = 83, "COE_EMERGENCY", false;
    /// 127: reset the chip.
    WarmReset = 127, "WARM_RESET", false;
    /// 130: current consecutive WKC errors.
    WkcContiErrCountGet = 130, "ECAT_WKC_CONTI_ERR_CNT_GET", false;
    /// 131: the consecutive-WKC-error limit.
    WkcContiErrMaxGet = 131, "ECAT_WKC_CONTI_ERR_MAX_GET", false;
    /// 132: set the consecutive-WKC-error limit.
    WkcContiErrMaxSet = 132, "ECAT_WKC_CONTI_ERR_MAX_SET", false;
    /// 137: send any EtherCAT datagram (fetch with 138).
    RawEcatReq = 137, "RAW_ECAT_FUNC_REQ", true;
    /// 138: the answer to 137.
    RawEcatGet = 138, "RAW_ECAT_FUNC_GET", false;
    /// 139: FoE and chip-flash staging operations (fetch with 140).
    FoeReq = 139, "FOE_FUNC_REQ", true;
    /// 140: data read by 139.
    FoeGet = 140, "FOE_FUNC_GET", false;
    /// 142: enable/disable LRW.
    EnableLrw = 142, "ENABLE_LRW", false;
    /// 143: read a slave's receive mailbox.
    RecvMailbox = 143, "RECV_MAILBOX", false;
    /// 144: receive-mailbox status and polling.
    MbxStat = 144, "MBX_STAT", false;
}

impl fmt::Display for CommandCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Other(v) => write!(f, "command {v}"),
            known => write!(f, "{} ({})", known.name(), known.to_u8()),
        }
    }
}

impl From<u8> for CommandCode {
    fn from(v: u8) -> Self {
        Self::from_u8(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_byte_round_trips() {
        for b in 0..=255u8 {
            assert_eq!(CommandCode::from_u8(b).to_u8(), b);
        }
    }

    #[test]
    fn listed_codes_are_the_notes_list() {
        let codes: std::vec::Vec<u8> = CommandCode::ALL.iter().map(|c| c.to_u8()).collect();
        let expected = [
            0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 15, 16, 18, 19, 20, 23, 24, 25, 26, 27, 28, 29, 30, 31, 32,
            33, 34, 35, 38, 39, 41, 50, 51, 52, 53, 54, 55, 56, 57, 58, 59, 66, 69, 70, 71, 72, 73, 74, 75, 81, 82, 83,
            127, 130, 131, 132, 137, 138, 139, 140, 142, 143, 144,
        ];
        assert_eq!(codes, expected);
        for c in CommandCode::ALL {
            assert!(!matches!(c, CommandCode::Other(_)));
            assert_ne!(c.name(), "UNKNOWN");
        }
    }

    #[test]
    fn v049_numbering_traps() {
        assert_eq!(CommandCode::from_u8(3), CommandCode::EcatInitDc);
        assert_eq!(CommandCode::from_u8(25), CommandCode::CrcTypeSet);
    }

    #[test]
    fn blocking_set_is_exactly_the_documented_one() {
        let blocking: std::vec::Vec<u8> =
            CommandCode::ALL.iter().filter(|c| c.is_blocking()).map(|c| c.to_u8()).collect();
        assert_eq!(blocking, [1, 2, 3, 7, 8, 10, 12, 38, 41, 50, 57, 66, 71, 73, 137, 139]);
        assert!(!CommandCode::Other(200).is_blocking());
    }
}
