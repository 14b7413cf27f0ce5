//! The files a configuration names, opened and read the way the daemon
//! will read them (`ecmxfd --check-config`): an ESI that does not parse, a
//! TLS file that is not PEM, a file that cannot be read fails the check
//! naming the key, so a mistake shows before the service is restarted,
//! not at its first client. Device nodes (spidev, the GPIO chip) are named
//! in notes when absent: the check may run on another machine than the
//! gateway.

use std::path::Path;

use super::{Config, ConfigError, LinkConfig};

impl Config {
    /// Opens every file the configuration names; returns notes for what
    /// cannot be checked here (device nodes absent on this machine).
    pub fn check_files(&self, path: &Path) -> Result<Vec<String>, ConfigError> {
        let bad = |key: String, message: String| ConfigError::Invalid { file: path.into(), key, message };
        let mut notes = Vec::new();
        if let Some(eni) = &self.eni {
            let file =
                ecmxf_devices::eni::Eni::load(eni).map_err(|e| bad("eni".into(), format!("{}: {e}", eni.display())))?;
            notes.extend(super::eni::eni_notes(&file));
        }
        for (i, s) in self.slaves.iter().enumerate() {
            if let Some(esi) = &s.esi {
                let key = format!("slave[{i}].esi");
                let text = ecmxf_devices::esi::read_xml(esi)
                    .map_err(|e| bad(key.clone(), format!("{}: {e}", esi.display())))?;
                let file = ecmxf_devices::esi::EsiFile::parse(&text)
                    .map_err(|e| bad(key.clone(), format!("{}: {e}", esi.display())))?;
                if file.devices.is_empty() {
                    return Err(bad(key, format!("{}: describes no device", esi.display())));
                }
                if self.eni.is_none() {
                    notes.extend(super::eni::esi_init_notes(i, s, &file));
                }
                // What the file's description of the device cannot carry
                // (a PDO on a sync manager the device lacks, a PDO listed
                // twice): the device the entry names, else every one it
                // may mean, as the daemon will say at start.
                for d in file.devices.iter().filter(|d| s.product_code.is_none_or(|p| d.product_code == p)) {
                    for w in &d.warnings {
                        notes.push(format!("{key}: {} (revision {:#010x}): {w}", d.type_name, d.revision));
                    }
                }
            }
        }
        for (key, file, label) in [
            ("api.tls_cert", &self.api.tls_cert, "CERTIFICATE"),
            ("api.tls_key", &self.api.tls_key, "PRIVATE KEY"),
            ("api.client_ca", &self.api.client_ca, "CERTIFICATE"),
        ] {
            let Some(file) = file else { continue };
            let text =
                std::fs::read_to_string(file).map_err(|e| bad(key.into(), format!("{}: {e}", file.display())))?;
            if !text.contains("-----BEGIN") || !text.contains(label) {
                return Err(bad(key.into(), format!("{}: no PEM {label} in it", file.display())));
            }
        }
        if let LinkConfig::Spidev { device, gpio_chip, .. } = &self.link {
            for (key, node) in [("link.device", Some(device)), ("link.gpio_chip", gpio_chip.as_ref())] {
                if let Some(node) = node.filter(|n| !n.exists()) {
                    notes.push(format!(
                        "{key}: {} is not on this machine (opened when the daemon starts)",
                        node.display()
                    ));
                }
            }
        }
        Ok(notes)
    }
}
