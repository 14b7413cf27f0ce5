//! Conformance through the real daemon and ecmxfctl: networks of the
//! devices ../shared/fixtures describes (every ESI device, every SII dump;
//! a file added there is picked up without code changes) run in `ecmxfd`
//! on its simulator, and every read command of ecmxfctl and every read RPC
//! answers within its deadline with what the files say: identity, name,
//! state, PDO entries with their names and types, process-image sizes,
//! object list, SII, registers; inputs flow.
//!
//! Networks: one mixed network of the first device of every file, where
//! every per-slave command runs for every slave; then each file's first
//! network of up to 24 devices / 128 bytes each way, checked through the
//! RPCs (every device of every file: ECMXF_CONFORMANCE_ALL=1). Every device
//! alone through the engine: daemon/tests/conformance.rs. Skipped without
//! the fixtures unless ECMXF_REQUIRE_FIXTURES.

use std::collections::BTreeSet;
use std::future::Future;
use std::path::Path;
use std::time::Duration;

use ecmxf_devices::catalog::{self, Catalog, CatalogDevice};
use ecmxf_devices::od::DataType;
use ecmxf_e2e::{Daemon, run};
use ecmxf_proto::v1 as pb;
use tokio_stream::StreamExt;
use tonic::transport::Channel;

/// The longest any read may take (the CLI's default call deadline).
const DEADLINE: Duration = Duration::from_secs(5);

/// A read RPC's answer within [`DEADLINE`], or what went wrong.
async fn within<T>(
    what: &str,
    call: impl Future<Output = Result<tonic::Response<T>, tonic::Status>>,
) -> Result<T, String> {
    match tokio::time::timeout(DEADLINE, call).await {
        Ok(Ok(r)) => Ok(r.into_inner()),
        Ok(Err(s)) => Err(format!("{what}: {:?} {}", s.code(), s.message())),
        Err(_) => Err(format!("{what}: no answer within {DEADLINE:?}")),
    }
}

/// The proto's data type for a device's (the proto numbers are the CoE
/// codes; BITn is shown as an unsigned byte).
fn pb_type(t: DataType) -> i32 {
    match t {
        DataType::Bits(_) => pb::DataType::Unsigned8 as i32,
        t => i32::from(t.code()),
    }
}

/// Starts the daemon on these devices (the simulator's network file in
/// `dir`); the daemon is configured with each ESI device's file, to name
/// and type its objects.
fn start(dir: &Path, devices: &[&CatalogDevice]) -> Daemon {
    let (link, slaves) = ecmxf_e2e::catalog_network(dir, devices);
    Daemon::binary_with_config(&ecmxf_e2e::config_with_cycle(&link, "sync0_us = 1000\n", &slaves))
}

/// Every read RPC, for the network and for each slave; an error per
/// disagreement, naming the device.
async fn rpcs(ch: Channel, devices: &[&CatalogDevice]) -> Vec<String> {
    let mut failures = Vec::new();
    let mut fail = |r: Result<(), String>| {
        if let Err(e) = r {
            failures.push(e);
        }
    };
    fail(network_rpcs(ch.clone(), devices).await);
    let mapping = within(
        "GetMapping",
        pb::process_data_client::ProcessDataClient::new(ch.clone()).get_mapping(pb::GetMappingRequest { slave: None }),
    )
    .await;
    let slaves =
        within("ListSlaves", pb::slaves_client::SlavesClient::new(ch.clone()).list_slaves(pb::ListSlavesRequest {}))
            .await;
    for (at, d) in devices.iter().enumerate() {
        let at = at as u32;
        let r = async {
            let s = slaves.as_ref()?.slaves.get(at as usize).ok_or("not listed by ListSlaves")?;
            let found = (s.vendor_id, s.product_code, s.revision);
            if found != (d.vendor, d.product, d.revision) {
                return Err(format!("ListSlaves: identity {found:#x?}"));
            }
            if !d.name.is_empty() && s.name != d.name {
                return Err(format!("ListSlaves: name {:?}, the file says {:?}", s.name, d.name));
            }
            if (s.output_bytes as usize, s.input_bytes as usize) != (d.rx_bytes(), d.tx_bytes()) {
                return Err(format!("ListSlaves: {} out / {} in bytes", s.output_bytes, s.input_bytes));
            }
            let m = mapping.as_ref()?.slaves.iter().find(|m| m.slave == at).ok_or("no GetMapping entry")?;
            check_mapping(m, d)?;
            slave_rpcs(ch.clone(), at, d).await
        }
        .await;
        if let Err(e) = r {
            failures.push(format!("{} (slave {at}): {e}", d.what));
        }
    }
    failures
}

