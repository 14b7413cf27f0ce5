//! The Python end-to-end test (`tests/python/test_api.py`): grpcio stubs
//! generated from proto/, the real daemon, a scan, an SDO read and write, a
//! CiA402 axis enabled, one second of streamed inputs, two seconds of
//! per-cycle frames (StreamFrames) checked through the IO slave's loopback.
//!
//! It needs the venv `.ci/run` creates (`target/py-venv`, or the Python in
//! `ECMXF_PYTHON`). Without one it is skipped with a note, unless
//! `ECMXF_REQUIRE_PYTHON=1` (CI sets it), where a missing venv fails.

use std::path::PathBuf;
use std::process::Command;

#[test]
fn python_client_scans_reads_writes_enables_and_streams() {
    let python = std::env::var_os("ECMXF_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| ecmxf_e2e::repo().join("target/py-venv/bin/python"));
    if !python.exists() {
        assert!(
            std::env::var_os("ECMXF_REQUIRE_PYTHON").is_none(),
            "ECMXF_REQUIRE_PYTHON is set but {} does not exist (bash .ci/run creates it)",
            python.display()
        );
        eprintln!("skipped: no Python venv at {} (bash .ci/run creates it)", python.display());
        return;
    }
    let _turn = ecmxf_e2e::SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let out = Command::new(&python)
        .arg(ecmxf_e2e::repo().join("tests/python/test_api.py"))
        .env("ECMXFD", ecmxf_e2e::daemon_binary())
        .output()
        .expect("run python");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    println!("{text}");
    assert!(out.status.success(), "the Python test failed:\n{text}");
    assert!(text.contains("Ran 5 tests") && text.contains("OK"), "{text}");
}
