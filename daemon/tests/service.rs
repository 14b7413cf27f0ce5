//! `ecmxfd` as a systemd service, without systemd: the test plays the
//! service manager (a `$NOTIFY_SOCKET` datagram socket and
//! `$WATCHDOG_USEC`), scrapes the metrics endpoint, sends SIGHUP after
//! editing the configuration, and checks the shipped unit file with
//! `systemd-analyze verify` (CI installs it; ECMXF_REQUIRE_SYSTEMD=1 makes
//! its absence a failure).

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::UnixDatagram;
use std::process::{Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_ecmxfd");

fn repo(path: &str) -> String {
    format!("{}/../{path}", env!("CARGO_MANIFEST_DIR"))
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn http_get(port: u16, path: &str) -> String {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(s, "GET {path} HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    out
}

/// Waits for a notification containing `want`; returns every one seen.
fn expect(rx: &UnixDatagram, want: &str, within: Duration) -> Vec<String> {
    let start = Instant::now();
    let mut seen = Vec::new();
    let mut buf = [0u8; 4096];
    while start.elapsed() < within {
        rx.set_read_timeout(Some(Duration::from_millis(200))).unwrap();
        if let Ok(n) = rx.recv(&mut buf) {
            let m = String::from_utf8_lossy(&buf[..n]).into_owned();
            let hit = m.contains(want);
            seen.push(m);
            if hit {
                return seen;
            }
        }
    }
    panic!("no {want:?} within {within:?}; got {seen:#?}");
}

fn wait_log(log: &Receiver<String>, lines: &mut Vec<String>, want: &str) {
    let start = Instant::now();
    while !lines.iter().any(|l| l.contains(want)) {
        match log.recv_timeout(Duration::from_secs(10)) {
            Ok(l) => lines.push(l),
            Err(_) => panic!("log never said {want:?}: {lines:#?}"),
        }
        assert!(start.elapsed() < Duration::from_secs(20), "log never said {want:?}: {lines:#?}");
    }
}

#[test]
fn notifies_systemd_feeds_the_watchdog_serves_metrics_and_reloads() {
    let dir = std::env::temp_dir().join(format!("ecmxfd-service-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let notify = dir.join("notify.sock");
    let rx = UnixDatagram::bind(&notify).unwrap();
    let port = free_port();
    let base = std::fs::read_to_string(repo("config/ecmxfd-sim.toml"))
        .unwrap()
        .replace("network = \"demo-network.toml\"", &format!("network = \"{}\"", repo("config/demo-network.toml")));
    let config =
        |extra: &str| format!("{base}\n[log]\nlevel = \"info\"\n[metrics]\nlisten = \"127.0.0.1:{port}\"\n{extra}");
    let path = dir.join("ecmxfd.toml");
    std::fs::write(&path, config("")).unwrap();
    let mut child = Command::new(BIN)
        .args(["--config", path.to_str().unwrap(), "--status-every", "0"])
        .args(["--socket", dir.join("api.sock").to_str().unwrap()])
        .env("NOTIFY_SOCKET", &notify)
        .env("WATCHDOG_USEC", "400000")
        .env_remove("RUST_LOG")
        .env_remove("JOURNAL_STREAM")
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, log) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let pid = nix::unistd::Pid::from_raw(child.id() as i32);

    // READY only once the network is in its target state, with a status line.
    let seen = expect(&rx, "READY=1", Duration::from_secs(30));
    let ready = seen.last().unwrap();
    assert!(ready.contains("STATUS=OP: 3 slaves, cycle 125 us"), "{seen:#?}");
    // The watchdog is fed (every 200 ms: half of WATCHDOG_USEC).
    let start = Instant::now();
    expect(&rx, "WATCHDOG=1", Duration::from_secs(2));
    expect(&rx, "WATCHDOG=1", Duration::from_secs(2));
    assert!(start.elapsed() >= Duration::from_millis(150), "pinged at half the watchdog period, not flooding");

    // Metrics.
    let m = http_get(port, "/metrics");
    assert!(m.starts_with("HTTP/1.1 200 OK") && m.contains("text/plain; version=0.0.4"), "{m}");
    for want in [
        "ecmxf_engine_phase{phase=\"ENGINE_PHASE_RUNNING\"} 1",
        concat!("ecmxf_build_info{version=\"", env!("CARGO_PKG_VERSION"), "\",firmware=\"0x"),
        "ecmxf_network_state 8",
        "# TYPE ecmxf_exchanges_total counter",
        "ecmxf_crc_errors_total ",
        "ecmxf_wkc_errors_total ",
        "ecmxf_process_data_flowing 1",
        "ecmxf_ring_overflows_total ",
        "ecmxf_rx_fifo_frames ",
        "ecmxf_fifo_underruns_total ",
        "ecmxf_recoveries_total 0",
        "ecmxf_sdo_duration_seconds_bucket{le=\"+Inf\"} 0",
        "ecmxf_slave_state{position=\"2\",name=\"8io\"} 8",
        "ecmxf_slave_al_status_code{position=\"1\",name=\"TI CiA402 3-axis\"} 0",
        "ecmxf_slave_scrape_ok 1",
    ] {
        assert!(m.contains(want), "metrics lack {want:?}:\n{m}");
    }
    // Every counter of the API (proto `message Counters`) is a metric of
    // the same name, with its help line, and the metrics list in
    // docs/troubleshooting.md names it: the three say the same.
    let proto =
        std::fs::read_to_string(format!("{}/../proto/ecmxf/v1/master.proto", env!("CARGO_MANIFEST_DIR"))).unwrap();
    let docs = std::fs::read_to_string(format!("{}/../docs/troubleshooting.md", env!("CARGO_MANIFEST_DIR"))).unwrap();
    let counters = proto.split("message Counters {").nth(1).unwrap().split('}').next().unwrap();
    let fields: Vec<&str> = counters
        .lines()
        .filter_map(|l| l.trim().strip_prefix("uint64 "))
        .map(|l| l.split(' ').next().unwrap())
        .collect();
    assert!(fields.len() >= 15, "{fields:?}");
    for f in fields {
        let metric = match f.strip_suffix("_us") {
            Some(stem) => format!("ecmxf_{stem}_seconds"),
            None => format!("ecmxf_{f}_total"),
        };
        assert!(m.contains(&format!("# HELP {metric} ")), "counter {f}: no metric {metric} with help:\n{m}");
        assert!(docs.contains(&format!("`{metric}`")), "counter {f}: docs/troubleshooting.md does not list {metric}");
    }
    let exchanges =
        |m: &str| -> u64 { m.lines().find_map(|l| l.strip_prefix("ecmxf_exchanges_total ")).unwrap().parse().unwrap() };
    let first = exchanges(&m);
    std::thread::sleep(Duration::from_millis(300));
    assert!(exchanges(&http_get(port, "/metrics")) > first, "exchanges advance between scrapes");
    assert!(http_get(port, "/nothing").starts_with("HTTP/1.1 404"));

    // SIGHUP: the log level and a token are applied, a cycle change is not.
    let mut lines = Vec::new();
    let token = "[[api.token]]\nname = \"t\"\nsha256 = \"0000000000000000000000000000000000000000000000000000000000000000\"\nrole = \"observer\"\n";
    std::fs::write(
        &path,
        config(token).replace("level = \"info\"", "level = \"debug\"").replace("sync0_us = 125", "sync0_us = 250"),
    )
    .unwrap();
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGHUP).unwrap();
    let seen = expect(&rx, "RELOADING=1", Duration::from_secs(5));
    assert!(!seen.is_empty());
    expect(&rx, "READY=1", Duration::from_secs(5));
    wait_log(&log, &mut lines, "log.level applied");
    wait_log(&log, &mut lines, "api roles, tokens and client certificates applied");
    wait_log(&log, &mut lines, "not applied while the bus runs");
    assert!(lines.iter().any(|l| l.contains("[cycle]")), "{lines:#?}");
    // A broken file changes nothing.
    std::fs::write(&path, "version = 1\n[link]\n").unwrap();
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGHUP).unwrap();
    wait_log(&log, &mut lines, "keeping the running configuration");
    assert!(http_get(port, "/metrics").contains("ecmxf_network_state 8"), "still running");

    // SIGTERM: STOPPING, exit 0.
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();
    expect(&rx, "STOPPING=1", Duration::from_secs(10));
    assert!(child.wait().unwrap().success());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_taken_metrics_port_fails_the_start_by_name() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let dir = std::env::temp_dir().join(format!("ecmxfd-metrics-port-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("c.toml");
    std::fs::write(
        &path,
        format!("version = 1\n[link]\nbackend = \"sim\"\n[metrics]\nlisten = \"127.0.0.1:{port}\"\n"),
    )
    .unwrap();
    let out = Command::new(BIN)
        .args(["--config", path.to_str().unwrap(), "--socket", dir.join("s.sock").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("metrics.listen 127.0.0.1:{port}")), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_unit_file_passes_systemd_analyze() {
    let Ok(out) = Command::new("systemd-analyze").arg("--version").output() else {
        assert!(
            std::env::var_os("ECMXF_REQUIRE_SYSTEMD").is_none(),
            "systemd-analyze is required here (ECMXF_REQUIRE_SYSTEMD)"
        );
        eprintln!("systemd-analyze not installed: unit file not verified (CI installs it)");
        return;
    };
    assert!(out.status.success());
    // verify wants ExecStart to exist: point it at this build's binary.
    let dir = std::env::temp_dir().join(format!("ecmxfd-unit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let unit = std::fs::read_to_string(repo("systemd/ecmxfd.service")).unwrap().replace("/usr/bin/ecmxfd", BIN);
    let path = dir.join("ecmxfd.service");
    std::fs::write(&path, unit).unwrap();
    let out = Command::new("systemd-analyze").arg("verify").arg(&path).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success() && !text.contains("ecmxfd.service:"), "systemd-analyze verify:\n{text}");
    // The hardening holds up: systemd's own exposure score, 0 (locked) ..10.
    let out = Command::new("systemd-analyze").args(["security", "--offline=yes"]).arg(&path).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    let score: f64 = text
        .lines()
        .find_map(|l| l.split("exposure level for ecmxfd.service: ").nth(1))
        .and_then(|r| r.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no exposure score:\n{text}"));
    assert!(score <= 2.5, "exposure {score} (was 1.9):\n{text}");
    let _ = std::fs::remove_dir_all(&dir);
}
