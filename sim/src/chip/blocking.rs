//! The single blocking slot (v049 表三 notes; docs/protocol.md §8): one
//! operation at a time, busy flag while it runs, effects
//! applied when it completes, error bit3 when it fails. A modelled duration
//! per operation stands in for the EtherCAT traffic it needs.

use ecmxf_wire::AnyRequest;
use ecmxf_wire::flags::ErrorFlags;
use ecmxf_wire::payload::ecat_init::{DcSync, DcTiming, EcatInit};
use ecmxf_wire::payload::eeprom::{EepromAccess, EepromRequest};
use ecmxf_wire::payload::foe::{FOE_MAX_CHUNK, FoeRequest};
use ecmxf_wire::payload::pdo::{ConfigSm, PdoConfig, PdoConfigForm, PdoConfigReq, PdoEntry, PdoMapping};
use ecmxf_wire::payload::raw::{DatagramCommand, DatagramHead};
use ecmxf_wire::payload::sdo::{SdoAbortCode, SdoAccess};
use ecmxf_wire::payload::state::SlaveSelector;

use super::exec::CommandError;
use super::{Chip, Slot};
use crate::net::esm::AlState;

/// Modelled durations of blocking operations.
#[derive(Clone, Debug)]
pub struct Timing {
    /// ECAT_INIT, fixed part.
    pub init_ns: u64,
    /// ECAT_INIT, per slave (scan, SII read, mailbox setup).
    pub init_per_slave_ns: u64,
    /// One state change, per slave addressed.
    pub state_ns: u64,
    /// One SDO round trip over the mailbox.
    pub sdo_ns: u64,
    /// Extra per byte beyond an expedited transfer (segmented SDO).
    pub sdo_per_byte_ns: u64,
    /// One EEPROM word operation.
    pub eeprom_ns: u64,
    /// PDO configuration set/read.
    pub pdo_config_ns: u64,
    /// RECONFIG / CONFIG_MAP / FIFO_INIT.
    pub reconfig_ns: u64,
    /// DCSYNC / INIT_DC.
    pub dc_ns: u64,
    /// Time until DC reports stable after INIT_DC.
    pub dc_settle_ns: u64,
    /// One raw datagram.
    pub raw_ns: u64,
    /// FoE, per 256-byte chunk.
    pub foe_chunk_ns: u64,
}

impl Default for Timing {
    fn default() -> Self {
        Self {
            init_ns: 20_000_000,
            init_per_slave_ns: 2_000_000,
            state_ns: 1_000_000,
            sdo_ns: 600_000,
            sdo_per_byte_ns: 2_000,
            eeprom_ns: 150_000,
            pdo_config_ns: 3_000_000,
            reconfig_ns: 2_000_000,
            dc_ns: 1_000_000,
            dc_settle_ns: 5_000_000,
            raw_ns: 100_000,
            foe_chunk_ns: 1_000_000,
        }
    }
}

/// CoE abort code 0x05040000: SDO protocol timed out (ETG.1000.6).
const SDO_PROTOCOL_TIMED_OUT: u32 = 0x0504_0000;

/// `op` taking `duration` ns, unless the request's timeout (us, 0: none) is
/// shorter: then it fails when the timeout runs out.
fn within(op: BlockingOp, duration: u64, timeout_us: u32, sdo: bool) -> (BlockingOp, u64) {
    let limit = u64::from(timeout_us) * 1000;
    if timeout_us != 0 && duration > limit { (BlockingOp::TimedOut { sdo }, limit) } else { (op, duration) }
}

/// The "operation error code" the GET commands return for the last request
/// of their kind (v049: EEPROM_GET's return value is 操作錯誤碼; SDO_GET,
/// RAW_ECAT_FUNC_GET and FOE_FUNC_GET answer the same way here). v049 lists
/// no values; the model's are: 0 done, [`RESULT_FAILED`], [`RESULT_TIMED_OUT`],
/// [`RESULT_NOT_DONE`]. A GET never hands back an earlier request's data as
/// the answer to a later one that failed (after a timed-out EEPROM_REQ a
/// host once read the previous word with error code 0).
pub mod result_code {
    /// The operation failed: no answer from the slave, or it refused.
    pub const RESULT_FAILED: u8 = 1;
    /// The request's own timeout ran out first.
    pub const RESULT_TIMED_OUT: u8 = 2;
    /// The request has not finished (or none was made).
    pub const RESULT_NOT_DONE: u8 = 3;
}
use result_code::*;

