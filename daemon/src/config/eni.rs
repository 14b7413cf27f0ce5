//! `eni = "FILE"`: the network as a configuration tool exported it
//! (ETG.2100; TwinCAT, acontis, the EtherCAT Configurator, or written by
//! hand as SOEM's sample is). What ecmxfd takes from it:
//! - the slaves in ring order with their names and identities, checked
//!   against the scan as `[[slave]]` entries are;
//! - the CoE init commands, in the file's order per transition: `IP`
//!   right after PRE-OP is reached, `PS` before SAFE-OP, `SO` in SAFE-OP
//!   before OP (engine/bringup.rs); `Disabled` ones skipped, complete
//!   access honoured, each one's `Timeout`. `Ccs` 1 is a download
//!   (ETG.2100, TwinCAT); `Ccs` 2 with data is a download too, as SOEM's
//!   files write it; `Ccs` 2 without data (an upload) is not replayed.
//!   Init commands that write a PDO assignment or mapping object (0x1C12,
//!   0x1C13, 0x16xx, 0x1Axx) make the chip read the mapping again
//!   (ECAT_RECONFIG), so assignments of any size reach the frames.
//! - the PDO assignment of each CoE slave's ProcessData (its PDOs with an
//!   `Sm`) as `rx_pdos`/`tx_pdos` (see `take_assignments`): bring-up
//!   writes it only where the slave does not run it, the assignment alone
//!   where the PDOs map as the file says (engine/bringup/pdos.rs), so the
//!   layout is the file's even without assigning init commands (beyond
//!   PDO_CONFIG_SET's 3 PDOs of 8 entries it is written over CoE);
//! - the DC block: `CycleTime0` is the SYNC0 cycle unless `[cycle]
//!   sync0_us` is given, `ShiftTime` the slave's shift, a slave without
//!   one runs without DC (see [`Config::take_dc`]);
//! - the ProcessImage's variables (and each slave's ProcessData for its
//!   `Send`/`Recv` start): they name GetLayout's entries
//!   (`WheelRearLeft.Inputs.Status word`), matched by offset from the
//!   slave's start and size; a variable no entry matches is a layout note
//!   (the network's mapping is not the file's). The absolute offsets are
//!   the tool's: the chip packs the slaves' data one after the other.
//!
//! - the register init commands a host may replay: the watchdogs (0x0400,
//!   0x0410, 0x0420), by raw datagram at their transition before its SDOs
//!   ([`register_fate`]).
//!
//! What it does not take, each named by `ecmxfd --check-config`
//! ([`eni_notes`]): the other register init commands, with the reason for
//! each kind (the chip's ECAT_INIT does the slaves' register set-up:
//! addresses, SII hand-over, SyncManagers, FMMUs, DC; its state machine the
//! AL control and the checks; v049 "ECM-XF 初始化EtherCAT網路"), the mailbox
//! areas (the chip sets them from the SII), the cyclic frames (the chip
//! builds its own), the master's own init commands, EoE/FoE/SoE settings.
//!
//! Without an ENI, a `[[slave]] esi` device's own CoE init commands
//! (`Mailbox/CoE/InitCmd` in its ESI: a Delta or Elmo servo sets its mode
//! of operation there) are written the same way, before the entry's
//! `[[slave.sdo]]`, as a configuration tool would put them into an ENI
//! (`esi_init_cmds = false` or `esi_init_cmds_skip = [index, ...]` switch
//! them off; an ENI carries them already, so with one they are not added).
//!
//! With `[[slave]]` entries beside the ENI, they must be as many; an
//! identity they give must be the ENI's; their names, ESI files, PDOs and
//! DC settings are kept, and their own `[[slave.sdo]]` run after the ENI's
//! init commands of the same transition.

use ecmxf_devices::eni::{CcsConvention, CoeAccess, CoeInitCmd, Eni, RegisterInitCmd, Transition};
use ecmxf_devices::esi::{EsiDevice, EsiFile};

use super::{Config, EsiChoice, InitTransition, PdoConfig, SlaveConfig, SlaveVariable, StartupRegister, StartupSdo};

