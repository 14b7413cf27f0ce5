//! An ENI file as the network description (`eni = "FILE"`, docs/eni.md): the
//! demo network's ENI (config/demo-network.eni.xml, TwinCAT's conventions)
//! brings the simulated network to OP with the slaves' names from the file
//! and the drive's CoE init commands written at their transitions in the
//! file's order (the value read back in OP is the SO command's, not the PS
//! one's; the disabled command is not written); process data flows.
//! `ecmxfd --check-config` lists what an ENI applies and every element it
//! does not, for the real TwinCAT export and SOEM's sample; a malformed ENI
//! is refused naming the element and its line, and nothing runs.

use std::process::Command;
use std::time::Duration;

use ecmxf_e2e::{Daemon, by_entry, config, config_with_cycle, daemon_binary, repo, run, temp_dir};
use ecmxf_proto::v1 as pb;

fn check_config(text: &str) -> (i32, String) {
    let dir = temp_dir("eni-check");
    let file = dir.join("ecmxfd.toml");
    std::fs::write(&file, text).unwrap();
    let out = Command::new(daemon_binary()).arg("--check-config").arg(&file).output().expect("run ecmxfd");
    let _ = std::fs::remove_dir_all(&dir);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.code().unwrap_or(-1), text)
}

/// The network is in OP and input frames arrive (not only a state).
async fn in_op_with_inputs_flowing(ch: tonic::transport::Channel) {
    let mut m = pb::master_client::MasterClient::new(ch);
    let frames = |s: pb::MasterStatus| s.counters.map_or(0, |c| c.input_frames);
    let before = frames(m.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner());
    tokio::time::sleep(Duration::from_millis(100)).await;
    let status = m.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
    assert_eq!(status.ecat_state, pb::EcatState::Op as i32, "{status:?}");
    assert!(frames(status) > before, "input frames flow");
}

#[test]
fn the_demo_networks_eni_brings_it_up_with_its_init_commands_in_order() {
    run(async {
        let eni = repo().join("config/demo-network.eni.xml");
        let text = format!("eni = \"{}\"\n{}", eni.display(), config("backend = \"sim\"", ""));
        let mut d = Daemon::with_config(&text);
        let ch = d.connect().await;
        let slaves = pb::slaves_client::SlavesClient::new(ch.clone())
            .list_slaves(pb::ListSlavesRequest {})
            .await
            .unwrap()
            .into_inner()
            .slaves;
        // The ENI's names and identities are what the configuration expects
        // (and they match what the scan found).
        let expected: Vec<(&str, u32)> =
            slaves.iter().filter_map(|s| s.expected.as_ref().map(|e| (e.name.as_str(), e.vendor_id))).collect();
        assert_eq!(expected, [("Core", 0x89A), ("Drive", 0x59D), ("IO", 0x1337)], "{slaves:?}");
        assert!(slaves.iter().all(|s| s.mismatch.is_empty()), "{slaves:?}");
        let mut sdo = pb::sdo_client::SdoClient::new(ch.clone());
        let mut read = async |index: u32| {
            let r = sdo.upload(pb::SdoUploadRequest { slave: 1, index, subindex: 0, ..Default::default() }).await;
            r.unwrap_or_else(|e| panic!("{index:#06x}: {e:?}")).into_inner().raw
        };
        assert_eq!(read(0x6072).await, vec![0x20, 0x03], "IP: max torque 800");
        assert_eq!(read(0x6085).await, 1_000_000u32.to_le_bytes(), "PS: quick stop deceleration");
        assert_eq!(read(0x6083).await, 0x2222u32.to_le_bytes(), "SO after PS: the acceleration is the SO value");
        assert_ne!(read(0x605A).await, vec![0x06, 0x00], "the disabled command was written");
        // The ProcessImage's names reach the values: the IO slave's output,
        // written by its variable name, comes back on its input, streamed
        // under the name it was asked for.
        let mut pd = pb::process_data_client::ProcessDataClient::new(ch.clone());
        let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 5000 }).await.unwrap();
        let write = by_entry("IO.Outputs.Outputs 1-8", pb::value::Kind::Unsigned(0x5A));
        pd.write_outputs(pb::WriteOutputsRequest { lease_id: lease.into_inner().id, writes: vec![write] })
            .await
            .unwrap();
        let name = "IO.Inputs.Inputs 1-8".to_string();
        let req = pb::StreamInputsRequest { entries: vec![name.clone()], decimation: 1, on_change: false };
        let mut samples = pd.stream_inputs(req).await.unwrap().into_inner();
        let mut seen = None;
        for _ in 0..2000 {
            let s = samples.message().await.unwrap().expect("a sample");
            assert_eq!(s.values[0].name, name, "named as asked for");
            seen = s.values[0].value.clone().and_then(|v| v.kind);
            if seen == Some(pb::value::Kind::Unsigned(0x5A)) {
                break;
            }
        }
        assert_eq!(seen, Some(pb::value::Kind::Unsigned(0x5A)), "the IO slave loops its output back");
        in_op_with_inputs_flowing(ch).await;
        d.stop();
    });
}

