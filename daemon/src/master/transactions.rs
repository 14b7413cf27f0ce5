//! The chip's blocking-slot operations as async methods: SDO, SII, states,
//! PDO assignment, raw datagrams, FoE. Each is one queued transaction (or,
//! for ranges, one per word pair) with a deadline; arguments are checked
//! here, before anything is queued, and errors name the field.

use ecmxf_wire::payload::foe::FOE_FLASH_SIZE;
use ecmxf_wire::payload::pdo::{PdoConfig, PdoConfigReply, RX_PDO_ASSIGN, TX_PDO_ASSIGN};
pub(crate) use ecmxf_wire::payload::raw::DatagramCommand;
use ecmxf_wire::payload::raw::{DatagramHead, RAW_MAX_DATA};
use ecmxf_wire::payload::slave_info::SlaveInfo;
pub(crate) use ecmxf_wire::payload::slave_info::SlaveInfoCode;
use ecmxf_wire::{EcatState, Reply, ReplyFields};
use std::sync::Arc;

use super::states::SlaveSelector;
use super::{Call, Master};
use crate::engine::error::EngineError;
pub(crate) use crate::engine::slot::Immediate;
use crate::engine::slot::{SlotRequest, TransferProgress};

/// The largest file FoE moves: what the chip's staging flash holds (FoE
/// commands, v049).
pub(crate) const FOE_MAX_FILE: usize = FOE_FLASH_SIZE as usize;

/// How long the chip waits for a raw datagram to come back, us.
const RAW_TIMEOUT_US: u32 = 10_000;

/// What a raw datagram brought back.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RawAnswer {
    /// Working counter: how many slaves acted on it.
    pub working_counter: u16,
    /// The datagram's data as it returned.
    pub data: Vec<u8>,
}

/// Auto-increment addressing: the slave at position n is -n.
fn position(slave: u8) -> u16 {
    0u16.wrapping_sub(slave.into())
}

impl Master {
    /// SDO upload.
    pub async fn sdo_read(
        &self,
        slave: u8,
        index: u16,
        subindex: u8,
        complete: bool,
        call: Call,
    ) -> Result<Vec<u8>, EngineError> {
        self.check_coe(slave, call).await?;
        let _mailbox = self.coe_lock(slave).await;
        self.request(SlotRequest::SdoRead { slave, index, subindex, complete }, call).await
    }

    /// SDO download.
    pub async fn sdo_write(
        &self,
        slave: u8,
        index: u16,
        subindex: u8,
        complete: bool,
        data: Vec<u8>,
        call: Call,
    ) -> Result<(), EngineError> {
        self.check_coe(slave, call).await?;
        let _mailbox = self.coe_lock(slave).await;
        self.request(SlotRequest::SdoWrite { slave, index, subindex, complete, data }, call).await.map(|_| ())
    }

    /// SII words `word` and `word + 1`.
    pub async fn eeprom_read(&self, slave: u8, word: u16, call: Call) -> Result<[u8; 4], EngineError> {
        let d = self.request(SlotRequest::EepromRead { slave, word }, call).await?;
        let mut out = [0xFF; 4];
        for (o, b) in out.iter_mut().zip(d) {
            *o = b;
        }
        Ok(out)
    }

    /// `count` SII words from `word` on. Each word pair is its own
    /// transaction, so a long read shares the blocking slot fairly with
    /// other callers; `call`'s deadline bounds the whole range.
    pub async fn eeprom_read_words(
        &self,
        slave: u8,
        word: u16,
        count: u16,
        call: Call,
    ) -> Result<Vec<u16>, EngineError> {
        if u32::from(word) + u32::from(count) > 0x1_0000 {
            let reason = format!("{count} words from {word:#06x} run past the 16-bit word address space");
            return Err(EngineError::BadArgument { field: "count", reason });
        }
        let mut out = Vec::with_capacity(usize::from(count));
        let mut at = word;
        while out.len() < usize::from(count) {
            let pair = self.eeprom_read(slave, at, call).await?;
            out.push(u16::from_le_bytes([pair[0], pair[1]]));
            if out.len() < usize::from(count) {
                out.push(u16::from_le_bytes([pair[2], pair[3]]));
            }
            at = at.wrapping_add(2);
        }
        Ok(out)
    }

