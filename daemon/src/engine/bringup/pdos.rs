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
//! An assignment beyond PDO_CONFIG_SET's 3 PDOs of 8 entries (v049, note
//! under command 7: more is for CoE) is written over CoE instead, in the
//! order ETG.1000.6 5.6.7.4 sets: the assignment's count 0, each PDO's
//! mapping (count 0, entries, count), the assigned PDOs, the count
//! ([`etg_sequence`]).
//!
//! Writes to PDO objects, from that sequence or from start-up SDOs (an
//! ENI's init commands), go through [`write_pdo_objects`]: a mapping the
//! PDO already has is not written again (a fixed PDO refuses it, as IgH's
//! PDO state machine also knows), and nothing is written when every object
//! already holds what the writes leave in it. The price is one SDO upload
//! per subindex compared, at bring-up only.
//!
//! Then ECAT_RECONFIG, when anything was written, so the chip's frames
//! follow.

use std::collections::BTreeMap;
use std::time::Duration;

use ecmxf_wire::payload::ecat_init::EcatReconfig;
use ecmxf_wire::payload::pdo::{
    MAPPING_ENTRIES, PdoConfig, PdoConfigForm, PdoConfigGet, PdoConfigReply, PdoConfigReq, PdoEntry, RX_PDO_ASSIGN,
    TX_PDO_ASSIGN,
};

use ecmxf_wire::payload::sdo::SdoAbortCode;

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
            if !fits_the_chip(pdos) {
                let writes = etg_sequence(assign, pdos);
                match write_pdo_objects(port, i as u8, &writes)? {
                    Ok(wrote) => remapped |= wrote,
                    Err((k, code)) => {
                        let w = &writes[k];
                        return Err(step(
                            "PDO mapping",
                            format!("slave {i} {:#06x}:{:02x} (over CoE): {code}", w.index, w.subindex),
                        ));
                    }
                }
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

/// Whether PDO_CONFIG_SET carries an assignment: 3 PDOs of 8 entries at most.
fn fits_the_chip(pdos: &[crate::config::PdoConfig]) -> bool {
    pdos.len() <= PdoConfigForm::Manual.slots() && pdos.iter().all(|p| p.entries.len() <= MAPPING_ENTRIES)
}

/// One SDO download to a PDO assignment (0x1C12/0x1C13) or mapping
/// (0x1600-0x17FF, 0x1A00-0x1BFF) object.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct PdoWrite {
    pub index: u16,
    pub subindex: u8,
    pub complete_access: bool,
    pub data: Vec<u8>,
    /// How long the slave gets to answer.
    pub timeout: Duration,
}

/// Whether an object is a PDO assignment or mapping: writing one changes
/// the frames.
pub(super) fn is_pdo_object(index: u16) -> bool {
    is_assignment(index) || is_mapping(index)
}

fn is_assignment(index: u16) -> bool {
    matches!(index, 0x1C12 | 0x1C13)
}

fn is_mapping(index: u16) -> bool {
    matches!(index, 0x1600..=0x17FF | 0x1A00..=0x1BFF)
}

/// The writes that give one direction `pdos` over CoE, in ETG.1000.6
/// 5.6.7.4's order: the assignment emptied, each mapping written (count 0,
/// entries, count), then the assignment filled and counted.
pub(super) fn etg_sequence(assign: u16, pdos: &[crate::config::PdoConfig]) -> Vec<PdoWrite> {
    let write = |index, subindex, data: Vec<u8>| PdoWrite {
        index,
        subindex,
        complete_access: false,
        data,
        timeout: Duration::from_secs(1),
    };
    let mut out = vec![write(assign, 0, vec![0])];
    for p in pdos {
        out.push(write(p.index, 0, vec![0]));
        for (k, e) in p.entries.iter().enumerate() {
            let entry = PdoEntry { index: e[0] as u16, subindex: e[1] as u8, bits: e[2] as u8 };
            out.push(write(p.index, k as u8 + 1, entry.to_u32().to_le_bytes().to_vec()));
        }
        out.push(write(p.index, 0, vec![p.entries.len() as u8]));
    }
    for (k, p) in pdos.iter().enumerate() {
        out.push(write(assign, k as u8 + 1, p.index.to_le_bytes().to_vec()));
    }
    out.push(write(assign, 0, vec![pdos.len() as u8]));
    out
}

fn le(bytes: &[u8]) -> u32 {
    bytes.iter().take(4).enumerate().fold(0, |v, (i, b)| v | u32::from(*b) << (8 * i))
}