/// The transition ecmxfd replays a command at, if it is one it makes
/// (it brings slaves up: IP, PS, SO).
fn replayed_at(t: &Transition) -> Option<InitTransition> {
    match t {
        Transition::InitPreOp => Some(InitTransition::Ip),
        Transition::PreOpSafeOp => Some(InitTransition::Ps),
        Transition::SafeOpOp => Some(InitTransition::So),
        Transition::Other(_) => None,
    }
}

/// The start-up SDOs of init commands (an ENI slave's or an ESI device's),
/// in file order, one per transition a command lists.
fn startup_sdos(cmds: &[CoeInitCmd], source: &str) -> Vec<StartupSdo> {
    let mut out = Vec::new();
    for c in cmds.iter().filter(|c| !c.disabled) {
        let CoeAccess::Download(data) = &c.access else { continue };
        for transition in c.transitions.iter().filter_map(replayed_at) {
            out.push(StartupSdo {
                index: c.index,
                subindex: c.subindex,
                value: None,
                size: None,
                bytes: Some(data.clone()),
                complete_access: c.complete_access,
                transition,
                timeout_ms: (c.timeout_ms > 0).then_some(c.timeout_ms),
                origin: if c.comment.is_empty() {
                    format!("{source} {}", c.at)
                } else {
                    format!("{source} {}, {:?}", c.at, c.comment)
                },
            });
        }
    }
    out
}

/// What becomes of a register init command: replayed at a transition, or
/// why not. The chip's ECAT_INIT and state machine do a master's ESC set-up
/// (v049 "ECM-XF 初始化EtherCAT網路": station addresses, SII hand-over,
/// sync managers, FMMUs, DC; AL control and status checks); a host writing
/// those registers behind its back would undo its work. The watchdogs
/// (0x0400 divider, 0x0410 PDI, 0x0420 sync manager) it does not set: an
/// ENI's values for them are replayed, by raw datagram (RAW_ECAT_FUNC_REQ
/// 137) to the slave's position.
pub(super) fn register_fate(c: &RegisterInitCmd) -> Result<InitTransition, &'static str> {
    let reason = match c.ado {
        _ if !c.writes() => "checks the chip's state machine makes itself",
        0x0010..=0x0013 => "station addresses: the chip's ECAT_INIT",
        0x0103 => "second station address: the chip's ECAT_INIT",
        0x0120..=0x0121 | 0x0130..=0x0135 => "AL control and status: the chip's state machine",
        0x0200..=0x0205 => "ECAT event mask: the chip's",
        0x0300..=0x0313 => "error counters: the chip's (ecmxfctl crc --reset clears them)",
        0x0400..=0x0443 => {
            return c
                .transitions
                .iter()
                .find_map(replayed_at)
                .ok_or("only at transitions down or to BOOT (ecmxfd brings slaves up)");
        }
        0x0500..=0x050F => "SII access: the chip's",
        0x0600..=0x06FF => "FMMUs: the chip's ECAT_INIT",
        0x0800..=0x087F => "sync managers: the chip's ECAT_INIT",
        0x0900..=0x09FF => "DC: the chip's ECAT_INIT_DC",
        _ => "a register the chip does not hand to the host",
    };
    Err(reason)
}

/// The register init commands of an ENI slave ecmxfd replays.
fn startup_registers(cmds: &[RegisterInitCmd]) -> Vec<StartupRegister> {
    cmds.iter()
        .filter_map(|c| {
            let transition = register_fate(c).ok()?;
            Some(StartupRegister {
                transition,
                ado: c.ado,
                data: c.data.clone(),
                origin: format!("ENI {}, {:?}", c.at, c.comment),
            })
        })
        .collect()
}

impl Config {
    /// Takes the ENI's slaves and init commands (see the module doc); the
    /// key and message of what does not fit.
    pub(super) fn apply_eni(&mut self, eni: &Eni, sync0_given: bool) -> Result<(), (String, String)> {
        self.take_slaves(eni)?;
        self.take_assignments(eni);
        self.take_variables(eni);
        self.take_dc(eni, sync0_given);
        self.eni_frames = eni_frames(eni);
        Ok(())
    }