/// A blocking operation in the slot, with everything it needs owned.
#[derive(Clone, Debug, PartialEq)]
pub enum BlockingOp {
    /// An SDO or EEPROM request whose modelled duration exceeds the
    /// timeout it carried: it fails when the timeout runs out.
    TimedOut {
        /// An SDO (abort 0x05040000 follows) or an EEPROM word.
        sdo: bool,
    },
    /// 1.
    EcatInit(EcatInit),
    /// 2 and 73.
    Reconfig,
    /// 3.
    InitDc,
    /// 7.
    PdoConfigSet(PdoConfig),
    /// 8.
    PdoConfigReq(PdoConfigReq),
    /// 10.
    Sdo {
        /// Slave.
        slave: usize,
        /// Index.
        index: u16,
        /// Subindex.
        sub: u8,
        /// Complete access.
        complete: bool,
        /// `None` = read.
        write: Option<Vec<u8>>,
    },
    /// 12 and 41 (41 also refreshes the cached states).
    StateSet {
        /// Which slaves.
        target: SlaveSelector,
        /// Requested state code.
        state: u8,
    },
    /// 57 and control bit1.
    StateUpdate,
    /// 38.
    Eeprom(EepromRequest),
    /// 50.
    DcSync(DcSync),
    /// 66.
    FifoInit,
    /// 71.
    ConfigSm(ConfigSm),
    /// 137.
    Raw {
        /// Addressing.
        head: DatagramHead,
        /// Data sent.
        data: Vec<u8>,
    },
    /// 139.
    Foe(FoeOp),
}

/// An owned FoE operation.
#[derive(Clone, Debug, PartialEq)]
pub enum FoeOp {
    /// Slave file -> flash.
    Upload {
        /// Slave.
        slave: usize,
        /// Name.
        name: Vec<u8>,
        /// Password.
        password: u32,
        /// Flash offset.
        offset: u32,
        /// Most bytes.
        max: u32,
    },
    /// Flash -> slave file.
    Download {
        /// Slave.
        slave: usize,
        /// Name.
        name: Vec<u8>,
        /// Password.
        password: u32,
        /// Flash offset.
        offset: u32,
        /// Length.
        length: u32,
    },
    /// Flash read.
    ReadFlash {
        /// Offset.
        offset: u32,
        /// Length.
        length: u16,
    },
    /// Flash write.
    WriteFlash {
        /// Offset.
        offset: u32,
        /// Bytes.
        data: Vec<u8>,
    },
}

impl Chip {
    fn slave_ok(&self, slave: usize) -> Result<usize, CommandError> {
        if slave < self.net.reachable() { Ok(slave) } else { Err(CommandError) }
    }

