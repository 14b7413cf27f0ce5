//! `ecmxfctl` end to end: every command against the real daemon on the
//! simulator, as tables and as `--json` (each JSON output checked against
//! the published schema, docs/ecmxfctl-json-schema.json), with the exit
//! codes scripts rely on.

use ecmxf_e2e::{Ctl, Daemon, TI_AXIS, assert_schema, run};

/// Runs `args` as a table and as JSON (schema `schema`); both must succeed.
/// Returns (table, json).
fn both(d: &Daemon, schema: &str, args: &[&str]) -> (String, serde_json::Value) {
    let text = d.ctl(args).ok().to_owned();
    assert!(!text.trim().is_empty(), "ecmxfctl {args:?} printed nothing");
    assert!(!text.trim_start().starts_with('{'), "ecmxfctl {args:?} printed JSON without --json:\n{text}");
    let mut j = vec!["--json"];
    j.extend_from_slice(args);
    let json = d.ctl(&j).json();
    assert_schema(schema, &json);
    (text, json)
}

/// Every line of a streaming command's --json output, each checked.
fn lines(c: &Ctl, schema: &str) -> Vec<serde_json::Value> {
    let v: Vec<serde_json::Value> = c
        .ok()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("ecmxfctl {}: line not JSON ({e}): {l}", c.args)))
        .collect();
    for x in &v {
        assert_schema(schema, x);
    }
    v
}

fn config() -> String {
    ecmxf_e2e::config("backend = \"sim\"", TI_AXIS)
}

