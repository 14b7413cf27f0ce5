//! Networks of a shape the demo does not have. A coupler with an input
//! terminal (the real Beckhoff EL1008 from ../shared/fixtures: inputs, no
//! outputs, no CoE) at 125 us and 1 ms with the simulator configuration's
//! FIFO marks: once, such a network wedged the engine (the RxFIFO level it
//! could never raise made it exchange FIFO packets back to back, every
//! slave call ended in "deadline exceeded" and the log filled with "RxFIFO
//! ran dry"). Skipped without the fixtures unless ECMXF_REQUIRE_FIXTURES.

use std::time::Duration;

use ecmxf_e2e::{Daemon, run};
use ecmxf_proto::v1 as pb;
use pb::master_client::MasterClient;

#[test]
fn an_input_only_network_runs_and_answers_at_125_us_and_1_ms() {
    let Some(esi) = ecmxf_e2e::fixture("esi_beckhoff_EL1xxx.xml") else { return };
    for sync0_us in [125, 1000] {
        let esi = esi.clone();
        run(async move {
            let dir = ecmxf_e2e::temp_dir("inputs-only");
            let network = dir.join("net.toml");
            let net = format!(
                "version = 1\n[[slave]]\nprofile = \"coupler\"\n[[slave]]\nesi = \"{}\"\nproduct_code = 0x03f03052\n",
                esi.display()
            );
            std::fs::write(&network, net).unwrap();
            let link = format!("backend = \"sim\"\nnetwork = \"{}\"", network.display());
            let config = ecmxf_e2e::config_with_cycle(&link, &format!("sync0_us = {sync0_us}\n"), "");
            let mut d = Daemon::binary_with_config(&config);
            let ch = d.connect().await;
            let at = format!("at {sync0_us} us");
            let mut m = MasterClient::new(ch);
            let s = m.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
            let frames = s.counters.as_ref().unwrap().input_frames;
            tokio::time::sleep(Duration::from_millis(500)).await;
            let s = m.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
            assert!(s.process_data_flowing, "{at}: {s:?}");
            let c = s.counters.unwrap();
            assert!(c.input_frames > frames, "{at}: inputs do not flow: {c:?}");
            assert_eq!(c.fifo_alarms, 0, "{at}: no outputs, nothing to run dry: {c:?}");
            // Every read command answers within its deadline.
            let slaves = d.ctl(&["--json", "slaves"]).json();
            let slaves = slaves["slaves"].as_array().unwrap();
            assert_eq!(slaves.len(), 2, "{at}");
            assert_eq!(slaves[1]["input_bytes"], 1, "{at}: {slaves:?}");
            d.ctl(&["master"]).ok();
            d.ctl(&["states"]).ok();
            d.ctl(&["sii", "read", "-p", "1", "--count", "16"]).ok();
            // The EL1008 has no CoE: its PDOs come from its SII, named and
            // typed as the device describes them; the coupler's CoE-less
            // emptiness fails nothing.
            let pdos = d.ctl(&["--json", "pdos"]).json();
            let el1008 = &pdos["slaves"][1];
            assert_eq!(el1008["source"], "sii", "{at}: {el1008}");
            let tx = el1008["tx_pdos"].as_array().unwrap();
            assert_eq!(tx.len(), 8, "{at}: eight one-bit TxPDOs: {el1008}");
            assert_eq!(tx[0]["index"], 0x1A00, "{at}");
            assert_eq!(tx[0]["name"], "Channel 1", "{at}: {el1008}");
            assert_eq!(tx[0]["entries"][0]["index"], 0x6000, "{at}");
            assert_eq!(tx[0]["entries"][0]["name"], "Input", "{at}");
            assert_eq!(tx[0]["entries"][0]["data_type"], "bool", "{at}: {el1008}");
            let inputs: Vec<&serde_json::Value> =
                pdos["image"]["entries"].as_array().unwrap().iter().filter(|e| e["slave"] == 1).collect();
            assert_eq!(inputs.len(), 8, "{at}: one image entry per input bit: {inputs:?}");
            assert!(inputs.iter().all(|e| e["data_type"] == "bool" && e["label"] == "Input"), "{at}: {inputs:?}");
            let data = d.ctl(&["--json", "data", "1.0x6000:01"]);
            assert_eq!(data.code, 0, "{at}: {}{}", data.stdout, data.stderr);
            let diag = d.ctl(&["diag"]);
            assert!(diag.healthy_but_for_passing_trouble(), "{at}: {}{}", diag.stdout, diag.stderr);
            let log = d.log();
            assert!(!log.contains("ran dry"), "{at}: the log warns of a dry RxFIFO:\n{log}");
            drop(d);
            let _ = std::fs::remove_dir_all(&dir);
        });
    }
}