    /// The slaves: names, identities, CoE init commands.
    fn take_slaves(&mut self, eni: &Eni) -> Result<(), (String, String)> {
        if self.slaves.is_empty() {
            self.slaves = eni
                .slaves
                .iter()
                .map(|s| SlaveConfig {
                    name: Some(s.name.clone()).filter(|n| !n.is_empty()),
                    vendor_id: Some(s.vendor_id),
                    product_code: Some(s.product_code),
                    revision: s.revision,
                    rx_pdos: Vec::new(),
                    tx_pdos: Vec::new(),
                    sdos: startup_sdos(&s.coe_init_cmds, "ENI"),
                    dc_assign_activate: None,
                    dc_shift_ns: None,
                    esi: None,
                    esi_init_cmds: true,
                    esi_init_cmds_skip: Vec::new(),
                    esi_choices: Vec::new(),
                    variables: Vec::new(),
                    registers: startup_registers(&s.register_init_cmds),
                })
                .collect();
            return Ok(());
        }
        if self.slaves.len() != eni.slaves.len() {
            return Err((
                "slave".into(),
                format!(
                    "{} [[slave]] entries beside an ENI that lists {} slaves: give one per ENI slave, in ring order, \
                     or none",
                    self.slaves.len(),
                    eni.slaves.len()
                ),
            ));
        }
        for (i, (mine, theirs)) in self.slaves.iter_mut().zip(&eni.slaves).enumerate() {
            for (key, given, eni_value) in [
                ("vendor_id", &mut mine.vendor_id, Some(theirs.vendor_id)),
                ("product_code", &mut mine.product_code, Some(theirs.product_code)),
                ("revision", &mut mine.revision, theirs.revision),
            ] {
                match (*given, eni_value) {
                    (Some(g), Some(e)) if g != e => {
                        return Err((
                            format!("slave[{i}].{key}"),
                            format!(
                                "{g:#010x}, but the ENI's slave {i} ({:?}, {}) has {e:#010x}",
                                theirs.name, theirs.at
                            ),
                        ));
                    }
                    (None, Some(e)) => *given = Some(e),
                    _ => {}
                }
            }
            if mine.name.is_none() && !theirs.name.is_empty() {
                mine.name = Some(theirs.name.clone());
            }
            let mut sdos = startup_sdos(&theirs.coe_init_cmds, "ENI");
            sdos.append(&mut mine.sdos);
            mine.sdos = sdos;
            mine.registers = startup_registers(&theirs.register_init_cmds);
        }
        Ok(())
    }

    /// The DC block of each slave (ETG.2100 `Slave/DC`): the SYNC0 cycle
    /// (`CycleTime0` of the reference clock, else of the first slave with
    /// one) unless `[cycle] sync0_us` is given; each slave's `ShiftTime`
    /// unless its entry sets `dc_shift_ns`; a slave without a DC block,
    /// in a file where others have one, runs without DC
    /// (`dc_assign_activate = 0`, as the tool configured it) unless its
    /// entry says otherwise. The start time is the chip's to compute
    /// (ECAT_INIT_DC), never the file's; the reference clock is the chip's
    /// first DC slave.
    fn take_dc(&mut self, eni: &Eni, sync0_given: bool) {
        let dcs: Vec<_> = eni.slaves.iter().map(|s| s.dc).collect();
        if dcs.iter().all(Option::is_none) {
            return;
        }
        let cycle = dcs
            .iter()
            .flatten()
            .find(|d| d.reference_clock && d.cycle_time0_ns > 0)
            .or_else(|| dcs.iter().flatten().find(|d| d.cycle_time0_ns > 0))
            .map(|d| d.cycle_time0_ns / 1000);
        if let (Some(us), false) = (cycle, sync0_given) {
            self.cycle.sync0_us = us;
        }
        for (mine, dc) in self.slaves.iter_mut().zip(&dcs) {
            match dc {
                Some(dc) if dc.shift_time_ns != 0 && mine.dc_shift_ns.is_none() => {
                    mine.dc_shift_ns = i32::try_from(dc.shift_time_ns).ok();
                }
                None if mine.dc_assign_activate.is_none() => mine.dc_assign_activate = Some(0),
                _ => {}
            }
        }
    }

