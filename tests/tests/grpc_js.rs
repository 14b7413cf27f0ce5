//! The API from Node as a first client writes it: grpc-js and
//! proto-loader from the npm registry (tests/node/grpc_client.js, at the
//! versions tests/node/package-lock.json pins, installed into target/node
//! by `.ci/run`), the `.proto` files of `proto/` and nothing else, default
//! channel options, the daemon's Unix socket as `unix:PATH` and
//! `unix:///PATH`.
//!
//! - One method of every `ecmxf.v1` service answers, and so does gRPC
//!   health; what they answer is what `ecmxfctl` says.
//! - An error's `grpc-status-details-bin` decodes with
//!   `proto/google/rpc/` alone: a google.rpc.Status with the call's code
//!   and message and an ErrorInfo naming the SDO abort.

use std::process::Command;

use ecmxf_e2e::opcua::last_json;
use ecmxf_e2e::{Daemon, run};
use serde_json::Value;

/// What grpc_client.js printed for one target.
fn node_client(modules: &std::path::Path, target: &str) -> Value {
    let repo = ecmxf_e2e::repo();
    let out = Command::new("node")
        .arg(repo.join("tests/node/grpc_client.js"))
        .arg(target)
        .arg(repo.join("proto"))
        .env("NODE_PATH", modules)
        .output()
        .expect("node");
    assert!(out.status.success(), "grpc_client.js failed:\n{}", String::from_utf8_lossy(&out.stderr));
    last_json(&out)
}

#[test]
fn grpc_js_with_default_options_reaches_every_service_and_reads_error_details() {
    let Some(modules) = ecmxf_e2e::node_modules("@grpc/grpc-js") else { return };
    let mut d = Daemon::sim();
    run(async {
        d.connect().await;
        let slaves = d.ctl(&["--json", "slaves"]).json()["slaves"].clone();
        let socket = d.socket.display().to_string();
        for target in [format!("unix:{socket}"), format!("unix://{socket}")] {
            let modules = modules.clone();
            let t = target.clone();
            let r = tokio::task::spawn_blocking(move || node_client(&modules, &t)).await.unwrap();

            for (call, answer) in r.as_object().unwrap() {
                match call.as_str() {
                    "missing" | "health" => {}
                    // Slave 99 is not on the ring: the service answered
                    // and named what was wrong.
                    "Foe.Read" => {
                        assert_eq!(answer["code"], "INVALID_ARGUMENT", "{target}: {call}: {answer}");
                        assert!(answer["message"].as_str().unwrap().contains("slave 99"), "{call}: {answer}");
                    }
                    _ => assert_eq!(answer["ok"], true, "{target}: {call}: {answer}"),
                }
            }
            // Health answers with the daemon's verdict: NOT_SERVING while a
            // loaded host's stall still degrades it.
            let health = r["health"]["status"].as_str().unwrap_or_default();
            assert!(["SERVING", "NOT_SERVING"].contains(&health), "{target}: {r}");
            let listed = r["Slaves.ListSlaves"]["value"]["slaves"].as_array().unwrap();
            assert_eq!(listed.len(), slaves.as_array().unwrap().len(), "{target}: {r}");
            for (got, want) in listed.iter().zip(slaves.as_array().unwrap()) {
                assert_eq!(got["name"], want["name"], "{target}: {got} vs {want}");
            }
            assert_eq!(r["ProcessData.StreamInputs"]["value"].as_array().unwrap().len(), 3, "{target}: {r}");

            // The error, decoded with proto/google/rpc only.
            let missing = &r["missing"];
            assert_eq!(missing["code"], "ABORTED", "{target}: {missing}");
            let status = &missing["status"];
            assert_eq!(status["code"], 10, "ABORTED in the details: {status}");
            assert_eq!(status["message"], missing["message"], "{status}");
            let info = &status["details"][0];
            assert_eq!(info["type"], "google.rpc.ErrorInfo", "{status}");
            assert_eq!(info["value"]["reason"], "SDO_ABORT", "{status}");
            assert_eq!(info["value"]["domain"], "ecmxf", "{status}");
            assert_eq!(info["value"]["metadata"]["abort_code"], "0x06020000", "{status}");
            assert_eq!(info["value"]["metadata"]["object"], "0x2fff:00", "{status}");
        }
    });
}
