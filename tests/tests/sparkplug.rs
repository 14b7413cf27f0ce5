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
use std::time::{Duration, Instant};

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
    assert!(text.contains("Ran 10 tests") && text.contains("OK"), "{text}");
}

/// A plant's broker: TLS with the plant's CA and client certificates
/// required. The node connects with `ca_file`, `client_cert` and
/// `client_key` and publishes its births (seen in the broker's log); a node
/// that trusts another CA never gets in and says why.
#[test]
fn the_node_connects_over_tls_with_a_client_certificate() {
    use rcgen::{BasicConstraints, CertificateParams, CertifiedIssuer, DnType, IsCa, KeyPair, KeyUsagePurpose};
    // Names of their own: OpenSSL takes a certificate whose subject is its
    // issuer's (rcgen's default for both) for a self-signed one.
    let named = |cn: &str, sans: Vec<String>| {
        let mut params = CertificateParams::new(sans).unwrap();
        params.distinguished_name.push(DnType::CommonName, cn);
        params
    };
    let Some(broker) = mosquitto() else { return };
    let _turn = ecmxf_e2e::SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = ecmxf_e2e::temp_dir("spb-tls");
    let issuer = |cn: &str| {
        let mut params = named(cn, Vec::new());
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        // OpenSSL (mosquitto) wants a CA that says it signs certificates.
        params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::DigitalSignature];
        CertifiedIssuer::self_signed(params, KeyPair::generate().unwrap()).unwrap()
    };
    let (ca, stranger_ca) = (issuer("plant CA"), issuer("another CA"));
    let server_key = KeyPair::generate().unwrap();
    let server = named("broker", vec!["localhost".to_string()]).signed_by(&server_key, &ca).unwrap();
    let client_key = KeyPair::generate().unwrap();
    let client = named("gateway-7", vec!["gateway-7".to_string()]).signed_by(&client_key, &ca).unwrap();
    let write = |name: &str, text: String| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.display().to_string()
    };
    let (ca_file, stranger_file) = (write("ca.pem", ca.pem()), write("stranger-ca.pem", stranger_ca.pem()));
    let (cert, key) = (write("server.pem", server.pem()), write("server.key", server_key.serialize_pem()));
    let (client_cert, client_key) =
        (write("client.pem", client.pem()), write("client.key", client_key.serialize_pem()));
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let conf = write(
        "mosquitto.conf",
        format!(
            "listener {port} 127.0.0.1\ncafile {ca_file}\ncertfile {cert}\nkeyfile {key}\nrequire_certificate true\n\
             use_identity_as_username true\nallow_anonymous true\npersistence false\n"
        ),
    );
    let log = dir.join("mosquitto.log");
    let out = std::fs::File::create(&log).unwrap();
    let mut mosquitto = Command::new(broker)
        .args(["-c", &conf, "-v"])
        .stdout(out.try_clone().unwrap())
        .stderr(out)
        .spawn()
        .expect("start mosquitto");
    let node = |name: &str, ca: &str| {
        ecmxf_e2e::config(
            "backend = \"sim\"",
            &format!(
                "[sparkplug]\nbroker = \"mqtts://localhost:{port}\"\ngroup_id = \"plant\"\nnode_id = \"{name}\"\n\
                 ca_file = \"{ca}\"\nclient_cert = \"{client_cert}\"\nclient_key = \"{client_key}\"\n"
            ),
        )
    };
    let births = |name: &str| {
        std::fs::read_to_string(&log).unwrap_or_default().contains(&format!("'spBv1.0/plant/NBIRTH/{name}'"))
    };
    let wait = |what: &dyn Fn() -> bool, limit: Duration| {
        let t = Instant::now();
        while !what() && t.elapsed() < limit {
            std::thread::sleep(Duration::from_millis(50));
        }
        what()
    };
    {
        let daemon = ecmxf_e2e::Daemon::binary_with_config(&node("trusted", &ca_file));
        let born = wait(&|| births("trusted"), Duration::from_secs(20));
        assert!(born, "no NBIRTH over TLS:\n{}\n{}", std::fs::read_to_string(&log).unwrap_or_default(), daemon.log());
    }
    {
        let daemon = ecmxf_e2e::Daemon::binary_with_config(&node("stranger", &stranger_file));
        let said = wait(&|| daemon.log().contains("sparkplug: connection lost"), Duration::from_secs(10));
        assert!(said && daemon.log().contains("certificate"), "{}", daemon.log());
        assert!(!births("stranger"), "a node that does not trust the broker's CA published");
    }
    let _ = mosquitto.kill();
    let _ = mosquitto.wait();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Fail-over and credentials: the first broker of the list does not