#[test]
fn check_config_says_what_an_eni_applies_and_what_it_does_not() {
    let dir = temp_dir("eni-check-nets");
    let Some((twincat, link)) = ecmxf_e2e::twincat_network(&dir) else { return };
    let (code, text) = check_config(&format!("version = 1\neni = \"{}\"\n[link]\n{link}\n", twincat.display()));
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("5 expected slaves"), "{text}");
    assert!(text.contains(r#"slave 1 "WheelRearLeft" (line 784:"#), "{text}");
    assert!(text.contains(r#"): 12 CoE init commands written"#), "{text}");
    assert!(
        text.contains(
            "InitCmds (register) (49): 3 replayed by raw datagram (watchdogs: 0x0400 at IP, 0x0410 at IP, 0x0420 at IP)"
        ),
        "{text}"
    );
    assert!(text.contains("9 sync managers: the chip's ECAT_INIT"), "{text}");
    assert!(text.contains("eni: ProcessImage (1) applied as names"), "{text}");
    assert!(text.contains(r#"slave 0 "Imu" (line 159:"#) && text.contains("): no DC block: runs without DC"), "{text}");
    assert!(text.contains("5 expected slaves, 10000 us cycle"), "the ENI's DC cycle: {text}");
    // The ENI's 5 slaves on the demo network's 3: bring-up would refuse
    // it for ever, so the check does, naming both counts and the source.
    let (code, text) =
        check_config(&format!("version = 1\neni = \"{}\"\n[link]\nbackend = \"sim\"\n", twincat.display()));
    assert_eq!(code, 2, "{text}");
    assert!(text.contains(&format!("the ENI {} lists 5", twincat.display())), "{text}");
    assert!(text.contains("the demo network (no link.network given) has 3"), "{text}");
    // SOEM's sample on a simulated network of its own two slaves, each
    // taken from the ENI by position.
    let Some(soem) = ecmxf_e2e::fixture("eni_soem_sample.xml") else { return };
    let net = dir.join("soem");
    std::fs::create_dir_all(&net).unwrap();
    let slaves =
        format!("[[slave]]\neni = \"{0}\"\neni_slave = 1\n[[slave]]\neni = \"{0}\"\neni_slave = 2\n", soem.display());
    let link = ecmxf_e2e::sim_network(&net, &slaves);
    let (code, text) = check_config(&format!("version = 1\neni = \"{}\"\n[link]\n{link}\n", soem.display()));
    assert_eq!(code, 0, "{text}");
    // The link budget is the ENI's own frames on the link it names: two
    // networks, two budgets, on a chip as on the simulator.
    let budget = |eni: &std::path::Path| {
        let spidev = "backend = \"spidev\"\ndevice = \"/dev/spidev0.0\"\nspi_hz = 20000000\n";
        let (code, text) = check_config(&format!("version = 1\neni = \"{}\"\n[link]\n{spidev}", eni.display()));
        assert_eq!(code, 0, "{text}");
        let line = text.lines().find(|l| l.starts_with("link budget: the process data needs")).map(str::to_owned);
        line.unwrap_or_else(|| panic!("no budget for {}: {text}", eni.display()))
    };
    // An ENI of the IMU and two drives only: fewer frames, another budget.
    let fewer = dir.join("fewer.xml");
    let xml = std::fs::read_to_string(&twincat).unwrap();
    let (head, rest) = xml.split_at(xml.find("<Slave>").expect("a Slave element"));
    let slaves: Vec<&str> = rest.split_inclusive("</Slave>").collect();
    let tail = rest[rest.rfind("</Slave>").unwrap() + "</Slave>".len()..].to_string();
    std::fs::write(&fewer, format!("{head}{}{tail}", slaves[..3].concat())).unwrap();
    assert_ne!(budget(&twincat), budget(&fewer), "budgets from each ENI's own frames");
    // SOEM's sample describes mailboxes only: its frames are the slaves'.
    let spidev = "backend = \"spidev\"\ndevice = \"/dev/spidev0.0\"\nspi_hz = 20000000\n";
    let (code, text) = check_config(&format!("version = 1\neni = \"{}\"\n[link]\n{spidev}", soem.display()));
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("link budget: not known offline"), "{text}");
    assert!(text.contains("has Ccs 2 with data: written, as SOEM's files mean it"), "{text}");
}

/// Without an ENI, the `[[slave]]` list is the network: one Elmo drive
/// and seven give two budgets from the ESI's assigned PDOs, and a slave
/// only the bus can describe is named as the reason there is none.
#[test]
fn check_config_budgets_a_slave_list_from_its_devices_or_names_the_slave_it_cannot() {
    let Some(elmo) = ecmxf_e2e::fixture("esi_elmo_gold_Elmo_ECAT_00010420_V11.xml") else { return };
    let spidev = "[link]\nbackend = \"spidev\"\ndevice = \"/dev/spidev0.0\"\nspi_hz = 20000000\n";
    let drive = format!("[[slave]]\nesi = \"{}\"\nproduct_code = 0x30924\nrevision = 0x10420\n", elmo.display());
    let budget = |slaves: &str| {
        let (code, text) = check_config(&format!("version = 1\n{spidev}{slaves}"));
        assert_eq!(code, 0, "{text}");
        text.lines().find(|l| l.starts_with("link budget:")).map(str::to_owned).unwrap_or_else(|| panic!("{text}"))
    };
    let (one, seven) = (budget(&drive), budget(&drive.repeat(7)));
    assert!(one.starts_with("link budget: the process data needs"), "{one}");
    assert!(seven.starts_with("link budget: the process data needs"), "{seven}");
    assert_ne!(one, seven, "budgets from each list's own devices");
    let unknown = budget(&format!("{drive}[[slave]]\nname = \"coupler\"\nvendor_id = 2\n"));
    assert!(
        unknown.contains("not known offline (slave[1] (coupler) has neither an ESI nor a PDO mapping"),
        "{unknown}"
    );
}

#[test]
fn a_malformed_eni_is_refused_naming_element_and_line() {
    let dir = temp_dir("eni-bad");
    let good = std::fs::read_to_string(repo().join("config/demo-network.eni.xml")).unwrap();
    for (what, from, to, says) in [
        (
            "Ccs out of range",
            "<Ccs>1</Ccs>\n\t\t\t\t\t\t\t<Index>24690",
            "<Ccs>4</Ccs>\n\t\t\t\t\t\t\t<Index>24690",
            "Ccs 4 is neither",
        ),
        ("a bad number", "<VendorId>1437</VendorId>", "<VendorId>14x37</VendorId>", "Slave[1]/Info/VendorId \"14x37\""),
        ("a truncated file", "</EtherCATConfig>", "", "not well-formed XML"),
    ] {
        assert!(good.contains(from), "{what}: the ENI changed");
        let file = dir.join("bad.eni.xml");
        std::fs::write(&file, good.replace(from, to)).unwrap();
        let (code, text) =
            check_config(&format!("version = 1\neni = \"{}\"\n[link]\nbackend = \"sim\"\n", file.display()));
        assert_eq!(code, 2, "{what}: {text}");
        assert!(text.contains("eni") && text.contains(says) && text.contains("line "), "{what}: {text}");
    }
    // Beside [[slave]] entries: as many, and the same identities.
    let eni = repo().join("config/demo-network.eni.xml");
    let text =
        format!("version = 1\neni = \"{}\"\n[link]\nbackend = \"sim\"\n[[slave]]\nname = \"x\"\n", eni.display());
    let (code, out) = check_config(&text);
    assert_eq!(code, 2, "{out}");
    assert!(out.contains("1 [[slave]] entries beside an ENI that lists 3 slaves"), "{out}");
    let text = format!(
        "version = 1\neni = \"{}\"\n[link]\nbackend = \"sim\"\n[[slave]]\n[[slave]]\nvendor_id = 0x59e\n[[slave]]\n",
        eni.display()
    );
    let (code, out) = check_config(&text);
    assert_eq!(code, 2, "{out}");
    assert!(out.contains("slave[1].vendor_id") && out.contains("0x0000059d"), "{out}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Without an ENI, a `[[slave]] esi` device's own CoE init commands are
/// written as a configuration tool would write them into one: the Elmo
/// Gold's ESI sets the mode of operation (0x6060 = 8) and the cycle time
/// (0x60C2:01 = 2) at PRE-OP -> SAFE-OP, before the entry's own
/// `[[slave.sdo]]` (which here sets the mode to 9); `esi_init_cmds = false`
/// switches them off.
#[test]
fn an_esi_devices_init_commands_are_written_before_the_entrys_own_sdos() {
    let Some(elmo) = ecmxf_e2e::fixture("esi_elmo_gold_Elmo_ECAT_00010420_V11.xml") else { return };
    run(async {
        let dir = temp_dir("esi-init");
        let device = format!("esi = \"{}\"\nproduct_code = 0x30924\n", elmo.display());
        let link = ecmxf_e2e::sim_network(&dir, &format!("[[slave]]\n{device}"));
        for (switch, mode, cycle) in [("", 9u8, Some(2u8)), ("esi_init_cmds = false\n", 9, None)] {
            let slave =
                format!("[[slave]]\n{device}{switch}  [[slave.sdo]]\n  index = 0x6060\n  value = 9\n  size = 1\n");
            let mut d = Daemon::with_config(&config(&link, &slave));
            let ch = d.connect().await;
            let mut sdo = pb::sdo_client::SdoClient::new(ch);
            let mut read = async |index: u32, subindex: u32| {
                let r = sdo.upload(pb::SdoUploadRequest { slave: 0, index, subindex, ..Default::default() }).await;
                r.unwrap_or_else(|e| panic!("{index:#06x}:{subindex}: {e:?}")).into_inner().raw
            };
            assert_eq!(read(0x6060, 0).await, vec![mode], "{switch}: the entry's own SDO comes last");
            let got = read(0x60C2, 1).await;
            match cycle {
                Some(c) => assert_eq!(got, vec![c], "the ESI's init command"),
                None => assert_ne!(got, vec![2], "esi_init_cmds = false: not written"),
            }
            d.stop();
        }
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// The TwinCAT export, the file an ENI user actually has: the network it describes
/// comes up in OP; each drive's 12 init commands ran in the file's order
/// (the assignment 0x1C12 = {0x1601} can only be written count-0 first,
/// entry, count: the simulated drive refuses any other order, as a real
/// one does); every variable of the ProcessImage names the entry at its
/// offset from its slave's start, with its size (no layout notes); the
/// outputs written by variable name reach that drive; input frames flow.
#[test]
fn the_twincat_export_brings_its_network_up_with_its_layout() {
    let dir = temp_dir("eni-twincat");
    let Some((eni_path, link)) = ecmxf_e2e::twincat_network(&dir) else { return };
    let eni = ecmxf_devices::eni::Eni::load(&eni_path).unwrap();
    run(async {
        // The file's 10 ms cycle with the tests' deep FIFO marks would hold
        // a write back for seconds: a budget of five cycles.
        let cycle = "output_latency_us = 50000\n";
        let text = format!("eni = \"{}\"\n{}", eni_path.display(), config_with_cycle(&link, cycle, ""));
        let mut d = Daemon::with_config(&text);
        let ch = d.connect().await;
        let slaves = pb::slaves_client::SlavesClient::new(ch.clone())
            .list_slaves(pb::ListSlavesRequest {})
            .await
            .unwrap()
            .into_inner()
            .slaves;
        let names: Vec<&str> = slaves.iter().filter_map(|s| s.expected.as_ref().map(|e| e.name.as_str())).collect();
        assert_eq!(names, ["Imu", "WheelRearLeft", "WheelRearRight", "WheelFrontLeft", "WheelFrontRight"]);
        assert!(slaves.iter().all(|s| s.mismatch.is_empty()), "{slaves:?}");

        let mut sdo = pb::sdo_client::SdoClient::new(ch.clone());
        for slave in 1..=4u32 {
            let mut read = async |index: u32, subindex: u32| {
                let r = sdo.upload(pb::SdoUploadRequest { slave, index, subindex, ..Default::default() }).await;
                r.unwrap_or_else(|e| panic!("{slave} {index:#06x}:{subindex}: {e:?}")).into_inner().raw
            };
            assert_eq!(read(0x1C12, 0).await, [1], "slave {slave}: one RxPDO");
            assert_eq!(read(0x1C12, 1).await, [0x01, 0x16], "slave {slave}: 0x1601");
            assert_eq!(read(0x1C13, 1).await, [0x03, 0x1A], "slave {slave}: 0x1A03");
            assert_eq!(read(0x6060, 0).await, [8], "slave {slave}: Op mode");
            assert_eq!(read(0x60C2, 1).await, [10], "slave {slave}: cycle time");
            assert_eq!(read(0x1A07, 0).await, [0], "slave {slave}: 0x1A07 cleared");
        }

        // The register init commands a host may replay: each drive's
        // watchdogs (divider 0x09C2, PDI 1000, sync manager 10000), written
        // at IP by raw datagram; the IMU's file sets none.
        let mut regs = pb::registers_client::RegistersClient::new(ch.clone());
        for (slave, want) in [(0u32, [0u8, 0]), (1, [0x10, 0x27]), (4, [0x10, 0x27])] {
            let read = pb::ReadRegistersRequest { slave, address: 0x0420, length: 2 };
            let got = regs.read_registers(read).await.unwrap().into_inner();
            assert_eq!((got.working_counter, got.data.as_slice()), (1, &want[..]), "slave {slave}: SM watchdog");
        }
        let divider = pb::ReadRegistersRequest { slave: 2, address: 0x0400, length: 2 };
        assert_eq!(regs.read_registers(divider).await.unwrap().into_inner().data, [0xC2, 0x09]);

        let mut pd = pb::process_data_client::ProcessDataClient::new(ch.clone());
        let layout = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        assert!(layout.notes.is_empty(), "{:?}", layout.notes);
        let variables = eni.relative_variables();
        assert_eq!(variables.len(), 31);
        for v in &variables {
            let output = v.variable.output;
            let dir = if output { pb::Direction::Output } else { pb::Direction::Input } as i32;
            let start = layout
                .entries
                .iter()
                .filter(|e| e.slave == v.slave as u32 && e.direction == dir)
                .map(|e| e.bit_offset)
                .min()
                .expect("the slave's entries");
            let e = layout
                .entries
                .iter()
                .find(|e| e.variable == v.variable.name)
                .unwrap_or_else(|| panic!("no entry named {:?}: {layout:#?}", v.variable.name));
            assert_eq!(
                (e.slave, e.direction, e.bit_offset - start, e.bit_length),
                (v.slave as u32, dir, v.relative_bit, v.variable.bit_size),
                "{}",
                v.variable.name
            );
        }
        let imu = layout.entries.iter().find(|e| e.variable == "Imu.Transmit PDO Mapping.Acceleration X").unwrap();
        assert_eq!(imu.data_type, pb::DataType::Integer16 as i32, "the ENI's INT");

        // Outputs by variable name land in that drive, within the budget
        // from the start (the RxFIFO is not prefilled past it).
        let lease =
            pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![], ttl_ms: 5000 }).await.unwrap().into_inner();
        let velocity = by_entry("WheelFrontLeft.Outputs.Target Velocity", pb::value::Kind::Integer(-123_456));
        pd.write_outputs(pb::WriteOutputsRequest { lease_id: lease.id.clone(), writes: vec![velocity] }).await.unwrap();
        let mut seen = Vec::new();
        let t0 = std::time::Instant::now();
        for _ in 0..100 {
            let r = sdo.upload(pb::SdoUploadRequest { slave: 3, index: 0x60FF, subindex: 0, ..Default::default() });
            seen = r.await.unwrap().into_inner().raw;
            if seen == (-123_456i32).to_le_bytes() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        assert_eq!(seen, (-123_456i32).to_le_bytes(), "the frame reached WheelFrontLeft (slave 3)");
        assert!(t0.elapsed() < Duration::from_millis(1000), "{:?} for a 50 ms budget", t0.elapsed());

        in_op_with_inputs_flowing(ch).await;
        d.stop();
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// An init command the slave refuses stops the bring-up with an error that
/// says which one: slave, object, transition, and its line and comment in
/// the ENI (here WheelRearLeft's "Cycle time" made to write 0x5FFF, an
/// object the Elmo does not have).
#[test]
fn a_refused_init_command_is_named_by_its_line_in_the_eni() {
    let dir = temp_dir("eni-refused");
    let Some((eni_path, link)) = ecmxf_e2e::twincat_network(&dir) else { return };
    run(async {
        let text = std::fs::read_to_string(&eni_path).unwrap();
        let at = text.find("<Index>24770</Index>").expect("the first drive's 0x60C2 command");
        let line = text[..at].lines().count();
        let bad = dir.join("bad.xml");
        std::fs::write(&bad, text.replacen("<Index>24770</Index>", "<Index>24575</Index>", 1)).unwrap();
        let mut d = Daemon::with_config(&format!("eni = \"{}\"\n{}", bad.display(), config(&link, "")));
        // The engine never runs: the error it keeps failing with.
        let status = d.status_with_an_error().await;
        let e = &status.last_error;
        assert!(e.contains("slave 1 0x5fff:01 (transition PS, ENI line"), "{e}");
        // The command element starts a few lines above its Index.
        let named: usize = e.split("ENI line ").nth(1).and_then(|r| r.split(':').next()).unwrap().parse().unwrap();
        assert!((line.saturating_sub(6)..=line).contains(&named), "line {named}, Index on {line}: {e}");
        assert!(e.contains("\"Cycle time\""), "{e}");
        assert_ne!(status.ecat_state, pb::EcatState::Op as i32);
        d.stop();
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// SOEM's hand-written sample (hex numbers, `Ccs` 2 for writes, complete
/// access on 0x1C12): its two devices, known only from the file, come up
/// in OP with the PDOs its init commands assign (device A: TxPDOs 0x1A02
/// and 0x1A05 one subindex at a time; device B: RxPDOs 0x1601, 0x1607 and
/// 0x161C in one complete-access write), and the layout follows.
#[test]
fn soems_sample_brings_its_network_up_with_the_pdos_it_assigns() {
    let Some(eni_path) = ecmxf_e2e::fixture("eni_soem_sample.xml") else { return };
    run(async {
        let dir = temp_dir("eni-soem");
        let mut slaves = String::new();
        for name in ["Sample device A", "Sample device B"] {
            slaves.push_str(&format!("[[slave]]\neni = \"{}\"\neni_slave = \"{name}\"\n", eni_path.display()));
        }
        let link = ecmxf_e2e::sim_network(&dir, &slaves);
        let mut d = Daemon::with_config(&format!("eni = \"{}\"\n{}", eni_path.display(), config(&link, "")));
        let ch = d.connect().await;
        let mut pd = pb::process_data_client::ProcessDataClient::new(ch.clone());
        let mapping = pd.get_mapping(pb::GetMappingRequest { slave: None }).await.unwrap().into_inner().slaves;
        let indexes = |p: &[pb::Pdo]| p.iter().map(|p| p.index).collect::<Vec<_>>();
        assert_eq!((indexes(&mapping[0].rx_pdos), indexes(&mapping[0].tx_pdos)), (vec![], vec![0x1A02, 0x1A05]));
        assert_eq!(
            (indexes(&mapping[1].rx_pdos), indexes(&mapping[1].tx_pdos)),
            (vec![0x1601, 0x1607, 0x161C], vec![])
        );
        let layout = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        assert_eq!((layout.output_bytes, layout.input_bytes), (12, 8), "{layout:?}");
        in_op_with_inputs_flowing(ch).await;
        d.stop();
        let _ = std::fs::remove_dir_all(&dir);
    });
}
