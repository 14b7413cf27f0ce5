//! The OPC UA server (docs/opcua.md) against an independent client:
//! Python's asyncua from PyPI (tests/python/opcua_client.py, in the venv
//! `.ci/run` makes), the real daemon, the simulator.
//!
//! - Browsing finds every slave with the identity `ecmxfctl --json slaves`
//!   gives, and every process-image entry with its name, its device's
//!   name for it and the OPC UA type of its CoE type: on the demo network
//!   and on seven Elmo drives known only from what they say of themselves.
//! - A subscription sees what flows: values written to the IO slave's
//!   outputs come back through its loopback, in order, each stamped with
//!   its input frame's time and none older than two sampling intervals,
//!   each the value StreamInputs gave for the frame of that time.
//! - A drive fault raised in the simulator reaches an event subscriber as
//!   an OPC UA event from that slave, within 100 ms.
//! - 200 connections that never say Hello are bounded by the listener's
//!   caps and closed at the deadline, while the gRPC administrator and an
//!   established OPC UA session keep being answered.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

use ecmxf_e2e::opcua::{free_port, last_json};
use ecmxf_e2e::{Daemon, by_entry, closed_within, config, connect_from, run};
use ecmxf_proto::v1 as pb;
use pb::process_data_client::ProcessDataClient;
use pb::value::Kind;
use serde_json::Value;

/// One OPC UA test at a time: several daemons and Python clients at once
/// on 2 cores would measure the machine, not the server (freshness is
/// judged in milliseconds).
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn turn() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

/// What the daemon logs once the devices named the image's entries.
const NAMED: &str = "process image entries named by their devices";

fn python() -> Option<PathBuf> {
    let imports = |python: &std::path::Path| {
        Command::new(python).args(["-c", "import asyncua"]).output().is_ok_and(|o| o.status.success())
    };
    let install = "python3 -m venv target/py-venv; target/py-venv/bin/pip install -r tests/python/requirements.txt";
    ecmxf_e2e::installed_tool("ECMXF_PYTHON", "target/py-venv/bin/python", imports, "ECMXF_REQUIRE_PYTHON", install)
}

/// The demo network with OPC UA on a port of its own, `extra` lines in
/// `[opcua]`.
fn daemon_with(extra: &str) -> (Daemon, u16) {
    let port = free_port();
    let link = "backend = \"sim\"\nnetwork = \"{repo}/config/demo-network.toml\"";
    let d = Daemon::binary_with_config(&config(link, &format!("[opcua]\nlisten = \"127.0.0.1:{port}\"\n{extra}")));
    (d, port)
}

fn daemon() -> (Daemon, String) {
    let (d, port) = daemon_with("");
    (d, format!("opc.tcp://127.0.0.1:{port}/"))
}

fn client(python: &PathBuf, args: &[&str]) -> Command {
    let mut c = Command::new(python);
    c.arg(ecmxf_e2e::repo().join("tests/python/opcua_client.py")).args(args);
    c
}

/// What an independent client browses on `url` is what `ecmxfctl` says
/// of the network: every slave's identity, every entry's name and type.
fn browsed_as_ecmxfctl_says(d: &Daemon, python: &PathBuf, url: &str, all_labelled: bool) {
    let slaves = d.ctl(&["--json", "slaves"]).json();
    let pdos = d.ctl(&["--json", "pdos"]).json();
    let space = last_json(&client(python, &[url, "browse"]).output().expect("python"));
    ecmxf_e2e::opcua::browsed_as_ecmxfctl_says(&space, &slaves, &pdos, all_labelled);
}

#[test]
fn every_slave_and_entry_of_the_demo_is_browsed_with_its_identity_name_and_type() {
    let Some(python) = python() else { return };
    let _turn = turn();
    let (mut d, url) = daemon();
    run(async {
        d.connect().await;
        assert!(d.logged(NAMED, Duration::from_secs(10)).await, "{}", d.log());
    });
    browsed_as_ecmxfctl_says(&d, &python, &url, true);
    assert_eq!(d.stop(), Some(0), "{}", d.log());
}

