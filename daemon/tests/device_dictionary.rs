//! A slave's object dictionary read from the slave itself (docs/mailbox.md; CoE
//! SDO Information through the host's mailbox channel), for every device
//! in ../shared/fixtures whose ESI has a `<Dictionary>`: simulated as its
//! file describes it, with no ESI configured in the daemon, the dictionary
//! the device describes must hold every object and entry of its file with
//! the same names, data types, sizes, access and PDO mapping flags. A
//! device whose ESI says it has no SDO Information is refused so, and not
//! asked again. Big lists come in fragments (the Elmo's hundreds of
//! objects in a 128-byte mailbox). Skipped without the fixtures unless
//! ECMXF_REQUIRE_FIXTURES is set.

mod common;
use common::fixtures;

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ecmxf_devices::catalog::{self, Catalog, CatalogDevice};
use ecmxf_devices::esi::EsiFile;
use ecmxf_devices::od::ObjectDictionary;
use ecmxfd::master::Call;
use ecmxfd::master::Master;
use ecmxfd::master::Phase;
use ecmxfd::master::device_dictionary::DictionaryError;

/// The file's dictionary of `d`, and whether the file gives it SDO Info.
fn described(d: &CatalogDevice) -> (ObjectDictionary, bool) {
    let xml = ecmxf_devices::esi::read_xml(d.origin.file()).unwrap();
    let file = EsiFile::parse(&xml).unwrap();
    let device = file.device(d.product, Some(d.revision)).unwrap();
    (device.dictionary.clone(), device.sdo_info)
}

/// Every object and entry of `file` in `device`, alike; the differences.
fn compare(file: &ObjectDictionary, device: &ObjectDictionary) -> Vec<String> {
    let mut out = Vec::new();
    for (index, want) in file.objects() {
        let Some(got) = device.object(index) else {
            out.push(format!("{index:#06x} {:?} not listed", want.name));
            continue;
        };
        if got.name != want.name {
            out.push(format!("{index:#06x} named {:?}, the file says {:?}", got.name, want.name));
        }
        for (sub, w) in &want.entries {
            let Some(g) = got.entries.get(sub) else {
                out.push(format!("{index:#06x}:{sub:02x} {:?} not listed", w.name));
                continue;
            };
            // A PDO mapping entry is 32 bits (ETG.1000.6 5.6.7.4.7); a file
            // that describes one with the mapped object's type (the Elmo
            // Gold ESI: 0x1600:03 "Controlword" UINT) is wrong there, and
            // the device holds 32 bits, under the file's name.
            let mapping = (0x1600..=0x17FF).contains(&index) || (0x1A00..=0x1BFF).contains(&index);
            if mapping && *sub > 0 && w.dtype.bits() != 32 {
                if g.name != w.name || g.dtype.bits() != 32 {
                    out.push(format!("{index:#06x}:{sub:02x}: described {:?} {:?}", g.name, g.dtype));
                }
                continue;
            }
            // A string the file gives no length (VisibleString(0)) has the
            // length of its value on the device.
            let size = g.dtype.bits() == w.dtype.bits() || (!w.dtype.is_fixed_size() && w.dtype.bits() == 0);
            let same = (g.name == w.name, g.dtype.code() == w.dtype.code(), size);
            if same != (true, true, true) || g.access != w.access || g.mappable != w.mappable {
                out.push(format!(
                    "{index:#06x}:{sub:02x}: described {:?} {:?} {:?} {:?}, the file says {:?} {:?} {:?} {:?}",
                    g.name, g.dtype, g.access, g.mappable, w.name, w.dtype, w.access, w.mappable
                ));
            }
        }
    }
    out
}

fn check(dir: &Path, devices: &[CatalogDevice]) -> Vec<String> {
    let mut config = common::simulated(dir, devices);
    config.state_dir = Some(dir.join("state"));
    let master = match Master::from_config(config) {
        Ok((m, _)) => Arc::new(m),
        Err(e) => return vec![format!("start: {e}")],
    };
    let t = Instant::now();
    while master.status().phase != Phase::Running {
        if t.elapsed() > Duration::from_secs(20) {
            master.stop();
            return vec![format!("not in OP after 20 s: {:?}", master.last_error())];
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    // All slaves at once, as clients would ask: each one's exchanges wait on
    // its own mailbox, the slot serves them in turn.
    let started = Instant::now();
    let reads = rt.block_on(async {
        let mut set = tokio::task::JoinSet::new();
        for i in 0..devices.len() {
            let m = Arc::clone(&master);
            set.spawn(async move { (i, m.device_dictionary(i as u8, Call::anonymous(None)).await) });
        }
        let mut reads: Vec<_> = set.join_all().await;
        reads.sort_by_key(|(i, _)| *i);
        reads
    });
    eprintln!("{} slaves described in {:.1?}", devices.len(), started.elapsed());
    let mut failures = Vec::new();
    for ((i, read), d) in reads.into_iter().zip(devices) {
        let (file, sdo_info) = described(d);
        let _ = i;
        match (read, sdo_info) {
            (Ok(dictionary), true) => {
                let device = dictionary.to_od();
                eprintln!(
                    "{}: {} objects described ({} in the file)",
                    d.what,
                    device.objects().count(),
                    file.objects().count()
                );
                failures.extend(compare(&file, &device).into_iter().map(|e| format!("{}: {e}", d.what)));
            }
            (Err(DictionaryError::NotSupported(_)), false) => {
                eprintln!("{}: no SDO Information, as its file says", d.what)
            }
            (Ok(_), false) => failures.push(format!("{}: described itself, but its file gives no SDO Info", d.what)),
            (Err(e), _) => failures.push(format!("{}: {e}", d.what)),
        }
    }
    master.stop();
    failures
}

#[test]
fn every_fixture_device_with_a_dictionary_describes_it_as_its_file_does() {
    let Some(dir) = fixtures() else { return };
    let tmp = std::env::temp_dir().join(format!("ecmxf-sdo-info-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    // The fixtures proper: incoming/ adds some sixty more Beckhoff devices
    // of the same kinds (ECMXF_SDO_INFO_INCOMING=1 checks them too).
    let catalog = if std::env::var_os("ECMXF_SDO_INFO_INCOMING").is_some() {
        Catalog::scan_with_incoming(&dir).unwrap()
    } else {
        Catalog::scan(&dir).unwrap()
    };
    let devices: Vec<CatalogDevice> = catalog.devices.into_iter().filter(|d| !d.objects.is_empty()).collect();
    assert!(devices.len() >= 10, "fixture devices with a Dictionary: {}", devices.len());
    let mut failures = Vec::new();
    // The networks side by side, each its own simulator and daemon: the
    // time goes into waiting on the slot, not the CPU.
    let networks = catalog::networks(&devices, 24, 128);
    std::thread::scope(|s| {
        let running: Vec<_> = networks
            .iter()
            .enumerate()
            .map(|(k, network)| {
                let dir = tmp.join(k.to_string());
                std::fs::create_dir_all(&dir).unwrap();
                s.spawn(move || check(&dir, network))
            })
            .collect();
        for r in running {
            failures.extend(r.join().expect("a network's check panicked"));
        }
    });
    let _ = std::fs::remove_dir_all(&tmp);
    assert!(failures.is_empty(), "{} differences:\n{}", failures.len(), failures.join("\n"));
}
