//! The real `ecmxfctl` binary without a daemon: version, help, and the
//! "daemon not running" answer. (Also what makes `cargo test --workspace`
//! build `target/<profile>/ecmxfctl` fresh for the end-to-end tests in
//! tests/, which run every command against a daemon.)

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_ecmxfctl");

#[test]
fn version_help_and_no_daemon() {
    let out = Command::new(BIN).arg("--version").output().unwrap();
    assert!(out.status.success());
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), format!("ecmxfctl {}", env!("CARGO_PKG_VERSION")));
    let out = Command::new(BIN).arg("--help").output().unwrap();
    assert!(String::from_utf8_lossy(&out.stdout).contains("Exit codes"));
    let socket = std::env::temp_dir().join(format!("ecmxfctl-nothing-{}.sock", std::process::id()));
    let out = Command::new(BIN).args(["--socket", socket.to_str().unwrap(), "master"]).output().unwrap();
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot reach ecmxfd"));
    let out = Command::new(BIN).args(["upload", "-p", "1"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2), "clap usage error");
}