/// Seven Elmo Gold drives from the vendor's ESI (the simulator's; the
/// daemon has none): what the drives say of themselves is what is browsed.
#[test]
fn seven_elmo_drives_are_browsed_as_ecmxfctl_lists_them() {
    let Some(python) = python() else { return };
    let _turn = turn();
    let Some(elmo) = ecmxf_e2e::fixture("esi_elmo_gold_Elmo_ECAT_00010420_V11.xml") else { return };
    let dir = ecmxf_e2e::temp_dir("opcua-elmo");
    let device = format!("[[slave]]\nesi = \"{}\"\nproduct_code = 0x30924\nrevision = 0x10420\n", elmo.display());
    let link = ecmxf_e2e::sim_network(&dir, &device.repeat(7));
    let port = free_port();
    let mut d = Daemon::binary_with_config(&config(&link, &format!("[opcua]\nlisten = \"127.0.0.1:{port}\"\n")));
    run(async {
        d.connect().await;
        assert!(d.logged("process image laid out", Duration::from_secs(20)).await, "{}", d.log());
        // Names the SII lacks come from the drives just after; when the
        // SII names them all, nothing is logged.
        let _ = d.logged(NAMED, Duration::from_secs(5)).await;
    });
    browsed_as_ecmxfctl_says(&d, &python, &format!("opc.tcp://127.0.0.1:{port}/"), false);
    assert_eq!(d.stop(), Some(0), "{}", d.log());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_subscription_sees_outputs_come_back_through_the_loopback_in_order_and_fresh() {
    let Some(python) = python() else { return };
    let _turn = turn();
    let (mut d, url) = daemon();
    run(async {
        let ch = d.connect().await;
        let mut pd = ProcessDataClient::new(ch);
        let layout = pd.get_layout(pb::GetLayoutRequest {}).await.expect("layout").into_inner();
        let input = layout.entries.iter().find(|e| e.slave == 2 && e.index == 0x6000).expect("the IO slave's inputs");
        let output = layout.entries.iter().find(|e| e.slave == 2 && e.index == 0x7000).expect("its outputs");
        let (input_id, output_id) =
            (format!("EtherCAT.Slaves.2.in.{}", input.name), format!("EtherCAT.Slaves.2.out.{}", output.name));
        let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 0 }).await.unwrap();
        let lease = lease.into_inner().id;
        let write = |v: u64| pb::WriteOutputsRequest {
            lease_id: lease.clone(),
            writes: vec![by_entry(&output.name, Kind::Unsigned(v))],
        };
        pd.write_outputs(write(0)).await.unwrap();
        // The same input from StreamInputs, every frame: (its time on the
        // host's CLOCK_MONOTONIC, its value).
        let mut stream = pd
            .stream_inputs(pb::StreamInputsRequest { entries: vec![input.name.clone()], ..Default::default() })
            .await
            .expect("StreamInputs")
            .into_inner();
        let frames = tokio::spawn(async move {
            let mut frames = Vec::new();
            let end = tokio::time::Instant::now() + Duration::from_millis(3600);
            while let Ok(Ok(Some(s))) = tokio::time::timeout_at(end, stream.message()).await {
                if let Some(Kind::Unsigned(v)) = s.values.first().and_then(|v| v.value.as_ref()?.kind.clone()) {
                    frames.push((s.monotonic_ns, v));
                }
            }
            frames
        });

        // 50 ms: the fastest sampling the server offers (docs/opcua.md),
        // publishing as often.
        let mut sub = client(&python, &[&url, "subscribe", "3", "50", &input_id, &output_id, "EtherCAT.Exchanges"]);
        let child = sub.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("python");
        let out = tokio::task::spawn_blocking(move || child.wait_with_output());
        // Its "subscribed" line is not waited for: values written before
        // the items exist are simply not seen, and five go out over 2 s.
        tokio::time::sleep(Duration::from_millis(700)).await;
        let values = [0x11u64, 0x22, 0x44, 0x88, 0xFF];
        for v in values {
            pd.write_outputs(write(v)).await.unwrap();
            tokio::time::sleep(Duration::from_millis(400)).await;
        }
        let seen = last_json(&out.await.unwrap().expect("python"));
        let seen = seen.as_array().expect("changes");
        let of = |id: &str| -> Vec<&Value> { seen.iter().filter(|c| c["node_id"] == id).collect() };
        let inputs: Vec<u64> = of(&input_id).iter().filter_map(|c| c["value"].as_u64()).collect();
        let outputs: Vec<u64> = of(&output_id).iter().filter_map(|c| c["value"].as_u64()).collect();
        // Every value written, looped back, in the order written.
        let wanted: Vec<u64> = values.to_vec();
        let looped: Vec<u64> = inputs.iter().copied().filter(|v| wanted.contains(v)).collect();
        assert_eq!(looped, wanted, "inputs seen: {inputs:?}");
        let written: Vec<u64> = outputs.iter().copied().filter(|v| wanted.contains(v)).collect();
        assert_eq!(written, wanted, "outputs seen: {outputs:?}");
        // Each input change is its frame's value, stamped with the frame's
        // time: never ahead of its arrival, never two intervals behind.
        let mut last = 0.0;
        let oldest = of(&input_id)
            .iter()
            .filter_map(|c| Some(c["arrived_ms"].as_f64()? - c["source_ms"].as_f64()?))
            .fold(0.0, f64::max);
        eprintln!("the oldest input value on arrival: {oldest:.1} ms");
        for c in of(&input_id) {
            assert_eq!(c["status"], "Good", "{c}");
            let (source, arrived) = (c["source_ms"].as_f64().unwrap(), c["arrived_ms"].as_f64().unwrap());
            assert!(source >= last, "source times go forward: {c}");
            assert!(source <= arrived + 5.0, "stamped after it arrived: {c}");
            assert!(arrived - source < 100.0, "older than 2 sampling intervals: {c}");
            last = source;
        }
        // Each input value is one StreamInputs gave for a frame of its
        // SourceTimestamp: the time the daemon received the frame. An
        // exchange brings several frames, received within microseconds,
        // so the value is one of those (the newest the daemon had when the
        // server sampled); cycles are 1 ms apart. Both clocks are this
        // host's.
        let frames = frames.await.unwrap();
        let wall_minus_monotonic = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos()
            .saturating_sub(u128::from(ecmxfd::realtime::monotonic_ns())) as f64;
        assert!(frames.len() > 2000, "StreamInputs: {} frames", frames.len());
        for c in of(&input_id) {
            let at = c["source_ms"].as_f64().unwrap() * 1e6 - wall_minus_monotonic;
            let received_then: Vec<u64> =
                frames.iter().filter(|(t, _)| (*t as f64 - at).abs() < 50_000.0).map(|(_, v)| *v).collect();
            let v = c["value"].as_u64().unwrap();
            assert!(received_then.contains(&v), "{c}: StreamInputs frames received then held {received_then:?}");
        }
        // The counters move while subscribed.
        let exchanges: Vec<u64> = of("EtherCAT.Exchanges").iter().filter_map(|c| c["value"].as_u64()).collect();
        assert!(exchanges.len() >= 10 && exchanges.windows(2).all(|w| w[0] < w[1]), "{exchanges:?}");
    });
    assert_eq!(d.stop(), Some(0), "{}", d.log());
}

