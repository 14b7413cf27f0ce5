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
//!
//! What it does not take, each named by `ecmxfd --check-config`
//! ([`eni_notes`]): register init commands (the chip's ECAT_INIT does the
//! slaves' register set-up: addresses, SyncManagers, FMMUs, DC; v049
//! "ECM-XF 初始化EtherCAT網路"), the mailbox areas (the chip sets them from
//! the SII), ProcessData and the DC block (the mapping comes from the
//! slaves after the init commands; the cycle from `[cycle]`), the cyclic
//! frames and the ProcessImage (the chip builds its own frames: offsets are
//! GetLayout's), the master's own init commands, EoE/FoE/SoE settings.
//!
//! With `[[slave]]` entries beside the ENI, they must be as many; an
//! identity they give must be the ENI's; their names, ESI files, PDOs and
//! DC settings are kept, and their own `[[slave.sdo]]` run after the ENI's
//! init commands of the same transition.

use ecmxf_devices::eni::{CcsConvention, CoeAccess, Eni, EniSlave, Transition};

use super::{Config, InitTransition, SlaveConfig, StartupSdo};

/// The start-up SDOs of one ENI slave, in file order, one per transition
/// an init command lists.
fn startup_sdos(slave: &EniSlave) -> Vec<StartupSdo> {
    let mut out = Vec::new();
    for c in slave.coe_init_cmds.iter().filter(|c| !c.disabled) {
        let CoeAccess::Download(data) = &c.access else { continue };
        for t in &c.transitions {
            let transition = match t {
                Transition::InitPreOp => InitTransition::Ip,
                Transition::PreOpSafeOp => InitTransition::Ps,
                Transition::SafeOpOp => InitTransition::So,
                Transition::Other(_) => continue,
            };
            out.push(StartupSdo {
                index: c.index,
                subindex: c.subindex,
                value: None,
                size: None,
                bytes: Some(data.clone()),
                complete_access: c.complete_access,
                transition,
                timeout_ms: (c.timeout_ms > 0).then_some(c.timeout_ms),
            });
        }
    }
    out
}

impl Config {
    /// Takes the ENI's slaves and init commands (see the module doc); the
    /// key and message of what does not fit.
    pub(super) fn apply_eni(&mut self, eni: &Eni) -> Result<(), (String, String)> {
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
                    sdos: startup_sdos(s),
                    dc_assign_activate: None,
                    dc_shift_ns: None,
                    esi: None,
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
                                "{g:#010x}, but the ENI's slave {i} ({:?}, line {}) has {e:#010x}",
                                theirs.name, theirs.line
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
            let mut sdos = startup_sdos(theirs);
            sdos.append(&mut mine.sdos);
            mine.sdos = sdos;
        }
        Ok(())
    }
}

/// What `--check-config` says about an ENI: what is applied, and every
/// element that is not, by slave.
pub fn eni_notes(eni: &Eni) -> Vec<String> {
    let mut notes = Vec::new();
    for (i, s) in eni.slaves.iter().enumerate() {
        let who = format!("eni: slave {i} {:?} (line {})", s.name, s.line);
        let applied =
            s.coe_init_cmds.iter().filter(|c| !c.disabled && matches!(c.access, CoeAccess::Download(_))).count();
        if applied > 0 {
            notes.push(format!("{who}: {applied} CoE init commands written at their transitions"));
        }
        for c in &s.coe_init_cmds {
            let at = format!("{who}: CoE init command {:#06x}:{:02x} (line {})", c.index, c.subindex, c.line);
            if c.disabled {
                notes.push(format!("{at} is disabled: skipped"));
            } else if c.access == CoeAccess::Upload {
                notes.push(format!("{at} is an upload (Ccs 2 without data): not replayed"));
            } else if c.ccs == CcsConvention::Soem {
                notes.push(format!("{at} has Ccs 2 with data: written, as SOEM's files mean it (ETG.2100: Ccs 1)"));
            }
            for t in c.transitions.iter().filter(|t| matches!(t, Transition::Other(_))) {
                notes.push(format!(
                    "{at} at transition {}: not replayed (ecmxfd brings slaves up, not down)",
                    t.letters()
                ));
            }
        }
        for (element, n) in &s.elements {
            let why = match *element {
                "InitCmds (register)" => {
                    "not replayed: the chip's ECAT_INIT sets up addresses, SyncManagers, FMMUs and DC"
                }
                "ProcessData" => "not applied: the mapping comes from the slave (after the CoE init commands)",
                "DC" => {
                    "not applied: the cycle is [cycle] sync0_us; per slave: [[slave]] dc_assign_activate / dc_shift_ns"
                }
                e if e.starts_with("Mailbox (") => "not applied: the chip sets the mailboxes up from the SII",
                _ => "not applied",
            };
            notes.push(format!("{who}: {element} ({n}) {why}"));
        }
    }
    for (element, n) in &eni.elements {
        let why = match *element {
            "ProcessImage" => "not applied: the chip builds the frames; offsets are GetLayout's (`ecmxfctl pdos`)",
            "Cyclic" => "not applied: the chip builds the cyclic frames",
            _ => "not applied",
        };
        notes.push(format!("eni: {element} ({n}) {why}"));
    }
    notes
}
