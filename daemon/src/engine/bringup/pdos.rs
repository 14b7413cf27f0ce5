//! Step 3 of bring-up: the `[[slave]]` PDO assignments and mappings
//! (`rx_pdos`/`tx_pdos`), written where the slave does not already run
//! them, and only what differs.
//!
//! A configuration may state the mapping a slave has (one written from the
//! live network by `ecmxfctl config`, or by hand from a drive's manual).
//! Writing it again is not free and not always possible: a PDO whose
//! mapping is fixed refuses any write to it (0x06010002), which the chip's
//! PDO_CONFIG_SET (7) does for every PDO it assigns. So, per slave and
//! direction:
//! 1. the assignment in force (PDO_CONFIG_REQ 8 / GET 9) is the configured
//!    one: nothing is written;
//! 2. every configured PDO already maps what is configured (SDO uploads of
//!    its subindexes), only the assignment differs: 0x1C12/0x1C13 is
//!    written by SDO (count 0, the PDOs, the count; ETG.1000.6 5.6.7.4), as
//!    configuration tools do for fixed PDOs;
//! 3. otherwise PDO_CONFIG_SET writes assignment and mappings.
//!
//! Then ECAT_RECONFIG, when anything was written, so the chip's frames
//! follow.

use std::time::Duration;

use ecmxf_wire::payload::ecat_init::EcatReconfig;
use ecmxf_wire::payload::pdo::{
    PdoConfig, PdoConfigForm, PdoConfigGet, PdoConfigReply, PdoConfigReq, PdoEntry, RX_PDO_ASSIGN, TX_PDO_ASSIGN,
};

use super::calls::{SLOW, abort_code, blocking, sdo_download, sdo_upload};
use super::error::{BringUpError, step};
use crate::config::Config;
use crate::link::Link;
use crate::port::Port;

fn pdo_config(slave: u8, assign: u16, pdos: &[crate::config::PdoConfig]) -> Result<PdoConfig, BringUpError> {
    let entries: Vec<(u16, Vec<PdoEntry>)> = pdos
        .iter()
        .map(|p| {
            (
                p.index,
                p.entries
                    .iter()
                    .map(|e| PdoEntry { index: e[0] as u16, subindex: e[1] as u8, bits: e[2] as u8 })
                    .collect(),
            )
        })
        .collect();
    let refs: Vec<(u16, &[PdoEntry])> = entries.iter().map(|(i, e)| (*i, e.as_slice())).collect();
    PdoConfig::new(slave, assign, &refs).map_err(|e| step("PDO mapping", format!("slave {slave}: {e}")))
}

/// Step 3 (module doc).
pub(super) fn map_pdos<L: Link>(port: &mut Port<L>, config: &Config) -> Result<(), BringUpError> {
    let mut remapped = false;
    for (i, s) in config.slaves.iter().enumerate() {
        for (assign, pdos) in [(RX_PDO_ASSIGN, &s.rx_pdos), (TX_PDO_ASSIGN, &s.tx_pdos)] {
            if pdos.is_empty() {
                continue;
            }
            let cfg = pdo_config(i as u8, assign, pdos)?;
            if in_force(port, &cfg)? {
                continue;
            }
            remapped = true;
            if mappings_in_place(port, &cfg)? {
                assign_only(port, &cfg)?;
                continue;
            }
            if let Err(e) = blocking(port, &cfg, SLOW) {
                let code = abort_code(port)?;
                return Err(step("PDO mapping", format!("slave {i} {assign:#06x}: {e}: {code}")));
            }
        }
    }
    if remapped {
        blocking(port, &EcatReconfig, SLOW)?;
    }
    Ok(())
}

/// Whether the slave already runs `cfg` (PDO_CONFIG_REQ 8, then GET 9). A
/// slave that cannot be read is written.
fn in_force<L: Link>(port: &mut Port<L>, cfg: &PdoConfig) -> Result<bool, BringUpError> {
    let req = PdoConfigReq { slave: cfg.slave, assign_index: cfg.assign_index, form: PdoConfigForm::Manual };
    if blocking(port, &req, SLOW).is_err() {
        return Ok(false);
    }
    let Ok(PdoConfigReply(now)) = port.call(&PdoConfigGet)?.answer_to(&PdoConfigGet) else { return Ok(false) };
    let same = now.pdo_count == cfg.pdo_count
        && now.used().len() == cfg.used().len()
        && now.used().iter().zip(cfg.used()).all(|(a, b)| a.index == b.index && a.used() == b.used());
    Ok(same)
}

/// Whether each configured PDO already maps its configured entries, read
/// subindex by subindex (a refused read: no).
fn mappings_in_place<L: Link>(port: &mut Port<L>, cfg: &PdoConfig) -> Result<bool, BringUpError> {
    for p in cfg.used() {
        if sdo_upload(port, cfg.slave, p.index, 0)? != Some(u32::from(p.entry_count)) {
            return Ok(false);
        }
        for (k, e) in p.used().iter().enumerate() {
            if sdo_upload(port, cfg.slave, p.index, k as u8 + 1)? != Some(e.to_u32()) {
                return Ok(false);
            }
        }
    }
    Ok(true)
}

/// Writes the assignment alone: count 0, each PDO, the count.
fn assign_only<L: Link>(port: &mut Port<L>, cfg: &PdoConfig) -> Result<(), BringUpError> {
    let pdos: Vec<u16> = cfg.used().iter().map(|p| p.index).collect();
    let mut writes: Vec<(u8, Vec<u8>)> = vec![(0, vec![0])];
    writes.extend(pdos.iter().enumerate().map(|(k, p)| (k as u8 + 1, p.to_le_bytes().to_vec())));
    writes.push((0, vec![pdos.len() as u8]));
    for (sub, data) in writes {
        let object = (cfg.assign_index, sub, false);
        if let Err(code) = sdo_download(port, cfg.slave, object, &data, Duration::from_secs(1))? {
            return Err(step(
                "PDO assignment",
                format!(
                    "slave {} {:#06x}:{sub:02x} (its PDOs already map as configured): {code}",
                    cfg.slave, cfg.assign_index
                ),
            ));
        }
    }
    Ok(())
}