#[test]
fn silent_connections_are_capped_and_closed_while_a_session_and_the_admin_are_answered() {
    let Some(python) = python() else { return };
    let _turn = turn();
    let (mut d, port) = daemon_with("max_connections = 64\nmax_connections_per_peer = 8\nhello_timeout_s = 1\n");
    let url = format!("opc.tcp://127.0.0.1:{port}/");
    run(async {
        let unix = d.connect().await;
        // The established session: a subscription to the exchange counter
        // for the whole flood.
        let mut sub = client(&python, &[&url, "subscribe", "4", "100", "EtherCAT.Exchanges"]);
        let mut child = sub.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("python");
        let mut stdout =
            tokio::io::BufReader::new(tokio::process::ChildStdout::from_std(child.stdout.take().unwrap()).unwrap());
        let mut line = String::new();
        use tokio::io::AsyncBufReadExt;
        tokio::time::timeout(Duration::from_secs(10), stdout.read_line(&mut line)).await.expect("subscribed").unwrap();
        assert_eq!(line.trim(), "subscribed");

        // The administrator asks every 50 ms throughout.
        let (done_tx, mut done_rx) = tokio::sync::watch::channel(false);
        let admin = tokio::spawn(async move {
            let mut master = pb::master_client::MasterClient::new(unix);
            let mut slowest = Duration::ZERO;
            while !*done_rx.borrow_and_update() {
                let t = std::time::Instant::now();
                master.get_status(pb::GetStatusRequest {}).await.expect("GetStatus");
                slowest = slowest.max(t.elapsed());
                let _ = tokio::time::timeout(Duration::from_millis(50), done_rx.changed()).await;
            }
            slowest
        });
        // 200 silent peers from 25 addresses: 8 each fill their cap, and
        // 64 in all the listener's.
        let mut waits = tokio::task::JoinSet::new();
        for n in 0..200u32 {
            let from = std::net::Ipv4Addr::new(127, 0, 1, 1 + (n / 8) as u8);
            let s = connect_from(from, port).await.expect("loopback connect");
            waits.spawn(closed_within(s, Duration::from_secs(3)));
        }
        let mut closed = Vec::new();
        while let Some(c) = waits.join_next().await {
            closed.push(c.unwrap());
        }
        done_tx.send(true).unwrap();
        let slowest = admin.await.unwrap();
        let open = closed.iter().filter(|c| c.is_none()).count();
        assert_eq!(open, 0, "{open} of 200 silent connections still open after 3 s");
        let at_once = closed.iter().flatten().filter(|t| **t < Duration::from_millis(500)).count();
        assert!(at_once >= 200 - 64, "over the caps, closed at once: {at_once}");
        assert!(slowest < Duration::from_millis(100), "slowest GetStatus: {slowest:?}");

        let mut rest = String::new();
        tokio::io::AsyncReadExt::read_to_string(&mut stdout, &mut rest).await.unwrap();
        child.wait().unwrap();
        let seen: Value = serde_json::from_str(rest.lines().last().unwrap_or("")).expect("changes");
        let arrived: Vec<f64> = seen.as_array().unwrap().iter().filter_map(|c| c["arrived_ms"].as_f64()).collect();
        let gap = arrived.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
        assert!(arrived.len() >= 20, "the session kept publishing: {} changes", arrived.len());
        assert!(gap < 300.0, "the session's longest silence: {gap} ms");
    });
    assert_eq!(d.stop(), Some(0), "{}", d.log());
}