    /// The PDO assignment each CoE slave's ProcessData gives (its PDOs
    /// with an `Sm`), as `rx_pdos`/`tx_pdos` where the entry gives none:
    /// bring-up writes only what the slave does not already run (the
    /// assignment alone where its PDOs map as the file says), so the
    /// layout is the file's even without init commands that assign it (a
    /// file `ecmxfctl config --format eni` wrote, its init commands taken
    /// out). A slave without CoE runs its fixed one.
    fn take_assignments(&mut self, eni: &Eni) {
        for (mine, theirs) in self.slaves.iter_mut().zip(&eni.slaves) {
            for (rx, list) in [(true, &mut mine.rx_pdos), (false, &mut mine.tx_pdos)] {
                if list.is_empty() {
                    if let Some(pdos) = assignment_of(theirs, rx) {
                        *list = pdos;
                    }
                }
            }
        }
    }

    /// The ProcessImage's variables, each to its slave.
    fn take_variables(&mut self, eni: &Eni) {
        for v in eni.relative_variables() {
            if let Some(s) = self.slaves.get_mut(v.slave) {
                s.variables.push(SlaveVariable {
                    name: v.variable.name.clone(),
                    output: v.variable.output,
                    bit: v.relative_bit,
                    bits: v.variable.bit_size,
                    data_type: Some(ecmxf_devices::esi::data_type(&v.variable.data_type, v.variable.bit_size))
                        .filter(|t| !v.variable.data_type.is_empty() && t.bits() == v.variable.bit_size),
                    at: v.variable.at,
                });
            }
        }
    }
}

/// An ENI slave's assignment in one direction (its ProcessData PDOs with
/// an `Sm`): `None` when it gives none or the slave has no CoE to write one
/// with.
fn assignment_of(slave: &ecmxf_devices::eni::EniSlave, rx: bool) -> Option<Vec<PdoConfig>> {
    let coe = slave.mailbox.is_some_and(|m| m.protocols & ecmxf_devices::sii::protocol::COE != 0);
    let pd = slave.process_data.as_ref().filter(|_| coe)?;
    let assigned: Vec<_> = if rx { &pd.rx_pdos } else { &pd.tx_pdos }.iter().filter(|p| p.sm.is_some()).collect();
    if assigned.is_empty() {
        return None;
    }
    Some(
        assigned
            .iter()
            .map(|p| PdoConfig {
                index: p.index,
                entries: p
                    .entries
                    .iter()
                    .map(|(e, _, _)| [u32::from(e.index), u32::from(e.subindex), u32::from(e.bits)])
                    .collect(),
            })
            .collect(),
    )
}

/// The devices of an ESI file a `[[slave]]` entry may mean: those with its
/// product code and revision where it gives them. One is the device (as
/// before any scan); several are narrowed at bring-up by the identity the
/// slave reports (`EsiFile::for_identity`'s rule: same revision, else the
/// nearest lower, else the highest), as TwinCAT and the IgH master match a
/// scanned slave to its description. Devices the file could not read (no
/// ProductCode) are not among them.
pub(super) fn esi_candidates<'a>(file: &'a EsiFile, slave: &SlaveConfig) -> Vec<&'a EsiDevice> {
    file.devices
        .iter()
        .filter(|d| slave.product_code.is_none_or(|p| d.product_code == p))
        .filter(|d| slave.revision.is_none_or(|r| d.revision == r))
        .collect()
}

/// How `[[slave]]`'s device is named in messages: its display name, else
/// its order name.
fn device_name(d: &EsiDevice) -> String {
    let name = if d.name.trim().is_empty() { &d.type_name } else { &d.name };
    name.trim().to_string()
}