    /// Validates a blocking command and puts it in the slot.
    ///
    /// SDO_REQ and EEPROM_REQ carry the longest wait in us (v049 SDO_REQ
    /// data 0x08, EEPROM_REQ; v031 said ns): an operation the model says
    /// takes longer fails when that time is up, an SDO with abort
    /// 0x05040000 (SDO protocol timed out). 0 is taken as no limit.
    pub(super) fn start_blocking(&mut self, req: &AnyRequest<'_>) -> Result<(), CommandError> {
        use AnyRequest as A;
        let t = &self.config.timing;
        let n = self.net.reachable() as u64;
        let (op, duration) = match *req {
            A::EcatInit(init) => {
                let sync0 = init.dc.sync0_ns;
                if sync0 != 0 && sync0 < DcTiming::MIN_CYCLE_NS {
                    return Err(CommandError);
                }
                (BlockingOp::EcatInit(init), t.init_ns + n * t.init_per_slave_ns)
            }
            A::EcatReconfig(_) | A::ConfigMap(_) => (BlockingOp::Reconfig, t.reconfig_ns),
            A::EcatInitDc(_) => (BlockingOp::InitDc, t.dc_ns),
            A::PdoConfigSet(c) => {
                self.slave_ok(c.slave.into())?;
                (BlockingOp::PdoConfigSet(c), t.pdo_config_ns)
            }
            A::PdoConfigReq(r) => {
                self.slave_ok(r.slave.into())?;
                (BlockingOp::PdoConfigReq(r), t.pdo_config_ns)
            }
            A::SdoReq(r) => {
                let slave = self.slave_ok(r.slave.into())?;
                let write = match r.access {
                    SdoAccess::Read { .. } => None,
                    SdoAccess::Write(b) => Some(b.to_vec()),
                };
                let bytes = write.as_ref().map_or(4, Vec::len).max(4) as u64 - 4;
                let op = BlockingOp::Sdo { slave, index: r.index, sub: r.subindex, complete: r.complete_access, write };
                within(op, t.sdo_ns + bytes * t.sdo_per_byte_ns, r.timeout_us, true)
            }
            A::StateSet(ecmxf_wire::payload::state::StateSet { target, state })
            | A::StateCheck(ecmxf_wire::payload::state::StateCheck { target, state }) => {
                if let SlaveSelector::One(i) = target {
                    self.slave_ok(i.into())?;
                }
                let k = if target == SlaveSelector::All { n.max(1) } else { 1 };
                (BlockingOp::StateSet { target, state: state.to_u8() }, k * t.state_ns)
            }
            A::StateUpdate(_) => (BlockingOp::StateUpdate, t.state_ns),
            A::EepromReq(r) => {
                self.slave_ok(r.slave.into())?;
                within(BlockingOp::Eeprom(r), t.eeprom_ns, r.timeout_us, false)
            }
            A::DcSync(d) => {
                self.slave_ok(d.slave.into())?;
                (BlockingOp::DcSync(d), t.dc_ns)
            }
            A::FifoInit(_) => (BlockingOp::FifoInit, t.reconfig_ns),
            A::ConfigSm(c) => {
                self.slave_ok(c.slave.into())?;
                (BlockingOp::ConfigSm(c), t.dc_ns)
            }
            A::RawEcatReq(r) => (BlockingOp::Raw { head: r.head, data: r.data.to_vec() }, t.raw_ns),
            A::FoeReq(f) => {
                let (op, chunks) = match f {
                    FoeRequest::Upload(x) => {
                        let slave = self.slave_ok(x.slave.into())?;
                        let op = FoeOp::Upload {
                            slave,
                            name: x.name.to_vec(),
                            password: x.password,
                            offset: x.flash_offset,
                            max: x.file_length,
                        };
                        (op, u64::from(x.file_length.div_ceil(FOE_MAX_CHUNK)).max(1))
                    }
                    FoeRequest::Download(x) => {
                        let slave = self.slave_ok(x.slave.into())?;
                        let op = FoeOp::Download {
                            slave,
                            name: x.name.to_vec(),
                            password: x.password,
                            offset: x.flash_offset,
                            length: x.file_length,
                        };
                        (op, u64::from(x.file_length.div_ceil(FOE_MAX_CHUNK)).max(1))
                    }
                    FoeRequest::ReadFlash { offset, length } => (FoeOp::ReadFlash { offset, length }, 0),
                    FoeRequest::WriteFlash { offset, data } => (FoeOp::WriteFlash { offset, data: data.to_vec() }, 0),
                };
                (BlockingOp::Foe(op), chunks * t.foe_chunk_ns + t.raw_ns)
            }
            _ => return Err(CommandError),
        };
        self.results.forget(&op);
        self.pending = Some((op, self.now_ns + duration));
        Ok(())
    }

    /// Control bit1: refresh the ECAT state from the slaves (blocking).
    pub(super) fn start_refresh(&mut self) {
        self.pending = Some((BlockingOp::StateUpdate, self.now_ns + self.config.timing.state_ns));
    }

    /// Applies a completed operation; a failure sets error bit3.
    pub(super) fn finish_blocking(&mut self, op: BlockingOp) {
        if !self.apply(op) {
            self.errors |= ErrorFlags::BLOCKING_FAILED;
        }
    }

    /// Reads every configured slave's state; one that no longer answers
    /// reads as an error.
    fn refresh_states(&mut self) {
        let reachable = self.net.reachable();
        self.master.cached_states = self
            .net
            .slaves
            .iter()
            .take(self.master.configured)
            .enumerate()
            .map(|(i, s)| if i < reachable { u8::try_from(s.esm.al_status_register()).unwrap_or(0x10) } else { 0x10 })
            .collect();
    }