#[test]
fn a_drive_fault_arrives_as_an_event_from_its_slave_within_100_ms() {
    let Some(python) = python() else { return };
    let _turn = turn();
    let dir = ecmxf_e2e::temp_dir("opcua-emcy");
    let sim = ecmxf_e2e::Simulator::serve(&dir, &[]);
    let port = free_port();
    let extra = format!("{}[opcua]\nlisten = \"127.0.0.1:{port}\"\n", ecmxf_e2e::TI_AXIS);
    let mut d = Daemon::binary_with_config(&config(&sim.link(), &extra));
    let url = format!("opc.tcp://127.0.0.1:{port}/");
    run(async {
        d.connect().await;
        let mut sub = client(&python, &[&url, "events", "2", "50"]);
        let mut child = sub.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("python");
        let stdout = tokio::process::ChildStdout::from_std(child.stdout.take().unwrap()).unwrap();
        let mut stdout = tokio::io::BufReader::new(stdout);
        let mut line = String::new();
        use tokio::io::AsyncBufReadExt;
        tokio::time::timeout(Duration::from_secs(10), stdout.read_line(&mut line)).await.expect("subscribed").unwrap();
        assert_eq!(line.trim(), "subscribed");
        tokio::time::sleep(Duration::from_millis(200)).await;
        let raised_ms =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_secs_f64() * 1000.0;
        sim.ctl("drive-fault 1 0 0x2310");
        let mut rest = String::new();
        tokio::io::AsyncReadExt::read_to_string(&mut stdout, &mut rest).await.unwrap();
        child.wait().unwrap();
        let seen: Value = serde_json::from_str(rest.lines().last().unwrap_or("")).expect("events");
        let emergency = seen
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["message"].as_str().is_some_and(|m| m.contains("emergency 0x2310")))
            .unwrap_or_else(|| panic!("no emergency event: {seen}"));
        assert_eq!(emergency["source_node"], "EtherCAT.Slaves.1", "{emergency}");
        assert_eq!(emergency["source_name"], "slave 1");
        assert!(emergency["severity"].as_u64() >= Some(500), "{emergency}");
        let latency = emergency["arrived_ms"].as_f64().unwrap() - raised_ms;
        println!("emergency event {latency:.1} ms after the fault was raised");
        assert!(latency < 100.0, "the event took {latency:.1} ms: {emergency}");
    });
    assert_eq!(d.stop(), Some(0), "{}", d.log());
    drop(sim);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Operators op1 and op2 (passwords op1-secret and op2-secret) and plc