    /// Writes SII words from `word` on, each verified by reading it back;
    /// stops at the first failure, which names the word.
    pub async fn eeprom_write_words(
        &self,
        slave: u8,
        word: u16,
        values: &[u16],
        call: Call,
    ) -> Result<(), EngineError> {
        if u32::from(word) + values.len() as u32 > 0x1_0000 {
            let reason = format!("{} words from {word:#06x} run past the 16-bit word address space", values.len());
            return Err(EngineError::BadArgument { field: "values", reason });
        }
        for (i, v) in values.iter().enumerate() {
            self.eeprom_write(slave, word + i as u16, *v, call).await?;
        }
        Ok(())
    }

    /// Writes one SII word and verifies it.
    pub async fn eeprom_write(&self, slave: u8, word: u16, value: u16, call: Call) -> Result<(), EngineError> {
        let written = self.request(SlotRequest::EepromWrite { slave, word, value }, call).await.map(|_| ());
        // What was read of this EEPROM (or one of its identity) may be old.
        self.sii_cache.forget();
        written
    }

    /// The state a slave (or, for `All`, the network) is in now, freshly
    /// read from the slaves.
    pub async fn get_state(&self, target: SlaveSelector, call: Call) -> Result<EcatState, EngineError> {
        let d = self.request(SlotRequest::GetState { target }, call).await?;
        Ok(EcatState::from_u8(d.first().copied().unwrap_or(0)))
    }

    /// One item of slave information, as the chip answers it (checked to
    /// decode as `item`); [`Master::slave_number`] and
    /// [`Master::slave_name`] decode it for callers.
    pub async fn slave_info(&self, slave: u8, item: SlaveInfoCode, call: Call) -> Result<Vec<u8>, EngineError> {
        let d = self.request(SlotRequest::SlaveInfo { slave, item }, call).await?;
        SlaveInfo::decode(item, &d)
            .map_err(|error| EngineError::BadAnswer { what: format!("{item} of slave {slave}"), error })?;
        Ok(d)
    }

    /// A numeric item of slave information (state, AL status code,
    /// identity, sizes, DC), decoded here once for every caller (the API,
    /// the metrics).
    pub(crate) async fn slave_number(&self, slave: u8, item: SlaveInfoCode, call: Call) -> Result<u32, EngineError> {
        let d = self.slave_info(slave, item, call).await?;
        SlaveInfo::decode(item, &d)
            .ok()
            .and_then(|i| i.number())
            .ok_or_else(|| EngineError::Failed(format!("{item} of slave {slave} is not a number")))
    }

    /// The slave's name as the chip reads it (up to the first NUL).
    pub(crate) async fn slave_name(&self, slave: u8, call: Call) -> Result<String, EngineError> {
        let d = self.slave_info(slave, SlaveInfoCode::Name, call).await?;
        match SlaveInfo::decode(SlaveInfoCode::Name, &d) {
            Ok(SlaveInfo::Name(n)) => Ok(String::from_utf8_lossy(n).into_owned()),
            _ => Err(EngineError::Failed(format!("the name of slave {slave} does not decode"))),
        }
    }

    /// A slave's PDO assignment (`assign_index` 0x1C12 for RxPDOs, 0x1C13
    /// for TxPDOs) and the mapping of each assigned PDO, read from the slave.
    pub async fn pdo_config_read(&self, slave: u8, assign_index: u16, call: Call) -> Result<PdoConfig, EngineError> {
        if ![RX_PDO_ASSIGN, TX_PDO_ASSIGN].contains(&assign_index) {
            let reason = format!("{assign_index:#06x}; use {RX_PDO_ASSIGN:#06x} or {TX_PDO_ASSIGN:#06x}");
            return Err(EngineError::BadArgument { field: "assign_index", reason });
        }
        // The chip reads the assignment over CoE.
        self.check_coe(slave, call).await?;
        let _mailbox = self.coe_lock(slave).await;
        let d = self.request(SlotRequest::PdoConfigRead { slave, assign_index }, call).await?;
        let fields = ReplyFields { value: 0, data_len: d.len() as u16 };
        PdoConfigReply::decode(&fields, &d).map(|r| r.0).map_err(|error| EngineError::BadAnswer {
            what: format!("PDO assignment {assign_index:#06x} of slave {slave}"),
            error,
        })
    }

