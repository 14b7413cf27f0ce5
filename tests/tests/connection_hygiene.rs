//! Connection hygiene on the API's listeners: peers that connect to the TLS
//! port and never handshake are closed at the handshake deadline or refused
//! at once by a cap, while the administrator on the Unix socket is still
//! answered promptly and the daemon stays cheap; a cap that refuses says so
//! in one log line; memory returns after many streams close.

use std::net::Ipv4Addr;
use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, closed_within, connect_from, run};
use ecmxf_proto::v1 as pb;
use pb::master_client::MasterClient;
use rcgen::{CertificateParams, KeyPair};
use sha2::{Digest, Sha256};
use tokio::io::AsyncReadExt;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// The test opens thousands of sockets: its own soft open-file limit goes
/// up to the hard one.
fn raise_own_fd_limit() -> u64 {
    use nix::sys::resource::{Resource, getrlimit, setrlimit};
    let (_, hard) = getrlimit(Resource::RLIMIT_NOFILE).unwrap();
    setrlimit(Resource::RLIMIT_NOFILE, hard, hard).unwrap();
    hard
}

/// A daemon on the simulator serving TCP with TLS on a free port, with
/// `extra` lines in `[api]`.
fn daemon_with_tcp(extra: &str) -> (Daemon, u16) {
    let dir = ecmxf_e2e::temp_dir("hygiene-pki");
    let key = KeyPair::generate().unwrap();
    let cert = CertificateParams::new(vec!["localhost".to_string()]).unwrap().self_signed(&key).unwrap();
    let write = |name: &str, text: String| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.display().to_string()
    };
    let (cert, key) = (write("server.pem", cert.pem()), write("server.key", key.serialize_pem()));
    let port = free_port();
    let api = format!(
        "[api]\ntcp = \"127.0.0.1:{port}\"\ntls_cert = \"{cert}\"\ntls_key = \"{key}\"\n{extra}\n\
         [[api.token]]\nname = \"dashboard\"\nsha256 = \"{}\"\nrole = \"observer\"\n",
        hex::encode(Sha256::digest(b"observer-secret"))
    );
    (Daemon::binary_with_config(&ecmxf_e2e::config("backend = \"sim\"", &api)), port)
}

/// CPU seconds the process has used (utime + stime, USER_HZ = 100).
fn process_cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let field = |n: usize| f.get(n - 3).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    (field(14) + field(15)) as f64 / 100.0
}

