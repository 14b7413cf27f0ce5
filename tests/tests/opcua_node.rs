//! The OPC UA server (docs/opcua.md) against a second independent client:
//! node-opcua from the npm registry (tests/node/opcua_client.js, at the
//! versions tests/node/package-lock.json pins, installed into
//! target/node by `.ci/run`), a stack of its own beside asyncua
//! (tests/tests/opcua.rs), the real daemon, the simulator.
//!
//! - Browsing finds every slave with the identity `ecmxfctl --json slaves`
//!   gives, and every process-image entry with its name, its device's
//!   name for it and the OPC UA type of its CoE type, under the node ids
//!   docs/opcua.md gives; nothing node-opcua reads there is odd to it (an
//!   attribute that does not read Good, a value of another type than its
//!   variable's DataType, a failed browse); every slave has its methods,
//!   every endpoint the address the client reached. The same for seven
//!   Elmo drives known only from what they say of themselves.
//! - A subscription at 100 ms sampling sees values flow: the exchange
//!   counter arrives Good and increasing, an input arrives Good.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use ecmxf_e2e::opcua::{free_port, last_json};
use ecmxf_e2e::{Daemon, config, run};
use serde_json::Value;

/// What the daemon logs once the devices named the image's entries.
const NAMED: &str = "process image entries named by their devices";

/// The demo network with OPC UA on a port of its own.
fn daemon() -> (Daemon, String) {
    let port = free_port();
    let link = "backend = \"sim\"\nnetwork = \"{repo}/config/demo-network.toml\"";
    let d = Daemon::binary_with_config(&config(link, &format!("[opcua]\nlisten = \"127.0.0.1:{port}\"\n")));
    (d, format!("opc.tcp://127.0.0.1:{port}/"))
}

/// The node-opcua client, its certificate in the daemon's folder (removed
/// with it) rather than under $HOME.
fn client(modules: &Path, d: &Daemon, args: &[&str]) -> Command {
    let mut c = Command::new("node");
    c.arg(ecmxf_e2e::repo().join("tests/node/opcua_client.js"))
        .args(args)
        .env("NODE_PATH", modules)
        .env("ECMXF_NODE_OPCUA_PKI", d.dir.join("node-opcua-pki"));
    c
}

/// What node-opcua browses on `url`, checked to hold nothing odd to it,
/// with what `ecmxfctl` says of the slaves and PDOs: (space, slaves, pdos).
async fn browse(modules: &Path, d: &Daemon, url: &str) -> (Value, Value, Value) {
    let slaves = d.ctl(&["--json", "slaves"]).json();
    let pdos = d.ctl(&["--json", "pdos"]).json();
    let mut browse = client(modules, d, &[url, "browse"]);
    let out = tokio::task::spawn_blocking(move || browse.output()).await.unwrap().expect("node");
    let space = last_json(&out);
    assert_eq!(space["odd"], serde_json::json!([]), "what node-opcua found odd");
    (space, slaves, pdos)
}

#[test]
fn node_opcua_browses_every_slave_and_entry_of_the_demo_as_ecmxfctl_lists_them() {
    let Some(modules) = ecmxf_e2e::node_modules("node-opcua-client") else { return };
    let (mut d, url) = daemon();
    run(async {
        d.connect().await;
        assert!(d.logged(NAMED, Duration::from_secs(10)).await, "{}", d.log());
        let (space, slaves, pdos) = browse(&modules, &d, &url).await;
        // Every endpoint is offered where the client reached it (not where
        // the server listens behind the daemon's connection gate).
        let endpoints = space["endpoints"].as_array().expect("endpoints");
        assert!(!endpoints.is_empty() && endpoints.iter().all(|e| e == url.as_str()), "{endpoints:?}");
        ecmxf_e2e::opcua::browsed_as_ecmxfctl_says(&space, &slaves, &pdos, true);
        for o in space["slaves"].as_array().expect("slaves") {
            assert_eq!(o["node_id"], format!("EtherCAT.Slaves.{}", o["Position"]), "{o}");
        }
    });
    assert_eq!(d.stop(), Some(0), "{}", d.log());
}