/// The network's read RPCs: sizes, health, and what runs without slaves.
async fn network_rpcs(ch: Channel, devices: &[&CatalogDevice]) -> Result<(), String> {
    use pb::master_client::MasterClient;
    use pb::process_data_client::ProcessDataClient;
    let mut master = MasterClient::new(ch.clone());
    within("GetInfo", master.get_info(pb::GetInfoRequest {})).await?;
    let layout = within("GetLayout", ProcessDataClient::new(ch.clone()).get_layout(pb::GetLayoutRequest {})).await?;
    let rx: usize = devices.iter().map(|d| d.rx_bytes()).sum();
    let tx: usize = devices.iter().map(|d| d.tx_bytes()).sum();
    if (layout.output_bytes as usize, layout.input_bytes as usize) != (rx, tx) {
        return Err(format!(
            "GetLayout: {}/{} bytes, the files make {rx}/{tx}",
            layout.output_bytes, layout.input_bytes
        ));
    }
    if tx > 0 {
        let mut stream = within(
            "StreamInputs",
            ProcessDataClient::new(ch.clone()).stream_inputs(pb::StreamInputsRequest::default()),
        )
        .await?;
        for n in 0..3 {
            match tokio::time::timeout(DEADLINE, stream.next()).await {
                Ok(Some(Ok(_))) => {}
                other => return Err(format!("StreamInputs: sample {n}: {other:?}")),
            }
        }
    }
    let status = within("GetStatus", master.get_status(pb::GetStatusRequest {})).await?;
    if !status.process_data_flowing {
        return Err(format!("GetStatus: process data not flowing: {}", status.health));
    }
    within("ReadOutputs", ProcessDataClient::new(ch.clone()).read_outputs(pb::ReadOutputsRequest::default())).await?;
    let mut diag = pb::diagnostics_client::DiagnosticsClient::new(ch.clone());
    within("GetEmergencies", diag.get_emergencies(pb::GetEmergenciesRequest::default())).await?;
    within("GetCounters", diag.get_counters(pb::GetCountersRequest::default())).await?;
    within("ListAxes", pb::cia402_client::Cia402Client::new(ch.clone()).list_axes(pb::ListAxesRequest::default()))
        .await?;
    let mut io = pb::peripherals_client::PeripheralsClient::new(ch.clone());
    within("GetGpio", io.get_gpio(pb::GetGpioRequest {})).await?;
    within("ReadAdc", io.read_adc(pb::ReadAdcRequest { differential: false })).await?;
    let state =
        within("GetState", pb::state_client::StateClient::new(ch).get_state(pb::GetStateRequest { slave: None }))
            .await?;
    if state.state != pb::EcatState::Op as i32 || state.slaves.len() != devices.len() {
        return Err(format!("GetState: {state:?}"));
    }
    Ok(())
}

