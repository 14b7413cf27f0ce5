//! PDO and entry names from the best source a slave has (docs/ecmxfctl.md,
//! `pdos`): the ENI or ESI, else the SII's strings, else the device's own
//! SDO Information; `names_from` says which. Against the real binaries.

use std::time::Duration;

use ecmxf_e2e::{Daemon, config, run, temp_dir};
use serde_json::Value;

/// What the daemon logs once its devices have named its image's entries
/// (a second pass after the first image: nothing waits for it).
const NAMED: &str = "process image entries named by their devices";

/// Every PDO and entry (gaps, index 0, left out) without a name, as
/// "slave S PDO 0x.... entry 0x....:..".
fn unnamed(report: &Value) -> Vec<String> {
    let mut out = Vec::new();
    for s in report["slaves"].as_array().expect("slaves") {
        for list in ["rx_pdos", "tx_pdos"] {
            for p in s[list].as_array().expect("PDO list") {
                let at = format!("slave {} PDO {:#06x}", s["slave"], p["index"].as_u64().unwrap_or(0));
                if p["name"].as_str().unwrap_or("").is_empty() {
                    out.push(at.clone());
                }
                for e in p["entries"].as_array().expect("entries") {
                    if e["index"].as_u64() != Some(0) && e["name"].as_str().unwrap_or("").is_empty() {
                        let (index, sub) = (e["index"].as_u64().unwrap_or(0), e["subindex"].as_u64().unwrap_or(0));
                        out.push(format!("{at} entry {index:#06x}:{sub:02x}"));
                    }
                }
            }
        }
    }
    out
}

fn entries(report: &Value) -> usize {
    report["slaves"]
        .as_array()
        .into_iter()
        .flatten()
        .flat_map(|s| ["rx_pdos", "tx_pdos"].map(|l| s[l].as_array().cloned().unwrap_or_default()))
        .flatten()
        .map(|p| p["entries"].as_array().map_or(0, Vec::len))
        .sum()
}

/// `ecmxfd --sim`: the demo devices name their PDOs and entries as a
/// real device does (CiA 402 "Controlword", "Statusword", ...), so the
/// names `SLAVE.PDO.ENTRY` are there to try.
#[test]
fn the_demo_network_names_every_entry() {
    let mut d = Daemon::binary_sim();
    run(async {
        d.connect().await;
        assert!(d.logged(NAMED, Duration::from_secs(10)).await, "{}", d.log());
    });
    let out = d.ctl(&["--json", "pdos"]);
    let report = out.json();
    ecmxf_e2e::assert_schema("pdos", &report);
    assert!(entries(&report) >= 40, "the demo maps 42 entries: {}", out.stdout);
    assert_eq!(unnamed(&report), Vec::<String>::new(), "{}", out.stdout);
    for s in report["slaves"].as_array().expect("slaves") {
        assert_ne!(s["names_from"], "none", "slave {} names its entries", s["slave"]);
        assert_ne!(s["names_from"], "", "slave {} says where its names are from", s["slave"]);
    }
    let text = d.ctl(&["pdos"]);
    assert!(text.ok().contains("Statusword"), "{}", text.stdout);
}

/// A network read over CoE and configured without `esi =`: the daemon has
/// only the device itself, and still names every entry (SII strings, SDO
/// Information) and says where the names are from.
#[test]
fn a_coe_network_without_an_esi_is_named_by_the_device() {
    let Some(elmo) = ecmxf_e2e::fixture("esi_elmo_gold_Elmo_ECAT_00010420_V11.xml") else { return };
    run(async {
        let dir = temp_dir("pdo-names");
        let device = format!("esi = \"{}\"\nproduct_code = 0x30924\nrevision = 0x10420\n", elmo.display());
        let link = ecmxf_e2e::sim_network(&dir, &format!("[[slave]]\n{device}[[slave]]\n{device}"));
        // The daemon's configuration names no ESI.
        let mut d = Daemon::binary_with_config(&config(&link, ""));
        d.connect().await;
        assert!(d.logged(NAMED, Duration::from_secs(10)).await, "{}", d.log());
        let out = d.ctl(&["--json", "pdos"]);
        let report = out.json();
        ecmxf_e2e::assert_schema("pdos", &report);
        assert!(entries(&report) > 0, "{}", out.stdout);
        assert_eq!(unnamed(&report), Vec::<String>::new(), "{}", out.stdout);
        for s in report["slaves"].as_array().expect("slaves") {
            assert_eq!(s["source"], "coe", "{}", out.stdout);
            let from = s["names_from"].as_str().unwrap_or("");
            assert!(["sii", "sdo_info"].contains(&from), "slave {}: names from {from:?}", s["slave"]);
        }
        let _ = std::fs::remove_dir_all(&dir);
    });
}