/// answer, the second wants a user name and password (mosquitto's
/// password file): the node reaches the second with `credentials_file`
/// and births there; with a wrong password the broker's refusal is logged.
#[test]
fn the_node_fails_over_to_the_next_broker_and_logs_in_with_its_credentials() {
    let Some(broker) = mosquitto() else { return };
    let passwd = broker.with_file_name("mosquitto_passwd");
    let passwd = if passwd.is_file() { passwd } else { PathBuf::from("/usr/bin/mosquitto_passwd") };
    let _turn = ecmxf_e2e::SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = ecmxf_e2e::temp_dir("spb-login");
    let file = |name: &str| dir.join(name).display().to_string();
    let made = Command::new(&passwd).args(["-b", "-c", &file("passwords"), "gateway", "s3cret"]).status();
    assert!(made.is_ok_and(|s| s.success()), "{} -b -c failed", passwd.display());
    let free = || std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let (dead, port) = (free(), free());
    std::fs::write(
        file("mosquitto.conf"),
        format!(
            "listener {port} 127.0.0.1\nallow_anonymous false\npassword_file {}\npersistence false\n",
            file("passwords")
        ),
    )
    .unwrap();
    let log = dir.join("mosquitto.log");
    let out = std::fs::File::create(&log).unwrap();
    let mut mosquitto = Command::new(broker)
        .args(["-c", &file("mosquitto.conf"), "-v"])
        .stdout(out.try_clone().unwrap())
        .stderr(out)
        .spawn()
        .expect("start mosquitto");
    let node = |name: &str, password: &str| {
        std::fs::write(file(name), format!("gateway\n{password}\n")).unwrap();
        ecmxf_e2e::config(
            "backend = \"sim\"",
            &format!(
                "[sparkplug]\nbroker = [\"mqtt://127.0.0.1:{dead}\", \"mqtt://127.0.0.1:{port}\"]\ngroup_id = \"plant\"\n\
                 node_id = \"{name}\"\ncredentials_file = \"{}\"\n",
                file(name)
            ),
        )
    };
    let births = |name: &str| {
        std::fs::read_to_string(&log).unwrap_or_default().contains(&format!("'spBv1.0/plant/NBIRTH/{name}'"))
    };
    let wait = |what: &dyn Fn() -> bool, limit: Duration| {
        let t = Instant::now();
        while !what() && t.elapsed() < limit {
            std::thread::sleep(Duration::from_millis(50));
        }
        what()
    };
    {
        let daemon = ecmxf_e2e::Daemon::binary_with_config(&node("right", "s3cret"));
        let born = wait(&|| births("right"), Duration::from_secs(20));
        assert!(born, "no NBIRTH on the second broker:\n{}", daemon.log());
        assert!(daemon.log().contains(&format!("127.0.0.1:{dead}")), "the dead broker tried first:\n{}", daemon.log());
    }
    {
        let daemon = ecmxf_e2e::Daemon::binary_with_config(&node("wrong", "guess"));
        let said = wait(&|| daemon.log().contains("the broker refused the connection"), Duration::from_secs(20));
        assert!(said, "{}", daemon.log());
        assert!(!births("wrong"));
    }
    let _ = mosquitto.kill();
    let _ = mosquitto.wait();
    let _ = std::fs::remove_dir_all(&dir);
}
