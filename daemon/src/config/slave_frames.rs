//! The frame sizes a `[[slave]]` list describes without an ENI: what
//! `--check-config` budgets the link with on a chip it cannot see. The list
//! is the whole network (bring-up refuses another slave count), so the
//! frames are the sum of each slave's process data, in whole bytes per
//! slave as the chip places it (docs/troubleshooting.md, the link budget). A slave's bits are
//! its configured mapping (`rx_pdos`/`tx_pdos`, what bring-up writes),
//! else its ESI device's default assignment (PDOs with a sync manager, the
//! excluded ones left out), which is what the device runs when nobody
//! remaps it. What only the slave can tell is said, naming the slave: no
//! ESI and no mapping, init commands that remap it, or candidate devices
//! of different sizes that only the scanned identity tells apart.

use ecmxf_devices::esi::{EsiDevice, EsiFile, EsiPdo};

use super::{Config, PdoConfig, SlaveConfig};

/// Whether `index` is a PDO assignment (0x1C12/0x1C13) or mapping object
/// (0x1600-0x17FF, 0x1A00-0x1BFF): a start-up SDO writing one remaps.
fn remaps(index: u16) -> bool {
    matches!(index, 0x1C12 | 0x1C13 | 0x1600..=0x17FF | 0x1A00..=0x1BFF)
}

fn configured_bits(pdos: &[PdoConfig]) -> usize {
    pdos.iter().flat_map(|p| &p.entries).map(|e| e[2] as usize).sum()
}

fn esi_bits(pdos: &[EsiPdo]) -> usize {
    EsiDevice::assigned_pdos(pdos).iter().flat_map(|p| &p.entries).map(|(e, _, _)| usize::from(e.bits)).sum()
}

/// One direction's bits: the configured mapping, else the device's.
fn bits(configured: &[PdoConfig], device: &[EsiPdo]) -> usize {
    if configured.is_empty() { esi_bits(device) } else { configured_bits(configured) }
}

impl Config {
    /// The output and input frame sizes the `[[slave]]` list describes, or
    /// why only the slaves can tell (the slave named as `slave[i]`). An
    /// empty list describes nothing: the network is whatever answers.
    pub(crate) fn slave_frames(&self) -> Result<(usize, usize), String> {
        if self.slaves.is_empty() {
            return Err("no [[slave]] entries describe the network".into());
        }
        self.slaves.iter().enumerate().try_fold((0, 0), |(rx, tx), (i, s)| {
            let (r, t) = slave_bits(i, s)?;
            Ok((rx + r.div_ceil(8), tx + t.div_ceil(8)))
        })
    }
}

/// `[[slave]]` `i`'s output and input bits.
fn slave_bits(i: usize, s: &SlaveConfig) -> Result<(usize, usize), String> {
    let who = match &s.name {
        Some(n) => format!("slave[{i}] ({n})"),
        None => format!("slave[{i}]"),
    };
    if let Some(sdo) = s.sdos.iter().find(|o| remaps(o.index)) {
        return Err(format!(
            "{who}'s start-up SDOs write {:#06x}: the slave's mapping is known once written",
            sdo.index
        ));
    }
    let both_configured = !s.rx_pdos.is_empty() && !s.tx_pdos.is_empty();
    if both_configured {
        return Ok((configured_bits(&s.rx_pdos), configured_bits(&s.tx_pdos)));
    }
    let Some(path) = &s.esi else {
        return Err(format!("{who} has neither an ESI nor a PDO mapping for both directions"));
    };
    let file = ecmxf_devices::esi::read_xml(path)
        .ok()
        .and_then(|text| EsiFile::parse(&text).ok())
        .ok_or_else(|| format!("{who}'s ESI {} does not read", path.display()))?;
    // A single device's init commands are among the start-up SDOs already
    // (config/eni.rs); each candidate's are its choice's.
    if let Some(c) = s.esi_choices.iter().find(|c| c.sdos.iter().any(|o| remaps(o.index))) {
        return Err(format!("{who}'s ESI init commands remap {}: the slave's mapping is known once written", c.name));
    }
    let candidates = super::eni::esi_candidates(&file, s);
    let sizes: Vec<(usize, usize)> =
        candidates.iter().map(|d| (bits(&s.rx_pdos, &d.rx_pdos), bits(&s.tx_pdos, &d.tx_pdos))).collect();
    match sizes.as_slice() {
        [] => Err(format!("{who}: no device of its ESI {} has its identity", path.display())),
        [first, rest @ ..] if rest.iter().all(|s| s == first) => Ok(*first),
        several => Err(format!(
            "{who}: its ESI's {} candidate devices map different sizes; the scanned identity chooses at bring-up",
            several.len()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slave(rx: &[[u32; 3]], tx: &[[u32; 3]]) -> SlaveConfig {
        let pdo = |e: &[[u32; 3]]| {
            if e.is_empty() { Vec::new() } else { vec![PdoConfig { index: 0x1600, entries: e.to_vec() }] }
        };
        SlaveConfig { rx_pdos: pdo(rx), tx_pdos: pdo(tx), ..SlaveConfig::default() }
    }

    #[test]
    fn configured_mappings_add_up_in_whole_bytes_per_slave() {
        let mut c = Config::simulator();
        c.slaves = vec![slave(&[[0x7000, 1, 1]], &[[0x6000, 1, 12]]), slave(&[[0x6040, 0, 16]], &[[0x6041, 0, 16]])];
        assert_eq!(c.slave_frames(), Ok((1 + 2, 2 + 2)));
    }

    #[test]
    fn what_only_the_slave_can_tell_is_said_naming_it() {
        let mut c = Config::simulator();
        assert!(c.slave_frames().unwrap_err().contains("no [[slave]] entries"));
        c.slaves = vec![slave(&[[0x7000, 1, 8]], &[[0x6000, 1, 8]]), slave(&[], &[])];
        c.slaves[1].name = Some("drive".into());
        let why = c.slave_frames().unwrap_err();
        assert!(why.contains("slave[1] (drive) has neither an ESI nor a PDO mapping"), "{why}");
        c.slaves[1] = slave(&[[0x7000, 1, 8]], &[[0x6000, 1, 8]]);
        c.slaves[1]
            .sdos
            .push(serde_json::from_value(serde_json::json!({"index": 0x1C12, "value": 0, "size": 1})).unwrap());
        let why = c.slave_frames().unwrap_err();
        assert!(why.contains("slave[1]'s start-up SDOs write 0x1c12"), "{why}");
    }
}
