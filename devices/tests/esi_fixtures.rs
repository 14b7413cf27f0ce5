//! The ESI files of ../shared/fixtures and its `incoming/` folder (origins
//! in its MANIFEST): each parses as a whole even where some of its devices
//! cannot be read (Beckhoff's catalogue lists passive terminals, EK0000 or
//! EL9011, without a ProductCode, and early files give PDOs by `Ref=`
//! only): those are skipped by name, the rest is usable, and a device is
//! found by the identity a slave would report.
//!
//! When the fixtures folder is absent the tests say so and pass, unless
//! ECMXF_REQUIRE_FIXTURES is set (CI sets it), where they fail.

use std::path::PathBuf;

use ecmxf_devices::esi::{EsiFile, read_xml};

mod common;
use common::fixtures;

fn esi_files(dir: &std::path::Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> =
        std::fs::read_dir(dir).map(|d| d.flatten().map(|e| e.path()).collect()).unwrap_or_default();
    files.retain(|p| {
        p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("esi_"))
            && p.extension().is_some_and(|e| e == "xml")
    });
    files.sort();
    files
}

#[test]
fn every_esi_fixture_parses_and_finds_each_device_by_its_identity() {
    let Some(dir) = fixtures() else { return };
    let mut files = esi_files(&dir);
    files.extend(esi_files(&dir.join("incoming")));
    assert!(!files.is_empty(), "no esi_*.xml in {}", dir.display());
    for path in files {
        let text = read_xml(&path).unwrap();
        let file = EsiFile::parse(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(!file.devices.is_empty(), "{}", path.display());
        for d in &file.devices {
            let found = file.for_identity(d.product_code, d.revision).unwrap();
            assert_eq!((found.product_code, found.revision), (d.product_code, d.revision), "{}", path.display());
        }
    }
}

#[test]
fn the_catalogue_without_product_codes_keeps_its_readable_devices_and_names_the_others() {
    let Some(dir) = fixtures() else { return };
    let path = dir.join("incoming/esi_beckhoff_EtherCAT_Terminals.xml");
    if !path.exists() {
        eprintln!("skipped: {} not present", path.display());
        return;
    }
    let file = EsiFile::parse(&read_xml(&path).unwrap()).unwrap();
    assert!(!file.skipped.is_empty(), "EK0000, EL0000...: no ProductCode");
    assert!(file.skipped.iter().any(|s| s.contains("ProductCode")), "{:?}", file.skipped);
    // A device without a product code matches no identity: 0 is no
    // readable device's product code here.
    assert!(file.for_identity(0, 0).is_none());
}
