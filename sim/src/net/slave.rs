//! One simulated EtherCAT slave: identity and SII image, ESM, object
//! dictionary and process image, ESC registers, FoE file store, and the
//! device model behind the process data.

use std::collections::BTreeMap;

use ecmxf_wire::payload::sdo::SdoAbortCode;

use super::cia402::{self, Axis, ERROR_PD_TIMEOUT};
use super::esm::{
    AL_INVALID_INPUTS, AL_INVALID_MAILBOX, AL_INVALID_OUTPUTS, AL_INVALID_SYNC_CYCLE, AL_SM_WATCHDOG, AlState, Esm,
    TransitionCheck,
};
use super::mailbox::{Mailboxes, SM1_ACTIVATE, SM1_PDI_CONTROL, SM1_STATUS};
use super::od::{ObjectDictionary, SdoResult, SdoServer};
use super::pdo_map::{self, Layout};
use super::sii::Sii;

/// What drives a slave's process data.
#[derive(Clone, Debug, PartialEq)]
pub enum Device {
    /// A CiA402 drive with one or more axes.
    Drive(Vec<Axis>),
    /// Digital outputs at 0x7000:01 looped back to inputs at 0x6000:01, plus
    /// input bits forced from tests (like the slave-stack "8io" example).
    DigitalIo {
        /// Bits ORed into the inputs.
        forced_inputs: u8,
    },
    /// No behaviour (couplers, slaves loaded from an ESI).
    Passive,
}

/// An emergency message a slave sent (CiA301 EMCY over CoE).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Emergency {
    /// Error code.
    pub error_code: u16,
    /// Error register (0x1001).
    pub error_register: u8,
    /// Manufacturer data.
    pub data: [u8; 5],
}

/// One slave.
#[derive(Clone, Debug)]
pub struct Slave {
    /// Name (SII general name string).
    pub name: String,
    /// The SII image, as words would be read from the EEPROM.
    pub eeprom: Vec<u8>,
    /// Whether the slave speaks CoE (has a mailbox).
    pub has_mailbox: bool,
    /// Whether its SII lists CoE among the mailbox protocols (word 0x1C): a
    /// slave without it never answers a CoE request.
    pub has_coe: bool,
    /// DC supported.
    pub has_dc: bool,
    /// Shortest SYNC0 cycle it accepts, ns (0 = no limit).
    pub min_cycle_ns: u32,
    /// ESM.
    pub esm: Esm,
    /// Object dictionary.
    pub od: ObjectDictionary,
    /// Device model.
    pub device: Device,
    /// Output layout, fixed when entering SAFE-OP.
    pub rx: Layout,
    /// Input layout.
    pub tx: Layout,
    /// Last output image received.
    pub outputs: Vec<u8>,
    /// Current input image.
    pub inputs: Vec<u8>,
    /// Sync manager watchdog, ns (the Neuromeka CORE's process-data timeout
    /// is 50 ms; ETG default 100 ms).
    pub watchdog_ns: u64,
    /// Time since outputs were last written, ns.
    pub since_outputs_ns: u64,
    /// Station alias (SII word 4, register 0x0012).
    pub alias: u16,
    /// Configured station address (register 0x0010).
    pub station_address: u16,
    /// ESC register and memory space (0x0000..0x1000), for raw datagrams.
    pub registers: Vec<u8>,
    /// FoE files.
    pub files: BTreeMap<Vec<u8>, Vec<u8>>,
    /// FoE password (0 = none).
    pub foe_password: u32,
    /// Emergencies not yet collected by the master.
    pub emergencies: Vec<Emergency>,
    /// Whether the slave is plugged in (unplug removes it from the ring).
    pub present: bool,
    /// The DC cycle the master configured, ns.
    pub dc_cycle_ns: u32,
    /// The ESC's two mailboxes, for raw datagrams from the master.
    pub mailboxes: Mailboxes,
    /// Whether it answers CoE SDO Information (SII CoE details bit 1).
    pub sdo_info: bool,
    /// What its description could not carry, in words (a PDO on a sync
    /// manager the device lacks: not assigned), for `ecmxf-sim check`.
    pub notes: Vec<String>,
}

/// Register addresses the simulation keeps live.
pub mod reg {
    /// Station address.
    pub const STATION_ADDRESS: u16 = 0x0010;
    /// Station alias.
    pub const STATION_ALIAS: u16 = 0x0012;
    /// AL control.
    pub const AL_CONTROL: u16 = 0x0120;
    /// AL status.
    pub const AL_STATUS: u16 = 0x0130;
    /// AL status code.
    pub const AL_STATUS_CODE: u16 = 0x0134;
}