/// (an X.509 user certificate), anonymous sessions observers, and the
/// client certificates op1, op2, stranger and plc the client makes as OPC
/// UA clients make their own.
struct Secured {
    daemon: Daemon,
    url: String,
    certs: PathBuf,
    pki: PathBuf,
    metrics: u16,
}

fn secured(python: &PathBuf) -> Secured {
    secured_with(python, "")
}

/// [`secured`] with `extra` sections after `[opcua]`'s. The certificate
/// `plc` is the X.509 identity of an operator, by its thumbprint.
fn secured_with(python: &PathBuf, extra: &str) -> Secured {
    use sha2::{Digest, Sha256};
    let certs = ecmxf_e2e::temp_dir("opcua-certs");
    let mut thumbprint = String::new();
    for name in ["op1", "op2", "stranger", "plc"] {
        let made = client(python, &["-", "makecert", certs.to_str().unwrap(), name]).output().expect("python");
        thumbprint = last_json(&made)["thumbprint"].as_str().unwrap().to_string();
    }
    let mut users = String::new();
    for name in ["op1", "op2"] {
        let hash: String =
            Sha256::digest(format!("{name}-secret")).iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().concat();
        users += &format!("[[opcua.user]]\nname = \"{name}\"\npassword_sha256 = \"{hash}\"\nrole = \"operator\"\n");
    }
    users +=
        &format!("[[opcua.certificate_user]]\nname = \"plc\"\nthumbprint = \"{thumbprint}\"\nrole = \"operator\"\n");
    let metrics = free_port();
    let (daemon, port) =
        daemon_with(&format!("pki_dir = \"{{dir}}/pki\"\n{users}[metrics]\nlisten = \"127.0.0.1:{metrics}\"\n{extra}"));
    let url = format!("opc.tcp://127.0.0.1:{port}/");
    let pki = daemon.dir.join("pki");
    Secured { daemon, url, certs, pki, metrics }
}

impl Secured {
    /// Object `index`:00 of `slave` as the gRPC API uploads it.
    fn uploaded(&mut self, slave: u32, index: u32) -> Vec<u8> {
        self.uploaded_sub(slave, index, 0)
    }