#[test]
fn every_command_works_as_a_table_and_as_json() {
    run(async {
        let mut d = Daemon::binary_with_config(&config());
        d.connect().await;

        // master, slaves, states.
        let (t, j) = both(&d, "master", &["master"]);
        assert!(t.contains("Phase:") && t.contains("RUNNING"), "{t}");
        assert_eq!(j["phase"], "RUNNING");
        assert_eq!(j["slave_count"], 3);
        let (t, j) = both(&d, "slaves", &["slaves"]);
        assert!(t.contains("TI CiA402 3-axis") && t.starts_with("POS"), "{t}");
        assert_eq!(j["slaves"].as_array().unwrap().len(), 3);
        assert_eq!(j["slaves"][1]["state"], "OP");
        let (t, _) = both(&d, "slaves", &["slaves", "-v", "-p", "1"]);
        assert!(t.contains("Station address:") && t.contains("DC:"), "{t}");
        let (_, j) = both(&d, "slaves", &["slaves", "--scan"]);
        assert_eq!(j["matches_config"], true);
        // The IgH verbs: version, graph, rescan.
        let (t, j) = both(&d, "version", &["version"]);
        assert!(t.contains("Chip firmware:") && t.contains("0x24") && t.contains("ecmxf.v1"), "{t}");
        assert_eq!(j["firmware"], 0x24);
        assert_eq!(j["daemon"], j["ecmxfctl"], "one workspace, one version");
        let (t, j) = both(&d, "graph", &["graph"]);
        assert!(t.starts_with("digraph ethercat {") && t.trim_end().ends_with('}'), "{t}");
        assert!(t.contains("master -> slave0;") && t.contains("slave1 -> slave2;"), "{t}");
        assert!(t.contains("1: TI CiA402 3-axis") && t.contains("0x0000059d:0x00000402"), "{t}");
        assert_eq!(j["dot"].as_str(), Some(t.as_str()));
        // Graphviz itself reads it: every slave is a node of the SVG.
        if let Some(dot) = ecmxf_e2e::dot_binary() {
            use std::io::Write as _;
            let mut child = std::process::Command::new(dot)
                .arg("-Tsvg")
                .stdin(std::process::Stdio::piped())
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .expect("run dot");
            child.stdin.take().unwrap().write_all(t.as_bytes()).unwrap();
            let out = child.wait_with_output().unwrap();
            let svg = String::from_utf8_lossy(&out.stdout);
            assert!(out.status.success(), "dot refused the graph: {}", String::from_utf8_lossy(&out.stderr));
            assert!(svg.contains("<svg") && (0..3).all(|n| svg.contains(&format!("<title>slave{n}</title>"))), "{svg}");
        }
        // A slave taken down to PRE-OP is brought back to OP by the rescan's
        // bring-up.
        d.ctl(&["states", "2", "preop"]).ok();
        let (t, j) = both(&d, "rescan", &["rescan"]);
        assert!(t.contains("TI CiA402 3-axis"), "{t}");
        assert_eq!(j["slaves"].as_array().unwrap().len(), 3);
        assert_eq!(j["matches_config"], true);
        assert_eq!(j["slaves"][2]["state"], "OP", "{t}");
        d.connect().await;
        let (t, j) = both(&d, "states", &["states"]);
        assert!(t.starts_with("network: OP"), "{t}");
        assert_eq!(j["slaves"].as_array().unwrap().len(), 3);
        let (t, j) = both(&d, "states", &["states", "2", "safeop"]);
        assert!(t.contains("requested SAFEOP, now SAFEOP"), "{t}");
        assert_eq!(j["state"], "SAFEOP");

        // diag: a slave held below the target is named, exit code 8.
        let c = d.ctl(&["diag"]);
        c.fails(8);
        assert!(c.stdout.contains("slave 2 (8io) is in SAFEOP, not OP"), "{}", c.stdout);
        let c = d.ctl(&["--json", "diag"]);
        c.fails(8);
        let j: serde_json::Value = serde_json::from_str(&c.stdout).unwrap();
        assert_schema("diag", &j);
        assert_eq!(j["healthy"], false);
        assert_eq!(j["slaves"][2]["suspect"], true);
        let e: serde_json::Value = serde_json::from_str(c.stderr.trim()).unwrap();
        assert_schema("error", &e);
        assert_eq!(e["error"]["exit_code"], 8);

        // events: a state change seen while it happens.
        let socket = d.socket.display().to_string();
        let changer = std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(700));
            ecmxf_e2e::ctl(&["--socket", &socket, "states", "2", "op"]).ok().to_owned()
        });
        let ev = d.ctl(&["--json", "events", "--for", "3s"]);
        changer.join().unwrap();
        let ev = lines(&ev, "events");
        assert!(ev.iter().any(|e| e["kind"] == "STATE_CHANGE"), "{ev:?}");
        let (_, j) = both(&d, "diag", &["diag"]);
        assert_eq!(j["healthy"], true, "{j}");
        let t = d.ctl(&["events", "--for", "200ms"]);
        t.ok();

        // SDO.
        let (t, j) = both(&d, "upload", &["upload", "-p", "1", "0x6041"]);
        assert!(t.contains("(0x"), "{t}");
        assert_eq!(j["data_type"], "uint16");
        let (t, j) = both(&d, "upload", &["upload", "-p", "1", "0x1008", "0"]);
        assert!(t.contains("\"TI CiA402 3-axis\""), "{t}");
        assert_eq!(j["value"], "TI CiA402 3-axis");
        let (_, j) = both(&d, "upload", &["upload", "-p", "1", "0x6041", "--type", "int16"]);
        assert_eq!(j["data_type"], "int16");
        let (_, j) = both(&d, "upload", &["upload", "-p", "1", "0x1018", "0", "--complete-access"]);
        assert!(j["raw"].as_str().unwrap().len() >= 2);
        let (t, j) = both(&d, "download", &["download", "-p", "1", "0x605A", "0", "0x2"]);
        assert!(t.contains("wrote 2 bytes"), "{t}");
        assert_eq!(j["bytes_written"], 2);
        let (_, j) = both(&d, "upload", &["upload", "-p", "1", "0x605A"]);
        assert_eq!(j["value"], 2);
        both(&d, "download", &["download", "-p", "1", "0x605A", "0", "-1", "--type", "int16"]);
        let (_, j) = both(&d, "upload", &["upload", "-p", "1", "0x605A"]);
        assert_eq!(j["value"], -1);
        let (t, j) = both(&d, "sdos", &["sdos", "-p", "1", "--source", "probe"]);
        assert!(t.contains("device_type"), "{t}");
        assert_eq!(j["source"], "PROBE");
        let (t, j) = both(&d, "sdos", &["sdos", "-p", "1"]);
        assert!(t.contains("(from the device,"), "{t}");
        assert_eq!(j["source"], "DEVICE");

        // SII: read, decode, dump, write (the same bytes back) with backup.
        let (t, j) = both(&d, "sii read", &["sii", "read", "-p", "2", "--word", "8", "--count", "4"]);
        assert!(t.starts_with("000010"), "{t}");
        let words = j["data"].as_str().unwrap().to_owned();
        assert_eq!(words.len(), 16);
        let (t, j) = both(&d, "sii decode", &["sii", "decode", "-p", "2"]);
        assert!(t.contains("Name:") && t.contains("8io"), "{t}");
        assert_eq!(j["mailbox_protocols"], serde_json::json!(["CoE"]));
        let dump = d.dir.join("sii.bin").display().to_string();
        let (t, j) = both(&d, "sii dump", &["sii", "dump", "-p", "2", "-o", &dump]);
        assert!(t.contains("written to"), "{t}");
        let image = std::fs::read(&dump).unwrap();
        assert_eq!(ecmxf_e2e_hex(&image), j["data"].as_str().unwrap());
        let backup = d.dir.join("backup.bin").display().to_string();
        let (t, j) =
            both(&d, "sii write", &["sii", "write", "-p", "2", "--word", "8", "--hex", &words, "--backup", &backup]);
        assert!(t.contains("verified 4 words"), "{t}");
        assert_eq!(j["words_written"], 4);
        assert_eq!(ecmxf_e2e_hex(&std::fs::read(&backup).unwrap()), words, "the backup holds what was there");
        let c = d.ctl(&["sii", "write", "-p", "2", "--hex", "010203"]);
        assert!(c.fails(2).contains("even number of bytes"), "{}", c.stderr);

        // Process data.
        let (t, j) = both(&d, "pdos", &["pdos"]);
        assert!(t.contains("SM2 outputs: RxPDO 0x1600") && t.contains("1.statusword"), "{t}");
        assert!(j["image"]["entries"].as_array().unwrap().len() > 10);
        let (t, j) = both(&d, "data", &["data"]);
        assert!(t.contains("1.statusword") && t.contains("1.controlword"), "{t}");
        assert!(j["seq"].as_u64().is_some());
        let (t, j) = both(&d, "data", &["data", "--raw"]);
        assert!(t.starts_with("inputs (53 bytes)"), "{t}");
        assert_eq!(j["output_image"].as_str().unwrap().len(), 2 * 53);
        let c = d.ctl(&["data", "1.nothing"]);
        assert!(c.fails(2).contains("\"1.nothing\""), "{}", c.stderr);
        let w = d.ctl(&["watch", "-n", "3", "--interval", "20ms", "1.statusword", "1.controlword"]);
        let text = w.ok();
        assert_eq!(text.lines().count(), 4, "a header and three lines:\n{text}");
        assert!(text.lines().next().unwrap().contains("1.statusword"), "{text}");
        let w = lines(&d.ctl(&["--json", "watch", "-n", "3", "--interval", "10ms"]), "watch");
        assert_eq!(w.len(), 3);
        assert!(w[1]["seq"].as_u64() > w[0]["seq"].as_u64());

        // CiA 402.
        let (t, j) = both(&d, "cia402 status", &["cia402", "status"]);
        assert!(t.starts_with("AXIS"), "{t}");
        assert_eq!(j["axes"].as_array().unwrap().len(), 1);
        let (t, j) = both(&d, "cia402 enable", &["cia402", "enable"]);
        assert!(t.contains("OPERATION_ENABLED"), "{t}");
        assert_eq!(j["state"], "OPERATION_ENABLED");
        let (_, j) = both(&d, "cia402 mode", &["cia402", "mode", "csp"]);
        assert_eq!(j["mode_display"], 8);
        let (t, j) = both(&d, "cia402 move", &["cia402", "move", "--position", "2000", "--wait-within", "100"]);
        assert!(t.contains("reached"), "{t}");
        assert!(j["reached_position"].as_i64().unwrap().abs_diff(2000) <= 100, "{j}");
        let c = d.ctl(&["cia402", "move", "--velocity", "1", "--wait-within", "5"]);
        assert!(c.fails(2).contains("--wait-within"), "{}", c.stderr);
        let (_, j) = both(&d, "cia402 quickstop", &["cia402", "quickstop"]);
        assert_ne!(j["state"], "OPERATION_ENABLED");
        let (_, j) = both(&d, "cia402 disable", &["cia402", "disable"]);
        assert_eq!(j["state"], "SWITCH_ON_DISABLED");
        let (_, j) = both(&d, "cia402 reset", &["cia402", "reset"]);
        assert_eq!(j["state"], "SWITCH_ON_DISABLED");
        let c = d.ctl(&["cia402", "enable", "--axis", "7"]);
        assert!(c.fails(2).contains("no axis 7"), "{}", c.stderr);

        // Peripherals.
        both(&d, "gpio config", &["gpio", "config", "0-3", "output"]);
        let (_, j) = both(&d, "gpio set", &["gpio", "set", "1=1", "3=1"]);
        assert_eq!(j["levels"].as_u64().unwrap() & 0b1010, 0b1010, "{j}");
        let (t, j) = both(&d, "gpio get", &["gpio", "get"]);
        assert!(t.contains("LINE"), "{t}");
        assert_eq!(j["lines"][3]["high"], true);
        both(&d, "gpio set", &["gpio", "set", "3=0"]);
        let (_, j) = both(&d, "gpio get", &["gpio", "get"]);
        assert_eq!(j["lines"][3]["high"], false);
        assert_eq!(j["lines"][1]["high"], true, "other lines keep their level");
        let (_, j) = both(&d, "dac", &["dac", "1234"]);
        assert_eq!(j["value"], 1234);
        both(&d, "adc", &["adc"]);
        both(&d, "adc", &["adc", "--differential"]);
        both(&d, "qei", &["qei", "start"]);
        both(&d, "qei", &["qei"]);
        both(&d, "qei", &["qei", "stop"]);
        assert!(d.ctl(&["dac", "5000"]).fails(2).contains("5000"));

        // FoE round trip.
        let file = d.dir.join("fw.bin");
        let data: Vec<u8> = (0..3000u32).map(|i| (i * 7) as u8).collect();
        std::fs::write(&file, &data).unwrap();
        let f = file.display().to_string();
        let (t, j) = both(&d, "foe write", &["foe", "write", "-p", "1", &f, "--name", "fw.bin"]);
        assert!(t.contains("3000 bytes"), "{t}");
        assert_eq!(j["bytes"], 3000);
        let back = d.dir.join("back.bin").display().to_string();
        let (_, j) = both(&d, "foe read", &["foe", "read", "-p", "1", "fw.bin", "-o", &back]);
        assert_eq!(j["bytes"], 3000);
        assert_eq!(std::fs::read(&back).unwrap(), data);
        let c = d.ctl(&["foe", "write", "-p", "1", "/nonexistent/fw.bin"]);
        assert!(c.fails(1).contains("/nonexistent/fw.bin"), "{}", c.stderr);

        // Registers.
        let (t, j) = both(&d, "reg read", &["reg", "read", "-p", "0", "0x130", "--type", "uint16"]);
        assert!(t.starts_with("0x0130: 08 00"), "{t}");
        assert_eq!(j["value"], 8);
        assert_eq!(j["working_counter"], 1);
        let (_, j) = both(&d, "reg read", &["reg", "read", "-p", "0", "0x0000", "4"]);
        assert_eq!(j["data"].as_str().unwrap().len(), 8);
        let (_, j) = both(&d, "reg write", &["reg", "write", "-p", "0", "0x0f80", "01 02"]);
        assert_eq!(j["data"], "0102");
        both(&d, "reg write", &["reg", "write", "-p", "0", "0x0f80", "--type", "uint16", "0x0304"]);

        // Emergencies (none on a healthy simulator), top.
        let (t, j) = both(&d, "emergencies", &["emergencies"]);
        assert!(t.contains("no emergencies") || t.contains("ERROR CODE"), "{t}");
        assert!(j["emergencies"].is_array());
        let top = d.ctl(&["top", "--once", "--size", "100x32"]);
        let screen = top.ok();
        assert!(screen.contains("phase RUNNING") && screen.contains("TI CiA402 3-axis"), "{screen}");
        assert!(screen.contains("1.position_actual"), "the first axis is plotted by default:\n{screen}");
        let top = lines(&d.ctl(&["--json", "top", "--once", "--plot", "1.velocity_actual"]), "top");
        assert_eq!(top.len(), 1);
        assert!(top[0]["plot"]["1.velocity_actual"].is_number(), "{}", top[0]);
        let c = d.ctl(&["top", "--once", "--plot", "1.controlword"]);
        assert!(c.fails(2).contains("only inputs"), "{}", c.stderr);
        d.stop();
    });
}