impl Config {
    /// Without an ENI, the CoE init commands of each `[[slave]] esi`
    /// device become its first start-up SDOs, as a configuration tool
    /// writes them into an ENI, so a network described by ESI files alone
    /// starts as it would from that tool's ENI. A file whose devices the
    /// entry does not narrow to one keeps each candidate's (`esi_choices`)
    /// for bring-up to choose by the scanned identity: a Beckhoff or Elmo
    /// file lists many devices and revisions, and a drive whose mode of
    /// operation is set there must not start without it. The key and
    /// message of a file that does not read.
    pub(super) fn apply_esi_init_cmds(&mut self) -> Result<(), (String, String)> {
        for (i, s) in self.slaves.iter_mut().enumerate() {
            let Some(path) = s.esi.as_ref().filter(|_| s.esi_init_cmds) else { continue };
            let key = format!("slave[{i}].esi");
            let text =
                ecmxf_devices::esi::read_xml(path).map_err(|e| (key.clone(), format!("{}: {e}", path.display())))?;
            let file = EsiFile::parse(&text).map_err(|e| (key.clone(), format!("{}: {e}", path.display())))?;
            let name = path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into());
            let source = format!("init command of ESI {name}");
            let sdos_of = |d: &EsiDevice| {
                let cmds: Vec<CoeInitCmd> =
                    d.init_cmds.iter().filter(|c| !s.esi_init_cmds_skip.contains(&c.index)).cloned().collect();
                startup_sdos(&cmds, &source)
            };
            match esi_candidates(&file, s).as_slice() {
                [] => {}
                [device] => {
                    let mut sdos = sdos_of(device);
                    sdos.append(&mut s.sdos);
                    s.sdos = sdos;
                }
                several => {
                    s.esi_choices = several
                        .iter()
                        .map(|d| EsiChoice {
                            name: device_name(d),
                            vendor_id: file.vendor_id,
                            product_code: d.product_code,
                            revision: d.revision,
                            sdos: sdos_of(d),
                        })
                        .collect();
                }
            }
        }
        Ok(())
    }
}

/// What `--check-config` says about the ESI init commands of `[[slave]]`
/// `i` (written, skipped, or chosen at bring-up among several devices).
pub(super) fn esi_init_notes(i: usize, slave: &SlaveConfig, file: &EsiFile) -> Vec<String> {
    let device = match esi_candidates(file, slave).as_slice() {
        [] => return Vec::new(),
        [device] => *device,
        several => {
            let with = several.iter().filter(|d| !d.init_cmds.is_empty()).count();
            let what = if !slave.esi_init_cmds {
                "not written (esi_init_cmds = false)".to_string()
            } else if with == 0 {
                "none of them has init commands".to_string()
            } else {
                format!(
                    "the init commands ({with} of them have some) are those of the device the slave's scanned \
                     identity (vendor, product, revision) names, chosen at bring-up; bring-up fails if none matches"
                )
            };
            return vec![format!("slave[{i}].esi: {} devices of the file may be this slave: {what}", several.len())];
        }
    };
    device
        .init_cmds
        .iter()
        .map(|c| {
            let what = format!(
                "slave[{i}].esi: init command {:#06x}:{:02x} at {} ({:?})",
                c.index,
                c.subindex,
                c.transitions.iter().map(Transition::letters).collect::<Vec<_>>().join("/"),
                c.comment
            );
            if !slave.esi_init_cmds {
                format!("{what}: not written (esi_init_cmds = false)")
            } else if slave.esi_init_cmds_skip.contains(&c.index) {
                format!("{what}: not written (esi_init_cmds_skip)")
            } else if c.disabled {
                format!("{what}: not written (its data is for the configuration tool to adapt)")
            } else {
                format!("{what}: written before the [[slave.sdo]] entries")
            }
        })
        .collect()
}