    /// What the gRPC API uploads from `slave`'s `index`:`subindex`.
    fn uploaded_sub(&mut self, slave: u32, index: u32, subindex: u32) -> Vec<u8> {
        let d = &mut self.daemon;
        let mut raw = Vec::new();
        run(async {
            let mut sdo = pb::sdo_client::SdoClient::new(d.connect().await);
            let up = sdo.upload(pb::SdoUploadRequest { slave, index, subindex, ..Default::default() }).await;
            raw = up.expect("upload").into_inner().raw;
        });
        raw
    }

    /// Stops the daemon, which must exit 0.
    fn stop(&mut self) {
        assert_eq!(self.daemon.stop(), Some(0), "{}", self.daemon.log());
    }

    /// Waits until the daemon answers and its process image is laid out
    /// and named (the slaves' nodes are made again then).
    fn ready(&mut self) {
        let d = &mut self.daemon;
        run(async {
            d.connect().await;
            assert!(d.logged(NAMED, Duration::from_secs(10)).await, "{}", d.log());
        });
    }

    /// Trusts a client's certificate as an administrator does: copied into
    /// trusted/ under a name of their own, while the daemon runs.
    fn trust(&self, name: &str) {
        let to = self.pki.join("trusted").join(format!("{name}-client.der"));
        std::fs::copy(self.certs.join(format!("{name}.der")), to).expect("copy into trusted/");
    }

    /// A metric's value from the daemon's metrics endpoint.
    fn metric(&self, name: &str) -> f64 {
        use std::io::{Read, Write};
        let mut s = std::net::TcpStream::connect(("127.0.0.1", self.metrics)).expect("metrics endpoint");
        s.write_all(b"GET /metrics HTTP/1.0\r\nHost: x\r\n\r\n").unwrap();
        let mut text = String::new();
        s.read_to_string(&mut text).unwrap();
        let line = text.lines().find(|l| l.split(' ').next() == Some(name));
        line.and_then(|l| l.split(' ').nth(1)?.parse().ok()).unwrap_or_else(|| panic!("no {name}:\n{text}"))
    }

    fn run(&self, python: &PathBuf, args: &[&str]) -> Value {
        let mut all = vec![self.url.as_str(), args[0], self.certs.to_str().unwrap()];
        all.extend_from_slice(&args[1..]);
        last_json(&client(python, &all).output().expect("python"))
    }
}

#[test]
fn operators_write_outputs_under_a_lease_their_session_holds_and_observers_cannot() {
    let Some(python) = python() else { return };
    let _turn = turn();
    let mut s = secured(&python);
    s.ready();
    s.trust("op1");
    s.trust("op2");
    let (out, input) = ("EtherCAT.Slaves.2.out.2.0x7000:01", "EtherCAT.Slaves.2.in.2.0x6000:01");
    let r = s.run(&python, &["writes", out, input]);
    // Anonymous: refused with the reason, nothing written.
    assert_eq!(r["anonymous"][0], "BadUserAccessDenied", "{r}");
    assert!(r["anonymous"][1].as_str().unwrap_or("").contains("operator"), "{r}");
    assert_eq!(r["anonymous_changed"], false, "{r}");
    // An operator's value reaches the slave and comes back through the
    // loopback.
    assert_eq!(r["op1"][0], "Good", "{r}");
    assert_eq!(r["op1_read_back"], 0x5A, "{r}");
    // A second operator is refused while the first session holds the
    // lease, told who holds it; nothing of theirs is written.
    assert_eq!(r["op2_while_op1"][0], "BadUserAccessDenied", "{r}");
    assert!(r["op2_while_op1"][1].as_str().unwrap_or("").contains("opcua:op1"), "the holder is named: {r}");
    assert_eq!(r["after_op2"], 0x5A, "{r}");
    // Closing the first session frees the outputs.
    assert_eq!(r["op2_after_op1_closed"][0], "Good", "{r}");
    assert_eq!(r["op2_read_back"], 0x66, "{r}");
    let log = s.daemon.log();
    assert!(log.contains("output lease released") && log.contains("opcua:op1"), "{log}");
    // The two writes done, the anonymous one and op2's (or more: op2
    // retries until op1's lease goes) refused, on the metrics endpoint.
    assert_eq!(s.metric("ecmxf_opcua_writes_total"), 2.0);
    assert!(s.metric("ecmxf_opcua_refused_total") >= 2.0);
    assert_eq!(s.daemon.stop(), Some(0), "{log}");
}