/// Resident memory, kB.
fn rss_kb(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

#[test]
fn idle_tcp_peers_are_closed_and_the_socket_stays_answered() {
    assert!(raise_own_fd_limit() >= 2200, "the test needs 2200 open files");
    run(async {
        let (mut d, port) = daemon_with_tcp("handshake_timeout_ms = 1000\nmax_connections = 1024\n");
        let unix = d.connect().await;
        let pid = d.pid();
        tokio::time::sleep(Duration::from_millis(300)).await;
        let cpu_idle = process_cpu_seconds(pid);
        tokio::time::sleep(Duration::from_secs(1)).await;
        let cpu_idle = process_cpu_seconds(pid) - cpu_idle;

        // The administrator asks every 50 ms throughout.
        let (done_tx, mut done_rx) = tokio::sync::watch::channel(false);
        let admin = tokio::spawn(async move {
            let mut master = MasterClient::new(unix);
            let mut slowest = Duration::ZERO;
            let mut calls = 0u32;
            while !*done_rx.borrow_and_update() {
                let t = Instant::now();
                tokio::time::timeout(Duration::from_secs(2), master.get_status(pb::GetStatusRequest {}))
                    .await
                    .expect("GetStatus answered within 2 s")
                    .expect("GetStatus");
                slowest = slowest.max(t.elapsed());
                calls += 1;
                let _ = tokio::time::timeout(Duration::from_millis(50), done_rx.changed()).await;
            }
            (calls, slowest)
        });

        let (cpu0, t0) = (process_cpu_seconds(pid), Instant::now());
        // 2000 peers from 63 addresses (32 each: the per-peer cap), in
        // batches of 100: 1024 fill the listener's cap and wait for their
        // deadline, the others are over a cap.
        let mut waits = tokio::task::JoinSet::new();
        for batch in 0..20u32 {
            let mut opening = tokio::task::JoinSet::new();
            for i in 0..100u32 {
                let n = batch * 100 + i;
                let from = Ipv4Addr::new(127, 0, 0, 2 + (n / 32) as u8);
                opening.spawn(async move { connect_from(from, port).await });
            }
            while let Some(s) = opening.join_next().await {
                let s = s.unwrap().expect("loopback connect");
                waits.spawn(closed_within(s, Duration::from_millis(4000)));
            }
        }
        let mut closed = Vec::new();
        while let Some(c) = waits.join_next().await {
            closed.push(c.unwrap());
        }
        // CPU over a fixed 3 s from the first connect: the accepts, the
        // refusals and the deadlines all fall inside it.
        tokio::time::sleep_until((t0 + Duration::from_secs(3)).into()).await;
        let wall = t0.elapsed().as_secs_f64();
        let cpu = (process_cpu_seconds(pid) - cpu0) / wall;
        done_tx.send(true).unwrap();
        let (calls, slowest) = admin.await.unwrap();

        let open = closed.iter().filter(|c| c.is_none()).count();
        assert_eq!(open, 0, "{open} of 2000 idle connections still open 4 s after connecting");
        // The deadline runs from the daemon's accept. The kernel completes a
        // connect before that, and with this test's other daemons busy on the
        // same 2 cores the accept has lagged the connect by a whole second:
        // the bound is the deadline, that lag, and half a second.
        let last = closed.iter().flatten().max().copied().unwrap_or_default();
        assert!(last < Duration::from_millis(2500), "the last one closed {last:?} after connecting (deadline 1 s)");
        // How many met a full listener depends on how fast the peers came
        // (places free up as the first ones reach their deadline).
        let at_once = closed.iter().flatten().filter(|t| **t < Duration::from_millis(500)).count();
        assert!(calls >= 10, "the admin kept asking: {calls} calls");
        assert!(slowest < Duration::from_millis(100), "slowest GetStatus on the socket: {slowest:?}");
        eprintln!(
            "2000 idle peers: {at_once} closed at once, the last after {last:?}; slowest admin call {slowest:?} \
             of {calls}; daemon CPU {:.1} % (idle before: {:.1} %)",
            cpu * 100.0,
            cpu_idle * 100.0
        );
        // What the peers cost on top of the engine's own work: this is a
        // debug build sharing 2 cores with other tests, whose idle figure
        // alone is 5-10 % (the release build's is under 7 %, ecmxfd-bench),
        // and whose 2000 accepts and closes alone measured 4-10 %. The fault
        // this guards against (peers held and polled) took it from 12 % to
        // 39-100 %: a bound of 20 % still catches it, with room for a host
        // stall.
        assert!(
            cpu - cpu_idle < 0.20,
            "2000 idle peers cost {:.1} % of a core on top of {:.1} % idle, over {wall:.1} s",
            (cpu - cpu_idle) * 100.0,
            cpu_idle * 100.0
        );
        assert_eq!(d.stop(), Some(0), "stops cleanly:\n{}", d.log());
    });
}

/// `n` connections from 127.0.0.1 that send nothing: those the daemon
/// kept open, and how many it closed at once.
async fn idle_peers(port: u16, n: usize) -> (Vec<tokio::net::TcpStream>, usize) {
    let mut held = Vec::new();
    let mut refused = 0;
    for _ in 0..n {
        let s = connect_from(Ipv4Addr::LOCALHOST, port).await.unwrap();
        // Give the daemon time to accept, then see whether it closed.
        tokio::time::sleep(Duration::from_millis(20)).await;
        let mut probe = [0u8; 1];
        match tokio::time::timeout(Duration::from_millis(200), s.peek(&mut probe)).await {
            Ok(Ok(0)) | Ok(Err(_)) => refused += 1,
            _ => held.push(s),
        }
    }
    (held, refused)
}

#[test]
fn a_peer_over_its_cap_is_refused_at_once_and_logged_once() {
    assert!(raise_own_fd_limit() >= 256);
    run(async {
        let (mut d, port) = daemon_with_tcp("handshake_timeout_ms = 5000\nmax_connections_per_peer = 4\n");
        d.connect().await;
        let (held, refused) = idle_peers(port, 20).await;
        assert_eq!(held.len(), 4, "the per-peer cap holds 4");
        assert_eq!(refused, 16, "the rest are closed at once, well before the 5 s deadline");
        // Another peer address is not affected by this one's cap.
        let other = connect_from(Ipv4Addr::new(127, 0, 0, 9), port).await.unwrap();
        assert!(closed_within(other, Duration::from_millis(300)).await.is_none(), "another address is admitted");

        let log = d.log();
        let lines: Vec<&str> = log.lines().filter(|l| l.contains("connection refused")).collect();
        assert_eq!(lines.len(), 1, "one line for 16 refusals:\n{log}");
        assert!(lines[0].contains("api.max_connections_per_peer"), "names the cap: {}", lines[0]);

        let t = Instant::now();
        assert_eq!(d.stop(), Some(0), "stops cleanly with connections open:\n{}", d.log());
        let took = t.elapsed();
        drop(held);
        assert!(took < Duration::from_secs(1), "SIGTERM took {took:?} with 5 connections in their handshake");
    });
}

/// Opening and closing many streams leaves the daemon's resident memory
/// near where it was, with the malloc settings of the shipped unit
/// (systemd/ecmxfd.service: without them glibc keeps the streams' freed
/// buffers in holes of its heap).
#[test]
fn memory_returns_after_many_streams_close() {
    run(async {
        let unit = std::fs::read_to_string(ecmxf_e2e::repo().join("systemd/ecmxfd.service")).unwrap();
        let env: Vec<(String, std::ffi::OsString)> = unit
            .lines()
            .filter_map(|l| l.strip_prefix("Environment=MALLOC_"))
            .filter_map(|kv| kv.split_once('='))
            .map(|(k, v)| (format!("MALLOC_{k}"), v.into()))
            .collect();
        assert!(!env.is_empty(), "the unit sets malloc's thresholds");
        let config = ecmxf_e2e::config("backend = \"sim\"", "");
        let mut d = Daemon::binary_with_config_on(&ecmxf_e2e::daemon_binary(), &config, &env);
        let unix = d.connect().await;
        let pid = d.pid();
        let round = |n: usize| {
            let path = d.socket.clone();
            async move {
                let mut channels = Vec::new();
                for _ in 0..10 {
                    channels.push(ecmxf_proto::connect_unix(&path).await.unwrap());
                }
                let mut streams = Vec::new();
                for i in 0..n {
                    // Events come seldom: the stream is open (its headers
                    // came) and idle, as a watching client's.
                    let mut c = pb::diagnostics_client::DiagnosticsClient::new(channels[i % 10].clone());
                    streams.push(c.stream_events(pb::StreamEventsRequest {}).await.unwrap().into_inner());
                }
                drop(streams);
                drop(channels);
            }
        };
        // A first round lets the runtime and the allocator reach their
        // working size; the measured one must not add to it.
        round(100).await;
        tokio::time::sleep(Duration::from_secs(1)).await;
        MasterClient::new(unix.clone()).get_status(pb::GetStatusRequest {}).await.unwrap();
        let before = rss_kb(pid);
        round(1000).await;
        tokio::time::sleep(Duration::from_secs(2)).await;
        MasterClient::new(unix.clone()).get_status(pb::GetStatusRequest {}).await.unwrap();
        let after = rss_kb(pid);
        eprintln!("RSS before {before} kB, after 1000 streams closed {after} kB");
        assert!(after <= before + 5 * 1024, "RSS grew from {before} kB to {after} kB");
    });
}

#[test]
fn the_metrics_endpoint_caps_a_peer_too() {
    run(async {
        let port = free_port();
        let extra = format!("[metrics]\nlisten = \"127.0.0.1:{port}\"\n");
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config("backend = \"sim\"", &extra));
        d.connect().await;
        // Idle peers that send no request: 8 are held (each until its
        // request deadline), the rest are closed at once.
        let (held, refused) = idle_peers(port, 12).await;
        assert_eq!((held.len(), refused), (8, 4), "8 per peer address");
        // Another address still scrapes.
        let mut other = connect_from(Ipv4Addr::new(127, 0, 0, 7), port).await.unwrap();
        use tokio::io::AsyncWriteExt;
        other.write_all(b"GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n").await.unwrap();
        let mut body = String::new();
        tokio::time::timeout(Duration::from_secs(5), other.read_to_string(&mut body)).await.unwrap().unwrap();
        assert!(body.starts_with("HTTP/1.1 200") && body.contains("ecmxf_"), "{body}");
        let log = d.log();
        let lines = log.lines().filter(|l| l.contains("connection refused")).count();
        assert_eq!(lines, 1, "one line for 4 refusals:\n{log}");
    });
}
