//! The Python end-to-end tests. `tests/python/test_package.py`: the `ecmxf`
//! package (clients/python) as users install it. `tests/python/test_api.py`: grpcio stubs
//! generated from proto/, the real daemon, a scan, an SDO read and write, a
//! CiA402 axis enabled, one second of streamed inputs, two seconds of
//! per-cycle frames (StreamFrames) checked through the IO slave's loopback.
//!
//! It needs the venv `.ci/run` creates (`target/py-venv`, or the Python in
//! `ECMXF_PYTHON`). Without one it is skipped with a note, unless
//! `ECMXF_REQUIRE_PYTHON=1` (CI sets it), where a missing venv fails.

use std::path::PathBuf;
use std::process::Command;

/// The venv's Python (`target/py-venv`, or `$ECMXF_PYTHON`) with `module`
/// importable; required where `ECMXF_REQUIRE_PYTHON` is set (CI).
fn python_with(module: &str, install: &str) -> Option<PathBuf> {
    let imports = |python: &std::path::Path| {
        Command::new(python).args(["-c", &format!("import {module}")]).output().is_ok_and(|o| o.status.success())
    };
    ecmxf_e2e::installed_tool("ECMXF_PYTHON", "target/py-venv/bin/python", imports, "ECMXF_REQUIRE_PYTHON", install)
}

fn run_python(python: &PathBuf, script: &str, tests: usize) {
    let _turn = ecmxf_e2e::SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let out = Command::new(python)
        .arg(ecmxf_e2e::repo().join(script))
        .env("ECMXFD", ecmxf_e2e::daemon_binary())
        .output()
        .expect("run python");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    println!("{text}");
    assert!(out.status.success(), "{script} failed:\n{text}");
    assert!(text.contains(&format!("Ran {tests} tests")) && text.contains("OK"), "{text}");
}

#[test]
fn python_client_scans_reads_writes_enables_and_streams() {
    let install = "python3 -m venv target/py-venv; target/py-venv/bin/pip install -r tests/python/requirements.txt";
    if let Some(python) = python_with("grpc_tools", install) {
        run_python(&python, "tests/python/test_api.py", 7);
    }
}

/// The `ecmxf` package (clients/python), installed as a user installs it,
/// against `ecmxfd --sim`: the README's five-line script and the typed API.
#[test]
fn python_package_reads_slaves_sdo_and_inputs_from_the_simulator() {
    if let Some(python) = python_with("ecmxf", "target/py-venv/bin/pip install ./clients/python") {
        run_python(&python, "tests/python/test_package.py", 7);
    }
}