    /// Sends one raw EtherCAT datagram and returns what came back. A reading
    /// datagram sends `head.length` zero bytes; a writing one sends `data`,
    /// which must be exactly `head.length` bytes.
    pub async fn raw_datagram(&self, head: DatagramHead, data: Vec<u8>, call: Call) -> Result<RawAnswer, EngineError> {
        if head.length > RAW_MAX_DATA {
            let reason = format!("{} bytes; a datagram carries at most {RAW_MAX_DATA}", head.length);
            return Err(EngineError::BadArgument { field: "length", reason });
        }
        if head.command.writes() && data.len() != usize::from(head.length) {
            let reason = format!("{} bytes given for a {}-byte writing datagram", data.len(), head.length);
            return Err(EngineError::BadArgument { field: "data", reason });
        }
        if !head.command.writes() && !data.is_empty() {
            let reason = format!("{} is a reading datagram and sends no data", head.command);
            return Err(EngineError::BadArgument { field: "data", reason });
        }
        let d = self.request(SlotRequest::Raw { head, data }, call).await?;
        let Some((wkc, data)) = d.split_first_chunk::<2>() else {
            return Err(EngineError::Failed("raw datagram: answer without a working counter".into()));
        };
        Ok(RawAnswer { working_counter: u16::from_le_bytes(*wkc), data: data.to_vec() })
    }

    /// Sends one datagram as a front end names it: `adp` and `ado` are the
    /// address (for the logical commands, the high and low halves of the
    /// logical address); a reading datagram brings back `length` bytes, a
    /// writing one sends `data` (`length` bytes).
    pub(crate) async fn datagram(
        &self,
        command: DatagramCommand,
        adp: u16,
        ado: u16,
        length: u16,
        data: Vec<u8>,
        call: Call,
    ) -> Result<RawAnswer, EngineError> {
        let logical = if matches!(command, DatagramCommand::Lrd | DatagramCommand::Lwr | DatagramCommand::Lrw) {
            (u32::from(adp) << 16) | u32::from(ado)
        } else {
            0
        };
        let head = DatagramHead { command, length, adp, ado, logical, timeout_us: RAW_TIMEOUT_US };
        self.raw_datagram(head, data, call).await
    }

    /// Reads `length` bytes of a slave's ESC registers from `address` on
    /// (APRD: the slave by its position).
    pub(crate) async fn read_registers(
        &self,
        slave: u8,
        address: u16,
        length: u16,
        call: Call,
    ) -> Result<RawAnswer, EngineError> {
        self.datagram(DatagramCommand::Aprd, position(slave), address, length, Vec::new(), call).await
    }

    /// Writes `data` to a slave's ESC registers from `address` on (APWR:
    /// the slave by its position).
    pub(crate) async fn write_registers(
        &self,
        slave: u8,
        address: u16,
        data: Vec<u8>,
        call: Call,
    ) -> Result<RawAnswer, EngineError> {
        let length = u16::try_from(data.len())
            .map_err(|_| EngineError::BadArgument { field: "length", reason: format!("{} bytes", data.len()) })?;
        self.datagram(DatagramCommand::Apwr, position(slave), address, length, data, call).await
    }

    /// Writes a file to a slave over FoE (the slave must be in PRE-OP or
    /// above). `progress`, when given, follows the bytes staged.
    pub async fn foe_write(
        &self,
        slave: u8,
        name: &str,
        password: u32,
        data: Vec<u8>,
        progress: Option<Arc<TransferProgress>>,
        call: Call,
    ) -> Result<(), EngineError> {
        self.check_foe(slave, call).await?;
        let request = SlotRequest::FoeWrite { slave, name: name.to_owned(), password, data };
        let _mailbox = self.coe_lock(slave).await;
        self.request_with_progress(request, call, progress).await.map(|_| ())
    }

    /// Reads a file of at most `max_len` bytes from a slave over FoE.
    /// `progress`, when given, follows the bytes read back.
    pub async fn foe_read(
        &self,
        slave: u8,
        name: &str,
        password: u32,
        max_len: u32,
        progress: Option<Arc<TransferProgress>>,
        call: Call,
    ) -> Result<Vec<u8>, EngineError> {
        self.check_foe(slave, call).await?;
        let request = SlotRequest::FoeRead { slave, name: name.to_owned(), password, max_len };
        let _mailbox = self.coe_lock(slave).await;
        self.request_with_progress(request, call, progress).await
    }

    /// A non-blocking chip command (peripherals, CiA402 helper, emergency
    /// history): its return value and data.
    pub async fn immediate(&self, command: Immediate, call: Call) -> Result<(u8, Vec<u8>), EngineError> {
        let mut d = self.request(SlotRequest::Immediate(command), call).await?;
        if d.is_empty() {
            return Err(EngineError::Failed(format!("{}: empty answer", SlotRequest::Immediate(command))));
        }
        let value = d.remove(0);
        Ok((value, d))
    }
}