fn ecmxf_e2e_hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

#[test]
fn errors_say_what_went_wrong_with_the_documented_exit_code() {
    // No daemon.
    let missing = std::env::temp_dir().join(format!("ecmxf-no-daemon-{}.sock", std::process::id()));
    let c = ecmxf_e2e::ctl(&["--socket", &missing.display().to_string(), "slaves"]);
    let err = c.fails(3);
    assert!(err.contains("cannot reach ecmxfd at") && err.contains("no socket there"), "{err}");
    assert!(err.contains("is ecmxfd running?"), "{err}");
    let c = ecmxf_e2e::ctl(&["--json", "--socket", &missing.display().to_string(), "slaves"]);
    c.fails(3);
    let e: serde_json::Value = serde_json::from_str(c.stderr.trim()).unwrap();
    assert_schema("error", &e);
    assert_eq!(e["error"]["kind"], "UNREACHABLE");
    // Plain HTTP is refused before anything is sent.
    let c = ecmxf_e2e::ctl(&["--connect", "http://127.0.0.1:1", "master"]);
    assert!(c.fails(2).contains("only with TLS"), "{}", c.stderr);
    // clap's own usage errors.
    ecmxf_e2e::ctl(&["upload", "-p", "1", "0x10000"]).fails(2);
    ecmxf_e2e::ctl(&["states", "1", "2", "3"]).fails(2);
    // ... as the JSON error object under --json (kind USAGE, the usage line
    // as the hint), like every other error.
    let c = ecmxf_e2e::ctl(&["--json", "upload"]);
    c.fails(2);
    let e: serde_json::Value = serde_json::from_str(c.stderr.trim())
        .unwrap_or_else(|why| panic!("a usage error under --json is JSON ({why}):\n{}", c.stderr));
    assert_schema("error", &e);
    assert_eq!((e["error"]["kind"].as_str(), e["error"]["exit_code"].as_u64()), (Some("USAGE"), Some(2)), "{e}");
    let message = e["error"]["message"].as_str().unwrap();
    assert!(message.contains("--position <POS>") && message.contains("<INDEX>"), "{e}");
    assert!(e["error"]["hint"].as_str().unwrap().starts_with("Usage: ecmxfctl upload"), "{e}");
    // $ECMXF_SOCKET set: its option is not shown as if typed.
    let out = std::process::Command::new(ecmxf_e2e::ctl_binary())
        .args(["upload"])
        .env("ECMXF_SOCKET", &missing)
        .output()
        .unwrap();
    let usage = String::from_utf8_lossy(&out.stderr);
    assert!(usage.contains("Usage: ecmxfctl upload") && !usage.contains("--socket"), "{usage}");
    let help = ecmxf_e2e::ctl(&["upload", "--help"]).ok().to_owned();
    assert_eq!(help.matches("[default: 0]").count(), 1, "{help}");

    run(async {
        let token = "observer-token".to_string();
        let sha = sha256_hex(token.as_bytes());
        let extra = format!("[[api.token]]\nname = \"viewer\"\nsha256 = \"{sha}\"\nrole = \"observer\"\n");
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config("backend = \"sim\"", &extra));
        d.connect().await;

        // SDO abort: exit 6, the abort code in the message and the JSON details.
        let c = d.ctl(&["upload", "-p", "1", "0x1234", "0"]);
        let err = c.fails(6);
        assert!(err.contains("0x06020000") && err.contains("does not exist"), "{err}");
        let c = d.ctl(&["--json", "upload", "-p", "1", "0x1234", "0"]);
        c.fails(6);
        let e: serde_json::Value = serde_json::from_str(c.stderr.trim()).unwrap();
        assert_schema("error", &e);
        assert_eq!(e["error"]["kind"], "ABORTED");
        assert_eq!(e["error"]["details"]["abort_code"], "0x06020000");

        // An object as the daemon names it, index:subindex.
        let both = d.ctl(&["upload", "-p", "1", "0x1018", "1"]).ok().to_owned();
        assert_eq!(d.ctl(&["upload", "-p", "1", "0x1018:01"]).ok(), both);
        assert_eq!(d.ctl(&["upload", "0x1018:1", "-p", "1"]).ok(), both);
        d.ctl(&["download", "-p", "1", "0x605A:00", "3"]).ok();
        assert!(d.ctl(&["upload", "-p", "1", "0x605A:0"]).ok().contains('3'));

        // Arguments the daemon refuses: exit 2, naming the argument.
        let err = d.ctl(&["upload", "-p", "99", "0x6041"]).fails(2).to_owned();
        assert!(err.contains("slave") && err.contains("99"), "{err}");
        let err = d.ctl(&["states", "run"]).fails(2).to_owned();
        assert!(err.contains("\"run\""), "{err}");
        let err = d.ctl(&["download", "-p", "1", "0x2000", "1", "5"]).fails(2).to_owned();
        assert!(err.contains("--type"), "{err}");
        let err = d.ctl(&["download", "-p", "1", "0x605A", "0", "70000"]).fails(2).to_owned();
        assert!(err.contains("70000") && err.contains("INTEGER16"), "{err}");
        // A type narrower than the object: an error naming both sizes, not
        // a truncated value.
        for (ty, name, n) in [("int8", "INTEGER8", "1 byte"), ("bool", "BOOLEAN", "1 byte")] {
            let err = d.ctl(&["upload", "-p", "1", "0x6041", "--type", ty]).fails(2).to_owned();
            assert!(err.contains("holds 2 bytes") && err.contains(name) && err.contains(n), "{ty}: {err}");
        }
        let err = d.ctl(&["upload", "-p", "1", "0x6064", "--type", "uint16"]).fails(2).to_owned();
        assert!(err.contains("holds 4 bytes") && err.contains("2 bytes"), "{err}");
        let err = d.ctl(&["cia402", "status"]).fails(0).to_owned();
        assert!(err.is_empty(), "no axes is not an error: {err}");

        // A role too low: exit 4, both roles named, a hint.
        let err = d.ctl(&["--token", &token, "download", "-p", "1", "0x605A", "0", "2"]).fails(4).to_owned();
        assert!(err.contains("permission denied") && err.contains("operator"), "{err}");
        assert!(err.contains("hint:"), "{err}");
        let err = d.ctl(&["--token", &token, "reg", "read", "-p", "0", "0x130"]).fails(4).to_owned();
        assert!(err.contains("admin"), "{err}");
        d.ctl(&["--token", &token, "slaves"]).ok();

        // A deadline too short for an SDO round trip: exit 5.
        let c = d.ctl(&["--timeout", "1ms", "upload", "-p", "1", "0x1008"]);
        let err = c.fails(5);
        assert!(err.contains("timed out"), "{err}");
        // A given --timeout bounds the long operations too (a full SII
        // range, the object probe, an FoE read): the command ends with
        // exit 5 within it, not at their own budgets.
        for args in [
            &["sii", "read", "-p", "1", "--count", "4096"][..],
            &["sdos", "-p", "1", "--source", "probe"],
            &["foe", "read", "-p", "1", "firmware.bin", "-o", "/dev/null"],
        ] {
            let started = std::time::Instant::now();
            let mut all = vec!["--timeout", "30ms"];
            all.extend_from_slice(args);
            let c = d.ctl(&all);
            let took = started.elapsed();
            assert_eq!(c.code, 5, "{args:?}: exit {} after {took:?}: {}{}", c.code, c.stdout, c.stderr);
            assert!(took < std::time::Duration::from_secs(2), "{args:?} took {took:?} with --timeout 30ms");
        }
        d.stop();
    });
}