/// One line on a slave's register init commands: how many are replayed
/// (which registers, when) and how many not, by reason.
fn register_notes(who: &str, cmds: &[RegisterInitCmd]) -> String {
    let mut replayed: Vec<String> = Vec::new();
    let mut skipped: Vec<(&'static str, usize)> = Vec::new();
    for c in cmds {
        match register_fate(c) {
            Ok(t) => replayed.push(format!("{:#06x} at {}", c.ado, t.letters())),
            Err(why) => match skipped.iter_mut().find(|(w, _)| *w == why) {
                Some((_, n)) => *n += 1,
                None => skipped.push((why, 1)),
            },
        }
    }
    let not: Vec<String> = skipped.iter().map(|(why, n)| format!("{n} {why}")).collect();
    format!(
        "{who}: InitCmds (register) ({}): {} replayed by raw datagram{}{}; not replayed: {}",
        cmds.len(),
        replayed.len(),
        if replayed.is_empty() { "" } else { " (watchdogs: " },
        if replayed.is_empty() { String::new() } else { format!("{})", replayed.join(", ")) },
        if not.is_empty() { "none".to_string() } else { not.join("; ") }
    )
}

/// What `--check-config` says about an ENI: what is applied, and every
/// element that is not, by slave.
pub(super) fn eni_notes(eni: &Eni) -> Vec<String> {
    let mut notes = Vec::new();
    for (i, s) in eni.slaves.iter().enumerate() {
        let who = format!("eni: slave {i} {:?} ({})", s.name, s.at);
        let applied =
            s.coe_init_cmds.iter().filter(|c| !c.disabled && matches!(c.access, CoeAccess::Download(_))).count();
        if applied > 0 {
            notes.push(format!("{who}: {applied} CoE init commands written at their transitions"));
        }
        for c in &s.coe_init_cmds {
            let at = format!("{who}: CoE init command {:#06x}:{:02x} ({})", c.index, c.subindex, c.at);
            if c.disabled {
                notes.push(format!("{at} is disabled: skipped"));
            } else if c.access == CoeAccess::Upload {
                notes.push(format!("{at} is an upload (Ccs 2 without data): not replayed"));
            } else if c.ccs == CcsConvention::Soem {
                notes.push(format!("{at} has Ccs 2 with data: written, as SOEM's files mean it (ETG.2100: Ccs 1)"));
            }
            for t in c.transitions.iter().filter(|t| replayed_at(t).is_none()) {
                notes.push(format!(
                    "{at} at transition {}: not replayed (ecmxfd brings slaves up, not down)",
                    t.letters()
                ));
            }
        }
        if s.dc.is_none() && eni.slaves.iter().any(|o| o.dc.is_some()) {
            notes.push(format!("{who}: no DC block: runs without DC (dc_assign_activate = 0) unless its entry says"));
        }
        if !s.register_init_cmds.is_empty() {
            notes.push(register_notes(&who, &s.register_init_cmds));
        }
        for (element, n) in s.elements.iter().filter(|(e, _)| *e != "InitCmds (register)") {
            let why = match *element {
                "ProcessData" => {
                    "applied: its PDOs with an Sm are the assignment, written where the slave does not run it \
                     (the assignment alone where the PDOs map as the file says; over CoE beyond PDO_CONFIG_SET's 3 PDOs of 8 \
                     entries); names and types name the entries"
                }
                "DC" => {
                    "applied: CycleTime0 is the SYNC0 cycle unless [cycle] sync0_us is given, ShiftTime the slave's \
                     shift; the start time is the chip's, the reference clock its first DC slave"
                }
                e if e.starts_with("Mailbox (") => "not applied: the chip sets the mailboxes up from the SII",
                _ => "not applied",
            };
            notes.push(format!("{who}: {element} ({n}) {why}"));
        }
    }
    for (element, n) in &eni.elements {
        let why = match *element {
            "ProcessImage" => {
                "applied as names: each slave's variables name GetLayout's entries, checked by offset from the \
                 slave's start and size (the chip packs the slaves; the tool's absolute offsets are its own)"
            }
            "Cyclic" => "not applied: the chip builds the cyclic frames",
            _ => "not applied",
        };
        notes.push(format!("eni: {element} ({n}) {why}"));
    }
    notes
}

/// The output and input frame sizes an ENI describes: each slave's
/// `ProcessData` `Send` and `Recv` lengths, in whole bytes per slave as the
/// chip places them. `None` when a slave with a mailbox has no
/// `ProcessData` (SOEM's samples, the demo's drive): its frames are the
/// mapping the slave itself reports at bring-up. A slave with neither (a
/// coupler) has no process data.
fn eni_frames(eni: &Eni) -> Option<(usize, usize)> {
    let bytes = |r: Option<ecmxf_devices::eni::BitRange>| r.map_or(0, |r| r.len.div_ceil(8) as usize);
    eni.slaves.iter().try_fold((0, 0), |(rx, tx), s| match (&s.process_data, &s.mailbox) {
        (Some(p), _) => Some((rx + bytes(p.outputs), tx + bytes(p.inputs))),
        (None, Some(_)) => None,
        (None, None) => Some((rx, tx)),
    })
}