#[test]
fn methods_move_typed_values_over_sdo_and_walk_a_slave_through_its_states() {
    let Some(python) = python() else { return };
    let _turn = turn();
    let mut s = secured(&python);
    s.ready();
    s.trust("op1");
    let r = s.run(&python, &["methods", "0"]);
    // 0x1018:01, the vendor id, typed UNSIGNED32: what ecmxfctl lists.
    let slaves = s.daemon.ctl(&["--json", "slaves"]).json();
    assert_eq!(r["upload_vendor"]["status"], "Good", "{r}");
    assert_eq!(r["upload_vendor"]["value"], slaves["slaves"][0]["vendor_id"], "{r}");
    assert_eq!(r["anonymous_download"], "BadUserAccessDenied", "{r}");
    assert_eq!(r["download"], "Good", "{r}");
    assert_eq!(r["read_back"], 4321, "{r}");
    // A value of another kind, or one the object's type cannot hold, is
    // refused before anything is sent.
    assert_eq!(r["mistyped"], "BadInvalidArgument", "{r}");
    assert_eq!(r["too_big"], "BadInvalidArgument", "{r}");
    assert_eq!((&r["to_preop"], &r["state_preop"]), (&Value::from("Good"), &Value::from("PREOP")), "{r}");
    assert_eq!((&r["to_op"], &r["state_op"]), (&Value::from("Good"), &Value::from("OP")), "{r}");
    assert_eq!(r["bad_state"], "BadInvalidArgument", "{r}");
    // What the gRPC API reads of the object is what was downloaded.
    assert_eq!(s.uploaded(0, 0x6083), 4321u32.to_le_bytes());
    s.stop();
}

#[test]
fn only_trusted_client_certificates_open_encrypted_sessions_and_passwords_name_roles() {
    let Some(python) = python() else { return };
    let _turn = turn();
    let mut s = secured(&python);
    s.ready();
    s.trust("op1");
    // Both policies, signed and encrypted: an operator sees outputs
    // writable, an anonymous session on the same certificate does not.
    for policy in ["Basic256Sha256", "Aes128Sha256RsaOaep"] {
        let r = s.run(&python, &["connect", "op1", policy, "op1", "op1-secret"]);
        assert_eq!((&r["ok"], &r["role_write"]), (&Value::from(true), &Value::from(true)), "{policy}: {r}");
    }
    let r = s.run(&python, &["connect", "op1", "Basic256Sha256"]);
    assert_eq!((&r["ok"], &r["role_write"]), (&Value::from(true), &Value::from(false)), "{r}");
    // An X.509 user identity named by its thumbprint is an operator; one
    // no [[opcua.certificate_user]] names is refused.
    let r = s.run(&python, &["connect", "op1", "Basic256Sha256", "cert:plc"]);
    assert_eq!((&r["ok"], &r["role_write"]), (&Value::from(true), &Value::from(true)), "{r}");
    let r = s.run(&python, &["connect", "op1", "Basic256Sha256", "cert:stranger"]);
    assert_eq!((&r["ok"], &r["error"]), (&Value::from(false), &Value::from("BadIdentityTokenRejected")), "{r}");
    let r = s.run(&python, &["connect", "op1", "Basic256Sha256", "op1", "op2-secret"]);
    assert_eq!((&r["ok"], &r["error"]), (&Value::from(false), &Value::from("BadIdentityTokenRejected")), "{r}");
    // An unknown certificate is refused and kept in rejected/, where an
    // administrator finds it.
    let r = s.run(&python, &["connect", "stranger", "Basic256Sha256"]);
    assert_eq!((&r["ok"], &r["error"]), (&Value::from(false), &Value::from("BadCertificateUntrusted")), "{r}");
    let rejected: Vec<String> = std::fs::read_dir(s.pki.join("rejected"))
        .expect("pki/rejected")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert!(rejected.iter().any(|n| n.contains("stranger")), "rejected/: {rejected:?}");
    // The server's own certificate was made at first start.
    assert!(s.pki.join("own/cert.der").exists() && s.pki.join("private/private.pem").exists());
    s.stop();
}