fn sha256_hex(b: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(b).iter().map(|x| format!("{x:02x}")).collect()
}

#[test]
fn completions_man_pages_and_schemas_need_no_daemon() {
    for shell in ["bash", "zsh", "fish"] {
        let c = ecmxf_e2e::ctl(&["completions", shell]);
        assert!(c.ok().contains("ecmxfctl"), "{shell}");
    }
    let dir = ecmxf_e2e::temp_dir("man");
    let c = ecmxf_e2e::ctl(&["man", &dir.display().to_string()]);
    c.ok();
    let page = std::fs::read_to_string(dir.join("ecmxfctl.1")).unwrap();
    assert!(page.contains(".TH ecmxfctl") && page.contains("upload"), "{page}");
    assert!(dir.join("ecmxfctl-cia402.1").exists());
    let _ = std::fs::remove_dir_all(&dir);
    let all = ecmxf_e2e::ctl(&["json-schema"]);
    let doc: serde_json::Value = serde_json::from_str(all.ok()).unwrap();
    assert!(doc["commands"]["slaves"].is_object());
    let one: serde_json::Value =
        serde_json::from_str(ecmxf_e2e::ctl(&["json-schema", "cia402", "status"]).ok()).unwrap();
    assert_eq!(one, doc["commands"]["cia402 status"]);
    ecmxf_e2e::ctl(&["json-schema", "nothing"]).fails(2);
}

