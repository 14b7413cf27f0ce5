//! The device of a multi-device `[[slave]] esi` file each slave is, chosen
//! by the identity it reports (ETG.2000: a slave's description is the
//! device with its vendor, product code and revision), and that device's
//! CoE init commands put before the entry's `[[slave.sdo]]`, as they are
//! at configuration time for a file the entry narrows to one device
//! (config/eni.rs, `apply_esi_init_cmds`). Runs once per bring-up, right
//! after the identity check: it may allocate.

use std::borrow::Cow;

use ecmxf_devices::esi::nearest_revision;

use super::super::layout::SlaveSummary;
use super::error::BringUpError;
use crate::config::{Config, EsiChoice};

/// `config` as this bring-up runs it: each slave with `esi_choices` gets
/// the init commands of the candidate its scanned identity names (same
/// vendor and product; the revision by `nearest_revision`); `config`
/// itself when no slave has choices. A slave none of whose candidates has
/// its vendor and product is an [`BringUpError::EsiDevice`].
pub(super) fn esi_device_sdos<'c>(
    config: &'c Config,
    slaves: &[SlaveSummary],
) -> Result<Cow<'c, Config>, BringUpError> {
    if config.slaves.iter().all(|s| s.esi_choices.is_empty()) {
        return Ok(Cow::Borrowed(config));
    }
    let mut run = config.clone();
    for (position, (entry, found)) in run.slaves.iter_mut().zip(slaves).enumerate() {
        if entry.esi_choices.is_empty() {
            continue;
        }
        let chosen = choose(&entry.esi_choices, found).ok_or_else(|| BringUpError::EsiDevice {
            position,
            name: entry.name.clone().unwrap_or_else(|| found.name.clone()),
            found: (found.vendor_id, found.product_code, found.revision),
            file: entry.esi.as_ref().map_or_else(String::new, |p| p.display().to_string()),
            candidates: entry.esi_choices.iter().map(|c| (c.name.clone(), c.product_code, c.revision)).collect(),
        })?;
        tracing::info!(
            slave = position,
            device = %chosen.name,
            revision = format_args!("{:#010x}", chosen.revision),
            init_commands = chosen.sdos.len(),
            "ESI device chosen by the scanned identity"
        );
        let mut sdos = chosen.sdos.clone();
        sdos.append(&mut entry.sdos);
        entry.sdos = sdos;
    }
    Ok(Cow::Owned(run))
}

/// The candidate a slave reporting `found` is.
fn choose<'a>(choices: &'a [EsiChoice], found: &SlaveSummary) -> Option<&'a EsiChoice> {
    let same = || choices.iter().filter(|c| c.vendor_id == found.vendor_id && c.product_code == found.product_code);
    let revision = nearest_revision(same().map(|c| c.revision), found.revision)?;
    same().find(|c| c.revision == revision)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{InitTransition, SlaveConfig, StartupSdo};

    fn choice(product_code: u32, revision: u32, mode: u8) -> EsiChoice {
        EsiChoice {
            name: format!("drive {product_code:#x} rev {revision:#x}"),
            vendor_id: 0x9a,
            product_code,
            revision,
            sdos: vec![sdo(0x6060, mode)],
        }
    }

    fn sdo(index: u16, byte: u8) -> StartupSdo {
        StartupSdo {
            index,
            subindex: 0,
            value: None,
            size: None,
            bytes: Some(vec![byte]),
            complete_access: false,
            transition: InitTransition::Ps,
            timeout_ms: None,
            origin: String::new(),
        }
    }

    fn found(product_code: u32, revision: u32) -> SlaveSummary {
        SlaveSummary { vendor_id: 0x9a, product_code, revision, name: "Drive".into(), ..SlaveSummary::default() }
    }

    fn config() -> Config {
        let own = sdo(0x2000, 1);
        let entry = SlaveConfig {
            esi: Some("elmo.xml".into()),
            sdos: vec![own],
            esi_choices: vec![choice(0x30924, 1, 1), choice(0x30924, 0x10420, 8), choice(0x30925, 0x10420, 9)],
            ..SlaveConfig::default()
        };
        Config { slaves: vec![SlaveConfig::default(), entry], ..Config::simulator() }
    }

    #[test]
    fn the_scanned_identity_puts_its_devices_init_commands_before_the_entrys_own() {
        let config = config();
        let run = esi_device_sdos(&config, &[found(1, 1), found(0x30924, 0x10420)]).unwrap();
        let sdos: Vec<_> = run.slaves[1].sdos.iter().map(|s| (s.index, s.bytes.clone().unwrap())).collect();
        assert_eq!(sdos, [(0x6060, vec![8]), (0x2000, vec![1])]);
        // A later revision than any the file describes runs as the nearest lower.
        let run = esi_device_sdos(&config, &[found(1, 1), found(0x30924, 0x10500)]).unwrap();
        assert_eq!(run.slaves[1].sdos[0].bytes, Some(vec![8]));
        // No slave with choices: the configuration itself, nothing copied.
        let plain = Config { slaves: vec![SlaveConfig::default()], ..Config::simulator() };
        assert!(matches!(esi_device_sdos(&plain, &[found(1, 1)]), Ok(Cow::Borrowed(_))));
    }

    #[test]
    fn a_slave_no_candidate_matches_fails_naming_it_its_identity_and_the_candidates() {
        let config = config();
        let e = esi_device_sdos(&config, &[found(1, 1), found(0x40000, 2)]).unwrap_err();
        assert!(!e.is_permanent(), "retried as an identity mismatch is");
        let text = e.to_string();
        for part in ["slave 1 (\"Drive\")", "product 0x00040000 revision 0x00000002", "elmo.xml", "3 candidates"] {
            assert!(text.contains(part), "{part}: {text}");
        }
        assert!(text.contains("\"drive 0x30925 rev 0x10420\" product 0x00030925 revision 0x00010420"), "{text}");
    }
}
