//! `ecmxf-devices`: EtherCAT device descriptions, read the same way by the
//! daemon (to name, type and list what a slave has) and by the simulator (to
//! build slaves from them). Nothing here simulates or does I/O.
//!
//! # Map
//! - [`sii`]: the SII EEPROM image (ETG.1000.6 / ETG.2010): parse and build,
//!   strings decoded as UTF-8 or else Windows-1252.
//! - [`esi`]: EtherCAT Slave Information XML files (ETG.2000): identity,
//!   sync managers, PDOs, mailbox protocols, DC modes, the dictionary, and
//!   the SII an ESI implies.
//! - [`eni`]: EtherCAT Network Information files (ETG.2100): slaves,
//!   identities and CoE init commands per transition, and what else the
//!   file holds.
//! - [`od`]: an object dictionary: types, access per state, PDO-mapping
//!   flags, defaults.
//! - [`pdo`]: PDO assignment and mapping objects.
//! - [`catalog`]: a folder of descriptions (ESI files and SII dumps) read
//!   as the devices they describe and what each must show on the bus.
//! - [`config_file`]: errors of the TOML files that describe networks and
//!   daemons, naming file, line and key.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod catalog;
pub mod config_file;
pub mod eni;
pub mod esi;
pub mod init_cmd;
pub mod od;
pub mod pdo;
pub mod sii;
mod xml;
pub use xml::TextPos;
