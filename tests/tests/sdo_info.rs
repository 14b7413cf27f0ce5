//! A slave's dictionary over SDO Information (docs/mailbox.md) end to end,
//! through the `ecmxfd` binary on a simulator in its
//! own process and `ecmxfctl`: a slave that answers CoE SDO Information is
//! listed from the device (no ESI configured for it); one whose ESI says it
//! has none is listed from its ESI, saying why; asking a source a slave has
//! not is an error naming it. The dictionary read is kept on disk and used
//! again by the next daemon. An answer lost on the way back is asked for
//! again (mailbox repeat), and an emergency the slave sends first goes to
//! the emergency events without disturbing the listing.

use ecmxf_e2e::{Daemon, Simulator, fixture, temp_dir};

#[test]
fn sdos_lists_what_the_device_describes_and_says_where_it_comes_from() {
    let (Some(soes), Some(nanotec)) =
        (fixture("esi_soes_lan9252_evb9252_dig.xml"), fixture("esi_nanotec_C5-E-2-21.xml"))
    else {
        return;
    };
    let dir = temp_dir("sdo-info");
    let network = dir.join("net.toml");
    std::fs::write(
        &network,
        format!(
            "version = 1\n[[slave]]\nesi = \"{}\"\nproduct_code = 1234\n[[slave]]\nesi = \"{}\"\nproduct_code = 0x4F\n",
            soes.display(),
            nanotec.display()
        ),
    )
    .unwrap();
    let sim = Simulator::serve(&dir, &["--network", &network.display().to_string()]);
    let state = dir.join("state");
    // An ESI for the Nanotec only: the SOES slave has to describe itself.
    // Kept where systemd's StateDirectory= says.
    let extra = format!("[[slave]]\n[[slave]]\nesi = \"{}\"\n", nanotec.display());
    let config = ecmxf_e2e::config(&sim.link(), &extra);
    let env = [("STATE_DIRECTORY".to_string(), state.clone().into_os_string())];
    let start = || Daemon::binary_with_config_on(&ecmxf_e2e::daemon_binary(), &config, &env);
    let mut d = start();
    ecmxf_e2e::run(async { drop(d.connect().await) });

    let listed = d.ctl(&["sdos", "-p", "0"]).ok().to_string();
    assert!(listed.contains("(from the device,"), "{listed}");
    let v = d.ctl(&["sdos", "-p", "0", "--json"]).json();
    ecmxf_e2e::assert_schema("sdos", &v);
    assert_eq!(v["source"], "DEVICE");
    let objects = v["objects"].as_array().unwrap();
    let param = objects.iter().find(|o| o["index"] == 0x8000 && o["subindex"] == 1).expect("0x8000:01 listed");
    assert_eq!((param["name"].as_str(), param["access"].as_str()), (Some("Parameters.Multiplier"), Some("rw")));
    let objects_before = v["objects"].clone();
    let kept = std::fs::read_dir(state.join("sdo-info")).expect("the dictionary is kept").count();
    assert_eq!(kept, 1, "one file for the SOES slave's identity");

    // What the device described types its values: a plain Sdo.Upload of a
    // maker's object (no type asked, none known to the daemon otherwise)
    // comes back decoded as the device's UDINT.
    let mut up = None;
    ecmxf_e2e::run(async {
        let ch = d.connect().await;
        let mut sdo = ecmxf_proto::v1::sdo_client::SdoClient::new(ch);
        let ask = ecmxf_proto::v1::SdoUploadRequest { slave: 0, index: 0x8000, subindex: 1, ..Default::default() };
        up = Some(sdo.upload(ask).await.unwrap().into_inner());
    });
    let up = up.unwrap();
    assert_eq!(up.data_type, ecmxf_proto::v1::DataType::Unsigned32 as i32, "{up:?}");
    assert!(up.value.is_some(), "{up:?}");

    // No SDO Information: the ESI, and the reason.
    let v = d.ctl(&["sdos", "-p", "1", "--json"]).json();
    assert_eq!(v["source"], "ESI");
    assert!(v["note"].as_str().unwrap().contains("no SDO Information"), "{v}");
    let e = d.ctl(&["sdos", "-p", "1", "--source", "device"]);
    assert_ne!(e.code, 0);
    assert!(e.stderr.contains("does not describe its objects"), "{}", e.stderr);

    // An answer lost on the way back, and an emergency before an answer:
    // a fresh daemon with nothing kept reads the dictionary again.
    drop(d);
    std::fs::remove_dir_all(&state).unwrap();
    sim.ctl("mailbox-lose 0 2");
    sim.ctl("mailbox-emergency 0 1");
    let mut d = start();
    ecmxf_e2e::run(async { drop(d.connect().await) });
    let again = d.ctl(&["sdos", "-p", "0", "--json"]).json();
    assert_eq!(again["objects"], objects_before, "the same listing");
    let mailbox = sim.ctl("mailbox 0");
    assert!(mailbox.contains("repeats=2"), "both lost answers asked again: {mailbox}");
    let log = d.log();
    assert!(log.contains("emergency") && log.contains("65280"), "the emergency is an event, logged:\n{log}");
    let e = d.ctl(&["emergencies", "--json"]).json();
    ecmxf_e2e::assert_schema("emergencies", &e);
    let from_mailbox: Vec<_> =
        e["emergencies"].as_array().unwrap().iter().filter(|r| r["source"] == "mailbox").collect();
    assert_eq!(from_mailbox.len(), 1, "kept among the emergencies: {e}");
    assert_eq!((from_mailbox[0]["slave"].as_u64(), from_mailbox[0]["error_code"].as_u64()), (Some(0), Some(0xFF00)));

    // Kept on disk: a new daemon lists it without asking the slave.
    drop(d);
    let before = sim.ctl("mailbox 0");
    let mut d = start();
    ecmxf_e2e::run(async { drop(d.connect().await) });
    assert_eq!(d.ctl(&["sdos", "-p", "0", "--json"]).json()["source"], "DEVICE");
    assert_eq!(sim.ctl("mailbox 0"), before, "no mailbox request: the kept dictionary was used");
}
