//! The real `ecmxfd` binary: `--check-config` on good and bad files, and
//! `--sim` running until SIGTERM, then stopping safely with exit code 0.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_ecmxfd");

fn repo(path: &str) -> String {
    format!("{}/../{path}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn check_config_accepts_the_examples_and_names_mistakes() {
    // Every example configuration the package ships.
    for (file, link) in [
        ("config/ecmxfd-sim.toml", "in-process simulator"),
        ("config/ecmxfd-rpi.toml", "/dev/spidev0.0"),
        ("config/ecmxfd-gateway.toml", "/dev/spidev1.0"),
        ("config/ecmxfd-eni.toml", "in-process simulator"),
    ] {
        let out = Command::new(BIN).args(["--check-config", &repo(file)]).output().unwrap();
        if file.ends_with("gateway.toml") && !std::path::Path::new("/etc/ecmxfd/tls/server.pem").exists() {
            // The gateway example names the TLS files the user creates:
            // until they exist, the check says which one is missing.
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{file}: {err}");
            assert!(err.contains("api.tls_cert") && err.contains("/etc/ecmxfd/tls/server.pem"), "{file}: {err}");
            continue;
        }
        assert!(out.status.success(), "{file}: {}", String::from_utf8_lossy(&out.stderr));
        assert!(String::from_utf8_lossy(&out.stdout).contains(&format!(": ok ({link}")), "{file}");
        assert!(String::from_utf8_lossy(&out.stdout).contains("output latency budget"), "{file}: the budget is said");
    }
    let examples: Vec<String> = std::fs::read_dir(repo("config"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("ecmxfd") && n.ends_with(".toml"))
        .collect();
    assert_eq!(examples.len(), 4, "a new example configuration needs a line above: {examples:?}");

    let bad = std::env::temp_dir().join(format!("ecmxfd-bad-{}.toml", std::process::id()));
    for (text, expect) in [
        ("version = 1\n[link]\nbackend = \"sim\"\n[cycle]\nsync0_us = 100\n", "cycle.sync0_us"),
        ("version = 1\n[link]\nbackend = \"sim\"\n[chip]\ndatasize = 1\n", "line 5"),
        ("version = 1\n", "link"),
        (
            "version = 1\n[link]\nbackend = \"sim\"\n[cycle]\ntarget_state = \"opp\"\n",
            "expected one of `preop`, `safeop`, `op`",
        ),
        ("version = 1\n[link]\nbackend = \"sim\"\n[log]\nlevel = \"info,=[\"\n", "log.level"),
        ("version = 1\n[link]\nbackend = \"sim\"\n[metrics]\nlisten = \"localhost\"\n", "line 5"),
        (
            "version = 1\n[link]\nbackend = \"sim\"\n[cycle]\nsync0_us = 1000\noutput_latency_us = 1500\n",
            "cycle.output_latency_us",
        ),
        // The demo's 248 us packets at 125 us: a refill behind a
        // transaction takes 8 cycles and the host's 1 ms stall 8 more, so
        // nothing under 33 holds; 2500 us, which the link alone holds, ran
        // late writes under real-time settings.
        (
            "version = 1\n[link]\nbackend = \"sim\"\n[cycle]\nsync0_us = 125\noutput_latency_us = 2500\n",
            "the smallest budget this link and host hold is 4125 us",
        ),
        (
            "version = 1\n[link]\nbackend = \"sim\"\n[realtime]\nhost_stall_us = 0\n[cycle]\nsync0_us = 125\n\
             output_latency_us = 1000\n",
            "the smallest budget this link and host hold is 2125 us",
        ),
        (
            "version = 1\n[link]\nbackend = \"spidev\"\ndevice = \"/dev/null\"\nspi_hz = 20000000\n\
             [cycle]\nsync0_us = 125\noutput_latency_us = 1000\n",
            "cycle.output_latency_us",
        ),
    ] {
        std::fs::write(&bad, text).unwrap();
        let out = Command::new(BIN).args(["--check-config", bad.to_str().unwrap()]).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{text}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(expect), "{text}: {err}");
    }
    // Files the configuration names are opened and read as the daemon
    // will: each mistake named by its key, before any restart.
    let dir = std::env::temp_dir().join(format!("ecmxfd-files-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("not-esi.xml"), "<html/>").unwrap();
    std::fs::write(dir.join("cert.pem"), "not a certificate").unwrap();
    std::fs::write(dir.join("net.toml"), "version = 1\n[[slave]]\nesi = \"missing.xml\"\n").unwrap();
    let sim = "version = 1\n[link]\nbackend = \"sim\"\n";
    for (text, key) in [
        (format!("{sim}[[slave]]\nesi = \"nowhere.xml\"\n"), "slave[0].esi"),
        (format!("{sim}[[slave]]\nesi = \"not-esi.xml\"\n"), "slave[0].esi"),
        (
            format!(
                "{sim}[api]\ntcp = \"127.0.0.1:0\"\ntls_cert = \"cert.pem\"\ntls_key = \"cert.pem\"\n\
                 [[api.token]]\nsha256 = \"{}\"\nrole = \"observer\"\n",
                "ab".repeat(32)
            ),
            "api.tls_cert",
        ),
        ("version = 1\n[link]\nbackend = \"sim\"\nnetwork = \"net.toml\"\n".to_string(), "link.network"),
        // The demo's IO slave maps no controlword: an [[axis]] there would
        // have the chip's CiA 402 helper drive its digital outputs.
        (format!("{sim}[[axis]]\nslave = 2\n"), "axis[0].controlword_offset"),
        (format!("{sim}[[axis]]\nslave = 1\ncontrolword_offset = 1\n"), "axis[0].controlword_offset"),
        (format!("{sim}[[axis]]\nslave = 7\n"), "axis[0].slave"),
    ] {
        let file = dir.join("ecmxfd.toml");
        std::fs::write(&file, &text).unwrap();
        let out = Command::new(BIN).args(["--check-config", file.to_str().unwrap()]).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{text}: {err}");
        assert!(err.contains(key), "{text}: wanted {key} in {err}");
        // A start refuses it the same way: the same status (which the
        // unit's RestartPreventExitStatus= lists), the same key, at once.
        let socket = dir.join("s.sock");
        let started = Instant::now();
        let out = Command::new(BIN)
            .args(["--config", file.to_str().unwrap(), "--socket", socket.to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "start with {text}: {err}");
        assert!(err.contains(key), "start with {text}: wanted {key} in {err}");
        assert!(started.elapsed() < Duration::from_secs(5), "start with {text}: took {:?}", started.elapsed());
    }
    // The unit does not restart what can never start.
    let unit = std::fs::read_to_string(repo("systemd/ecmxfd.service")).unwrap();
    assert!(unit.lines().any(|l| l == "RestartPreventExitStatus=2 78"), "the unit lists 2 and 78");
    // The TI drive (slave 1) maps both at byte 0: the check passes.
    let file = dir.join("ecmxfd.toml");
    std::fs::write(&file, format!("{sim}[[axis]]\nslave = 1\n")).unwrap();
    let out = Command::new(BIN).args(["--check-config", file.to_str().unwrap()]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::remove_file(&bad).ok();
    let out = Command::new(BIN).output().unwrap();
    assert_eq!(out.status.code(), Some(2), "no config and no --sim");
}

#[test]
fn runs_on_the_simulator_until_sigterm() {
    let mut child = Command::new(BIN)
        .args(["--config", &repo("config/ecmxfd-sim.toml"), "--status-every", "0"])
        .args([
            "--socket",
            &std::env::temp_dir().join(format!("ecmxfd-binary-{}.sock", std::process::id())).display().to_string(),
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let start = Instant::now();
    let mut log = Vec::new();
    while !log.iter().any(|l: &String| l.contains("ready")) {
        let line = rx.recv_timeout(Duration::from_secs(30)).expect("ecmxfd printed nothing for 30 s");
        log.push(line);
        assert!(start.elapsed() < Duration::from_secs(30), "not ready: {log:#?}");
    }
    assert!(log.iter().any(|l| l.contains("slave") && l.contains("8io")), "{log:#?}");
    std::thread::sleep(Duration::from_millis(300));
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(child.id() as i32), nix::sys::signal::Signal::SIGTERM).unwrap();
    let status = child.wait().unwrap();
    log.extend(rx.try_iter());
    assert!(status.success(), "{status:?} {log:#?}");
    assert!(
        log.iter().any(|l| l.contains("safe stop")) && log.iter().any(|l| l.contains("engine stopped")),
        "{log:#?}"
    );
}

/// `ecmxfd man DIR` writes ecmxfd(8), which `man -l` renders with its
/// options, signals, files and exit statuses (when man is installed; the
/// .deb's smoke test checks the page is installed), and ecmxfd.toml(5)
/// (checked below).
#[test]
fn the_manual_page_renders_with_options_signals_and_files() {
    let dir = std::env::temp_dir().join(format!("ecmxfd-man-{}", std::process::id()));
    let out = Command::new(BIN).args(["man", dir.to_str().unwrap()]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let page = dir.join("ecmxfd.8");
    let roff = std::fs::read_to_string(&page).unwrap();
    assert!(roff.contains(".TH ecmxfd 8"), "section 8: {}", &roff[..roff.len().min(200)]);
    if let Ok(rendered) = Command::new("man").env("MANWIDTH", "100").arg("-l").arg(&page).output() {
        let text = String::from_utf8_lossy(&rendered.stdout);
        for heading in ["SYNOPSIS", "DESCRIPTION", "SIGNALS", "FILES", "EXIT STATUS", "OPTIONS", "--check-config"] {
            assert!(text.contains(heading), "no {heading} in:\n{text}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// ecmxfd.toml(5) documents every key the example configurations use (and
/// the schema it is made from holds every key the parser takes), under the
/// table the file has it in; `man -l` renders it.
#[test]
fn the_configuration_page_documents_every_key_of_the_examples() {
    let dir = std::env::temp_dir().join(format!("ecmxfd-man5-{}", std::process::id()));
    let out = Command::new(BIN).args(["man", dir.to_str().unwrap()]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let roff = std::fs::read_to_string(dir.join("ecmxfd.toml.5")).unwrap();
    assert!(roff.contains(".TH ecmxfd.toml 5"), "section 5: {}", &roff[..roff.len().min(200)]);
    let documented = ecmxfd::config::documented_keys();

    fn keys(prefix: &str, table: &toml::Table, out: &mut Vec<String>) {
        for (k, v) in table {
            let path = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
            match v {
                toml::Value::Table(t) => keys(&path, t, out),
                toml::Value::Array(items) if items.iter().all(toml::Value::is_table) && !items.is_empty() => {
                    for t in items.iter().filter_map(toml::Value::as_table) {
                        keys(&path, t, out);
                    }
                }
                _ => {}
            }
            out.push(path);
        }
    }
    for file in
        ["config/ecmxfd-sim.toml", "config/ecmxfd-rpi.toml", "config/ecmxfd-gateway.toml", "config/ecmxfd-eni.toml"]
    {
        let table: toml::Table = std::fs::read_to_string(repo(file)).unwrap().parse().unwrap();
        let mut used = Vec::new();
        keys("", &table, &mut used);
        for key in used {
            assert!(documented.contains(&key), "{file}: {key} is not in ecmxfd.toml(5)");
        }
    }
    // Each key is in the page (its last word), each table heads a section.
    for key in &documented {
        let word = key.rsplit('.').next().unwrap().replace('-', "\\-");
        assert!(roff.contains(&format!(".B {word}\n")) || roff.contains(&format!("{key}]")), "{key} not in the page");
    }
    if let Ok(rendered) = Command::new("man").env("MANWIDTH", "100").arg("-l").arg(dir.join("ecmxfd.toml.5")).output() {
        let text = String::from_utf8_lossy(&rendered.stdout);
        for heading in ["SYNOPSIS", "DESCRIPTION", "[link]", "[cycle]", "[[slave]]", "sync0_us", "SEE ALSO"] {
            assert!(text.contains(heading), "no {heading} in:\n{text}");
        }
        let err = String::from_utf8_lossy(&rendered.stderr);
        assert!(!err.contains("warning"), "man warns: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