struct Checks<'a> {
    slave: &'a Slave,
}

impl TransitionCheck for Checks<'_> {
    fn check(&self, _from: AlState, to: AlState) -> Result<(), u16> {
        let s = self.slave;
        match to {
            AlState::PreOp if s.has_mailbox => {
                let sii = Sii::parse(&s.eeprom).map_err(|_| AL_INVALID_MAILBOX)?;
                if sii.mailbox.rx_size == 0 || sii.mailbox.tx_size == 0 {
                    return Err(AL_INVALID_MAILBOX);
                }
                Ok(())
            }
            AlState::SafeOp => {
                pdo_map::layout(&s.od, true).map_err(|_| AL_INVALID_OUTPUTS)?;
                pdo_map::layout(&s.od, false).map_err(|_| AL_INVALID_INPUTS)?;
                if s.has_dc && s.dc_cycle_ns != 0 && s.dc_cycle_ns < s.min_cycle_ns {
                    return Err(AL_INVALID_SYNC_CYCLE);
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }
}

impl Slave {
    /// A slave from its parts; the SII image decides name, alias and mailbox.
    pub fn new(eeprom: Vec<u8>, od: ObjectDictionary, device: Device, has_dc: bool) -> Self {
        let sii = Sii::parse(&eeprom).unwrap_or_default();
        let name = sii.name().unwrap_or_default();
        let alias = sii.config[4];
        let mut s = Self {
            name,
            has_mailbox: sii.mailbox.rx_size > 0,
            has_coe: sii.protocols & ecmxf_devices::sii::protocol::COE != 0,
            eeprom,
            has_dc,
            min_cycle_ns: 125_000,
            esm: Esm::default(),
            od,
            device,
            rx: Layout::default(),
            tx: Layout::default(),
            outputs: Vec::new(),
            inputs: Vec::new(),
            watchdog_ns: 100_000_000,
            since_outputs_ns: 0,
            alias,
            station_address: 0,
            registers: vec![0; 0x1000],
            files: BTreeMap::new(),
            foe_password: 0,
            emergencies: Vec::new(),
            present: true,
            dc_cycle_ns: 0,
            mailboxes: Mailboxes::new(sii.mailbox),
            sdo_info: sii.general.as_ref().is_some_and(|g| g.coe_details & 0x02 != 0),
            notes: Vec::new(),
        };
        s.relayout();
        s.sync_registers();
        s
    }

    /// SII identity.
    pub fn sii(&self) -> Sii {
        Sii::parse(&self.eeprom).unwrap_or_default()
    }

    /// Recomputes the process-image layout from the dictionary.
    pub fn relayout(&mut self) {
        self.rx = pdo_map::layout(&self.od, true).unwrap_or_default();
        self.tx = pdo_map::layout(&self.od, false).unwrap_or_default();
        self.outputs = vec![0; self.rx.bytes()];
        self.inputs = vec![0; self.tx.bytes()];
    }

    /// An AL control request; returns whether the state was reached.
    pub fn request_state(&mut self, code: u8) -> bool {
        let before = self.esm.state;
        let mut esm = self.esm;
        let ok = esm.request(code, &Checks { slave: self });
        self.esm = esm;
        if ok && before < AlState::SafeOp && self.esm.state >= AlState::SafeOp {
            self.relayout();
        }
        if self.esm.state == AlState::Op && before != AlState::Op {
            self.since_outputs_ns = 0;
        }
        if matches!(self.esm.state, AlState::Init | AlState::Boot) && before >= AlState::PreOp {
            self.mailboxes.reset();
        }
        self.sync_registers();
        ok
    }

    fn mailbox_ready(&self) -> SdoResult<()> {
        // Without a mailbox, without CoE in its SII's protocols, or below
        // PRE-OP, the request never gets a CoE answer: the master times out.
        if !self.present
            || !self.has_mailbox
            || !self.has_coe
            || matches!(self.esm.state, AlState::Init | AlState::Boot)
        {
            return Err(SdoAbortCode::TIMEOUT);
        }
        Ok(())
    }

    /// SDO upload.
    pub fn sdo_upload(&self, index: u16, sub: u8, complete: bool) -> SdoResult<Vec<u8>> {
        self.mailbox_ready()?;
        self.od.upload(index, sub, complete, self.esm.state)
    }

    /// SDO download.
    pub fn sdo_download(&mut self, index: u16, sub: u8, complete: bool, data: &[u8]) -> SdoResult<()> {
        self.mailbox_ready()?;
        let state = self.esm.state;
        self.od.download(index, sub, complete, data, state, pdo_map::validate_write)
    }

    /// Reads an EEPROM word pair (ESCs read 4 bytes at a time).
    pub fn eeprom_read(&self, word: u16) -> [u8; 4] {
        let mut out = [0xFF; 4];
        for (i, b) in out.iter_mut().enumerate() {
            if let Some(v) = self.eeprom.get(usize::from(word) * 2 + i) {
                *b = *v;
            }
        }
        out
    }

    /// Writes one EEPROM word, growing the image if needed.
    pub fn eeprom_write(&mut self, word: u16, value: u16) {
        let at = usize::from(word) * 2;
        if self.eeprom.len() < at + 2 {
            self.eeprom.resize(at + 2, 0xFF);
        }
        self.eeprom[at..at + 2].copy_from_slice(&value.to_le_bytes());
        if word == 4 {
            self.alias = value;
            self.sync_registers();
        }
    }

    /// Mirrors ESM and addresses into the ESC registers.
    pub fn sync_registers(&mut self) {
        let put = |r: &mut Vec<u8>, at: u16, v: u16| {
            r[usize::from(at)..usize::from(at) + 2].copy_from_slice(&v.to_le_bytes())
        };
        put(&mut self.registers, reg::STATION_ADDRESS, self.station_address);
        put(&mut self.registers, reg::STATION_ALIAS, self.alias);
        put(&mut self.registers, reg::AL_STATUS, self.esm.al_status_register());
        put(&mut self.registers, reg::AL_STATUS_CODE, self.esm.al_status);
    }

    /// A raw register read.
    pub fn read_registers(&self, ado: u16, out: &mut [u8]) {
        for (i, b) in out.iter_mut().enumerate() {
            *b = *self.registers.get(usize::from(ado) + i).unwrap_or(&0);
        }
    }

    /// A datagram's write into the ESC: its mailboxes (a request handed to
    /// the slave when the receive mailbox's last byte is written) and its
    /// registers (SM1's repeat request among them).
    pub fn esc_write(&mut self, ado: u16, data: &[u8]) {
        if self.mailboxes.touches(ado, data.len()) {
            if let Some(request) = self.mailboxes.write(ado, data) {
                self.take_mailbox(&request);
            }
        } else {
            self.write_registers(ado, data);
            let at = usize::from(SM1_ACTIVATE);
            if usize::from(ado) <= at && at < usize::from(ado) + data.len() {
                let ack = self.mailboxes.repeat_request(self.registers[at] & 0x02 != 0);
                let pdi = &mut self.registers[usize::from(SM1_PDI_CONTROL)];
                *pdi = (*pdi & !0x02) | if ack { 0x02 } else { 0 };
            }
        }
        self.sync_mailbox_status();
    }

    /// A datagram's read of the ESC; `Some(false)` when it is not counted
    /// (an empty send mailbox, or the receive mailbox, which the master
    /// does not read), `None` when the datagram was lost (a fault).
    pub fn esc_read(&mut self, ado: u16, out: &mut [u8]) -> Option<bool> {
        self.sync_mailbox_status();
        if self.mailboxes.touches(ado, out.len()) {
            let counted = self.mailboxes.read(ado, out);
            self.sync_mailbox_status();
            return counted;
        }
        self.read_registers(ado, out);
        Some(true)
    }

    /// SM1's status: "mailbox full" (bit 3) while an answer waits.
    fn sync_mailbox_status(&mut self) {
        let full = self.mailboxes.full();
        let status = &mut self.registers[usize::from(SM1_STATUS)];
        *status = (*status & !0x08) | if full { 0x08 } else { 0 };
    }

    /// A request the receive mailbox handed over (ETG.1000.4 5.6): CoE
    /// SDO transfers and SDO Information are answered, anything else with
    /// a mailbox error. Below PRE-OP the mailbox is not running: nothing
    /// answers.
    fn take_mailbox(&mut self, request: &[u8]) {
        use ecmxf_wire::mbx::{MailboxError, MailboxType, Message};
        if !self.present || !self.has_mailbox || matches!(self.esm.state, AlState::Init | AlState::Boot) {
            return;
        }
        let Ok(m) = Message::parse(request) else {
            self.mailboxes.post(MailboxType::Error, 0, &MailboxError::SYNTAX.body());
            return;
        };
        let address = m.header.address;
        if self.mailboxes.faults.emergency_first > 0 {
            self.mailboxes.faults.emergency_first -= 1;
            let e =
                ecmxf_wire::mbx::coe::CoeEmergency { error_code: 0xFF00, error_register: 0x80, data: [1, 2, 3, 4, 5] };
            let mut body = [0u8; 10];
            if e.encode(&mut body).is_ok() {
                self.mailboxes.post(MailboxType::Coe, address, &body);
            }
        }
        match m.header.kind {
            MailboxType::Coe if self.has_coe => self.take_coe(address, m.body),
            _ => self.mailboxes.post(MailboxType::Error, address, &MailboxError::UNSUPPORTED_PROTOCOL.body()),
        }
    }

    fn take_coe(&mut self, address: u16, body: &[u8]) {
        use ecmxf_wire::mbx::coe::{CoeHeader, CoeService};
        use ecmxf_wire::mbx::sdo::{SdoRequest, SdoResponse};
        use ecmxf_wire::mbx::sdo_info::{InfoFragment, InfoHeader, InfoOpcode, InfoRequest};
        use ecmxf_wire::mbx::{MailboxError, MailboxType};
        let tx_size = usize::from(self.mailboxes.area.tx_size);
        let mut out = vec![0u8; tx_size.max(64)];
        match CoeHeader::decode(body).map(|h| h.service) {
            Ok(CoeService::SdoRequest) => {
                let answer = match SdoRequest::decode(body) {
                    Ok(SdoRequest::Upload { index, subindex, complete_access }) => {
                        match self.sdo_upload(index, subindex, complete_access) {
                            // Size, then the data, in one message.
                            Ok(data) if data.len() + 16 <= tx_size => {
                                let r = SdoResponse::Uploaded { index, subindex, complete_access, data: &data };
                                r.encode(&mut out)
                            }
                            Ok(_) => {
                                SdoResponse::Abort { index, subindex, code: SdoAbortCode::GENERAL.0 }.encode(&mut out)
                            }
                            Err(code) => SdoResponse::Abort { index, subindex, code: code.0 }.encode(&mut out),
                        }
                    }
                    Ok(SdoRequest::Download { index, subindex, complete_access, data }) => {
                        let data = data.to_vec();
                        match self.sdo_download(index, subindex, complete_access, &data) {
                            Ok(()) => SdoResponse::Downloaded { index, subindex }.encode(&mut out),
                            Err(code) => SdoResponse::Abort { index, subindex, code: code.0 }.encode(&mut out),
                        }
                    }
                    Err(_) => {
                        let (index, subindex) = (
                            u16::from_le_bytes([*body.get(3).unwrap_or(&0), *body.get(4).unwrap_or(&0)]),
                            *body.get(5).unwrap_or(&0),
                        );
                        let code = SdoAbortCode::COMMAND_SPECIFIER.0;
                        SdoResponse::Abort { index, subindex, code }.encode(&mut out)
                    }
                };
                if let Ok(n) = answer {
                    self.mailboxes.post(MailboxType::Coe, address, &out[..n]);
                }
            }
            Ok(CoeService::SdoInformation) if self.sdo_info => {
                let Ok(request) = InfoRequest::decode(body) else {
                    self.mailboxes.post(MailboxType::Error, address, &MailboxError::INVALID_HEADER.body());
                    return;
                };
                match super::sdo_info::answer(&self.od, request) {
                    Ok((opcode, payload)) => {
                        for f in InfoFragment::split(opcode, &payload, tx_size) {
                            if let Ok(n) = f.encode(&mut out) {
                                self.mailboxes.post(MailboxType::Coe, address, &out[..n]);
                            }
                        }
                    }
                    Err(code) => {
                        let payload = code.0.to_le_bytes();
                        let f = InfoFragment { header: InfoHeader::whole(InfoOpcode::Error), payload: &payload };
                        if let Ok(n) = f.encode(&mut out) {
                            self.mailboxes.post(MailboxType::Coe, address, &out[..n]);
                        }
                    }
                }
            }
            _ => self.mailboxes.post(MailboxType::Error, address, &MailboxError::SERVICE_NOT_SUPPORTED.body()),
        }
    }

    /// A raw register write; AL control requests a state.
    pub fn write_registers(&mut self, ado: u16, data: &[u8]) {
        for (i, b) in data.iter().enumerate() {
            let at = usize::from(ado) + i;
            if at < self.registers.len() && !(0x0130..0x0138).contains(&at) {
                self.registers[at] = *b;
            }
        }
        if ado <= reg::AL_CONTROL && usize::from(ado) + data.len() > usize::from(reg::AL_CONTROL) {
            let code = self.registers[usize::from(reg::AL_CONTROL)] & 0x0F;
            self.request_state(code);
        }
        if ado <= reg::STATION_ADDRESS && usize::from(ado) + data.len() >= usize::from(reg::STATION_ADDRESS) + 2 {
            self.station_address = u16::from_le_bytes([self.registers[0x10], self.registers[0x11]]);
        }
        // A write to one of the RX error counters (0x0300..=0x030B) clears
        // all the error counters 0x0300..=0x0313 (ET1100 datasheet, section
        // II, "RX Error Counter"), which is how a master resets them.
        if usize::from(ado) <= 0x030B && usize::from(ado) + data.len() > 0x0300 {
            if let Some(counters) = self.registers.get_mut(0x0300..=0x0313) {
                counters.fill(0);
            }
        }
    }

    /// One DC cycle. `outputs` is this cycle's output image for the slave, or
    /// `None` when the master sent none. Returns the working-counter
    /// contribution of this slave in an LRW: +1 for inputs read (SAFE-OP or
    /// OP), +2 for outputs written (OP).
    pub fn cycle(&mut self, outputs: Option<&[u8]>, dt_ns: u64) -> u16 {
        if !self.present {
            return 0;
        }
        let state = self.esm.state;
        let mut wkc = 0;
        match outputs {
            Some(o) if state == AlState::Op && !self.outputs.is_empty() => {
                let n = o.len().min(self.outputs.len());
                self.outputs[..n].copy_from_slice(&o[..n]);
                pdo_map::image_to_od(&mut self.od, &self.rx, &self.outputs);
                self.since_outputs_ns = 0;
                wkc += 2;
            }
            _ => self.since_outputs_ns = self.since_outputs_ns.saturating_add(dt_ns),
        }
        if state == AlState::Op && !self.outputs.is_empty() && self.since_outputs_ns > self.watchdog_ns {
            self.esm.fail(AlState::SafeOp, AL_SM_WATCHDOG);
            self.sync_registers();
            if let Device::Drive(axes) = &mut self.device {
                for a in axes.iter_mut() {
                    if let Some(code) = a.raise_fault(ERROR_PD_TIMEOUT, true) {
                        self.emergencies.push(Emergency { error_code: code, error_register: 0x11, data: [0; 5] });
                    }
                }
            }
        }
        let communicating = !matches!(self.esm.state, AlState::Init | AlState::Boot);
        match &mut self.device {
            Device::Drive(axes) => {
                for a in axes.iter_mut() {
                    a.step(&mut self.od, dt_ns, communicating);
                }
            }
            Device::DigitalIo { forced_inputs } => {
                let out = self.od.int(0x7000, 1);
                self.od.set_int(0x6000, 1, out | i64::from(*forced_inputs));
            }
            Device::Passive => {}
        }
        if matches!(self.esm.state, AlState::SafeOp | AlState::Op) && !self.inputs.is_empty() {
            pdo_map::od_to_image(&self.od, &self.tx, &mut self.inputs);
            wkc += 1;
        }
        wkc
    }

    /// Injects a drive fault on an axis (fault injection).
    pub fn inject_drive_fault(&mut self, axis: usize, code: u16) -> bool {
        let Device::Drive(axes) = &mut self.device else { return false };
        let Some(a) = axes.get_mut(axis) else { return false };
        if let Some(c) = a.raise_fault(code, false) {
            self.emergencies.push(Emergency { error_code: c, error_register: 0x81, data: [0; 5] });
        }
        true
    }

    /// Clears an injected fault's cause so a fault reset succeeds.
    pub fn clear_drive_fault(&mut self, axis: usize) -> bool {
        let Device::Drive(axes) = &mut self.device else { return false };
        axes.get_mut(axis).map(Axis::clear_fault_cause).is_some()
    }

    /// Forces an AL error (fault injection): the slave drops to SAFE-OP (or
    /// stays lower) with the given AL status code.
    pub fn inject_al_error(&mut self, code: u16) {
        let to = self.esm.state.min(AlState::SafeOp);
        self.esm.fail(to, code);
        self.sync_registers();
    }
}

/// Re-exported for device builders.
pub use cia402::AxisSpec;
