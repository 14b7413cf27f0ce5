//! `ecmxfctl config` (docs/eni.md): the network a daemon runs, written
//! as a configuration (`--format toml`) or an ENI (`--format eni`), is
//! taken unchanged by ecmxfd, and running it gives the same process image:
//! every entry with the same name, object, direction, offset, size and type,
//! and the same cycle. Through the ENI, every entry is named by the file's
//! ProcessImage and no variable disagrees with the layout. The TwinCAT
//! network (an IMU known only from its ENI, four Elmo drives whose fixed
//! PDOs 0x1601/0x1A03 its init commands assigned) goes round the same way:
//! its TOML states the assignment, which bring-up writes alone (the PDOs
//! already map it; writing their fixed mapping would be refused), and its
//! entries keep their places (their types came from the ENI's descriptions,
//! which a TOML does not carry).

use ecmxf_e2e::{Daemon, assert_schema, config, run, temp_dir};
use ecmxf_proto::v1 as pb;

/// What must be the same: everything but the variable names (a written
/// configuration names its slaves, and names are what it may change).
type Key = (String, u32, u32, u32, i32, u32, u32, i32);

async fn layout(d: &mut Daemon) -> (pb::ProcessImage, Vec<Key>) {
    let ch = d.connect().await;
    let image = pb::process_data_client::ProcessDataClient::new(ch)
        .get_layout(pb::GetLayoutRequest {})
        .await
        .expect("GetLayout")
        .into_inner();
    let keys = image
        .entries
        .iter()
        .map(|e| (e.name.clone(), e.slave, e.index, e.subindex, e.direction, e.bit_offset, e.bit_length, e.data_type))
        .collect();
    (image, keys)
}

