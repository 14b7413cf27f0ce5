//! An ENI file as the network description (`eni = "FILE"`, issue 32): the
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

use ecmxf_e2e::{Daemon, config, daemon_binary, repo, run, temp_dir};
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
        let mut m = pb::master_client::MasterClient::new(ch);
        let frames = |s: pb::MasterStatus| s.counters.map_or(0, |c| c.input_frames);
        let before = frames(m.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner());
        tokio::time::sleep(Duration::from_millis(100)).await;
        let status = m.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
        assert_eq!(status.ecat_state, pb::EcatState::Op as i32, "{status:?}");
        assert!(frames(status) > before, "input frames flow");
        d.stop();
    });
}

#[test]
fn check_config_says_what_an_eni_applies_and_what_it_does_not() {
    let Some(twincat) = ecmxf_e2e::fixture("eni_twincat_elmo4_imu.xml") else { return };
    let (code, text) =
        check_config(&format!("version = 1\neni = \"{}\"\n[link]\nbackend = \"sim\"\n", twincat.display()));
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("5 expected slaves"), "{text}");
    assert!(text.contains(r#"slave 1 "WheelRearLeft" (line 784): 12 CoE init commands written"#), "{text}");
    assert!(text.contains("InitCmds (register) (49) not replayed"), "{text}");
    assert!(text.contains("eni: ProcessImage (1) not applied"), "{text}");
    let Some(soem) = ecmxf_e2e::fixture("eni_soem_sample.xml") else { return };
    let (code, text) = check_config(&format!("version = 1\neni = \"{}\"\n[link]\nbackend = \"sim\"\n", soem.display()));
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("has Ccs 2 with data: written, as SOEM's files mean it"), "{text}");
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
        let net = dir.join("net.toml");
        let device = format!("esi = \"{}\"\nproduct_code = 0x30924\n", elmo.display());
        std::fs::write(&net, format!("version = 1\n[[slave]]\n{device}")).unwrap();
        let link = format!("backend = \"sim\"\nnetwork = \"{}\"", net.display());
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