    fn apply(&mut self, op: BlockingOp) -> bool {
        match op {
            BlockingOp::EcatInit(init) => self.ecat_init(init),
            BlockingOp::Reconfig => {
                self.build_frames();
                true
            }
            BlockingOp::InitDc => {
                self.master.dc_stable_at = Some(self.now_ns + self.config.timing.dc_settle_ns);
                true
            }
            BlockingOp::PdoConfigSet(c) => self.pdo_config_set(c),
            BlockingOp::PdoConfigReq(r) => self.pdo_config_req(r),
            BlockingOp::TimedOut { sdo } => {
                if sdo {
                    self.results.sdo = RESULT_TIMED_OUT;
                    self.results.sdo_abort = SDO_PROTOCOL_TIMED_OUT;
                } else {
                    self.results.eeprom = (RESULT_TIMED_OUT, Vec::new());
                }
                false
            }
            BlockingOp::Sdo { slave, index, sub, complete, write } => {
                let s = &mut self.net.slaves[slave];
                s.mailboxes.chip_request();
                let result = match write {
                    Some(data) => s.sdo_download(index, sub, complete, &data).map(|()| Vec::new()),
                    None => s.sdo_upload(index, sub, complete),
                };
                match result {
                    Ok(mut data) => {
                        data.truncate(self.spi.data_size);
                        self.results.sdo_data = data;
                        self.results.sdo = 0;
                        self.results.sdo_abort = 0;
                        true
                    }
                    Err(code) => {
                        self.results.sdo = RESULT_FAILED;
                        self.results.sdo_abort = code.0;
                        false
                    }
                }
            }
            BlockingOp::StateSet { target, state } => {
                let mut ok = true;
                let reachable = self.net.reachable();
                for (i, s) in self.net.slaves.iter_mut().enumerate().take(self.master.configured.max(reachable)) {
                    if target == SlaveSelector::All || target == SlaveSelector::One(i as u8) {
                        ok &= i < reachable && s.request_state(state);
                    }
                }
                self.refresh_states();
                ok
            }
            BlockingOp::StateUpdate => {
                self.refresh_states();
                true
            }
            BlockingOp::Eeprom(r) => {
                let s = &mut self.net.slaves[usize::from(r.slave)];
                if !s.present {
                    self.results.eeprom = (RESULT_FAILED, Vec::new());
                    return false;
                }
                self.results.eeprom = match r.access {
                    EepromAccess::Read { address } => (0, s.eeprom_read(address).to_vec()),
                    EepromAccess::Write { address, value } => {
                        s.eeprom_write(address, value);
                        (0, Vec::new())
                    }
                };
                true
            }
            BlockingOp::DcSync(d) => {
                let s = &mut self.net.slaves[usize::from(d.slave)];
                s.dc_cycle_ns = if d.dc.assign_activate != 0 { d.dc.sync0_ns } else { 0 };
                true
            }
            BlockingOp::FifoInit => self.fifo.init(self.master.rx_size, self.master.tx_size),
            BlockingOp::ConfigSm(_) => true,
            BlockingOp::Raw { head, data } => {
                let ok = self.raw_datagram(head, &data);
                self.results.raw_error = if ok { 0 } else { RESULT_FAILED };
                ok
            }
            BlockingOp::Foe(f) => {
                let ok = self.foe(f);
                self.results.foe = if ok { 0 } else { RESULT_FAILED };
                ok
            }
        }
    }

    fn ecat_init(&mut self, init: EcatInit) -> bool {
        let reachable = self.net.reachable();
        if reachable == 0 {
            return false;
        }
        self.master.configured = reachable;
        self.master.dc = init.dc;
        self.master.lrw = !init.disable_lrw;
        self.master.cycle_ns =
            if init.dc.sync0_ns != 0 { u64::from(init.dc.sync0_ns) } else { self.config.free_run_cycle_ns };
        self.master.next_cycle_ns = self.now_ns + self.master.cycle_ns;
        self.master.dc_stable_at =
            (init.dc.assign_activate != 0).then_some(self.now_ns + self.config.timing.dc_settle_ns);
        self.master.exchange_stopped = false;
        self.master.wkc_streak = 0;
        // FIFO output stays off until enabled in OP (v049 ECAT_INIT data 1).
        self.fifo.enabled = false;
        for (i, s) in self.net.slaves.iter_mut().enumerate().take(reachable) {
            s.station_address = 0x1001 + i as u16;
            s.dc_cycle_ns = if s.has_dc && init.dc.assign_activate != 0 { init.dc.sync0_ns } else { 0 };
            s.request_state(AlState::Init.code());
            s.request_state(AlState::PreOp.code());
            s.sync_registers();
        }
        self.master.inited = true;
        self.build_frames();
        self.refresh_states();
        true
    }