/// `crc`: the ESC error counters per port, as the simulated slaves count
/// them (`ecmxf-sim ctl port-errors`), and `--reset` clearing them.
#[test]
fn crc_reads_each_ports_error_counters_and_reset_clears_them() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("crc");
        let sim = ecmxf_e2e::Simulator::serve(&dir, &[]);
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config(&sim.link(), ""));
        d.connect().await;
        sim.ctl("port-errors 1 0 5 2 1");
        sim.ctl("port-errors 2 1 3");
        let (t, j) = both(&d, "crc", &["crc"]);
        assert!(t.starts_with("POS") && t.contains("2/5/1") && t.contains("0/3/0"), "{t}");
        let slaves = j["slaves"].as_array().unwrap();
        assert_eq!(slaves.len(), 3);
        let p = &slaves[1]["ports"][0];
        assert_eq!(
            (p["invalid_frames"].as_u64(), p["rx_errors"].as_u64(), p["forwarded_rx_errors"].as_u64()),
            (Some(2), Some(5), Some(1))
        );
        assert_eq!(slaves[2]["ports"][1]["rx_errors"], 3);
        assert_eq!(slaves[0]["ports"][0]["rx_errors"], 0);
        assert!(slaves.iter().all(|s| s["working_counter"] == 1), "{j}");
        let (_, j) = both(&d, "crc", &["crc", "-p", "1", "--reset"]);
        assert_eq!(j["reset"], true);
        assert_eq!(j["slaves"].as_array().unwrap().len(), 1);
        assert_eq!(j["slaves"][0]["ports"][0]["rx_errors"], 0, "{j}");
        let j = d.ctl(&["--json", "crc"]).json();
        assert_eq!(j["slaves"][2]["ports"][1]["rx_errors"], 3, "only slave 1 was cleared: {j}");
        d.stop();
    });
}

