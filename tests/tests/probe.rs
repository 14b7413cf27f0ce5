//! `ecmxfd probe`, the real binary: every step passes on the simulator (in
//! process, as `config/ecmxfd-sim.toml` runs it, and served on its socket);
//! the failures the simulator can be made to show (no simulator, INT0 held,
//! no slave, bit errors) and a missing SPI device each fail at their step
//! with the cause and fix printed under it, the steps after it skipped, and
//! exit 1; a daemon using the chip is not disturbed; and the daemon brings
//! up the network the probe leaves, with inputs flowing. (Steps 3, 5 and 7
//! fail only through faults outside the simulator's control language:
//! daemon/src/probe.rs tests them over scripted links.)

use std::process::{Command, Output};
use std::time::Duration;

use ecmxf_e2e::probe_report::{assert_fails_at, assert_passes, step};
use ecmxf_e2e::{Daemon, Simulator, config, daemon_binary, repo, run, temp_dir};
use ecmxf_proto::v1 as pb;
use pb::master_client::MasterClient;

/// Runs `ecmxfd probe` with `args`; exit code and stdout (stderr appended).
fn probe(args: &[&str]) -> (i32, String) {
    let out: Output = Command::new(daemon_binary()).arg("probe").args(args).output().expect("run ecmxfd probe");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.code().unwrap_or(-1), text)
}

#[test]
fn every_step_passes_on_the_simulator_config() {
    let file = repo().join("config/ecmxfd-sim.toml");
    let (code, text) = probe(&["--config", &file.display().to_string()]);
    assert_passes(code, &text);
    assert!(step(&text, 6).contains(r#"3 slaves: 0 "CORE", 1 "TI CiA402 3-axis", 2 "8io""#), "{text}");
    assert!(step(&text, 4).contains("CRC-32 check word and the 512-byte data section"), "{text}");
    let (code, text) = probe(&["--sim"]);
    assert_passes(code, &text);
}

#[test]
fn on_the_simulator_socket_each_fault_fails_its_step_and_the_daemon_starts_after() {
    let dir = temp_dir("probe");
    let file = dir.join("probe.toml");
    let write = |link: &str| {
        let text = format!("{}\n[api]\nsocket = \"{}\"\n", config(link, ""), dir.join("api.sock").display());
        std::fs::write(&file, text).unwrap();
    };
    let path = file.display().to_string();

    // 1: nobody serves the socket.
    write(&format!("backend = \"sim-socket\"\nsocket = \"{}\"", dir.join("sim.sock").display()));
    let (code, text) = probe(&["--config", &path]);
    assert_fails_at(&text, 1, code, &["connect to simulator", "no simulator serves this socket", "ecmxf-sim serve"]);

    let sim = Simulator::serve(&dir, &[]);
    write(&sim.link());
    let (code, text) = probe(&["--config", &path]);
    assert_passes(code, &text);
    assert!(step(&text, 1).contains("simulator socket"), "{text}");

    // 2: INT0 held.
    sim.ctl("int0 stuck low");
    let (code, text) = probe(&["--config", &path]);
    assert_fails_at(&text, 2, code, &["INT0 never said ready within 1s", "int0 stuck off"]);
    sim.ctl("int0 stuck off");

    // 4: answers garbled (the MISO wire, as a clock too fast would).
    sim.ctl("flip miso 0.002");
    let (code, text) = probe(&["--config", &path]);
    assert_eq!(code, 1, "{text}");
    assert!(text.contains("FAIL") && text.contains("bit flips injected"), "{text}");
    sim.ctl("flip miso 0");

    // 6: the first slave unplugged: nothing answers.
    sim.ctl("unplug 0");
    let (code, text) = probe(&["--config", &path]);
    assert_fails_at(&text, 6, code, &["ECAT_INIT", "no slave answers", "IN port"]);
    sim.ctl("replug 0");
    let (code, text) = probe(&["--config", &path]);
    assert_passes(code, &text);

    // The daemon takes the chip as the probe left it, and inputs flow.
    run(async {
        let mut d = Daemon::with_config(&config(&sim.link(), ""));
        let ch = d.connect().await;
        let mut master = MasterClient::new(ch);
        let frames = |s: pb::MasterStatus| s.counters.map_or(0, |c| c.input_frames);
        let before = frames(master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner());
        tokio::time::sleep(Duration::from_millis(200)).await;
        let status = master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
        assert_eq!(status.ecat_state, pb::EcatState::Op as i32, "{status:?}");
        // Finding the chip at the probe's packet size and CRC is no link
        // error: none is counted.
        let counters = status.counters.unwrap_or_default();
        assert_eq!(counters.corrupt_answers, 0, "{counters:?}");
        assert!(frames(status) > before, "no input frames after the probe");

        // A daemon using the chip: the probe refuses to break in.
        let mut text = std::fs::read_to_string(&file).unwrap();
        text = text.replace(&dir.join("api.sock").display().to_string(), &d.socket.display().to_string());
        std::fs::write(&file, text).unwrap();
        let (code, text) = probe(&["--config", &path]);
        assert_eq!(code, 2, "{text}");
        assert!(text.contains("ecmxfd is running on this configuration") && text.contains("--force"), "{text}");
        assert!(!text.contains("1. device opens"), "{text}");
        d.stop();
    });
}

#[test]
fn a_missing_spi_device_names_the_kernel_setting() {
    let dir = temp_dir("probe-spi");
    let file = dir.join("rpi.toml");
    let text = std::fs::read_to_string(repo().join("config/ecmxfd-rpi.toml"))
        .unwrap()
        .replace("/dev/spidev0.0", &dir.join("spidev0.0").display().to_string());
    std::fs::write(&file, text).unwrap();
    let (code, text) = probe(&["--config", &file.display().to_string()]);
    assert_fails_at(&text, 1, code, &["No such file", "the kernel has no SPI device", "dtparam=spi=on"]);
}
