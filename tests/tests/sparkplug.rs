//! The Sparkplug B edge node against a real broker and an independent
//! host: `tests/python/test_sparkplug.py` starts mosquitto (the Debian
//! package `.ci/run` installs), `ecmxf-sim serve` and `ecmxfd` with
//! `[sparkplug]`, and checks as a Sparkplug host (paho-mqtt, the Eclipse
//! Tahu schema from pysparkplug): births, aliases, seq, DDATA against
//! `ecmxfctl data`, a DCMD write through the IO slave's loopback, rebirth,
//! unplug/replug, a broker restart, kill -9 (the will) and refused
//! commands.
//!
//! Skipped with a note without mosquitto or the venv's packages, unless
//! `ECMXF_REQUIRE_MOSQUITTO` / `ECMXF_REQUIRE_PYTHON` are set (CI).

use std::path::PathBuf;
use std::process::Command;

/// mosquitto: `$MOSQUITTO`, on the PATH, or where Debian installs it.
fn mosquitto() -> Option<PathBuf> {
    let found = std::env::var_os("MOSQUITTO")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("PATH")
                .and_then(|p| std::env::split_paths(&p).map(|d| d.join("mosquitto")).find(|b| b.is_file()))
        })
        .or_else(|| Some(PathBuf::from("/usr/sbin/mosquitto")).filter(|b| b.is_file()));
    if found.is_none() {
        assert!(
            std::env::var_os("ECMXF_REQUIRE_MOSQUITTO").is_none(),
            "mosquitto missing (apt-get install mosquitto; .ci/run does)"
        );
        eprintln!("skipped: mosquitto missing (apt-get install mosquitto)");
    }
    found
}

#[test]
fn a_sparkplug_host_sees_births_data_commands_and_deaths_through_mosquitto() {
    let Some(broker) = mosquitto() else { return };
    let imports = |python: &std::path::Path| {
        Command::new(python)
            .args(["-c", "import paho.mqtt.client, pysparkplug"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    let install = "target/py-venv/bin/pip install -r tests/python/requirements.txt";
    let Some(python) = ecmxf_e2e::installed_tool(
        "ECMXF_PYTHON",
        "target/py-venv/bin/python",
        imports,
        "ECMXF_REQUIRE_PYTHON",
        install,
    ) else {
        return;
    };
    let _turn = ecmxf_e2e::SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let daemon = ecmxf_e2e::daemon_binary();
    let out = Command::new(&python)
        .arg(ecmxf_e2e::repo().join("tests/python/test_sparkplug.py"))
        .env("ECMXFD", &daemon)
        .env("ECMXFCTL", ecmxf_e2e::ctl_binary())
        .env("ECMXF_SIM", ecmxf_e2e::sim_binary())
        .env("MOSQUITTO", &broker)
        .output()
        .expect("run python");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    println!("{text}");
    assert!(out.status.success(), "test_sparkplug.py failed:\n{text}");
    assert!(text.contains("Ran 8 tests") && text.contains("OK"), "{text}");
}
