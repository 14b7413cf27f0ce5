//! Conformance over every device description in ../shared/fixtures and its
//! incoming/ folder: each
//! device of every ESI file, and every SII dump, alone on the simulator,
//! through the daemon's engine as it runs in production. Files added there
//! are picked up without code changes. Per device:
//! - the network reaches OP and input frames flow;
//! - the slave reports the identity the file gives;
//! - its process data is as many bytes as the file's default assignment;
//! - `Master::slave_pdos` lists exactly the file's PDO entries (index,
//!   subindex, bits), from CoE when the device has it, else from its SII,
//!   with the names and types the file declares.
//!
//! A device that cannot be simulated (no process data at all: a coupler,
//! a bootloader entry) is named in the output with the reason. The same
//! devices as networks through the real daemon and ecmxfctl:
//! tests/tests/conformance.rs. Skipped without the fixtures unless
//! ECMXF_REQUIRE_FIXTURES is set.

mod common;
use common::fixtures;

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ecmxf_devices::catalog::{self, Catalog, CatalogDevice, CatalogEntry};
use ecmxfd::config::SlaveConfig;
use ecmxfd::master::Call;
use ecmxfd::master::Master;
use ecmxfd::master::Phase;
use ecmxfd::master::pdos::{PdoSource, SlavePdos};

/// Networks of devices in file order: up to 24 slaves and 128 bytes of
/// process data each way, a device with more alone.
/// ECMXF_CONFORMANCE_ALONE=1: every device alone (about 2 s a device).
fn networks(devices: &[CatalogDevice]) -> Vec<&[CatalogDevice]> {
    if std::env::var_os("ECMXF_CONFORMANCE_ALONE").is_some() {
        return catalog::networks(devices, 1, 0);
    }
    catalog::networks(devices, 24, 128)
}

