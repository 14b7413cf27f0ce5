//! What the OPC UA tests (tests/tests/opcua.rs with asyncua,
//! tests/tests/opcua_node.rs with node-opcua) check of a browsed address
//! space, whichever client browsed it: both clients print the same JSON.

use serde_json::Value;

/// The OPC UA built-in type (OPC 10000-6 5.1.2, its numeric node id) of
/// an ecmxfctl type name.
pub fn opc_ua_type(name: &str) -> u64 {
    match name {
        "bool" => 1,
        "int8" => 2,
        "uint8" => 3,
        "int16" => 4,
        "uint16" => 5,
        "int32" => 6,
        "uint32" => 7,
        "int64" => 8,
        "uint64" => 9,
        "float" => 10,
        "double" => 11,
        "string" => 12,
        "octet_string" => 15,
        other => panic!("no OPC UA type for {other:?}"),
    }
}

/// A free port on loopback.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// A client's JSON (its last line of output), after it succeeded.
pub fn last_json(out: &std::process::Output) -> Value {
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "the OPC UA client failed:\n{text}\n{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_str(text.lines().last().unwrap_or("")).unwrap_or_else(|e| panic!("{e}: {text}"))
}

/// What a client browsed (`space`) is what `ecmxfctl --json slaves` and
/// `--json pdos` say of the network: the master running, every slave with
/// its identity, state, health and methods, every entry in its folder
/// with its name, type, display name (the device's name for it when
/// `all_labelled`) and node id, all Good.
pub fn browsed_as_ecmxfctl_says(space: &Value, slaves: &Value, pdos: &Value, all_labelled: bool) {
    assert_eq!(space["master"]["Phase"], "running", "{space}");
    assert_eq!(space["master"]["State"], "OP");
    assert_eq!(space["master"]["ProcessDataFlowing"], true);
    let expected = slaves["slaves"].as_array().expect("slaves");
    let browsed = space["slaves"].as_array().expect("slaves browsed");
    assert_eq!(browsed.len(), expected.len(), "one object per slave: {space}");
    for s in expected {
        let p = s["position"].as_u64().unwrap();
        let o = browsed.iter().find(|o| o["Position"].as_u64() == Some(p)).unwrap_or_else(|| panic!("slave {p}"));
        assert_eq!(o["VendorId"], s["vendor_id"], "slave {p}");
        assert_eq!(o["ProductCodeNumber"], s["product_code"], "slave {p}");
        assert_eq!(o["RevisionNumber"], s["revision"], "slave {p}");
        assert_eq!(o["Model"], s["name"], "slave {p}");
        assert_eq!(o["ProductCode"], format!("{:#010x}", s["product_code"].as_u64().unwrap()), "slave {p}");
        assert_eq!(o["EtherCATState"], "OP", "slave {p}");
        assert_eq!(o["ALStatusCode"], 0, "slave {p}");
        assert_eq!(o["ALStatusText"], "no error", "slave {p}");
        assert_eq!(o["DeviceHealth"], 0, "slave {p}: NORMAL");
        let mut methods: Vec<&str> =
            o["methods"].as_array().expect("methods").iter().filter_map(Value::as_str).collect();
        methods.sort_unstable();
        assert_eq!(methods, ["RequestState", "SdoDownload", "SdoUpload"], "slave {p}");
    }
    let entries = pdos["image"]["entries"].as_array().expect("image entries");
    let all: Vec<&Value> = browsed.iter().flat_map(|o| o["entries"].as_array().unwrap()).collect();
    assert_eq!(all.len(), entries.len(), "one variable per entry");
    for e in entries {
        let name = e["name"].as_str().unwrap();
        let v = all.iter().find(|v| v["browse_name"] == name).unwrap_or_else(|| panic!("no variable {name}"));
        let (folder, dir) = if e["direction"] == "output" { ("Outputs", "out") } else { ("Inputs", "in") };
        assert_eq!(v["folder"], folder, "{name}");
        assert_eq!(v["node_id"], format!("EtherCAT.Slaves.{}.{dir}.{name}", e["slave"]), "{name}");
        assert_eq!(v["data_type"].as_u64(), Some(opc_ua_type(e["data_type"].as_str().unwrap())), "{name}: {v}");
        let label = e["label"].as_str().unwrap();
        assert!(!all_labelled || !label.is_empty(), "{name}: the devices name every entry");
        assert_eq!(v["display"], if label.is_empty() { name } else { label }, "{name}");
        assert_eq!(v["status"], "Good", "{name}: {v}");
    }
}
