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
//! strict_lengths = false    # true: refuse a packet whose declared data
//!                           # length is not its v049 layout's
//!
//! [[slave]]
//! profile = "neuromeka-core" # neuromeka-core | ti-3axis | digital-io | coupler
//! alias = 1
//!
//! [[slave]]
//! sii = "dumps/el2889.bin"  # an SII EEPROM dump: PDOs from its categories
//!
//! [[slave]]
//! esi = "devices/EK11xx.xml" # relative to this file
//! product_code = 0x044C2C52
//! revision = 0x00120000      # optional: highest revision when absent
//! ```

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::chip::ChipConfig;
use crate::net::esi::{EsiFile, SimulatedDevice};
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
    /// Refuse commands whose declared data length is not their layout's.
    #[serde(default)]
    pub strict_lengths: bool,
}

/// Which slave entry of an ENI file a simulated slave is: `eni_slave =
/// 2` (position from 1) or `eni_slave = "Imu"` (its `Info/Name`; a name
/// of digits only is a position too).
#[derive(Clone, Debug, Deserialize, PartialEq, Eq)]
#[serde(untagged)]
pub enum EniSlaveRef {
    /// Position from 1.
    Position(u64),
    /// Name, or position written as text.
    Name(String),
}

impl EniSlaveRef {
    fn find<'a>(&self, slaves: &'a [ecmxf_devices::eni::EniSlave]) -> Option<&'a ecmxf_devices::eni::EniSlave> {
        let at = |n: u64| slaves.get(usize::try_from(n).ok()?.checked_sub(1)?);
        match self {
            Self::Position(n) => at(*n),
            Self::Name(name) => slaves.iter().find(|s| s.name == *name).or_else(|| at(name.parse().ok()?)),
        }
    }
}

impl std::fmt::Display for EniSlaveRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Position(n) => write!(f, "at position {n}"),
            Self::Name(name) => write!(f, "{name:?}"),
        }
    }
}

/// `[[slave]]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SlaveSection {
    /// A ready-made profile.
    pub profile: Option<String>,
    /// An ESI file.
    pub esi: Option<PathBuf>,
    /// An SII EEPROM dump (binary), the slave's only description.
    pub sii: Option<PathBuf>,
    /// An ENI file whose slave entry (`eni_slave`) describes the device
    /// (a device known only from a configuration tool's export).
    pub eni: Option<PathBuf>,
    /// The ENI slave entry by name (`Info/Name`), or by position from 1
    /// (a number, or a name that is all digits).
    pub eni_slave: Option<EniSlaveRef>,
    /// Product code of the ESI device.
    pub product_code: Option<u32>,
    /// Revision of the ESI device.
    pub revision: Option<u32>,
    /// Station alias.
    #[serde(default)]
    pub alias: u16,
    /// Serial number (profiles).
    pub serial: Option<u32>,
    /// The shortest DC cycle the slave runs, us (default 125): a shorter
    /// SYNC0 makes it refuse SAFE-OP with AL status 0x0035 (invalid sync
    /// cycle time), as a real slave does.
    pub min_cycle_us: Option<u32>,
}

pub use ecmxf_devices::config_file::{ConfigError, key_line};
pub use ecmxf_wire::limits::{MAX_SLAVES, SPI_HZ};

impl SlaveSection {
    /// The `[[slave]]` table that puts a catalogued device on the ring: its
    /// ESI device by product code and revision, or its SII dump.
    pub fn table_for(device: &ecmxf_devices::catalog::CatalogDevice) -> String {
        use ecmxf_devices::catalog::Origin;
        use ecmxf_devices::config_file::toml_path as quoted;
        match &device.origin {
            Origin::Esi { file } => format!(
                "[[slave]]\nesi = {}\nproduct_code = {:#x}\nrevision = {:#x}\n",
                quoted(file),
                device.product,
                device.revision
            ),
            Origin::Sii { file } => format!("[[slave]]\nsii = {}\n", quoted(file)),
        }
    }
}