/// The slave's PDOs as GetMapping lists them against its file.
fn check_mapping(m: &pb::SlaveMapping, d: &CatalogDevice) -> Result<(), String> {
    let want = if d.coe { pb::PdoSource::Coe } else { pb::PdoSource::Sii };
    if m.source != want as i32 {
        return Err(format!("GetMapping: source {:?}, expected {want:?} ({})", m.source(), m.note));
    }
    let listed = |pdos: &[pb::Pdo]| -> Vec<pb::PdoEntry> { pdos.iter().flat_map(|p| p.entries.clone()).collect() };
    for (dir, listed, file) in [("rx", listed(&m.rx_pdos), &d.rx), ("tx", listed(&m.tx_pdos), &d.tx)] {
        let ids = |e: &pb::PdoEntry| (e.index, e.subindex, e.bit_length);
        let got: Vec<_> = listed.iter().map(ids).collect();
        let want: Vec<_> =
            file.iter().map(|e| (u32::from(e.index), u32::from(e.subindex), u32::from(e.bits))).collect();
        if got != want {
            return Err(format!("GetMapping {dir}: entries {got:x?}, the file's {want:x?}"));
        }
        for (e, f) in listed.iter().zip(file.iter()) {
            if f.index != 0 && !f.name.is_empty() && e.name != f.name {
                return Err(format!(
                    "GetMapping: {:#06x}:{:02x} named {:?}, the file {:?}",
                    e.index, e.subindex, e.name, f.name
                ));
            }
            let declared = d.types.iter().find(|(k, _)| *k == (f.index, f.subindex)).map(|(_, t)| pb_type(*t));
            if let Some(t) = declared.filter(|t| *t != e.data_type) {
                return Err(format!(
                    "GetMapping: {:#06x}:{:02x} typed {:?}, the file {t}",
                    e.index,
                    e.subindex,
                    e.data_type()
                ));
            }
        }
    }
    Ok(())
}

/// One slave's read RPCs.
async fn slave_rpcs(ch: Channel, at: u32, d: &CatalogDevice) -> Result<(), String> {
    let state = within(
        "GetState",
        pb::state_client::StateClient::new(ch.clone()).get_state(pb::GetStateRequest { slave: Some(at) }),
    )
    .await?;
    if state.state != pb::EcatState::Op as i32 {
        return Err(format!("GetState: {:?} ({})", state.state(), state.al_status_text));
    }
    let mut sii = pb::sii_client::SiiClient::new(ch.clone());
    let decoded = within("Sii.Decode", sii.decode(pb::SiiDecodeRequest { slave: at })).await?;
    if (decoded.vendor_id, decoded.product_code, decoded.revision) != (d.vendor, d.product, d.revision) {
        return Err(format!(
            "Sii.Decode: identity {:#x}/{:#x}/{:#x}",
            decoded.vendor_id, decoded.product_code, decoded.revision
        ));
    }
    if !d.name.is_empty() && decoded.name != d.name {
        return Err(format!("Sii.Decode: name {:?}, the file says {:?}", decoded.name, d.name));
    }
    let words = within("Sii.Read", sii.read(pb::SiiReadRequest { slave: at, word: 8, count: 2 })).await?;
    if words.data != d.vendor.to_le_bytes() {
        return Err(format!("Sii.Read: words 8..10 {:02x?}, the vendor id is {:#x}", words.data, d.vendor));
    }
    let al = within(
        "ReadRegisters",
        pb::registers_client::RegistersClient::new(ch.clone()).read_registers(pb::ReadRegistersRequest {
            slave: at,
            address: 0x130,
            length: 2,
        }),
    )
    .await?;
    if al.data.first() != Some(&8) {
        return Err(format!("ReadRegisters: AL status 0x130 = {:02x?}, not OP", al.data));
    }
    if !d.coe {
        return Ok(());
    }
    let mut sdo = pb::sdo_client::SdoClient::new(ch.clone());
    for (sub, want) in [(1u32, d.vendor), (2, d.product), (3, d.revision)] {
        let up = within(
            "Sdo.Upload",
            sdo.upload(pb::SdoUploadRequest { slave: at, index: 0x1018, subindex: sub, ..Default::default() }),
        )
        .await?;
        if up.raw != want.to_le_bytes() {
            return Err(format!("Sdo.Upload 0x1018:{sub:02x} = {:02x?}, the file says {want:#x}", up.raw));
        }
    }
    // With a Dictionary in the file, the file's list (the device's own,
    // read with SDO Information, is checked in device_dictionary.rs).
    let source = if d.objects.is_empty() { pb::DictionarySource::Unspecified } else { pb::DictionarySource::Esi };
    let ask = pb::ListObjectsRequest { slave: at, source: source as i32 };
    let objects = within("Sdo.ListObjects", sdo.list_objects(ask)).await?;
    let listed: BTreeSet<u16> = objects.entries.iter().map(|e| e.index as u16).collect();
    if d.objects.is_empty() {
        if !listed.contains(&0x1018) {
            return Err(format!("Sdo.ListObjects (probed) lacks 0x1018: {listed:x?}"));
        }
    } else {
        let want: BTreeSet<u16> = d.objects.iter().copied().collect();
        if objects.source != pb::DictionarySource::Esi as i32 || listed != want {
            let (missing, extra): (Vec<_>, Vec<_>) =
                (want.difference(&listed).collect(), listed.difference(&want).collect());
            return Err(format!(
                "Sdo.ListObjects ({:?}): missing {missing:x?}, not in the file {extra:x?}",
                objects.source()
            ));
        }
    }
    Ok(())
}