    /// Lays out the FIFO frames from each slave's current mapping, in ring
    /// order (RECONFIG, CONFIG_MAP, ECAT_INIT).
    pub(super) fn build_frames(&mut self) {
        let mut slots = Vec::new();
        let (mut rx, mut tx) = (0, 0);
        for (i, s) in self.net.slaves.iter_mut().enumerate().take(self.master.configured) {
            s.relayout();
            let forced = self.direct_assign.iter().find(|e| usize::from(e.0) == i);
            let rx_len = forced.and_then(|e| e.2).map_or(s.rx.bytes(), usize::from);
            let tx_len = forced.and_then(|e| e.3).map_or(s.tx.bytes(), usize::from);
            slots.push(Slot { slave: i, rx_offset: rx, rx_len, tx_offset: tx, tx_len });
            rx += rx_len;
            tx += tx_len;
        }
        self.master.slots = slots;
        self.master.rx_size = rx;
        self.master.tx_size = tx;
        self.master.outputs = vec![0; rx];
        self.master.inputs = vec![0; tx];
        self.fifo.rx.clear();
        self.fifo.tx.clear();
    }

    fn pdo_config_set(&mut self, c: PdoConfig) -> bool {
        let s = &mut self.net.slaves[usize::from(c.slave)];
        let mut steps: Vec<(u16, u8, Vec<u8>)> = vec![(c.assign_index, 0, vec![0])];
        for (i, p) in c.used().iter().enumerate() {
            steps.push((p.index, 0, vec![0]));
            for (k, e) in p.used().iter().enumerate() {
                steps.push((p.index, k as u8 + 1, e.to_u32().to_le_bytes().to_vec()));
            }
            steps.push((p.index, 0, vec![p.used().len() as u8]));
            steps.push((c.assign_index, i as u8 + 1, p.index.to_le_bytes().to_vec()));
        }
        steps.push((c.assign_index, 0, vec![c.used().len() as u8]));
        for (index, sub, data) in steps {
            if let Err(code) = s.sdo_download(index, sub, false, &data) {
                self.results.sdo_abort = code.0;
                return false;
            }
        }
        true
    }

    /// Reads the assignment and its mappings into the result GET answers
    /// with, in the form the request used ([`PdoConfigForm`]): a vendor
    /// form carries four PDO slots, the 156-byte one the slave's vendor id
    /// and product code ahead of them.
    fn pdo_config_req(&mut self, r: PdoConfigReq) -> bool {
        let s = &self.net.slaves[usize::from(r.slave)];
        let Ok(count) = s.sdo_upload(r.assign_index, 0, false) else {
            self.results.sdo_abort = SdoAbortCode::OBJECT_MISSING.0;
            return false;
        };
        let count = count.first().copied().unwrap_or(0);
        let form = match r.form {
            PdoConfigForm::Identified { .. } => PdoConfigForm::Identified {
                vendor_id: s.od.int(0x1018, 1) as u32,
                product_code: s.od.int(0x1018, 2) as u32,
            },
            other => other,
        };
        let mut cfg =
            PdoConfig { slave: r.slave, pdo_count: count, assign_index: r.assign_index, form, ..PdoConfig::default() };
        for (i, slot) in cfg.pdos.iter_mut().enumerate().take(usize::from(count).min(form.slots())) {
            let idx = s.od.int(r.assign_index, i as u8 + 1) as u16;
            let n = s.od.int(idx, 0) as u16;
            let mut m = PdoMapping { index: idx, entry_count: n, entries: Default::default() };
            for (k, e) in m.entries.iter_mut().enumerate().take(usize::from(n)) {
                *e = PdoEntry::from_u32(s.od.int(idx, k as u8 + 1) as u32);
            }
            *slot = m;
        }
        self.results.pdo_config = cfg;
        true
    }