/// Writes the network `d` runs in both forms, then runs each and compares.
/// `typed_by_toml`: whether the TOML can carry what typed the entries (an
/// ENI's descriptions type them; a TOML names no description unless the
/// network's configuration gave ESI files).
async fn round_trip(d: &mut Daemon, link: &str, typed_by_toml: bool) {
    let (before, keys) = layout(d).await;
    // The text and the JSON say the same of one state of the daemon; the
    // names its devices give arrive in a second pass after the layout,
    // so a pair read across it is read again.
    let toml = {
        let mut tries = 0;
        loop {
            let toml = d.ctl(&["config"]);
            assert_eq!(toml.code, 0, "{}", toml.stderr);
            let json = d.ctl(&["config", "--json"]).json();
            assert_schema("config", &json);
            tries += 1;
            if json["text"] == toml.stdout.as_str() || tries == 5 {
                assert_eq!(json["text"], toml.stdout.as_str());
                break toml;
            }
            tokio::time::sleep(std::time::Duration::from_millis(200)).await;
        }
    };
    let eni = d.ctl(&["config", "--format", "eni"]);
    assert_eq!(eni.code, 0, "{}", eni.stderr);
    d.stop();

    let mut again = Daemon::with_config(&toml.stdout);
    let (after, same) = layout(&mut again).await;
    again.stop();
    let untyped = |k: &[Key]| k.iter().map(|k| (k.0.clone(), k.1, k.2, k.3, k.4, k.5, k.6)).collect::<Vec<_>>();
    if typed_by_toml {
        assert_eq!(same, keys, "the TOML gives the same layout:\n{}", toml.stdout);
    } else {
        assert_eq!(untyped(&same), untyped(&keys), "the TOML gives the same layout:\n{}", toml.stdout);
    }
    assert_eq!(
        (after.output_bytes, after.input_bytes, after.cycle_us),
        (before.output_bytes, before.input_bytes, before.cycle_us)
    );

    let dir = temp_dir("config-eni");
    let file = dir.join("network.xml");
    std::fs::write(&file, &eni.stdout).unwrap();
    let text = format!("eni = \"{}\"\n{}", file.display(), config(link, ""));
    let mut from_eni = Daemon::with_config(&text);
    let (image, same) = layout(&mut from_eni).await;
    from_eni.stop();
    assert_eq!(same, keys, "the ENI gives the same layout:\n{}", eni.stdout);
    assert!(image.notes.is_empty(), "{:?}", image.notes);
    let unnamed: Vec<&str> =
        image.entries.iter().filter(|e| e.index != 0 && e.variable.is_empty()).map(|e| e.name.as_str()).collect();
    assert!(unnamed.is_empty(), "every entry is named by the ENI's ProcessImage: {unnamed:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_demo_network_written_as_toml_and_as_eni_runs_with_the_same_layout() {
    run(async {
        let link = "backend = \"sim\"";
        let mut d = Daemon::with_config(&config(link, ""));
        round_trip(&mut d, link, true).await;
    });
}

#[test]
fn the_twincat_network_goes_round_too() {
    let dir = temp_dir("config-twincat");
    let Some((eni, link)) = ecmxf_e2e::twincat_network(&dir) else { return };
    run(async {
        let mut d = Daemon::with_config(&format!("eni = \"{}\"\n{}", eni.display(), config(&link, "")));
        round_trip(&mut d, &link, false).await;
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// Slaves configured with their ESI (here two Elmo drives): the TOML names
/// the same files, so the entries keep the names and types the ESI gives.
#[test]
fn slaves_with_their_esi_keep_it() {
    let Some(elmo) = ecmxf_e2e::fixture("esi_elmo_gold_Elmo_ECAT_00010420_V11.xml") else { return };
    run(async {
        let dir = temp_dir("config-esi");
        let device = format!("esi = \"{}\"\nproduct_code = 0x30924\nrevision = 0x10420\n", elmo.display());
        let slaves = format!("[[slave]]\n{device}[[slave]]\n{device}");
        let link = ecmxf_e2e::sim_network(&dir, &slaves);
        let mut d = Daemon::with_config(&config(&link, &slaves));
        d.connect().await;
        let toml = d.ctl(&["config"]);
        assert_eq!(toml.stdout.matches(&format!("esi = \"{}\"", elmo.display())).count(), 2, "{}", toml.stdout);
        round_trip(&mut d, &link, true).await;
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// Seven Elmo drives, each with 4 RxPDOs and 5 TxPDOs (one of each mapped
/// here, the others fixed): more than PDO_CONFIG_SET's 3 PDOs, so bring-up
/// writes them over CoE. The ENI carries them as CoE init commands and as
/// its ProcessData; either alone rebuilds the same image on fresh drives.
#[test]
fn seven_drives_with_more_pdos_than_the_chip_carries_go_round() {
    let Some(elmo) = ecmxf_e2e::fixture("esi_elmo_gold_Elmo_ECAT_00010420_V11.xml") else { return };
    run(async {
        let dir = temp_dir("config-elmo7");
        let device = format!("[[slave]]\nesi = \"{}\"\nproduct_code = 0x30924\nrevision = 0x10420\n", elmo.display());
        let link = ecmxf_e2e::sim_network(&dir, &device.repeat(7));
        let pdos = "[[slave]]\nproduct_code = 0x30924\n\
            [[slave.rx_pdos]]\nindex = 0x1607\nentries = [[0x607A, 0, 32], [0x60FF, 0, 32]]\n\
            [[slave.rx_pdos]]\nindex = 0x160A\nentries = [[0x6040, 0, 16]]\n\
            [[slave.rx_pdos]]\nindex = 0x160B\nentries = [[0x6060, 0, 8], [0, 0, 8]]\n\
            [[slave.rx_pdos]]\nindex = 0x160C\nentries = [[0x6071, 0, 16]]\n\
            [[slave.tx_pdos]]\nindex = 0x1A07\nentries = [[0x6064, 0, 32], [0x60F4, 0, 32]]\n\
            [[slave.tx_pdos]]\nindex = 0x1A0A\nentries = [[0x6041, 0, 16]]\n\
            [[slave.tx_pdos]]\nindex = 0x1A0B\nentries = [[0x6061, 0, 8], [0, 0, 8]]\n\
            [[slave.tx_pdos]]\nindex = 0x1A0C\nentries = [[0x6062, 0, 32]]\n\
            [[slave.tx_pdos]]\nindex = 0x1A0D\nentries = [[0x6063, 0, 32]]\n";
        let mut d = Daemon::with_config(&config(&link, &pdos.repeat(7)));
        let (image, _) = layout(&mut d).await;
        assert_eq!((image.output_bytes, image.input_bytes), (7 * 14, 7 * 20), "every PDO reaches the frames");
        assert_eq!(image.entries.iter().filter(|e| e.index != 0).count(), 7 * 11);
        let eni = d.ctl(&["config", "--format", "eni"]);
        assert_eq!(eni.code, 0, "{}", eni.stderr);
        assert_eq!(
            eni.stdout.matches("<InitCmd>").count(),
            7 * ((1 + 4 * 2 + 6 + 4 + 1) + (1 + 5 * 2 + 7 + 5 + 1)),
            "{}",
            eni.stdout
        );
        round_trip(&mut d, &link, true).await;

        // The ProcessData alone (init commands taken out) gives the same.
        let (before, keys) = {
            let mut again = Daemon::with_config(&config(&link, &pdos.repeat(7)));
            let out = layout(&mut again).await;
            again.stop();
            out
        };
        // So do the init commands alone (no PDO with an Sm).
        let places = |k: &[Key]| k.iter().map(|k| (k.1, k.2, k.3, k.4, k.5, k.6)).collect::<Vec<_>>();
        let bare = strip_between(&eni.stdout, "<CoE>", "</CoE>");
        let unassigned = eni.stdout.replace(" Sm=\"2\"", "").replace(" Sm=\"3\"", "");
        assert!(!bare.contains("<InitCmd>") && !unassigned.contains(" Sm="));
        for (name, text) in [("bare.xml", bare), ("unassigned.xml", unassigned)] {
            let file = dir.join(name);
            std::fs::write(&file, &text).unwrap();
            let mut d = Daemon::with_config(&format!("eni = \"{}\"\n{}", file.display(), config(&link, "")));
            let (image, same) = layout(&mut d).await;
            d.stop();
            assert_eq!((image.output_bytes, image.input_bytes), (before.output_bytes, before.input_bytes), "{name}");
            assert_eq!(places(&same), places(&keys), "{name}:\n{text}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// `text` without every `open`...`close` span.
fn strip_between(text: &str, open: &str, close: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    while let Some(a) = rest.find(open) {
        out.push_str(&rest[..a]);
        match rest[a..].find(close) {
            Some(b) => rest = &rest[a + b + close.len()..],
            None => rest = "",
        }
    }
    out.push_str(rest);
    out
}

/// SOEM's sample (two devices known only from it, PDOs assigned by its
/// init commands, one of them by complete access) goes round too.
#[test]
fn soems_sample_goes_round() {
    let Some(soem) = ecmxf_e2e::fixture("eni_soem_sample.xml") else { return };
    run(async {
        let dir = temp_dir("config-soem");
        let mut slaves = String::new();
        for position in [1, 2] {
            slaves.push_str(&format!("[[slave]]\neni = \"{}\"\neni_slave = {position}\n", soem.display()));
        }
        let link = ecmxf_e2e::sim_network(&dir, &slaves);
        let mut d = Daemon::with_config(&format!("eni = \"{}\"\n{}", soem.display(), config(&link, "")));
        round_trip(&mut d, &link, false).await;
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// A network of the first device of every ESI and SII file in the
/// fixtures (a file added there is picked up), each configured with its
/// ESI, goes round through both forms.
#[test]
fn a_network_of_every_fixture_goes_round() {
    use ecmxf_devices::catalog::Catalog;
    let Some(fixtures) = ecmxf_e2e::fixtures_dir() else { return };
    let catalog = Catalog::scan_with_incoming(&fixtures).unwrap();
    let mut firsts = Vec::new();
    for d in catalog.devices.iter().filter(|d| d.has_process_data()) {
        if !firsts.iter().any(|f: &&ecmxf_devices::catalog::CatalogDevice| f.origin.file() == d.origin.file()) {
            firsts.push(d);
        }
    }
    run(async {
        let dir = temp_dir("config-fixtures");
        let (link, slaves) = ecmxf_e2e::catalog_network(&dir, &firsts);
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config_with_cycle(&link, "sync0_us = 1000\n", &slaves));
        round_trip(&mut d, &link, true).await;
        let _ = std::fs::remove_dir_all(&dir);
    });
}
