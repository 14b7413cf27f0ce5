//! The network description file (TOML): which slaves, in ring order, and
//! how the chip behaves. Unknown keys are errors, and every error names the
//! key (and, for syntax, the line) so a typo never silently changes the
//! network.
//!
//! ```toml
//! version = 1
//!
//! [chip]                    # all optional
//! processing_us = 30        # busy time after each packet (INT0 inactive)
//! firmware_version = 0x24
//! spi_hz = 20_000_000
//!
//! [[slave]]
//! profile = "neuromeka-core" # neuromeka-core | ti-3axis | digital-io | coupler
//! alias = 1
//!
//! [[slave]]
//! esi = "devices/EK11xx.xml" # relative to this file
//! product_code = 0x044C2C52
//! revision = 0x00120000      # optional: highest revision when absent
//! ```

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::chip::ChipConfig;
use crate::net::esi::EsiFile;
use crate::net::{Network, Slave, profiles};

/// The file's version this build reads.
pub const VERSION: u32 = 1;

/// A network description as written.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NetworkFile {
    /// Format version, must be 1.
    pub version: u32,
    /// Chip settings.
    #[serde(default)]
    pub chip: ChipSection,
    /// Slaves in ring order.
    #[serde(default, rename = "slave")]
    pub slaves: Vec<SlaveSection>,
}

/// `[chip]`.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ChipSection {
    /// Busy time after each packet, us.
    pub processing_us: Option<u64>,
    /// Firmware version.
    pub firmware_version: Option<u8>,
    /// SPI clock, Hz.
    pub spi_hz: Option<u64>,
}

/// `[[slave]]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SlaveSection {
    /// A ready-made profile.
    pub profile: Option<String>,
    /// An ESI file.
    pub esi: Option<PathBuf>,
    /// Product code of the ESI device.
    pub product_code: Option<u32>,
    /// Revision of the ESI device.
    pub revision: Option<u32>,
    /// Station alias.
    #[serde(default)]
    pub alias: u16,
    /// Serial number (profiles).
    pub serial: Option<u32>,
}

/// Why a network file was refused.
#[derive(Debug)]
pub enum ConfigError {
    /// Could not read the file.
    Io(PathBuf, std::io::Error),
    /// Syntax or schema error; toml's message names key, line and column.
    Toml(PathBuf, String),
    /// A value is wrong.
    Invalid {
        /// The file.
        file: PathBuf,
        /// The key, e.g. `slave[2].profile`.
        key: String,
        /// What is wrong.
        message: String,
    },
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Toml(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Invalid { file, key, message } => write!(f, "{}: {key}: {message}", file.display()),
        }
    }
}

impl std::error::Error for ConfigError {}

impl NetworkFile {
    /// Parses and checks the text of a file at `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let file: Self = toml::from_str(text).map_err(|e| ConfigError::Toml(path.into(), e.to_string()))?;
        if file.version != VERSION {
            return Err(ConfigError::Invalid {
                file: path.into(),
                key: "version".into(),
                message: format!("version {} is not supported (this build reads {VERSION})", file.version),
            });
        }
        Ok(file)
    }

    /// Reads and checks a file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError::Io(path.into(), e))?;
        Self::parse(&text, path)
    }

    /// The chip configuration.
    pub fn chip_config(&self) -> ChipConfig {
        let mut c = ChipConfig::default();
        if let Some(us) = self.chip.processing_us {
            c.processing_ns = us * 1000;
        }
        if let Some(v) = self.chip.firmware_version {
            c.firmware_version = v;
        }
        if let Some(hz) = self.chip.spi_hz {
            c.spi_hz = hz;
        }
        c
    }

    /// Builds the network; ESI paths are relative to `base` (the file's
    /// folder).
    pub fn build(&self, path: &Path) -> Result<Network, ConfigError> {
        let base = path.parent().unwrap_or(Path::new("."));
        let mut slaves = Vec::new();
        for (i, s) in self.slaves.iter().enumerate() {
            slaves.push(s.build(i, base, path)?);
        }
        if slaves.is_empty() {
            return Err(ConfigError::Invalid {
                file: path.into(),
                key: "slave".into(),
                message: "the network has no slaves".into(),
            });
        }
        Ok(Network::new(slaves))
    }
}

