//! The simulator over its Unix socket: the real `ecmxf-sim` binary serving,
//! a host speaking the documented framing, run-time control.

use std::path::PathBuf;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

use ecmxf_sim::server::{LINE_INT0, SocketClient};
use ecmxf_wire::payload::control::{FwVersionGet, InfoUpdate};
use ecmxf_wire::payload::slave_info::SlaveCountGet;
use ecmxf_wire::{CheckType, CommandCode, CommandHeader, Request, decode_response, encode_request};

struct Served {
    child: Child,
    socket: PathBuf,
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_file(&self.socket);
    }
}

fn serve(args: &[&str]) -> Served {
    let socket = std::env::temp_dir().join(format!("ecmxf-sim-test-{}-{}.sock", std::process::id(), args.len()));
    let child = Command::new(env!("CARGO_BIN_EXE_ecmxf-sim"))
        .arg("serve")
        .arg("--socket")
        .arg(&socket)
        .args(args)
        .spawn()
        .expect("start ecmxf-sim");
    let start = Instant::now();
    while SocketClient::connect(&socket).is_err() {
        assert!(start.elapsed() < Duration::from_secs(10), "ecmxf-sim did not start");
        std::thread::sleep(Duration::from_millis(20));
    }
    Served { child, socket }
}

fn exchange<'a, R: Request<'a>>(c: &mut SocketClient, req: &R, index: u8) -> Vec<u8> {
    assert!(c.wait_ready(Duration::from_secs(1)).unwrap(), "INT0 ready");
    let mut buf = [0u8; 144];
    encode_request(req, CommandHeader::new(R::CODE, index), CheckType::Fixed, &mut buf).unwrap();
    let mut miso = [0u8; 144];
    c.transfer(&buf, &mut miso).unwrap();
    miso.to_vec()
}

#[test]
fn a_host_talks_to_the_served_chip() {
    let s = serve(&["--network", concat!(env!("CARGO_MANIFEST_DIR"), "/../config/demo-network.toml")]);
    let mut c = SocketClient::connect(&s.socket).unwrap();
    let (lines, t0, _) = c.lines().unwrap();
    assert!(lines & LINE_INT0 != 0, "INT0 active-high when idle");
    let first = exchange(&mut c, &FwVersionGet, 1);
    assert!(decode_response(&first, CheckType::Fixed).unwrap().header.is_nop());
    let second = exchange(&mut c, &SlaveCountGet, 2);
    let a = decode_response(&second, CheckType::Fixed).unwrap();
    assert_eq!((a.header.code, a.header.return_value), (CommandCode::FwVersionGet, 0x24));
    let third = exchange(&mut c, &InfoUpdate, 3);
    assert_eq!(decode_response(&third, CheckType::Fixed).unwrap().header.return_value, 3);
    let (_, t1, _) = c.lines().unwrap();
    assert!(t1 > t0, "simulated time runs with the wall clock");

    // Run-time control from a second connection while the first stays open.
    let mut ctl = SocketClient::connect(&s.socket).unwrap();
    assert_eq!(ctl.control("unplug 2").unwrap(), Ok("ok".into()));
    assert!(ctl.control("unplug 7").unwrap().unwrap_err().contains("no slave 7"));
    let status = ctl.control("status").unwrap().unwrap();
    assert!(status.contains("packets=3"), "{status}");
    // Stuck INT0: waiting for ready times out.
    ctl.control("int0 stuck low").unwrap().unwrap();
    assert!(!c.wait_ready(Duration::from_millis(20)).unwrap());
    ctl.control("int0 stuck off").unwrap().unwrap();
    assert!(c.wait_ready(Duration::from_millis(20)).unwrap());

    // Transfer-when-ready: one round trip; refused (nothing clocked) while INT0 is stuck.
    let mut buf = [0u8; 144];
    encode_request(&SlaveCountGet, CommandHeader::new(SlaveCountGet::CODE, 4), CheckType::Fixed, &mut buf).unwrap();
    let mut miso = [0u8; 144];
    ctl.control("int0 stuck low").unwrap().unwrap();
    assert_eq!(c.transfer_when_ready(Duration::from_millis(20), &buf, &mut miso).unwrap(), None);
    ctl.control("int0 stuck off").unwrap().unwrap();
    assert!(c.transfer_when_ready(Duration::from_millis(100), &buf, &mut miso).unwrap().is_some());
    let answer = decode_response(&miso, CheckType::Fixed).unwrap();
    assert_eq!(answer.header.code, CommandCode::InfoUpdate, "the previous packet's answer");
    let status = ctl.control("status").unwrap().unwrap();
    assert!(status.contains("packets=4"), "the timed-out request clocked nothing: {status}");
}