/// Runs these devices as one network; returns an error per device that
/// disagrees with its file, naming what.
fn check(dir: &Path, devices: &[CatalogDevice]) -> Vec<String> {
    let mut config = common::simulated(dir, devices);
    config.slaves = devices
        .iter()
        .map(|d| SlaveConfig { esi: d.origin.esi().map(Path::to_path_buf), ..SlaveConfig::default() })
        .collect();
    let all = |e: String| devices.iter().map(|d| format!("{}: {e}", d.what)).collect();
    let (master, sim) = match Master::from_config(config) {
        Ok((m, Some(sim))) => (Arc::new(m), sim),
        Ok((_, None)) => return all("no simulator".into()),
        Err(e) => return all(format!("start: {e}")),
    };
    let t = Instant::now();
    while master.status().phase != Phase::Running {
        if t.elapsed() > Duration::from_secs(20) {
            let slaves: Vec<String> = sim.with_chip(|c| {
                c.net.slaves.iter().map(|s| format!("{} {:#06x}", s.esm.state, s.esm.al_status)).collect()
            });
            let why = format!(
                "not in OP after 20 s: {:?} {:?}; slaves (state, AL status): {slaves:?}",
                master.status().phase,
                master.last_error()
            );
            master.stop();
            return all(why);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut failures = Vec::new();
    if let Err(e) = flows(&master, &sim) {
        failures.extend(all(e));
    }
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    for (i, d) in devices.iter().enumerate() {
        if let Err(e) = verify(&master, &rt, i as u8, d) {
            failures.push(format!("{} (slave {i}): {e}", d.what));
        }
    }
    master.stop();
    failures
}

/// Process data moves: input frames arrive (when there are inputs), and a
/// pattern written to the outputs reaches every simulated slave (when
/// there are outputs).
fn flows(m: &Master, sim: &ecmxfd::link::sim::SimHandle) -> Result<(), String> {
    let layout = m.layout();
    if layout.tx_size > 0 {
        let frames = m.status().input_frames;
        let t = Instant::now();
        while m.status().input_frames < frames + 3 {
            if t.elapsed() > Duration::from_secs(2) {
                return Err("input frames do not flow".into());
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    if layout.rx_size > 0 {
        let pattern: Vec<u8> = (0..layout.rx_size).map(|i| (i as u8).wrapping_mul(37).wrapping_add(0x5A)).collect();
        m.write_outputs(0, &pattern).map_err(|e| format!("write outputs: {e}"))?;
        let t = Instant::now();
        loop {
            let got: Vec<u8> = sim.with_chip(|c| c.net.slaves.iter().flat_map(|s| s.outputs.clone()).collect());
            if got == pattern {
                break;
            }
            if t.elapsed() > Duration::from_secs(2) {
                let first = pattern.iter().zip(&got).position(|(a, b)| a != b).unwrap_or(got.len());
                return Err(format!(
                    "outputs written do not reach the slaves: {} bytes written, {} held, first difference at byte {first}",
                    pattern.len(),
                    got.len()
                ));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    Ok(())
}

fn verify(m: &Master, rt: &tokio::runtime::Runtime, at: u8, want: &CatalogDevice) -> Result<(), String> {
    let layout = m.layout();
    let s = layout.slaves.get(usize::from(at)).ok_or("slave not found")?;
    let found = (s.vendor_id, s.product_code, s.revision);
    if found != (want.vendor, want.product, want.revision) {
        return Err(format!("identity {found:#x?}, the file says {:#x?}", (want.vendor, want.product, want.revision)));
    }
    let bytes = (want.rx_bytes(), want.tx_bytes());
    if (s.rx_bytes, s.tx_bytes) != bytes {
        return Err(format!(
            "process data {:?} bytes (out, in), the file's PDOs make {bytes:?}",
            (s.rx_bytes, s.tx_bytes)
        ));
    }
    let pdos: SlavePdos = rt
        .block_on(m.slave_pdos(at, s.rx_bytes, s.tx_bytes, Call::anonymous(None)))
        .map_err(|e| format!("PDO listing failed: {e}"))?;
    let want_source = if want.coe { PdoSource::Coe } else { PdoSource::Sii };
    if pdos.source != want_source {
        return Err(format!("PDOs from {:?}, expected {want_source:?} ({})", pdos.source, pdos.note));
    }
    let listed = |list: &[ecmxfd::master::pdos::PdoDescription]| -> Vec<(u16, u8, u8)> {
        list.iter().flat_map(|p| p.entries.iter().map(|e| (e.index, e.subindex, e.bits))).collect()
    };
    let file =
        |list: &[CatalogEntry]| -> Vec<(u16, u8, u8)> { list.iter().map(|e| (e.index, e.subindex, e.bits)).collect() };
    if listed(&pdos.rx) != file(&want.rx) || listed(&pdos.tx) != file(&want.tx) {
        return Err(format!(
            "PDO entries differ:\n  listed rx {:x?}\n  file   rx {:x?}\n  listed tx {:x?}\n  file   tx {:x?}",
            listed(&pdos.rx),
            file(&want.rx),
            listed(&pdos.tx),
            file(&want.tx)
        ));
    }
    let named = pdos.rx.iter().chain(&pdos.tx).flat_map(|p| &p.entries);
    for (e, f) in named.zip(want.rx.iter().chain(&want.tx)) {
        // A gap (object 0) names no object; several share 0:00.
        if f.index != 0 && !f.name.is_empty() && e.name != f.name {
            return Err(format!("{:#06x}:{:02x} named {:?}, the file says {:?}", e.index, e.subindex, e.name, f.name));
        }
    }
    for e in pdos.rx.iter().chain(&pdos.tx).flat_map(|p| &p.entries) {
        if let Some((_, t)) = want.types.iter().find(|(k, _)| *k == (e.index, e.subindex)) {
            if e.data_type != Some(*t) {
                return Err(format!(
                    "{:#06x}:{:02x} typed {:?}, the file says {t:?}",
                    e.index, e.subindex, e.data_type
                ));
            }
        }
    }
    Ok(())
}

#[test]
fn every_fixture_device_alone_reaches_op_with_the_pdos_its_file_describes() {
    let Some(dir) = fixtures() else { return };
    let tmp = std::env::temp_dir().join(format!("ecmxf-conformance-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let catalog = Catalog::scan_with_incoming(&dir).unwrap();
    for skipped in &catalog.skipped {
        eprintln!("{skipped}, skipped");
    }
    let mut failed = catalog.failed.clone();
    let (mut devices, mut not_simulated) = (Vec::new(), Vec::new());
    for d in catalog.devices {
        match d.no_process_data() {
            Some(why) => not_simulated.push(format!("{}: {why}", d.what)),
            None => devices.push(d),
        }
    }
    // ECMXF_CONFORMANCE_ONLY=EL1252: only devices whose description says so.
    if let Ok(only) = std::env::var("ECMXF_CONFORMANCE_ONLY") {
        devices.retain(|d| d.what.contains(&only));
    }
    let started = Instant::now();
    for group in networks(&devices) {
        failed.extend(check(&tmp, group));
    }
    let passed = devices.len() - failed.len();
    let _ = std::fs::remove_dir_all(&tmp);
    eprintln!(
        "{passed} of {} devices reached OP with the process data and PDOs their files describe ({:.1} s)",
        devices.len(),
        started.elapsed().as_secs_f64()
    );
    for n in &not_simulated {
        eprintln!("not simulated: {n}");
    }
    assert!(failed.is_empty(), "{} devices disagree with their files:\n{}", failed.len(), failed.join("\n"));
    assert!(passed > 0, "no device was checked");
}

/// A PDO numbered where another object is (a TxPDO at 0x1018, the identity
/// object's index; seen in two-channel drives' ESI files): the simulated
/// device maps with it while CoE reads the identity object there, and the
/// daemon takes that PDO's entries from the device's description instead
/// of the identity values CoE returns, which it once took for the PDO's
/// entries. The same checks as every
/// fixture: OP, process data, the file's PDO entries.
#[test]
fn a_pdo_numbered_at_a_standard_objects_index_is_described_from_the_file() {
    let tmp = std::env::temp_dir().join(format!("ecmxf-pdo-at-1018-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let esi = r##"<EtherCATInfo><Vendor><Id>#x0000ABCD</Id></Vendor><Descriptions><Devices>
        <Device Physics="YY"><Type ProductCode="#x00001018" RevisionNo="1">TWO-CHANNEL</Type><Name>Two-channel drive</Name>
          <Sm ControlByte="#x26" Enable="1" StartAddress="#x1000" DefaultSize="128">MBoxOut</Sm>
          <Sm ControlByte="#x22" Enable="1" StartAddress="#x1080" DefaultSize="128">MBoxIn</Sm>
          <Sm ControlByte="#x64" Enable="1" StartAddress="#x1100">Outputs</Sm>
          <Sm ControlByte="#x20" Enable="1" StartAddress="#x1180">Inputs</Sm>
          <RxPdo Sm="2" Fixed="1"><Index>#x1600</Index><Name>Outputs</Name>
            <Entry><Index>#x7000</Index><SubIndex>1</SubIndex><BitLen>16</BitLen><Name>Command</Name><DataType>UINT</DataType></Entry>
          </RxPdo>
          <TxPdo Sm="3" Fixed="1"><Index>#x1a00</Index><Name>Channel 1</Name>
            <Entry><Index>#x6000</Index><SubIndex>1</SubIndex><BitLen>32</BitLen><Name>Position 1</Name><DataType>DINT</DataType></Entry>
          </TxPdo>
          <TxPdo Sm="3" Fixed="1"><Index>#x1018</Index><Name>Channel 2</Name>
            <Entry><Index>#x6010</Index><SubIndex>1</SubIndex><BitLen>32</BitLen><Name>Position 2</Name><DataType>DINT</DataType></Entry>
            <Entry><Index>#x6010</Index><SubIndex>2</SubIndex><BitLen>16</BitLen><Name>Status 2</Name><DataType>UINT</DataType></Entry>
          </TxPdo>
          <Mailbox DataLinkLayer="true"><CoE SdoInfo="true" PdoAssign="false" PdoConfig="false"/></Mailbox>
          <Eeprom><ByteSize>2048</ByteSize><ConfigData>0C0D</ConfigData></Eeprom>
        </Device></Devices></Descriptions></EtherCATInfo>"##;
    std::fs::write(tmp.join("two-channel.xml"), esi).unwrap();
    let catalog = Catalog::scan(&tmp).unwrap();
    assert_eq!(catalog.devices.len(), 1, "{:?}", catalog.skipped);
    let d = &catalog.devices[0];
    assert_eq!(d.tx_bytes(), 10, "both TxPDOs are assigned: 4 + 4 + 2 bytes");
    let failures = check(&tmp, std::slice::from_ref(d));
    let _ = std::fs::remove_dir_all(&tmp);
    assert!(failures.is_empty(), "{failures:#?}");
}