/// A coupler with an output terminal from a real SII dump (the Beckhoff
/// EL2889: 16 outputs, no CoE, no inputs at all) at 125 us and 1 ms, on a
/// simulator of its own so the test sees what reaches the slave: every read
/// command answers (none waits for an input frame that never comes), and a
/// value written through the API is what the simulated EL2889 holds.
#[test]
fn an_output_only_network_without_coe_runs_answers_and_its_outputs_reach_the_slave() {
    let Some(dump) = ecmxf_e2e::fixture("sii_beckhoff_el2889.bin") else { return };
    for sync0_us in [125, 1000] {
        let dump = dump.clone();
        run(async move {
            let dir = ecmxf_e2e::temp_dir("outputs-only");
            let network = dir.join("net.toml");
            let net =
                format!("version = 1\n[[slave]]\nprofile = \"coupler\"\n[[slave]]\nsii = \"{}\"\n", dump.display());
            std::fs::write(&network, net).unwrap();
            let sim = ecmxf_e2e::Simulator::serve(&dir, &["--network", &network.display().to_string()]);
            let config = ecmxf_e2e::config_with_cycle(&sim.link(), &format!("sync0_us = {sync0_us}\n"), "");
            let mut d = Daemon::binary_with_config(&config);
            let ch = d.connect().await;
            let at = format!("at {sync0_us} us");
            let mut m = MasterClient::new(ch.clone());
            let s = m.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
            assert!(s.process_data_flowing, "{at}: an output-only network is healthy: {s:?}");
            let layout = pb::process_data_client::ProcessDataClient::new(ch.clone())
                .get_layout(pb::GetLayoutRequest {})
                .await
                .unwrap()
                .into_inner();
            assert_eq!((layout.output_bytes, layout.input_bytes), (2, 0), "{at}: {layout:?}");
            // Every read command answers; `data --raw` does not wait for an
            // input frame, StreamInputs says why there is none.
            for cmd in [&["master"][..], &["states"], &["slaves", "-v"], &["pdos"], &["data"], &["data", "--raw"]] {
                let out = d.ctl(cmd);
                assert_eq!(out.code, 0, "{at}: ecmxfctl {cmd:?}: {}{}", out.stdout, out.stderr);
            }
            d.ctl(&["sii", "decode", "-p", "1"]).ok();
            let watch = d.ctl(&["watch", "-n", "1"]);
            assert_eq!(watch.code, 7, "{at}: {}{}", watch.stdout, watch.stderr);
            assert!(watch.stderr.contains("no inputs"), "{at}: {}", watch.stderr);
            let pdos = d.ctl(&["--json", "pdos"]).json();
            let el2889 = &pdos["slaves"][1];
            assert_eq!(el2889["source"], "sii", "{at}: {el2889}");
            assert_eq!(el2889["rx_pdos"].as_array().unwrap().len(), 16, "{at}: {el2889}");
            // A value written through the API reaches the slave.
            let mut pd = pb::process_data_client::ProcessDataClient::new(ch);
            let lease =
                pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![1], ttl_ms: 0 }).await.unwrap().into_inner();
            let write = |name: &str| pb::OutputWrite {
                target: Some(pb::output_write::Target::Entry(name.into())),
                value: Some(pb::Value { kind: Some(pb::value::Kind::Boolean(true)) }),
            };
            let writes = vec![write("1.0x7000:01"), write("1.0x70f0:01")];
            pd.write_outputs(pb::WriteOutputsRequest { lease_id: lease.id, writes }).await.unwrap();
            let start = std::time::Instant::now();
            loop {
                let held = sim.ctl("outputs 1");
                if held.trim() == "ok state=OP outputs=0180" {
                    break;
                }
                assert!(start.elapsed() < Duration::from_secs(2), "{at}: the EL2889 holds {held}");
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            let diag = d.ctl(&["diag"]);
            assert!(diag.healthy_but_for_passing_trouble(), "{at}: {}{}", diag.stdout, diag.stderr);
            let log = d.log();
            assert!(!log.contains("ran dry"), "{at}: the log warns of a dry RxFIFO:\n{log}");
            drop(d);
            drop(sim);
            let _ = std::fs::remove_dir_all(&dir);
        });
    }
}