#[test]
fn an_axis_is_enabled_disabled_and_set_to_a_mode_by_an_operator_and_shows_its_state() {
    let Some(python) = python() else { return };
    let _turn = turn();
    let mut s = secured_with(&python, ecmxf_e2e::TI_AXIS);
    s.ready();
    s.trust("op1");
    let r = s.run(&python, &["axis", "0"]);
    assert_eq!(r["anonymous_enable"], "BadUserAccessDenied", "{r}");
    // Each command answers the state the drive reached, and the State
    // variable (decoded from the statusword the inputs carry) agrees.
    for (step, state) in
        [("Disable", "SWITCH ON DISABLED"), ("Enable", "OPERATION ENABLED"), ("SetMode", "OPERATION ENABLED")]
    {
        assert_eq!(r[step]["status"], "Good", "{step}: {r}");
        assert_eq!(r[step]["state"], state, "{step}: {r}");
        assert_eq!(r[step]["read"], state, "{step}: {r}");
    }
    assert_eq!(r["Enable"]["statusword"].as_u64().unwrap() & 0x6F, 0x27, "{r}");
    assert_eq!(r["bad_mode"], "BadInvalidArgument", "{r}");
    // The mode went out under op1's session lease, shown by the drive.
    run(async {
        let mut cia = pb::cia402_client::Cia402Client::new(s.daemon.connect().await);
        let st = cia.get_axis(pb::GetAxisRequest { axis: 0 }).await.expect("status").into_inner();
        assert_eq!(st.mode_display, 9, "{st:?}");
    });
    s.stop();
}

#[test]
fn a_dictionary_entry_is_read_from_the_device_and_written_by_an_operator_only() {
    let Some(python) = python() else { return };
    let _turn = turn();
    let mut s = secured(&python);
    s.ready();
    s.trust("op1");
    // 0x6083:00, the drive's profile acceleration (UNSIGNED32).
    let r = s.run(&python, &["dictionary", "0", "0x6083:00"]);
    assert_eq!(r["data_type"], 7, "UInt32: {r}");
    assert!(r["read"].is_u64(), "{r}");
    assert_eq!(r["anonymous_write"][0], "BadUserAccessDenied", "{r}");
    assert_eq!(r["op1_write"][0], "Good", "{r}");
    assert_eq!(r["read_fresh"], 999, "MaxAge 0 reads the device: {r}");
    assert_eq!(r["op1_write_again"][0], "Good", "{r}");
    assert_eq!(r["read_aged"], 999, "MaxAge 60 s takes the value uploaded last: {r}");
    assert_eq!(r["read_now"], 1000, "{r}");
    // A number the entry cannot hold is refused naming its type.
    assert_eq!(r["too_big"][0], "BadOutOfRange", "-1 for a UInt32 entry: {r}");
    assert!(r["too_big"][1].as_str().unwrap_or("").contains("UNSIGNED32"), "{r}");
    // The device holds what the operator wrote.
    assert_eq!(s.uploaded(0, 0x6083), 1000u32.to_le_bytes());
    // DI's SerialNumber and SoftwareRevision are the device's 0x1018:04
    // and 0x100A, as text.
    let serial = u32::from_le_bytes(s.uploaded_sub(0, 0x1018, 4).try_into().expect("4 bytes"));
    assert_eq!(r["SerialNumber"], serial.to_string(), "{r}");
    let software = String::from_utf8(s.uploaded(0, 0x100A)).expect("text");
    assert_eq!(r["SoftwareRevision"], software.trim_end_matches('\0'), "{r}");
    s.stop();
}