/// `alias`: the SII's station alias (word 4), and `--set` writing it with
/// the config area's checksum (word 7), which `sii decode` then finds right.
#[test]
fn alias_reads_and_writes_the_sii_station_alias_with_its_checksum() {
    run(async {
        let mut d = Daemon::binary_with_config(&config());
        d.connect().await;
        let (t, j) = both(&d, "alias", &["alias"]);
        assert!(t.starts_with("POS") && t.contains("TI CiA402 3-axis"), "{t}");
        let before = j["slaves"][2]["alias"].as_u64().unwrap();
        let (t, j) = both(&d, "alias", &["alias", "-p", "2", "--set", "7"]);
        assert!(t.contains(&format!("alias {before} -> 7 written to the SII")), "{t}");
        assert_eq!((j["slaves"][0]["alias"].as_u64(), j["slaves"][0]["previous"].as_u64()), (Some(7), Some(7)), "{j}");
        let j = d.ctl(&["--json", "alias", "-p", "2"]).json();
        assert_eq!(j["slaves"][0]["alias"], 7);
        assert!(j["slaves"][0]["previous"].is_null());
        let decoded = d.ctl(&["--json", "sii", "decode", "-p", "2"]).json();
        assert_eq!(decoded["checksum_ok"], true, "the checksum follows the alias: {decoded}");
        let e = d.ctl(&["alias", "--set", "7"]);
        e.fails(2);
        assert!(e.stderr.contains("-p POS"), "{}", e.stderr);
        d.stop();
    });
}