    fn raw_datagram(&mut self, head: DatagramHead, data: &[u8]) -> bool {
        let len = usize::from(head.length);
        let mut out = if data.is_empty() { vec![0u8; len] } else { data.to_vec() };
        let mut wkc = 0u16;
        let targets: Vec<usize> = match head.command {
            DatagramCommand::Aprd | DatagramCommand::Apwr | DatagramCommand::Armw => {
                let pos = 0u16.wrapping_sub(head.adp);
                vec![usize::from(pos)]
            }
            DatagramCommand::Fprd | DatagramCommand::Fpwr | DatagramCommand::Frmw => {
                let reachable = self.net.reachable();
                self.net.slaves.iter().take(reachable).position(|s| s.station_address == head.adp).into_iter().collect()
            }
            DatagramCommand::Brd | DatagramCommand::Bwr => (0..self.net.reachable()).collect(),
            DatagramCommand::Lrd | DatagramCommand::Lwr | DatagramCommand::Lrw => {
                return self.logical_datagram(head, out);
            }
            DatagramCommand::Other(_) => return false,
        };
        let write = matches!(head.command, DatagramCommand::Apwr | DatagramCommand::Fpwr | DatagramCommand::Bwr);
        let rmw = matches!(head.command, DatagramCommand::Armw | DatagramCommand::Frmw);
        let reachable = self.net.reachable();
        for i in targets.into_iter().filter(|i| *i < reachable) {
            let Some(s) = self.net.slaves.get_mut(i) else { continue };
            if write {
                s.esc_write(head.ado, &out);
            } else {
                let mut buf = vec![0u8; len];
                match s.esc_read(head.ado, &mut buf) {
                    Some(true) => {}
                    Some(false) => continue,
                    // The frame did not come back: the datagram failed.
                    None => {
                        self.results.raw = None;
                        return false;
                    }
                }
                if head.command == DatagramCommand::Brd {
                    for (o, b) in out.iter_mut().zip(&buf) {
                        *o |= b;
                    }
                } else {
                    out = buf;
                }
            }
            wkc += 1;
        }
        if rmw {
            let addressed = wkc > 0;
            for s in self.net.slaves.iter_mut().take(reachable) {
                s.write_registers(head.ado, &out);
            }
            wkc = u16::from(addressed) + (reachable as u16).saturating_sub(1);
        }
        self.refresh_states();
        self.results.raw = Some((head, wkc, out));
        true
    }

    fn logical_datagram(&mut self, head: DatagramHead, mut out: Vec<u8>) -> bool {
        let start = head.logical as usize;
        let write = matches!(head.command, DatagramCommand::Lwr | DatagramCommand::Lrw);
        let read = matches!(head.command, DatagramCommand::Lrd | DatagramCommand::Lrw);
        if write {
            for (i, b) in out.iter().enumerate() {
                if let Some(o) = self.master.outputs.get_mut(start + i) {
                    *o = *b;
                }
            }
        }
        if read {
            for (i, b) in out.iter_mut().enumerate() {
                *b = self.master.inputs.get(start + i).copied().unwrap_or(0);
            }
        }
        let wkc = self.master.slots.iter().filter(|s| s.tx_len > 0 && read).count()
            + 2 * self.master.slots.iter().filter(|s| s.rx_len > 0 && write).count();
        self.results.raw = Some((head, wkc as u16, out));
        true
    }

    fn foe(&mut self, op: FoeOp) -> bool {
        match op {
            FoeOp::WriteFlash { offset, data } => {
                let at = offset as usize;
                self.flash[at..at + data.len()].copy_from_slice(&data);
                true
            }
            FoeOp::ReadFlash { offset, length } => {
                let at = offset as usize;
                self.results.foe_read = self.flash[at..at + usize::from(length)].to_vec();
                true
            }
            FoeOp::Upload { slave, name, password, offset, max } => {
                let s = &self.net.slaves[slave];
                if !s.present || !s.has_mailbox || s.esm.state == AlState::Init || password != s.foe_password {
                    return false;
                }
                let Some(file) = s.files.get(&name) else { return false };
                let at = offset as usize;
                let n = file.len().min(max as usize).min(self.flash.len() - at);
                self.flash[at..at + n].copy_from_slice(&file[..n]);
                self.results.foe_read = (n as u32).to_le_bytes().to_vec();
                true
            }
            FoeOp::Download { slave, name, password, offset, length } => {
                let at = offset as usize;
                let end = (at + length as usize).min(self.flash.len());
                let content = self.flash[at..end].to_vec();
                let s = &mut self.net.slaves[slave];
                if !s.present || !s.has_mailbox || s.esm.state == AlState::Init || password != s.foe_password {
                    return false;
                }
                s.files.insert(name, content);
                true
            }
        }
    }
}