/// Every read command of ecmxfctl: the network's, and (`per_slave`) each
/// slave's; an error per command that fails or disagrees with the files.
fn ctl_reads(d: &Daemon, devices: &[&CatalogDevice], per_slave: bool) -> Vec<String> {
    let failures = std::cell::RefCell::new(Vec::new());
    let run = |args: &[&str], ok: &[i32]| -> Option<serde_json::Value> {
        let out = d.ctl(args);
        if !ok.contains(&out.code) {
            failures.borrow_mut().push(format!(
                "ecmxfctl {}: exit {}: {}{}",
                args.join(" "),
                out.code,
                out.stdout,
                out.stderr
            ));
            return None;
        }
        serde_json::from_str(&out.stdout).ok()
    };
    for cmd in [
        &["--json", "master"][..],
        &["--json", "states"],
        &["--json", "emergencies"],
        &["--json", "data"],
        &["--json", "data", "--raw"],
        &["--json", "gpio", "get"],
        &["--json", "adc"],
        &["--json", "qei", "read"],
        &["top", "--once"],
        &["events", "--for", "100ms"],
    ] {
        run(cmd, &[0]);
    }
    // Hundreds of slaves at a 1 ms cycle on a shared 2-core host: the chip
    // may drop an input frame now and then, which health reports for a
    // while. That is what diag must say then; anything else is a failure.
    let diag = d.ctl(&["diag"]);
    if !diag.healthy_but_for_passing_trouble() {
        failures.borrow_mut().push(format!("ecmxfctl diag: exit {}: {}{}", diag.code, diag.stdout, diag.stderr));
    }
    if devices.iter().any(|d| d.tx_bytes() > 0) {
        run(&["watch", "-n", "2", "-i", "10ms"], &[0]);
    }
    if let Some(v) = run(&["--json", "slaves", "-v"], &[0]) {
        for (at, d) in devices.iter().enumerate() {
            let s = &v["slaves"][at];
            if s["vendor_id"] != d.vendor || s["product_code"] != d.product || s["revision"] != d.revision {
                failures.borrow_mut().push(format!("{} (slave {at}): ecmxfctl slaves: {s}", d.what));
            }
        }
    }
    if let Some(v) = run(&["--json", "pdos"], &[0]) {
        for (at, d) in devices.iter().enumerate() {
            let entries = |dir: &str| -> usize {
                v["slaves"][at][dir]
                    .as_array()
                    .map_or(0, |p| p.iter().map(|p| p["entries"].as_array().map_or(0, Vec::len)).sum())
            };
            if (entries("rx_pdos"), entries("tx_pdos")) != (d.rx.len(), d.tx.len()) {
                failures.borrow_mut().push(format!("{} (slave {at}): ecmxfctl pdos: {}", d.what, v["slaves"][at]));
            }
        }
    }
    if !per_slave {
        return failures.into_inner();
    }
    for (at, dev) in devices.iter().enumerate() {
        let p = at.to_string();
        if let Some(v) = run(&["--json", "sii", "decode", "-p", &p], &[0]) {
            if v["product_code"] != dev.product {
                failures
                    .borrow_mut()
                    .push(format!("{} (slave {at}): ecmxfctl sii decode: {}", dev.what, v["product_code"]));
            }
        }
        run(&["sii", "read", "-p", &p, "--count", "8"], &[0]);
        run(&["--json", "reg", "read", "-p", &p, "0x130", "--type", "uint16"], &[0]);
        if dev.coe {
            if let Some(v) = run(&["--json", "upload", "-p", &p, "0x1018", "1"], &[0]) {
                if v["value"] != dev.vendor {
                    failures.borrow_mut().push(format!("{} (slave {at}): ecmxfctl upload 0x1018 1: {v}", dev.what));
                }
            }
            run(&["--json", "sdos", "-p", &p], &[0]);
        }
    }
    failures.into_inner()
}