/// IgH `ethercat` habits: `states -p 1 SAFEOP`, `upload -t uint16`; the
/// verbs for protocols the chip does not carry (eoe, soe, ip) and `xml`
/// exit 2 saying what there is instead, without a daemon.
#[test]
fn igh_spellings_are_taken_and_igh_verbs_answered() {
    for (verb, says) in [
        ("eoe", "the ECM-XF speaks the CoE and FoE mailbox protocols only"),
        ("soe", "no SoE"),
        ("ip", "no EoE (so no `ip` settings)"),
        ("xml", "`ecmxfctl config --format eni`"),
    ] {
        let c = ecmxf_e2e::ctl(&[verb, "-p", "1"]);
        assert_eq!(c.code, 2, "{verb}: {}", c.stderr);
        assert!(c.stderr.contains(says), "{verb}: {}", c.stderr);
    }
    run(async {
        let mut d = Daemon::with_config(&config());
        d.connect().await;
        let igh = d.ctl(&["upload", "-p", "1", "0x6041", "-t", "uint16"]);
        assert_eq!(igh.code, 0, "{}", igh.stderr);
        assert_eq!(igh.stdout, d.ctl(&["upload", "-p", "1", "0x6041", "--type", "uint16"]).stdout);
        assert_eq!(igh.stdout, d.ctl(&["upload", "-p", "1", "0x6041", "-d", "uint16"]).stdout);
        let set = d.ctl(&["states", "-p", "2", "PREOP"]);
        assert_eq!(set.code, 0, "{}", set.stderr);
        let now = d.ctl(&["--json", "slaves", "-p", "2"]).json();
        assert_eq!(now["slaves"][0]["state"], "PREOP", "{now}");
        d.stop();
    });
}

