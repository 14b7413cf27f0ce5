//! What the daemon's fixture-driven tests share.

use std::path::{Path, PathBuf};

/// ../shared/fixtures, or `None` (the test skips, saying so) when it is
/// missing, unless ECMXF_REQUIRE_FIXTURES is set (CI), where that fails.
pub fn fixtures() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/fixtures");
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(std::env::var_os("ECMXF_REQUIRE_FIXTURES").is_none(), "{} missing", dir.display());
    eprintln!("skipped: {} missing", dir.display());
    None
}

/// A configuration that runs `devices` as one network on the in-process
/// simulator at a 1 ms cycle (its network file written into `dir`).
pub fn simulated(dir: &Path, devices: &[ecmxf_devices::catalog::CatalogDevice]) -> ecmxfd::config::Config {
    let network = dir.join("net.toml");
    let lines: String = devices.iter().map(ecmxf_sim::config::SlaveSection::table_for).collect();
    std::fs::write(&network, format!("version = 1\n{lines}")).unwrap();
    let mut config = ecmxfd::config::Config::simulator();
    config.link = ecmxfd::config::LinkConfig::Sim { network: Some(network) };
    config.cycle.sync0_us = 1000;
    config
}
