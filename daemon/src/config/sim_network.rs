//! What a simulator configuration's network file says about the rest of
//! the configuration, checked offline (`--check-config`): the file loads
//! and builds as the daemon will build it, and each `[[axis]]` finds its
//! slave's controlword (0x6040, or an axis's at +0x800 x n) at its output
//! offset and its statusword (0x6041) at its input offset, the bytes the
//! chip's CiA 402 helper drives (v049 `ECM_CMD_402_CONFIG_SET`).

use std::path::Path;

use super::{Config, ConfigError, LinkConfig};

/// The simulated network a configuration runs on: `None` when its link is
/// not the in-process simulator.
pub(crate) fn load(
    c: &Config,
    path: &Path,
) -> Result<Option<(ecmxf_sim::Network, ecmxf_sim::ChipConfig)>, ConfigError> {
    let LinkConfig::Sim { network } = &c.link else { return Ok(None) };
    let bad = |message: String| ConfigError::Invalid { file: path.into(), key: "link.network".into(), message };
    Ok(Some(match network {
        None => (ecmxf_sim::Network::demo(), ecmxf_sim::ChipConfig::default()),
        Some(p) => {
            let f = ecmxf_sim::config::NetworkFile::load(p).map_err(|e| bad(e.to_string()))?;
            (f.build(p).map_err(|e| bad(e.to_string()))?, f.chip_config())
        }
    }))
}

/// The slaves the configuration expects against those the simulated
/// network has: bring-up would refuse a network of another size for ever,
/// so `--check-config` says so first, naming both counts.
pub(crate) fn check_count(c: &Config, net: &ecmxf_sim::Network, path: &Path) -> Result<(), ConfigError> {
    if c.slaves.is_empty() || c.slaves.len() == net.slaves.len() {
        return Ok(());
    }
    let which = match &c.link {
        LinkConfig::Sim { network: Some(p) } => format!("the simulated network {}", p.display()),
        _ => "the demo network (no link.network given)".to_string(),
    };
    let key = if c.eni.is_some() { "eni" } else { "slave" };
    let message = format!("{}, {which} has {}", c.expected_slaves(), net.slaves.len());
    Err(ConfigError::Invalid { file: path.into(), key: key.into(), message })
}

/// Each `[[axis]]` against the simulated network `net`: the first axis
/// whose slave or CiA 402 words are not there, named by its key.
pub(crate) fn check_axes(c: &Config, net: &ecmxf_sim::Network, path: &Path) -> Result<(), ConfigError> {
    let bad = |key: String, message: String| ConfigError::Invalid { file: path.into(), key, message };
    let maps = |entries: &[ecmxf_sim::net::pdo_map::MappedEntry], base: u16, byte: u8| {
        entries.iter().any(|e| {
            (0..8u16).any(|k| e.index == base + 0x800 * k) && e.subindex == 0 && e.bit_offset == u32::from(byte) * 8
        })
    };
    for (i, a) in c.axes.iter().enumerate() {
        let Some(s) = net.slaves.get(usize::from(a.slave)) else {
            let why = format!("slave {} is not in the simulated network of {}", a.slave, net.slaves.len());
            return Err(bad(format!("axis[{i}].slave"), why));
        };
        if !maps(&s.rx.entries, 0x6040, a.controlword_offset) {
            let why = format!(
                "slave {} ({}) maps no controlword (0x6040) at output byte {}",
                a.slave, s.name, a.controlword_offset
            );
            return Err(bad(format!("axis[{i}].controlword_offset"), why));
        }
        if !maps(&s.tx.entries, 0x6041, a.statusword_offset) {
            let why = format!(
                "slave {} ({}) maps no statusword (0x6041) at input byte {}",
                a.slave, s.name, a.statusword_offset
            );
            return Err(bad(format!("axis[{i}].statusword_offset"), why));
        }
    }
    Ok(())
}