/// Seven Elmo Gold drives known only from what they say of themselves
/// (the simulator has the vendor's ESI, the daemon none): node-opcua
/// browses them as `ecmxfctl` lists them, with nothing odd to it.
#[test]
fn node_opcua_browses_seven_elmo_drives_as_ecmxfctl_lists_them() {
    let Some(modules) = ecmxf_e2e::node_modules("node-opcua-client") else { return };
    let Some(elmo) = ecmxf_e2e::fixture("esi_elmo_gold_Elmo_ECAT_00010420_V11.xml") else { return };
    let dir = ecmxf_e2e::temp_dir("opcua-node-elmo");
    let device = format!("[[slave]]\nesi = \"{}\"\nproduct_code = 0x30924\nrevision = 0x10420\n", elmo.display());
    let link = ecmxf_e2e::sim_network(&dir, &device.repeat(7));
    let port = free_port();
    let url = format!("opc.tcp://127.0.0.1:{port}/");
    let mut d = Daemon::binary_with_config(&config(&link, &format!("[opcua]\nlisten = \"127.0.0.1:{port}\"\n")));
    run(async {
        d.connect().await;
        assert!(d.logged("process image laid out", Duration::from_secs(20)).await, "{}", d.log());
        // Names the SII lacks come from the drives just after; when the
        // SII names them all, nothing is logged.
        let _ = d.logged(NAMED, Duration::from_secs(5)).await;
        let (space, slaves, pdos) = browse(&modules, &d, &url).await;
        assert_eq!(space["slaves"].as_array().map(Vec::len), Some(7), "{}", space["slaves"]);
        ecmxf_e2e::opcua::browsed_as_ecmxfctl_says(&space, &slaves, &pdos, false);
    });
    assert_eq!(d.stop(), Some(0), "{}", d.log());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn node_opcua_sees_the_exchange_counter_and_an_input_flow_at_100_ms_sampling() {
    let Some(modules) = ecmxf_e2e::node_modules("node-opcua-client") else { return };
    let (mut d, url) = daemon();
    run(async {
        d.connect().await;
        // The slaves' nodes are replaced once the devices named the
        // entries: subscribed before, the items would go with them.
        assert!(d.logged(NAMED, Duration::from_secs(10)).await, "{}", d.log());
        let pdos = d.ctl(&["--json", "pdos"]).json();
        let entries = pdos["image"]["entries"].as_array().expect("image entries");
        let input =
            entries.iter().find(|e| e["slave"] == 2 && e["direction"] == "input").expect("the IO slave's inputs");
        let input_id = format!("EtherCAT.Slaves.2.in.{}", input["name"].as_str().unwrap());

        // 100 ms: the sampling the server offers (docs/opcua.md).
        let mut sub = client(&modules, &d, &[&url, "subscribe", "1.5", "100", &input_id, "EtherCAT.Exchanges"]);
        let out = tokio::task::spawn_blocking(move || sub.output()).await.unwrap().expect("node");
        let seen = last_json(&out);

        assert_eq!(seen["odd"], serde_json::json!([]), "what node-opcua found odd");
        for id in [input_id.as_str(), "EtherCAT.Exchanges"] {
            assert_eq!(seen["revised"]["sampling_interval_ms"][id], 100, "{id}: {}", seen["revised"]);
        }
        let changes = seen["changes"].as_array().expect("changes");
        let of = |id: &str| -> Vec<&Value> { changes.iter().filter(|c| c["node_id"] == id).collect() };
        for c in changes {
            assert_eq!(c["status"], "Good", "{c}");
        }
        let inputs = of(&input_id);
        assert!(!inputs.is_empty() && inputs.iter().all(|c| c["value"].is_u64()), "{inputs:?}");
        // The counter's values themselves, not only a status: 15 samples
        // in 1.5 s at most, at least one every 300 ms, each further than
        // the last.
        let exchanges: Vec<u64> = of("EtherCAT.Exchanges").iter().filter_map(|c| c["value"].as_u64()).collect();
        assert!(exchanges.len() >= 5 && exchanges.windows(2).all(|w| w[0] < w[1]), "{exchanges:?}");
        let sources: Vec<f64> = of("EtherCAT.Exchanges").iter().filter_map(|c| c["source_ms"].as_f64()).collect();
        assert!(sources.len() == exchanges.len() && sources.windows(2).all(|w| w[0] < w[1]), "{sources:?}");
    });
    assert_eq!(d.stop(), Some(0), "{}", d.log());
}
