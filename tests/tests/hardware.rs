//! The hardware link end to end: `ecmxfd` with `link.backend = "spidev"`
//! and config/ecmxfd-rpi.toml's wiring, on `/dev/spidev0.0` and
//! `/dev/gpiochip0` emulated by the preload library of sim/hw-emu in front
//! of a served simulator (this machine has no SPI or GPIO). What runs is
//! the code a Raspberry Pi runs: daemon/src/link/hardware.rs, the `spidev`
//! and `gpiocdev` crates, libc's ioctl/ppoll/read; both the default build
//! and the one without the simulator (`--no-default-features`, as the
//! hardware .deb ships it).
//!
//! - `ecmxfd probe` passes every step, and each hardware diagnosis
//!   docs/raspberry-pi.md lists is triggered through the devices: no SPI
//!   device, no permission, no GPIO chip, not a GPIO chip, no such line, a
//!   line another program holds, INT0 never ready, INT0 never moving, MISO
//!   stuck high or low, the wrong SPI mode, bit errors (fail and warn), no
//!   slave. (Steps 5 and 7 cannot be made to fail through the simulator:
//!   daemon/src/probe.rs tests them over scripted links.)
//! - The daemon reaches OP and process data flows through the hardware
//!   link under the fault matrix's INT0, warm-reset and bit-error faults
//!   (tests/tests/faults.rs runs them), and SIGTERM leaves the slaves in
//!   INIT.

use std::process::Command;

use ecmxf_e2e::hardware::{Build, emulation, rpi_link};
use ecmxf_e2e::probe_report::{assert_fails_at, assert_passes, step};
use ecmxf_e2e::{SERIAL, Simulator, config, temp_dir};

/// `ecmxfd probe` of `build` with the `[link]` table `link`, on the
/// emulated devices of `sim` with `env` added: exit code and report.
fn probe(build: Build, sim: &Simulator, link: &str, env: &[(&str, &str)]) -> (i32, String) {
    let dir = temp_dir("hw-probe");
    let file = dir.join("probe.toml");
    let text = format!("{}\n[api]\nsocket = \"{}\"\n", config(link, ""), dir.join("api.sock").display());
    std::fs::write(&file, text).unwrap();
    let out = Command::new(build.binary())
        .envs(emulation(sim, env))
        .args(["probe", "--config"])
        .arg(&file)
        .output()
        .expect("run ecmxfd probe");
    let _ = std::fs::remove_dir_all(&dir);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.code().unwrap_or(-1), text)
}

#[test]
fn probe_passes_every_step_through_spidev_and_gpio_in_both_builds() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    for build in [Build::Default, Build::NoSim] {
        let dir = temp_dir("hw-probe-ok");
        let sim = Simulator::serve(&dir, &[]);
        let (code, text) = probe(build, &sim, &rpi_link(), &[]);
        assert_passes(code, &text);
        assert!(step(&text, 1).contains("/dev/spidev0.0 at 20000000 Hz, INT0 line 24, INT1 line 25"), "{text}");
        // Edges, read as gpio_v2_line_event records: not a level looked at.
        assert!(step(&text, 2).contains("went busy when a packet was complete and ready again"), "{text}");
        assert!(step(&text, 6).contains(r#"3 slaves: 0 "CORE", 1 "TI CiA402 3-axis", 2 "8io""#), "{text}");
        println!("{build:?}:\n{text}");
    }
}

/// A debounce on the lines (`link.debounce_us`) applies to INT1 only: on
/// INT0 it would erase the chip's busy pulse (tens of us) and step 2 would
/// fail blaming the wiring (the emulated kernel debounces as the real one).
#[test]
fn a_debounce_does_not_erase_int0s_pulses() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = temp_dir("hw-probe-debounce");
    let sim = Simulator::serve(&dir, &[]);
    let link = rpi_link().replace("idle_us = 200", "idle_us = 200\ndebounce_us = 100");
    assert!(link.contains("debounce_us = 100"), "{link}");
    let (code, text) = probe(Build::NoSim, &sim, &link, &[]);
    assert_passes(code, &text);
}