/// What `writes` leave in each object they touch: its entries 1..=count,
/// or `None` where they do not say it all (a count without every entry
/// written, a complete access of an odd length).
fn left_by(writes: &[PdoWrite]) -> BTreeMap<u16, Option<Vec<u32>>> {
    let mut subs: BTreeMap<u16, Option<BTreeMap<u8, u32>>> = BTreeMap::new();
    for w in writes {
        let object = subs.entry(w.index).or_insert_with(|| Some(BTreeMap::new()));
        let Some(object) = object.as_mut() else { continue };
        if w.complete_access {
            // ETG.1000.6 5.6.2.1: subindex 0 then the entries, subindex 0
            // taking 16 bits; an assignment's entries 16 bits, a mapping's 32.
            let width = if is_assignment(w.index) { 2 } else { 4 };
            let Some(&count) = w.data.first() else {
                subs.insert(w.index, None);
                continue;
            };
            let entries = w.data.get(2..).unwrap_or_default();
            if entries.len() < usize::from(count) * width {
                subs.insert(w.index, None);
                continue;
            }
            object.clear();
            object.insert(0, u32::from(count));
            for (k, e) in entries.chunks(width).take(usize::from(count)).enumerate() {
                object.insert(k as u8 + 1, le(e));
            }
        } else {
            object.insert(w.subindex, le(&w.data));
        }
    }
    subs.into_iter()
        .map(|(index, object)| {
            let entries = object.and_then(|o| {
                let count = *o.get(&0)?;
                (1..=count).map(|k| u8::try_from(k).ok().and_then(|k| o.get(&k).copied())).collect()
            });
            (index, entries)
        })
        .collect()
}

/// Whether `index` holds `entries` now (a refused read: no).
fn holds<L: Link>(port: &mut Port<L>, slave: u8, index: u16, entries: &[u32]) -> Result<bool, BringUpError> {
    if sdo_upload(port, slave, index, 0)?.map(|c| c & 0xFF) != Some(entries.len() as u32) {
        return Ok(false);
    }
    for (k, e) in entries.iter().enumerate() {
        let now = sdo_upload(port, slave, index, k as u8 + 1)?;
        let mask = if is_assignment(index) { 0xFFFF } else { u32::MAX };
        if now.map(|v| v & mask) != Some(*e) {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Writes to PDO objects (module doc): nothing when every object already
/// holds what the writes leave in it; else every write but those to a
/// mapping that holds its entries already. `Ok(Ok(wrote))`, or the write
/// the slave refused (its place in `writes`) with its abort code.
pub(super) fn write_pdo_objects<L: Link>(
    port: &mut Port<L>,
    slave: u8,
    writes: &[PdoWrite],
) -> Result<Result<bool, (usize, SdoAbortCode)>, BringUpError> {
    let mut in_place = BTreeMap::new();
    for (index, entries) in left_by(writes) {
        let holds = match &entries {
            Some(e) => holds(port, slave, index, e)?,
            None => false,
        };
        in_place.insert(index, holds);
    }
    if in_place.values().all(|&h| h) {
        return Ok(Ok(false));
    }
    for (k, w) in writes.iter().enumerate() {
        if is_mapping(w.index) && in_place.get(&w.index) == Some(&true) {
            continue;
        }
        let object = (w.index, w.subindex, w.complete_access);
        if let Err(code) = sdo_download(port, slave, object, &w.data, w.timeout)? {
            return Ok(Err((k, code)));
        }
    }
    Ok(Ok(true))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::PdoConfig as Configured;

    #[test]
    fn the_etg_sequence_empties_maps_then_assigns() {
        let pdos = [Configured { index: 0x1607, entries: vec![[0x607A, 0, 32], [0x6040, 0, 16]] }];
        let w = etg_sequence(0x1C12, &pdos);
        let short: Vec<(u16, u8, Vec<u8>)> = w.iter().map(|w| (w.index, w.subindex, w.data.clone())).collect();
        assert_eq!(
            short,
            vec![
                (0x1C12, 0, vec![0]),
                (0x1607, 0, vec![0]),
                (0x1607, 1, vec![0x20, 0x00, 0x7A, 0x60]),
                (0x1607, 2, vec![0x10, 0x00, 0x40, 0x60]),
                (0x1607, 0, vec![2]),
                (0x1C12, 1, vec![0x07, 0x16]),
                (0x1C12, 0, vec![1]),
            ]
        );
        let left = left_by(&w);
        assert_eq!(left[&0x1C12], Some(vec![0x1607]));
        assert_eq!(left[&0x1607], Some(vec![0x607A_0020, 0x6040_0010]));
    }

    #[test]
    fn what_writes_leave_is_unknown_where_they_do_not_say_it_all() {
        let w = |index, subindex, data: &[u8]| PdoWrite {
            index,
            subindex,
            complete_access: false,
            data: data.to_vec(),
            timeout: Duration::from_secs(1),
        };
        // A count of 2 with only entry 1 written.
        let left = left_by(&[w(0x1A00, 0, &[0]), w(0x1A00, 1, &[0x10, 0, 0x41, 0x60]), w(0x1A00, 0, &[2])]);
        assert_eq!(left[&0x1A00], None);
        // An entry written without a count.
        assert_eq!(left_by(&[w(0x1C13, 1, &[0, 0x1A])])[&0x1C13], None);
        // Complete access: subindex 0 in 16 bits, then the entries.
        let ca = PdoWrite {
            index: 0x1C12,
            subindex: 0,
            complete_access: true,
            data: vec![2, 0, 0, 0x16, 1, 0x16],
            timeout: Duration::from_secs(1),
        };
        assert_eq!(left_by(std::slice::from_ref(&ca))[&0x1C12], Some(vec![0x1600, 0x1601]));
        let short = PdoWrite { data: vec![2, 0, 0, 0x16], ..ca };
        assert_eq!(left_by(&[short])[&0x1C12], None);
    }
}
