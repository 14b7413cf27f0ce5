//! Roles and transports: the Unix socket's mode and peer credentials,
//! bearer tokens, TCP only with TLS, client certificates; denied calls are
//! PERMISSION_DENIED or UNAUTHENTICATED, never a silent no-op.

use std::os::unix::fs::PermissionsExt;

use ecmxf_e2e::{Daemon, run, sdo_write, with_token};
use ecmxf_proto::v1 as pb;
use pb::master_client::MasterClient;
use pb::registers_client::RegistersClient;
use pb::sdo_client::SdoClient;
use rcgen::{BasicConstraints, CertificateParams, CertifiedIssuer, IsCa, KeyPair};
use sha2::{Digest, Sha256};
use tonic::Code;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Identity};

fn sha(b: &[u8]) -> String {
    hex::encode(Sha256::digest(b))
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn reg_read() -> pb::ReadRegistersRequest {
    pb::ReadRegistersRequest { slave: 0, address: 0x0130, length: 2 }
}

#[test]
fn roles_tokens_tls_and_client_certificates() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("pki");
        let mut ca_params = CertificateParams::new(Vec::<String>::new()).unwrap();
        ca_params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        let ca = CertifiedIssuer::self_signed(ca_params, KeyPair::generate().unwrap()).unwrap();
        let server_key = KeyPair::generate().unwrap();
        let server =
            CertificateParams::new(vec!["localhost".to_string()]).unwrap().signed_by(&server_key, &ca).unwrap();
        let client_key = KeyPair::generate().unwrap();
        let client = CertificateParams::new(vec!["robot".to_string()]).unwrap().signed_by(&client_key, &ca).unwrap();
        let stranger_key = KeyPair::generate().unwrap();
        let stranger =
            CertificateParams::new(vec!["stranger".to_string()]).unwrap().signed_by(&stranger_key, &ca).unwrap();
        let write = |name: &str, text: String| {
            let p = dir.join(name);
            std::fs::write(&p, text).unwrap();
            p.display().to_string()
        };
        let (cert, key, ca_file) = (
            write("server.pem", server.pem()),
            write("server.key", server_key.serialize_pem()),
            write("ca.pem", ca.pem()),
        );
        let port = free_port();
        let api = format!(
            r#"
[api]
socket_mode = 0o600
tcp = "127.0.0.1:{port}"
tls_cert = "{cert}"
tls_key = "{key}"
client_ca = "{ca_file}"
[[api.token]]
name = "dashboard"
sha256 = "{obs}"
role = "observer"
[[api.token]]
name = "plc"
sha256 = "{op}"
role = "operator"
[[api.client_cert]]
name = "robot"
sha256 = "{robot}"
role = "admin"
"#,
            obs = sha(b"observer-secret"),
            op = sha(b"operator-secret"),
            robot = sha(client.der()),
        );
        let mut d = Daemon::with_config(&ecmxf_e2e::config("backend = \"sim\"", &api));
        let unix = d.connect().await;
        let mode = std::fs::metadata(&d.socket).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600, "socket mode from api.socket_mode");

        // Unix socket, same uid as the daemon: admin.
        RegistersClient::new(unix.clone()).read_registers(reg_read()).await.unwrap();
        // A token on the Unix socket is that token's role.
        let e = SdoClient::new(unix.clone()).download(with_token(sdo_write(), "observer-secret")).await.unwrap_err();
        assert_eq!(e.code(), Code::PermissionDenied, "{e:?}");
        assert!(e.message().contains("observer") && e.message().contains("operator"), "{}", e.message());

        // TCP with TLS.
        let tls = || ClientTlsConfig::new().ca_certificate(Certificate::from_pem(ca.pem())).domain_name("localhost");
        let url = format!("https://localhost:{port}");
        let tcp: Channel =
            Channel::from_shared(url.clone()).unwrap().tls_config(tls()).unwrap().connect().await.unwrap();
        // No identity at all.
        let e = MasterClient::new(tcp.clone()).get_info(pb::GetInfoRequest {}).await.unwrap_err();
        assert_eq!(e.code(), Code::Unauthenticated, "{e:?}");
        // Unknown token.
        let e = MasterClient::new(tcp.clone()).get_info(with_token(pb::GetInfoRequest {}, "guess")).await.unwrap_err();
        assert_eq!(e.code(), Code::Unauthenticated, "{e:?}");
        // Observer reads, may not write.
        MasterClient::new(tcp.clone()).get_info(with_token(pb::GetInfoRequest {}, "observer-secret")).await.unwrap();
        let e = SdoClient::new(tcp.clone()).download(with_token(sdo_write(), "observer-secret")).await.unwrap_err();
        assert_eq!(e.code(), Code::PermissionDenied);
        // Operator writes SDOs, may not touch registers.
        SdoClient::new(tcp.clone()).download(with_token(sdo_write(), "operator-secret")).await.unwrap();
        let e = RegistersClient::new(tcp.clone())
            .read_registers(with_token(reg_read(), "operator-secret"))
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::PermissionDenied);
        assert!(e.message().contains("admin"), "{}", e.message());

        // A client certificate mapped to admin.
        let robot = Channel::from_shared(url.clone())
            .unwrap()
            .tls_config(tls().identity(Identity::from_pem(client.pem(), client_key.serialize_pem())))
            .unwrap()
            .connect()
            .await
            .unwrap();
        RegistersClient::new(robot).read_registers(reg_read()).await.unwrap();
        // A certificate from the same CA but not listed.
        let other = Channel::from_shared(url.clone())
            .unwrap()
            .tls_config(tls().identity(Identity::from_pem(stranger.pem(), stranger_key.serialize_pem())))
            .unwrap()
            .connect()
            .await
            .unwrap();
        let e = MasterClient::new(other).get_info(pb::GetInfoRequest {}).await.unwrap_err();
        assert_eq!(e.code(), Code::Unauthenticated, "{e:?}");

        // Plain HTTP/2 to the TLS port gets nowhere.
        let plain = Channel::from_shared(format!("http://127.0.0.1:{port}")).unwrap().connect().await;
        if let Ok(ch) = plain {
            assert!(
                MasterClient::new(ch).get_info(with_token(pb::GetInfoRequest {}, "observer-secret")).await.is_err()
            );
        }
        // ecmxfctl over TCP with TLS: no identity, a token, a client certificate.
        let url = format!("localhost:{port}");
        let tcp = |extra: &[&str]| {
            let mut a = vec!["--connect", url.as_str(), "--ca", ca_file.as_str()];
            a.extend_from_slice(extra);
            ecmxf_e2e::ctl(&a)
        };
        let c = tcp(&["master"]);
        assert!(c.fails(4).contains("not authenticated") && c.stderr.contains("--token"), "{}", c.stderr);
        assert!(tcp(&["--token", "observer-secret", "master"]).ok().contains("RUNNING"));
        let c = tcp(&["--token", "observer-secret", "download", "-p", "1", "0x605A", "0", "2"]);
        assert!(c.fails(4).contains("permission denied"), "{}", c.stderr);
        tcp(&["--token", "operator-secret", "download", "-p", "1", "0x605A", "0", "2"]).ok();
        let token_file = dir.join("token");
        std::fs::write(&token_file, "operator-secret\n").unwrap();
        tcp(&["--token-file", &token_file.display().to_string(), "download", "-p", "1", "0x605A", "0", "2"]).ok();
        let (client_pem, client_key_pem) =
            (write("client.pem", client.pem()), write("client.key", client_key.serialize_pem()));
        let out = tcp(&["--cert", &client_pem, "--key", &client_key_pem, "reg", "read", "-p", "0", "0x130"]);
        assert!(out.ok().starts_with("0x0130:"), "{}", out.stdout);
        // A daemon certificate the given CA did not sign: refused, exit 3.
        let other_ca = CertifiedIssuer::self_signed(
            {
                let mut p = CertificateParams::new(Vec::<String>::new()).unwrap();
                p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
                p
            },
            KeyPair::generate().unwrap(),
        )
        .unwrap();
        let wrong_ca = write("other-ca.pem", other_ca.pem());
        let c = ecmxf_e2e::ctl(&["--connect", &url, "--ca", &wrong_ca, "--token", "observer-secret", "master"]);
        assert!(c.fails(3).contains("cannot reach ecmxfd at https://localhost"), "{}", c.stderr);

        drop(d);
        let _ = std::fs::remove_dir_all(&dir);
    });
}

#[test]
fn tcp_without_tls_is_refused_by_name() {
    let dir = ecmxf_e2e::temp_dir("notls");
    let path = dir.join("c.toml");
    std::fs::write(&path, "version = 1\n[link]\nbackend = \"sim\"\n[api]\ntcp = \"127.0.0.1:1\"\n").unwrap();
    let out = std::process::Command::new(ecmxf_e2e::daemon_binary()).arg("--check-config").arg(&path).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("api.tcp") && err.contains("TLS"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