/// One fault: what to change, where the probe must stop and what it says.
struct Case {
    name: &'static str,
    /// `[link]` keys replaced: (the rpi file's line, the new one).
    link: &'static [(&'static str, &'static str)],
    env: &'static [(&'static str, &'static str)],
    /// `ecmxf-sim ctl` commands before the probe.
    ctl: &'static [&'static str],
    step: usize,
    says: &'static [&'static str],
}

const CASES: &[Case] = &[
    Case {
        name: "SPI not enabled (no /dev/spidev1.0)",
        link: &[("device = \"/dev/spidev0.0\"", "device = \"/dev/spidev1.0\"")],
        env: &[],
        ctl: &[],
        step: 1,
        says: &["open /dev/spidev1.0", "No such file", "the kernel has no SPI device", "dtparam=spi=on"],
    },
    Case {
        name: "no permission on the SPI device",
        link: &[],
        env: &[("ECMXF_EMU_DENY", "/dev/spidev0.0")],
        ctl: &[],
        step: 1,
        says: &["Permission denied", "may not open the SPI device", "usermod -aG ecmxfd"],
    },
    Case {
        name: "no permission on the GPIO chip",
        link: &[],
        env: &[("ECMXF_EMU_DENY", "/dev/gpiochip0")],
        ctl: &[],
        step: 1,
        says: &["request int0 line 24", "may not open /dev/gpiochip0"],
    },
    Case {
        name: "no such GPIO chip",
        link: &[("gpio_chip = \"/dev/gpiochip0\"", "gpio_chip = \"/dev/gpiochip9\"")],
        env: &[],
        ctl: &[],
        step: 1,
        says: &["/dev/gpiochip9 does not exist", "gpiodetect"],
    },
    Case {
        name: "not a GPIO chip",
        link: &[("gpio_chip = \"/dev/gpiochip0\"", "gpio_chip = \"/dev/null\"")],
        env: &[],
        ctl: &[],
        step: 1,
        says: &["/dev/null is not a GPIO chip"],
    },
    Case {
        name: "no such line",
        link: &[("int0_line = 24", "int0_line = 60")],
        env: &[],
        ctl: &[],
        step: 1,
        says: &["request int0 line 60", "has no such line", "gpioinfo"],
    },
    Case {
        name: "INT0 never ready",
        link: &[],
        env: &[],
        ctl: &["int0 stuck low"],
        step: 2,
        says: &["INT0 never said ready", "never reached its ready level on /dev/gpiochip0 line 24"],
    },
    Case {
        name: "INT0 never moving",
        link: &[],
        env: &[],
        ctl: &["int0 stuck high"],
        step: 2,
        says: &["no INT0 edge", "stays at its ready level", "gpiomon"],
    },
    Case {
        name: "MISO stuck high",
        link: &[],
        env: &[("ECMXF_EMU_MISO", "high")],
        ctl: &[],
        step: 3,
        says: &["ff ff ff ff", "MISO sits high"],
    },
    Case {
        name: "MISO stuck low",
        link: &[],
        env: &[("ECMXF_EMU_MISO", "low")],
        ctl: &[],
        step: 3,
        says: &["00 00 00 00", "MISO sits low"],
    },
    Case {
        name: "the controller clocks SPI mode 1",
        link: &[],
        env: &[("ECMXF_EMU_FORCE_MODE", "1")],
        ctl: &[],
        step: 3,
        says: &["never form packets", "the SPI mode is not 0", "spi-cpha"],
    },
    Case {
        name: "bit errors on MISO",
        link: &[],
        env: &[],
        ctl: &["flip miso 0.0003"],
        step: 4,
        says: &["corrupt answers", "bit errors on the SPI wires", "lower link.spi_hz (try 10000000 Hz)"],
    },
    Case { name: "no slave answers", link: &[], env: &[], ctl: &["unplug 0"], step: 6, says: &["no slave answers"] },
];