/// IgH's `cstruct`, `domains` and `debug` against the running daemon: the
/// C arrays carry, entry by entry, the mapping `pdos` lists; the domain is
/// the image and the flow `master` reports; `debug 1` makes the daemon log
/// its own debug lines (an SDO download's shows up) until `debug 0`, and
/// an observer may read the filter but not set it.
#[test]
fn cstruct_domains_and_debug_say_what_the_daemon_runs() {
    run(async {
        let mut d = Daemon::binary_with_config(&format!(
            "{}[[api.token]]\nname = \"viewer\"\nsha256 = \"{}\"\nrole = \"observer\"\n",
            config(),
            sha256_hex(b"viewer-token")
        ));
        d.connect().await;
        let named = "process image entries named by their devices";
        assert!(d.logged(named, std::time::Duration::from_secs(10)).await, "{}", d.log());

        let c = d.ctl(&["cstruct"]).ok().to_owned();
        let pdos = d.ctl(&["--json", "pdos"]).json();
        for m in pdos["slaves"].as_array().unwrap() {
            let slave = m["slave"].as_u64().unwrap();
            let want: Vec<String> = ["rx_pdos", "tx_pdos"]
                .iter()
                .flat_map(|dir| m[dir].as_array().unwrap().iter())
                .flat_map(|p| p["entries"].as_array().unwrap().iter())
                .map(|e| {
                    format!(
                        "{{{:#06x}, {:#04x}, {}}},",
                        e["index"].as_u64().unwrap(),
                        e["subindex"].as_u64().unwrap(),
                        e["bit_length"].as_u64().unwrap()
                    )
                })
                .collect();
            let array = format!("ec_pdo_entry_info_t slave_{slave}_pdo_entries[] = {{\n");
            let got: Vec<String> = c
                .split(&array)
                .nth(1)
                .unwrap_or_else(|| panic!("no {array} in:\n{c}"))
                .lines()
                .take_while(|l| !l.starts_with("};"))
                .map(|l| l.trim().split(" /*").next().unwrap().to_owned())
                .collect();
            assert_eq!(got, want, "slave {slave}:\n{c}");
            assert!(c.contains(&format!("ec_sync_info_t slave_{slave}_syncs[] = {{")), "{c}");
        }

        let domains = d.ctl(&["--json", "domains", "-v"]).json();
        let master = d.ctl(&["--json", "master"]).json();
        let domain = &domains["domains"][0];
        assert_eq!(domain["output_bytes"], master["output_image_bytes"], "{domain}");
        assert_eq!(domain["input_bytes"], master["input_image_bytes"], "{domain}");
        assert_eq!(domain["flowing"], true, "{domain}");
        let image = domain["input_image"].as_str().unwrap();
        assert_eq!(image.len() as u64, 2 * master["input_image_bytes"].as_u64().unwrap(), "{domain}");

        let viewer = d.ctl(&["--token", "viewer-token", "debug", "1"]);
        assert_eq!(viewer.code, 4, "an observer sets no filter: {}", viewer.stderr);
        let shown = d.ctl(&["--token", "viewer-token", "--json", "debug"]).json();
        assert_eq!(shown["filter"], "info", "{shown}");
        if std::env::var_os("RUST_LOG").is_some() {
            eprintln!("skipped the debug flow: RUST_LOG is set, and it wins in the daemon");
            d.stop();
            return;
        }
        let set = d.ctl(&["--json", "debug", "1"]).json();
        assert_eq!(set["filter"], "info,ecmxfd=debug", "{set}");
        d.ctl(&["download", "-p", "1", "0x605a", "0", "2"]).ok();
        assert!(d.logged("SDO download", std::time::Duration::from_secs(5)).await, "{}", d.log());
        d.ctl(&["debug", "0"]).ok();
        let before = d.log().matches("SDO download").count();
        d.ctl(&["download", "-p", "1", "0x605a", "0", "2"]).ok();
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        assert_eq!(d.log().matches("SDO download").count(), before, "debug 0 quiets it: {}", d.log());
        let bad = d.ctl(&["debug", "nonsense=%%"]);
        assert_eq!(bad.code, 2, "{}", bad.stderr);
        assert!(bad.stderr.contains("is not a log filter"), "{}", bad.stderr);
        d.stop();
    });
}