#[test]
fn check_and_ctl_commands() {
    let out = Command::new(env!("CARGO_BIN_EXE_ecmxf-sim"))
        .args(["check", concat!(env!("CARGO_MANIFEST_DIR"), "/../config/demo-network.toml")])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(text.lines().count(), 3, "{text}");
    assert!(text.contains("CORE") && text.contains("0x0000059d") && text.contains("8io"), "{text}");

    let bad = std::env::temp_dir().join(format!("ecmxf-bad-{}.toml", std::process::id()));
    std::fs::write(&bad, "version = 1\n[[slave]]\nprofile = \"coupler\"\nspeed = 3\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_ecmxf-sim")).args(["check", bad.to_str().unwrap()]).output().unwrap();
    assert_eq!(out.status.code(), Some(2), "a bad file is a usage error, as in ecmxfd --check-config");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("speed") && err.contains("line 4"), "{err}");
    // A value out of the chip's range, with its line.
    std::fs::write(&bad, "version = 1\n[chip]\nspi_hz = 0\n[[slave]]\nprofile = \"coupler\"\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_ecmxf-sim")).args(["check", bad.to_str().unwrap()]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("chip.spi_hz") && err.contains("line 3"), "{err}");
    // `serve` says the same of the same file, with the same exit code.
    let socket = std::env::temp_dir().join(format!("ecmxf-bad-{}.sock", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_ecmxf-sim"))
        .args(["serve", "--socket", socket.to_str().unwrap(), "--network", bad.to_str().unwrap()])
        .output()
        .unwrap();
    std::fs::remove_file(&bad).ok();
    assert_eq!(out.status.code(), Some(2), "serve and check share exit codes");
    assert!(String::from_utf8_lossy(&out.stderr).contains("chip.spi_hz"));

    let s = serve(&[]);
    let out = Command::new(env!("CARGO_BIN_EXE_ecmxf-sim"))
        .args(["ctl", "--socket", s.socket.to_str().unwrap(), "help"])
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("drive-fault"));
    assert!(String::from_utf8_lossy(&out.stdout).contains("tx-fifo"));
}

/// `ecmxf-sim check FILE | head -1`: a reader that stops early ends the
/// listing, never in a panic.
#[test]
fn check_ends_quietly_when_its_reader_stops() {
    use std::process::Stdio;
    let net = std::env::temp_dir().join(format!("ecmxf-many-{}.toml", std::process::id()));
    std::fs::write(&net, format!("version = 1\n{}", "[[slave]]\nprofile = \"digital-io\"\n".repeat(128))).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_ecmxf-sim"))
        .args(["check", net.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Closed before the first line is written: every write finds no reader.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(out.status.success(), "{:?} {stderr}", out.status);
    let _ = std::fs::remove_file(&net);
}

/// `ecmxf-sim man DIR` writes ecmxf-sim(1): its commands, the network
/// file and every control command `ctl help` lists, which `man -l`
/// renders (when man is installed; the .deb's smoke test checks the page
/// is installed).
#[test]
fn the_manual_page_has_the_commands_the_network_file_and_the_control_language() {
    let dir = std::env::temp_dir().join(format!("ecmxf-sim-man-{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_ecmxf-sim")).args(["man", dir.to_str().unwrap()]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let page = dir.join("ecmxf-sim.1");
    let roff = std::fs::read_to_string(&page).unwrap();
    assert!(roff.contains(".TH ecmxf-sim 1"), "section 1: {}", &roff[..roff.len().min(200)]);
    if let Ok(rendered) = Command::new("man").env("MANWIDTH", "120").arg("-l").arg(&page).output() {
        let text = String::from_utf8_lossy(&rendered.stdout);
        for heading in ["SYNOPSIS", "DESCRIPTION", "NETWORK FILE", "CONTROL COMMANDS", "EXIT STATUS", "serve", "check"]
        {
            assert!(text.contains(heading), "no {heading} in:\n{text}");
        }
        // Every control command, as `ctl help` names it.
        for line in ecmxf_sim::control::HELP.lines() {
            let command = line.split_whitespace().next().unwrap();
            assert!(text.contains(command), "control command {command} not in:\n{text}");
        }
        let err = String::from_utf8_lossy(&rendered.stderr);
        assert!(!err.contains("warning"), "man warns: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