/// Runs one network through the daemon: every read RPC and command.
fn check(label: &str, devices: &[&CatalogDevice], per_slave: bool) -> Vec<String> {
    let mut failures = Vec::new();
    let dir = ecmxf_e2e::temp_dir("conformance");
    run(async {
        let mut d = start(&dir, devices);
        let ch = d.connect().await;
        failures.extend(rpcs(ch, devices).await);
        failures.extend(ctl_reads(&d, devices, per_slave));
        let log = d.log();
        // One line opens each spell of alarms (its count follows when it ends).
        let dry: Vec<&str> = log.lines().filter(|l| l.contains("ran dry: slaves got")).collect();
        if dry.len() > 1 {
            failures.push(format!("{label}: the log repeats \"ran dry\":\n{}", dry.join("\n")));
        }
    });
    let _ = std::fs::remove_dir_all(&dir);
    failures
}

#[test]
fn fixture_networks_answer_every_read_command_and_rpc_with_what_their_files_say() {
    let Some(dir) = ecmxf_e2e::fixtures_dir() else { return };
    let catalog = Catalog::scan_with_incoming(&dir).unwrap();
    // In catalogue order: a file's devices are together.
    let devices: Vec<CatalogDevice> = catalog.devices.into_iter().filter(|d| d.has_process_data()).collect();
    let mut by_file: Vec<&[CatalogDevice]> = Vec::new();
    let mut start = 0;
    for i in 1..=devices.len() {
        if i == devices.len() || devices[i].origin.file() != devices[start].origin.file() {
            by_file.push(&devices[start..i]);
            start = i;
        }
    }
    // One device of every file with every per-slave command, then each
    // file's first network (all of them: ECMXF_CONFORMANCE_ALL=1).
    let mut networks: Vec<(String, Vec<&CatalogDevice>, bool)> =
        vec![(format!("one device of each of {} files", by_file.len()), by_file.iter().map(|f| &f[0]).collect(), true)];
    let all = std::env::var_os("ECMXF_CONFORMANCE_ALL").is_some();
    for file in &by_file {
        for group in catalog::networks(file, 24, 128).into_iter().take(if all { usize::MAX } else { 1 }) {
            let label = format!("{} ({} devices)", group[0].origin.file().display(), group.len());
            networks.push((label, group.iter().collect(), false));
        }
    }
    let started = std::time::Instant::now();
    let (mut failures, mut checked) = (Vec::new(), 0);
    for (label, group, per_slave) in &networks {
        let f = check(label, group, *per_slave);
        eprintln!("{label}: {}", if f.is_empty() { "ok".to_string() } else { format!("{} failures", f.len()) });
        checked += group.len();
        failures.extend(f);
    }
    eprintln!(
        "{} networks, {checked} slaves through ecmxfd and ecmxfctl ({:.1} s)",
        networks.len(),
        started.elapsed().as_secs_f64()
    );
    assert!(failures.is_empty(), "{} disagreements:\n{}", failures.len(), failures.join("\n"));
}