/// 48 slaves, 40 of them laid out from their SII (a Beckhoff EL2889 and an
/// EasyCAT board: about a hundred EEPROM reads each), asked for by callers
/// that give up after 100 ms, again and again: the daemon builds the
/// layout once, on its own, and the callers get it as soon as it exists
/// (when it was built inside a caller's deadline, it never finished).
#[test]
fn a_48_slave_layout_is_built_once_by_the_daemon_whatever_callers_give_up() {
    let (Some(el2889), Some(easycat)) =
        (ecmxf_e2e::fixture("sii_beckhoff_el2889.bin"), ecmxf_e2e::fixture("sii_abt_easycat_32x32.bin"))
    else {
        return;
    };
    run(async move {
        let dir = ecmxf_e2e::temp_dir("layout-48");
        let network = dir.join("net.toml");
        let mut net = String::from("version = 1\n");
        for _ in 0..8 {
            for slave in [
                "profile = \"digital-io\"".to_string(),
                format!("sii = \"{}\"", el2889.display()),
                "profile = \"digital-io\"".to_string(),
                format!("sii = \"{}\"", el2889.display()),
                format!("sii = \"{}\"", easycat.display()),
                "profile = \"coupler\"".to_string(),
            ] {
                net.push_str(&format!("[[slave]]\n{slave}\n"));
            }
        }
        std::fs::write(&network, net).unwrap();
        let link = format!("backend = \"sim\"\nnetwork = \"{}\"", network.display());
        let config = ecmxf_e2e::config_with_cycle(&link, "sync0_us = 1000\n", "");
        let mut d = Daemon::binary_with_config(&config);
        let ch = d.connect().await;
        let running = std::time::Instant::now();
        let mut pd = pb::process_data_client::ProcessDataClient::new(ch);
        let mut gave_up = 0;
        let image = loop {
            let mut r = tonic::Request::new(pb::GetLayoutRequest {});
            r.set_timeout(Duration::from_millis(100));
            match pd.get_layout(r).await {
                Ok(image) => break image.into_inner(),
                // The caller gives up: the daemon's deadline answer, or
                // the client's own timer when it fires first on a loaded
                // host (tonic's "Timeout expired", Cancelled).
                Err(e) => {
                    let own_timer = e.code() == tonic::Code::Cancelled && e.message() == "Timeout expired";
                    assert!(e.code() == tonic::Code::DeadlineExceeded || own_timer, "{e:?}");
                    gave_up += 1;
                }
            }
            let waited = running.elapsed();
            assert!(waited < Duration::from_secs(20), "no layout {waited:?} after OP, callers gave up {gave_up} times");
        };
        assert!(gave_up > 0, "the layout was there before the first call: this test would show nothing");
        let slaves: std::collections::BTreeSet<u32> = image.entries.iter().map(|e| e.slave).collect();
        assert_eq!(slaves.len(), 40, "every slave with process data: {slaves:?}");
        let named = image.entries.iter().filter(|e| e.slave == 46 && !e.label.is_empty()).count();
        assert!(named > 0, "the EasyCAT's entries are named from its SII strings");
        assert_eq!(d.log().matches("process image laid out").count(), 1, "{}", d.log());
        eprintln!("48 slaves laid out {:?} after OP ({gave_up} callers gave up meanwhile)", running.elapsed());
    });
}

/// A network the SPI link can never carry is refused once, with exit
/// status 78 (EX_CONFIG, in the unit's RestartPreventExitStatus=), and a
/// line naming the sizes and what to change, instead of a bring-up retried
/// every few seconds forever for a network that could only ever run its
/// RxFIFO dry.
#[test]
fn a_network_the_link_cannot_carry_exits_once_with_status_78() {
    let Some(easycat) = ecmxf_e2e::fixture("sii_abt_easycat_32x32.bin") else { return };
    let dir = ecmxf_e2e::temp_dir("refused");
    let network = dir.join("net.toml");
    // 20 boards of 32 output bytes: a 640-byte frame, 512-byte packets.
    let net: String = (0..20).map(|_| format!("[[slave]]\nsii = \"{}\"\n", easycat.display())).collect();
    std::fs::write(&network, format!("version = 1\n{net}")).unwrap();
    let config = dir.join("ecmxfd.toml");
    std::fs::write(
        &config,
        format!(
            "version = 1\n[link]\nbackend = \"sim\"\nnetwork = \"{}\"\n[chip]\ndata_size = 512\n[realtime]\npriority = 0\n\
             lock_memory = false\nspin_us = 0\n[recovery]\nbackoff_ms = 100\n",
            network.display()
        ),
    )
    .unwrap();
    let started = std::time::Instant::now();
    let out = std::process::Command::new(ecmxf_e2e::daemon_binary())
        .args(["--config", &config.display().to_string(), "--socket", &dir.join("s.sock").display().to_string()])
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(78), "{log}");
    assert!(started.elapsed() < Duration::from_secs(20), "took {:?}: {log}", started.elapsed());
    let errors: Vec<&str> = log.lines().filter(|l| l.contains("ERROR")).collect();
    assert_eq!(errors.len(), 1, "one line says it: {log}");
    for needed in ["640 bytes", "512", "chip.data_size", "not retried"] {
        assert!(errors[0].contains(needed), "{needed:?} missing: {}", errors[0]);
    }
    // Tried once: at most the bring-up event (when the log gets to it
    // before the daemon exits) besides the line above.
    assert!(log.matches("link budget").count() <= 2, "tried once: {log}");
    // --check-config says so offline, with the same status.
    let out = std::process::Command::new(ecmxf_e2e::daemon_binary())
        .args(["--check-config", &config.display().to_string()])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(78), "{said}");
    assert!(said.contains("640 bytes") && said.contains("chip.data_size"), "{said}");
}