/// Names of the ready-made profiles.
pub const PROFILES: [&str; 4] = ["neuromeka-core", "ti-3axis", "digital-io", "coupler"];

impl SlaveSection {
    fn build(&self, i: usize, base: &Path, file: &Path) -> Result<Slave, ConfigError> {
        let invalid = |key: &str, message: String| ConfigError::Invalid {
            file: file.into(),
            key: format!("slave[{i}].{key}"),
            message,
        };
        let serial = self.serial.unwrap_or(1000 + i as u32);
        match (&self.profile, &self.esi) {
            (Some(p), None) => match p.as_str() {
                "neuromeka-core" => Ok(profiles::neuromeka_core(serial, self.alias)),
                "ti-3axis" => Ok(profiles::ti_three_axis(serial, self.alias)),
                "digital-io" => Ok(profiles::digital_io(serial, self.alias)),
                "coupler" => Ok(profiles::coupler(serial)),
                other => Err(invalid("profile", format!("unknown profile {other:?}; known: {}", PROFILES.join(", ")))),
            },
            (None, Some(esi)) => {
                let path = base.join(esi);
                let text =
                    std::fs::read_to_string(&path).map_err(|e| invalid("esi", format!("{}: {e}", path.display())))?;
                let f = EsiFile::parse(&text).map_err(|e| invalid("esi", format!("{}: {e}", path.display())))?;
                let code = match self.product_code {
                    Some(c) => c,
                    None if f.devices.len() == 1 => f.devices[0].product_code,
                    None => {
                        return Err(invalid(
                            "product_code",
                            format!("{} describes {} devices: say which", path.display(), f.devices.len()),
                        ));
                    }
                };
                let d = f.device(code, self.revision).map_err(|e| invalid("product_code", e.to_string()))?;
                Ok(d.to_slave(f.vendor_id, self.alias))
            }
            (Some(_), Some(_)) => Err(invalid("profile", "give either profile or esi, not both".into())),
            (None, None) => Err(invalid("profile", "each slave needs a profile or an esi".into())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(t: &str) -> Result<NetworkFile, ConfigError> {
        NetworkFile::parse(t, Path::new("net.toml"))
    }

    #[test]
    fn demo_shape_parses() {
        let f = parse("version = 1\n[chip]\nprocessing_us = 20\n[[slave]]\nprofile = \"coupler\"\n[[slave]]\nprofile = \"digital-io\"\nalias = 5\n").unwrap();
        assert_eq!(f.chip_config().processing_ns, 20_000);
        let net = f.build(Path::new("net.toml")).unwrap();
        assert_eq!(net.slaves.len(), 2);
        assert_eq!(net.slaves[1].alias, 5);
    }

    #[test]
    fn mistakes_name_key_and_line() {
        let e = parse("version = 1\n[[slave]]\nprofil = \"coupler\"\n").unwrap_err().to_string();
        assert!(e.contains("profil") && e.contains("line 3"), "{e}");
        let e = parse("version = 2\n").unwrap_err().to_string();
        assert!(e.contains("version 2"), "{e}");
        let f = parse("version = 1\n[[slave]]\nprofile = \"servo\"\n").unwrap();
        let e = f.build(Path::new("net.toml")).unwrap_err().to_string();
        assert!(e.contains("slave[0].profile") && e.contains("servo"), "{e}");
        let f = parse("version = 1\n").unwrap();
        assert!(f.build(Path::new("net.toml")).is_err());
        let f = parse("version = 1\n[[slave]]\nesi = \"missing.xml\"\n").unwrap();
        let e = f.build(Path::new("net.toml")).unwrap_err().to_string();
        assert!(e.contains("slave[0].esi") && e.contains("missing.xml"), "{e}");
    }
}