impl NetworkFile {
    /// Parses and checks the text of a file at `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let file: Self = toml::from_str(text).map_err(|e| ConfigError::Toml(path.into(), e.to_string()))?;
        file.validate(path).map_err(|e| e.at_line(text))?;
        Ok(file)
    }

    /// Checks the values the schema cannot: version, ranges, the chip's
    /// limits, unique aliases.
    fn validate(&self, path: &Path) -> Result<(), ConfigError> {
        let bad =
            |key: &str, message: String| Err(ConfigError::Invalid { file: path.into(), key: key.into(), message });
        if self.version != VERSION {
            return bad("version", format!("version {} is not supported (this build reads {VERSION})", self.version));
        }
        if let Some(hz) = self.chip.spi_hz {
            if !SPI_HZ.contains(&hz) {
                return bad(
                    "chip.spi_hz",
                    format!("{hz} Hz is outside the chip's {}..={} Hz", SPI_HZ.start(), SPI_HZ.end()),
                );
            }
        }
        if let Some(us) = self.chip.processing_us {
            if !(1..=10_000).contains(&us) {
                return bad("chip.processing_us", format!("{us} us is outside 1..=10000"));
            }
        }
        if self.slaves.len() > MAX_SLAVES {
            return bad("slave", format!("{} slaves; the chip takes at most {MAX_SLAVES}", self.slaves.len()));
        }
        for (i, s) in self.slaves.iter().enumerate() {
            if s.alias != 0 {
                if let Some(j) = self.slaves[..i].iter().position(|o| o.alias == s.alias) {
                    return bad(
                        &format!("slave[{i}].alias"),
                        format!("alias {} is already slave {j}'s; aliases address one slave each", s.alias),
                    );
                }
            }
        }
        Ok(())
    }

    /// Reads and checks a file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = ConfigError::read(path)?;
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
        c.strict_lengths = self.chip.strict_lengths;
        c
    }

    /// Builds the network; ESI paths are relative to `base` (the file's
    /// folder).
    pub fn build(&self, path: &Path) -> Result<Network, ConfigError> {
        let base = path.parent().unwrap_or(Path::new("."));
        let mut slaves = Vec::new();
        for (i, s) in self.slaves.iter().enumerate() {
            // The line of the slave at fault, when the file can be read.
            let at_line = |e: ConfigError| match std::fs::read_to_string(path) {
                Ok(text) => e.at_line(&text),
                Err(_) => e,
            };
            slaves.push(s.build(i, base, path).map_err(at_line)?);
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
        let mut slave = self.described(i, base, file)?;
        if let Some(us) = self.min_cycle_us {
            slave.min_cycle_ns = us.saturating_mul(1000);
        }
        Ok(slave)
    }

    fn described(&self, i: usize, base: &Path, file: &Path) -> Result<Slave, ConfigError> {
        let invalid = |key: &str, message: String| ConfigError::Invalid {
            file: file.into(),
            key: format!("slave[{i}].{key}"),
            message,
        };
        let serial = self.serial.unwrap_or(1000 + i as u32);
        if let Some(eni) = &self.eni {
            if self.profile.is_some() || self.esi.is_some() || self.sii.is_some() {
                return Err(invalid("eni", "give one of profile, esi, sii or eni".into()));
            }
            let path = base.join(eni);
            let file =
                ecmxf_devices::eni::Eni::load(&path).map_err(|e| invalid("eni", format!("{}: {e}", path.display())))?;
            let wanted = self.eni_slave.clone().unwrap_or(EniSlaveRef::Position(1));
            let entry = wanted.find(&file.slaves).ok_or_else(|| {
                let names: Vec<&str> = file.slaves.iter().map(|s| s.name.as_str()).collect();
                invalid(
                    "eni_slave",
                    format!(
                        "{} has no slave {wanted} (its {} slaves: {})",
                        path.display(),
                        file.slaves.len(),
                        names.join(", ")
                    ),
                )
            })?;
            return Ok(crate::net::eni_slave::slave_from_eni(entry, self.alias));
        }
        if self.eni_slave.is_some() {
            return Err(invalid("eni_slave", "eni_slave names a slave of an `eni` file; give `eni` too".into()));
        }
        if let Some(sii) = &self.sii {
            if self.profile.is_some() || self.esi.is_some() {
                return Err(invalid("sii", "give one of profile, esi or sii".into()));
            }
            let path = base.join(sii);
            let image = std::fs::read(&path).map_err(|e| invalid("sii", format!("{}: {e}", path.display())))?;
            let mut s = crate::net::sii_slave::slave_from_sii(image)
                .map_err(|e| invalid("sii", format!("{}: {e}", path.display())))?;
            if self.alias != 0 {
                s.eeprom_write(4, self.alias);
            }
            return Ok(s);
        }
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
                    crate::net::esi::read_xml(&path).map_err(|e| invalid("esi", format!("{}: {e}", path.display())))?;
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
            (None, None) => Err(invalid("profile", "each slave needs a profile, an esi, an sii or an eni".into())),
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
    fn a_catalogued_device_becomes_a_slave_table_that_reads_back() {
        use ecmxf_devices::catalog::{CatalogDevice, Origin};
        let mut d = CatalogDevice {
            origin: Origin::Esi { file: PathBuf::from("/odd \"dir\"\\x.xml") },
            what: String::new(),
            name: String::new(),
            vendor: 2,
            product: 0x3f03052,
            revision: 0x120000,
            coe: false,
            rx: vec![],
            tx: vec![],
            types: vec![],
            objects: vec![],
        };
        let f = parse(&format!("version = 1\n{}", SlaveSection::table_for(&d))).unwrap();
        assert_eq!(f.slaves[0].esi.as_deref(), Some(Path::new("/odd \"dir\"\\x.xml")));
        assert_eq!((f.slaves[0].product_code, f.slaves[0].revision), (Some(0x3f03052), Some(0x120000)));
        d.origin = Origin::Sii { file: PathBuf::from("d.bin") };
        let f = parse(&format!("version = 1\n{}", SlaveSection::table_for(&d))).unwrap();
        assert_eq!(f.slaves[0].sii.as_deref(), Some(Path::new("d.bin")));
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

    #[test]
    fn values_outside_the_chip_s_limits_are_refused_with_their_line() {
        let e = parse("version = 1\n[chip]\nspi_hz = 0\n").unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("chip.spi_hz") && e.contains("96000000"), "{e}");
        let e = parse(
            "version = 1\n[[slave]]\nprofile = \"coupler\"\nalias = 7\n[[slave]]\nprofile = \"coupler\"\nalias = 7\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("slave[1].alias") && e.contains("slave 0") && e.contains("line 7"), "{e}");
        let many = "[[slave]]\nprofile = \"coupler\"\n".repeat(129);
        let e = parse(&format!("version = 1\n{many}")).unwrap_err().to_string();
        assert!(e.contains("129 slaves") && e.contains("128"), "{e}");
        assert!(parse(&format!("version = 1\n{}", "[[slave]]\nprofile = \"coupler\"\n".repeat(128))).is_ok());
    }

    #[test]
    fn keys_are_found_at_their_lines() {
        let text =
            "version = 1\n\n[cycle]\nsync0_us = 5\n\n[[slave]]\nname = \"a\"\n[[slave]]\nname = \"b\"\nalias = 3\n";
        assert_eq!(key_line(text, "version"), Some(1));
        assert_eq!(key_line(text, "cycle.sync0_us"), Some(4));
        assert_eq!(key_line(text, "cycle.fifo_high"), Some(3), "not written: its table");
        assert_eq!(key_line(text, "slave[1].alias"), Some(10));
        assert_eq!(key_line(text, "nothing"), None);
    }

    #[test]
    fn a_binary_file_is_named_as_such() {
        let dir = std::env::temp_dir().join(format!("ecmxf-sim-bin-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("garbage.toml");
        std::fs::write(&p, b"version = 1\n\xff\xfe\x00binary").unwrap();
        let e = NetworkFile::load(&p).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("not UTF-8"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// `eni_slave` takes the position as a number (from 1) as well as a
    /// name or the position as text.
    #[test]
    fn an_eni_slave_is_named_or_numbered() {
        #[derive(Deserialize)]
        struct One {
            eni_slave: EniSlaveRef,
        }
        let pick = |t: &str| toml::from_str::<One>(t).unwrap().eni_slave;
        assert_eq!(pick("eni_slave = 2"), EniSlaveRef::Position(2));
        assert_eq!(pick("eni_slave = \"Imu\""), EniSlaveRef::Name("Imu".into()));
        let eni = ecmxf_devices::eni::Eni::parse(
            r#"<EtherCATConfig><Config>
              <Slave><Info><Name>Imu</Name><VendorId>1</VendorId><ProductCode>2</ProductCode></Info></Slave>
              <Slave><Info><Name>Drive</Name><VendorId>1</VendorId><ProductCode>3</ProductCode></Info></Slave>
            </Config></EtherCATConfig>"#,
        )
        .unwrap();
        let name = |r: EniSlaveRef| r.find(&eni.slaves).map(|s| s.name.clone());
        assert_eq!(name(EniSlaveRef::Position(2)), Some("Drive".into()));
        assert_eq!(name(EniSlaveRef::Name("2".into())), Some("Drive".into()));
        assert_eq!(name(EniSlaveRef::Name("Imu".into())), Some("Imu".into()));
        assert_eq!(name(EniSlaveRef::Position(0)), None);
        assert_eq!(name(EniSlaveRef::Position(3)), None);
        assert_eq!(EniSlaveRef::Position(3).to_string(), "at position 3");
    }
}
