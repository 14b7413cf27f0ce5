//! Under systemd (`$JOURNAL_STREAM` set) the daemon logs to journald's
//! native socket with its identifier and structured fields, and falls back
//! to stderr when journald does not answer. The test plays journald on
//! /run/systemd/journal/socket, so it runs only as root on a machine
//! without a journald of its own (CI); elsewhere it says why it skipped.

use std::os::unix::net::UnixDatagram;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_ecmxfd");
const JOURNAL: &str = "/run/systemd/journal/socket";

/// One entry of journald's native protocol: `KEY=value\n`, or `KEY\n` +
/// little-endian u64 length + bytes + `\n` for values that may hold newlines.
fn parse_entry(mut b: &[u8]) -> Vec<(String, String)> {
    let mut fields = Vec::new();
    while let Some(nl) = b.iter().position(|c| *c == b'\n') {
        let line = &b[..nl];
        if let Some(eq) = line.iter().position(|c| *c == b'=') {
            fields.push((String::from_utf8_lossy(&line[..eq]).into(), String::from_utf8_lossy(&line[eq + 1..]).into()));
            b = &b[nl + 1..];
        } else {
            let key = String::from_utf8_lossy(line).into_owned();
            let rest = &b[nl + 1..];
            let Some(len) = rest.get(..8).map(|l| u64::from_le_bytes(l.try_into().unwrap()) as usize) else { break };
            let Some(value) = rest.get(8..8 + len) else { break };
            fields.push((key, String::from_utf8_lossy(value).into()));
            b = rest.get(8 + len + 1..).unwrap_or_default();
        }
    }
    fields
}

fn sim_daemon(dir: &std::path::Path) -> Command {
    let mut c = Command::new(BIN);
    c.args(["--sim", "--status-every", "0", "--socket", dir.join("api.sock").to_str().unwrap()])
        .env("JOURNAL_STREAM", "8:12345")
        .env_remove("RUST_LOG");
    c
}

#[test]
fn logs_go_to_journald_when_systemd_says_so() {
    let dir = std::env::temp_dir().join(format!("ecmxfd-journald-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let sigterm = |pid: u32| {
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), nix::sys::signal::Signal::SIGTERM).unwrap()
    };

    if std::path::Path::new(JOURNAL).exists() || !nix::unistd::geteuid().is_root() {
        eprintln!("journald test skipped: needs root and no journald of this machine's own at {JOURNAL}");
    } else {
        std::fs::create_dir_all("/run/systemd/journal").unwrap();
        let journal = UnixDatagram::bind(JOURNAL).unwrap();
        journal.set_read_timeout(Some(Duration::from_millis(200))).unwrap();
        let child = sim_daemon(&dir).stderr(Stdio::piped()).spawn().unwrap();
        let start = Instant::now();
        let mut entries: Vec<Vec<(String, String)>> = Vec::new();
        let mut buf = vec![0u8; 65536];
        let is_ready = |e: &Vec<(String, String)>| e.iter().any(|(k, v)| k == "MESSAGE" && v == "ready");
        while !entries.iter().any(is_ready) && start.elapsed() < Duration::from_secs(30) {
            if let Ok(n) = journal.recv(&mut buf) {
                entries.push(parse_entry(&buf[..n]));
            }
        }
        sigterm(child.id());
        let out = child.wait_with_output().unwrap();
        let _ = std::fs::remove_file(JOURNAL);
        let _ = std::fs::remove_dir("/run/systemd/journal");
        let _ = std::fs::remove_dir("/run/systemd");
        let ready = entries.iter().find(|e| is_ready(e)).unwrap_or_else(|| panic!("{entries:#?}"));
        let field = |k: &str| ready.iter().find(|(key, _)| key == k).map(|(_, v)| v.as_str());
        assert_eq!(field("SYSLOG_IDENTIFIER"), Some("ecmxfd"), "{ready:?}");
        assert_eq!(field("PRIORITY"), Some("5"), "INFO is notice (5) in tracing-journald: {ready:?}");
        assert_eq!(field("STATE"), Some("OP"), "structured fields are journal fields: {ready:?}");
        let slave = entries.iter().find(|e| e.iter().any(|(k, v)| k == "NAME" && v == "8io")).expect("slave lines");
        assert!(slave.iter().any(|(k, v)| k == "POSITION" && v == "2"), "{slave:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("ready"), "nothing duplicated on stderr: {stderr}");
    }

    // No journald answering: stderr, as without systemd.
    if !std::path::Path::new(JOURNAL).exists() {
        let child = sim_daemon(&dir).stderr(Stdio::piped()).spawn().unwrap();
        std::thread::sleep(Duration::from_secs(2));
        sigterm(child.id());
        let out = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains("logs=\"stderr\"") || stderr.contains("logs=stderr"), "{stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
