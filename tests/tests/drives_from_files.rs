//! Every CiA 402 drive described in ../shared/fixtures (an ESI or SII
//! whose default PDOs map the controlword 0x6040 and the statusword 0x6041;
//! a file added there is picked up) moves end to end: the simulator runs
//! the drive model behind the file's own mapping, the daemon's `[[axis]]`
//! drives it through the chip's CiA 402 helper, and ecmxfctl enables it,
//! sets CSP, moves it, and disables it while the position actual follows.

use std::time::{Duration, Instant};

use ecmxf_devices::catalog::{Catalog, CatalogDevice, CatalogEntry};
use ecmxf_e2e::{Daemon, run, temp_dir};

/// The byte offset of `index:00` in one direction's entries, if mapped at a
/// byte boundary.
fn offset(entries: &[CatalogEntry], index: u16) -> Option<u32> {
    let mut bits = 0u32;
    for e in entries {
        if e.index == index && e.subindex == 0 {
            return (bits % 8 == 0).then_some(bits / 8);
        }
        bits += u32::from(e.bits);
    }
    None
}

/// The first drive of each file: (device, controlword offset, statusword
/// offset).
fn drives(catalog: &Catalog) -> Vec<(&CatalogDevice, u32, u32)> {
    let mut out: Vec<(&CatalogDevice, u32, u32)> = Vec::new();
    for d in &catalog.devices {
        if out.iter().any(|(o, _, _)| o.origin.file() == d.origin.file()) {
            continue;
        }
        if let (Some(cw), Some(sw)) = (offset(&d.rx, 0x6040), offset(&d.tx, 0x6041)) {
            out.push((d, cw, sw));
        }
    }
    out
}

fn move_one(d: &CatalogDevice, cw: u32, sw: u32) -> Result<(), String> {
    let dir = temp_dir("drives-from-files");
    let (link, slave) = ecmxf_e2e::catalog_network(&dir, &[d]);
    let extra = format!("{slave}[[axis]]\nslave = 0\ncontrolword_offset = {cw}\nstatusword_offset = {sw}\n");
    let label = format!("{} ({})", d.name, d.origin.file().display());
    let mut result = Ok(());
    run(async {
        result = drive(&link, &extra, d, &label).await;
    });
    let _ = std::fs::remove_dir_all(&dir);
    result
}

async fn drive(link: &str, extra: &str, d: &CatalogDevice, label: &str) -> Result<(), String> {
    {
        let mut daemon = Daemon::with_config(&ecmxf_e2e::config_with_cycle(link, "sync0_us = 1000\n", extra));
        daemon.connect().await;
        let step = |args: &[&str]| -> Result<String, String> {
            let out = daemon.ctl(args);
            if out.code == 0 {
                Ok(out.stdout)
            } else {
                Err(format!("{label}: ecmxfctl {}: {}", args.join(" "), out.stderr))
            }
        };
        step(&["cia402", "enable", "-a", "0"])?;
        step(&["cia402", "mode", "-a", "0", "csp"])?;
        let target = if offset(&d.rx, 0x607A).is_some() { 20_000 } else { 0 };
        if target != 0 {
            step(&["cia402", "move", "-a", "0", "--position", "20000"])?;
        }
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            let status = daemon.ctl(&["--json", "cia402", "status", "-a", "0"]).json();
            let axis = &status["axes"][0];
            let position = axis["position_actual"].as_i64().unwrap_or(i64::MAX / 2);
            if axis["state"] == "OPERATION_ENABLED" && (position - target).abs() <= 100 {
                break;
            }
            if Instant::now() > deadline {
                return Err(format!("{label}: the position actual does not follow: {status}"));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        step(&["cia402", "disable", "-a", "0"])?;
        daemon.stop();
        Ok(())
    }
}

#[test]
fn every_drive_file_in_the_fixtures_enables_moves_and_disables() {
    let Some(dir) = ecmxf_e2e::fixtures_dir() else { return };
    let catalog = Catalog::scan_with_incoming(&dir).unwrap();
    let drives = drives(&catalog);
    let failures: Vec<String> = drives.iter().filter_map(|(d, cw, sw)| move_one(d, *cw, *sw).err()).collect();
    eprintln!("{} drive files moved", drives.len() - failures.len());
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