#[test]
fn probe_diagnoses_each_hardware_fault_through_the_emulated_devices() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    for case in CASES {
        let dir = temp_dir("hw-probe-fault");
        let sim = Simulator::serve(&dir, &["--seed", "7"]);
        for c in case.ctl {
            sim.ctl(c);
        }
        let mut link = rpi_link();
        for (from, to) in case.link {
            assert!(link.contains(from), "{}: config/ecmxfd-rpi.toml has no {from:?}", case.name);
            link = link.replace(from, to);
        }
        let (code, text) = probe(Build::NoSim, &sim, &link, case.env);
        println!("== {}\n{}", case.name, step(&text, case.step));
        assert_fails_at(&text, case.step, code, case.says);
    }
}

#[test]
fn probe_warns_of_a_few_corrupt_answers() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = temp_dir("hw-probe-warn");
    let sim = Simulator::serve(&dir, &["--seed", "7"]);
    sim.ctl("flip miso 0.00003");
    let (code, text) = probe(Build::NoSim, &sim, &rpi_link(), &[]);
    assert_eq!(code, 0, "{text}");
    let s = step(&text, 4);
    assert!(s.contains(" WARN ") && s.contains("bit errors on the SPI wires"), "{text}");
}

#[test]
fn a_line_another_program_holds_is_named_by_the_probe() {
    // Another program requests INT0 through the same (emulated) kernel:
    // the running daemon (the probe's own refusal is for a daemon on the
    // same API socket; this one has another). `run` takes SERIAL.
    ecmxf_e2e::run(async {
        let dir = temp_dir("hw-probe-busy");
        let sim = Simulator::serve(&dir, &[]);
        let text = config(&rpi_link(), "");
        let mut d = ecmxf_e2e::Daemon::binary_with_config_on(&Build::NoSim.binary(), &text, &emulation(&sim, &[]));
        d.connect().await;
        let (code, out) = probe(Build::NoSim, &sim, &rpi_link(), &[]);
        assert_fails_at(
            &out,
            1,
            code,
            &["request int0 line 24", "Device or resource busy", "another program holds the line"],
        );
        assert_eq!(d.stop(), Some(0), "{}", d.log());
        // Its lines are free once it has stopped.
        let (code, text) = probe(Build::NoSim, &sim, &rpi_link(), &[]);
        assert_passes(code, &text);
    });
}

/// The one command docs/raspberry-pi.md gives for a machine without a
/// board: `ecmxf-sim hardware -- ecmxfd probe --config
/// config/ecmxfd-rpi.toml`, the configuration file as it ships.
#[test]
fn one_command_probes_the_shipped_rpi_configuration_on_emulated_devices() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let sim = ecmxf_e2e::daemon_binary().with_file_name("ecmxf-sim");
    let out = Command::new(&sim)
        .args(["hardware", "--library"])
        .arg(ecmxf_e2e::hardware::emu_library())
        .arg("--")
        .arg(Build::NoSim.binary())
        .args(["probe", "--config"])
        .arg(ecmxf_e2e::repo().join("config/ecmxfd-rpi.toml"))
        .output()
        .expect("run ecmxf-sim hardware");
    let text = String::from_utf8_lossy(&out.stdout);
    assert_passes(out.status.code().unwrap_or(-1), &text);
    // The command's exit status is passed on.
    let out = Command::new(&sim)
        .args(["hardware", "--library"])
        .arg(ecmxf_e2e::hardware::emu_library())
        .args(["--", "sh", "-c", "exit 3"])
        .output()
        .expect("run ecmxf-sim hardware");
    assert_eq!(out.status.code(), Some(3));
}