/// A slave that refuses SAFE-OP at bring-up is named, with its state and
/// AL status, where a user looks: `ecmxfctl master` (the last error) and
/// `ecmxfctl slaves`, which says the network is not running and why
/// instead of "MISSING" for a slave that answers (which sent users
/// looking for a cable fault where the slave had refused).
#[test]
fn a_slave_refusing_safe_op_is_named_by_master_and_slaves() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("refusing");
        let network = dir.join("net.toml");
        let net = "version = 1\n[[slave]]\nprofile = \"digital-io\"\n[[slave]]\nprofile = \"ti-3axis\"\nmin_cycle_us = 2000\n";
        std::fs::write(&network, net).unwrap();
        let link = format!("backend = \"sim\"\nnetwork = \"{}\"", network.display());
        let expected = "[[slave]]\nproduct_code = 0x0808\n[[slave]]\nproduct_code = 0x0402\n";
        let config = ecmxf_e2e::config_with_cycle(&link, "sync0_us = 1000\n", expected);
        let d = Daemon::binary_with_config(&config);
        let want = "slave 1 PREOP, AL status 0x0035 (invalid sync cycle time)";
        let started = std::time::Instant::now();
        let master = loop {
            let out = d.ctl(&["master"]);
            if out.stdout.contains(want) {
                break out;
            }
            assert!(started.elapsed() < Duration::from_secs(20), "not named: {}\n{}", out.stdout, d.log());
            tokio::time::sleep(Duration::from_millis(100)).await;
        };
        assert!(master.stdout.contains("SAFEOP"), "{}", master.stdout);
        let slaves = d.ctl(&["slaves"]);
        assert!(!slaves.stdout.contains("MISSING"), "{}", slaves.stdout);
        assert!(slaves.stderr.contains(want), "{}{}", slaves.stdout, slaves.stderr);
        assert!(d.log().contains(want), "{}", d.log());
    });
}

/// An SDO to a slave whose SII lists no CoE (a Beckhoff EL2889: no
/// mailbox at all) is answered at once with FAILED_PRECONDITION naming the
/// slave, not sent to time out in the chip as "SDO protocol timeout"; its
/// PDOs still come from its SII (the timeout, a second later, named
/// neither the slave nor the cause).
#[test]
fn an_sdo_to_a_slave_without_coe_is_refused_at_once_naming_it() {
    let Some(el2889) = ecmxf_e2e::fixture("sii_beckhoff_el2889.bin") else { return };
    run(async move {
        let dir = ecmxf_e2e::temp_dir("no-coe");
        let network = dir.join("net.toml");
        let net =
            format!("version = 1\n[[slave]]\nprofile = \"ti-3axis\"\n[[slave]]\nsii = \"{}\"\n", el2889.display());
        std::fs::write(&network, net).unwrap();
        let link = format!("backend = \"sim\"\nnetwork = \"{}\"", network.display());
        let mut d = Daemon::with_config(&ecmxf_e2e::config(&link, ""));
        let ch = d.connect().await;
        let mut sdo = pb::sdo_client::SdoClient::new(ch.clone());
        let upload = |slave| pb::SdoUploadRequest { slave, index: 0x1018, subindex: 1, ..Default::default() };
        assert!(sdo.upload(upload(0)).await.is_ok(), "the drive speaks CoE");
        for _ in 0..2 {
            let started = std::time::Instant::now();
            let e = sdo.upload(upload(1)).await.unwrap_err();
            assert_eq!(e.code(), tonic::Code::FailedPrecondition, "{e:?}");
            assert!(e.message().contains("slave 1 has no CoE mailbox"), "{}", e.message());
            assert!(started.elapsed() < Duration::from_millis(500), "took {:?}", started.elapsed());
        }
        let mut pd = pb::process_data_client::ProcessDataClient::new(ch);
        let mapping = pd.get_mapping(pb::GetMappingRequest { slave: Some(1) }).await.unwrap().into_inner();
        assert_eq!(mapping.slaves[0].source, pb::PdoSource::Sii as i32, "{mapping:?}");
    });
}
