//! A lease belongs to the identity that took it: another identity quoting
//! its id (which a refused AcquireLease names) can neither write under it,
//! renew it nor release it, and the outputs stay what the holder wrote,
//! checked through the IO slave's loopback (what flows). An admin may
//! break it.

use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, by_entry, run, with_token};
use ecmxf_proto::v1 as pb;
use pb::process_data_client::ProcessDataClient;
use pb::value::Kind;
use sha2::{Digest, Sha256};
use tokio_stream::StreamExt;
use tonic::Code;

fn token(name: &str, secret: &str, role: &str) -> String {
    format!(
        "[[api.token]]\nname = \"{name}\"\nsha256 = \"{}\"\nrole = \"{role}\"\n",
        hex::encode(Sha256::digest(secret.as_bytes()))
    )
}

/// The IO slave's input `name` as the frames of the next 200 ms end with
/// it: what flows now.
async fn input_settles(pd: &mut ProcessDataClient<tonic::transport::Channel>, name: &str, secret: &str) -> Kind {
    let request = pb::StreamInputsRequest { entries: vec![name.to_string()], decimation: 1, on_change: false };
    let mut stream = pd.stream_inputs(with_token(request, secret)).await.unwrap().into_inner();
    let start = Instant::now();
    let mut last = None;
    while start.elapsed() < Duration::from_millis(200) {
        let s = stream.next().await.unwrap().unwrap();
        last = s.values[0].value.as_ref().and_then(|v| v.kind.clone());
    }
    last.expect("an input value")
}

#[test]
fn a_lease_is_its_takers_and_no_other_identity_writes_renews_or_releases_it() {
    run(async {
        let api = format!(
            "[api]\n{}{}{}",
            token("one", "secret-one", "operator"),
            token("two", "secret-two", "operator"),
            token("boss", "secret-boss", "admin")
        );
        let mut d = Daemon::with_config(&ecmxf_e2e::config("backend = \"sim\"", &api));
        let ch = d.connect().await;
        let mut pd = ProcessDataClient::new(ch.clone());
        let (one, two, boss) = ("secret-one", "secret-two", "secret-boss");

        let image = pd.get_layout(with_token(pb::GetLayoutRequest {}, one)).await.unwrap().into_inner();
        let out = |dir: pb::Direction| {
            image.entries.iter().find(|e| e.slave == 2 && e.direction == dir as i32 && e.bit_length == 8).cloned()
        };
        let (Some(out0), Some(in0)) = (out(pb::Direction::Output), out(pb::Direction::Input)) else {
            panic!("the IO slave has byte entries: {image:?}")
        };

        // One takes slave 2 and writes 0xA5.
        let lease = pd
            .acquire_lease(with_token(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 5000 }, one))
            .await
            .unwrap()
            .into_inner();
        let write = |value: u64, lease_id: &str| pb::WriteOutputsRequest {
            lease_id: lease_id.to_string(),
            writes: vec![by_entry(&out0.name, Kind::Unsigned(value))],
        };
        pd.write_outputs(with_token(write(0xA5, &lease.id), one)).await.unwrap();
        assert_eq!(input_settles(&mut pd, &in0.name, one).await, Kind::Unsigned(0xA5));

        // Two is told who holds it, and learns the id: it still gets nothing.
        let e = pd
            .acquire_lease(with_token(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 0 }, two))
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::PermissionDenied, "{e:?}");
        assert!(e.message().contains("token one") && e.message().contains(&lease.id), "{}", e.message());
        let refusals = [
            ("WriteOutputs", pd.write_outputs(with_token(write(0x5A, &lease.id), two)).await.map(|_| ())),
            (
                "StreamOutputs",
                pd.stream_outputs(with_token(tokio_stream::iter(vec![write(0x5A, &lease.id)]), two)).await.map(|_| ()),
            ),
            (
                "KeepAlive",
                pd.keep_alive(with_token(pb::KeepAliveRequest { lease_id: lease.id.clone() }, two)).await.map(|_| ()),
            ),
            (
                "ReleaseLease",
                pd.release_lease(with_token(pb::ReleaseLeaseRequest { lease_id: lease.id.clone() }, two))
                    .await
                    .map(|_| ()),
            ),
        ];
        for (what, r) in refusals {
            let e = r.expect_err(what);
            assert_eq!(e.code(), Code::PermissionDenied, "{what}: {e:?}");
            assert!(e.message().contains("held by token one, not token two"), "{what}: {}", e.message());
        }
        // Nothing two asked for happened: the outputs are one's, and flow.
        assert_eq!(input_settles(&mut pd, &in0.name, one).await, Kind::Unsigned(0xA5));
        let outs = pd
            .read_outputs(with_token(pb::ReadOutputsRequest { entries: vec![out0.name.clone()] }, one))
            .await
            .unwrap()
            .into_inner();
        assert_eq!(outs.values[0].value.as_ref().and_then(|v| v.kind.clone()), Some(Kind::Unsigned(0xA5)));
        // The lease is still one's to use.
        pd.keep_alive(with_token(pb::KeepAliveRequest { lease_id: lease.id.clone() }, one)).await.unwrap();

        // An admin may break it (logged with both identities); then two may take it.
        pd.release_lease(with_token(pb::ReleaseLeaseRequest { lease_id: lease.id.clone() }, boss)).await.unwrap();
        let e = pd.write_outputs(with_token(write(0x11, &lease.id), one)).await.unwrap_err();
        assert_eq!(e.code(), Code::PermissionDenied, "a broken lease writes nothing: {e:?}");
        pd.acquire_lease(with_token(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 0 }, two)).await.unwrap();
    });
}

/// A token taken out of the configuration (SIGHUP) ends what it holds: its
/// open input stream ends within a second with PERMISSION_DENIED, its lease
/// is gone (another operator takes the slave), and it is refused from then
/// on. A token kept keeps its stream.
#[test]
fn a_revoked_token_loses_its_streams_and_leases_at_the_reload() {
    run(async {
        let link = "backend = \"sim\"";
        let both =
            format!("[api]\n{}{}", token("one", "secret-one", "operator"), token("two", "secret-two", "operator"));
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config(link, &both));
        let ch = d.connect().await;
        let mut pd = ProcessDataClient::new(ch.clone());
        let (one, two) = ("secret-one", "secret-two");
        let inputs = || pb::StreamInputsRequest { entries: vec![], decimation: 1, on_change: false };
        let mut streamed_one = pd.stream_inputs(with_token(inputs(), one)).await.unwrap().into_inner();
        let mut streamed_two = pd.stream_inputs(with_token(inputs(), two)).await.unwrap().into_inner();
        pd.acquire_lease(with_token(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 60_000 }, one)).await.unwrap();
        streamed_one.next().await.unwrap().unwrap();

        // One's token is taken out; the daemon reads its file again.
        let only_two = format!("[api]\n{}", token("two", "secret-two", "operator"));
        std::fs::write(d.dir.join("ecmxfd.toml"), ecmxf_e2e::config(link, &only_two)).unwrap();
        let pid = nix::unistd::Pid::from_raw(d.pid() as i32);
        let revoked = Instant::now();
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGHUP).unwrap();
        let end = tokio::time::timeout(Duration::from_secs(1), async {
            loop {
                match streamed_one.next().await {
                    Some(Ok(_)) => continue,
                    Some(Err(e)) => return Some(e),
                    None => return None,
                }
            }
        })
        .await
        .expect("one's stream ends within a second of the reload");
        let e = end.expect("ends with a status");
        eprintln!("one's stream ended {:?} after SIGHUP: {e:?}", revoked.elapsed());
        assert_eq!(e.code(), Code::PermissionDenied, "{e:?}");
        assert!(e.message().contains("token one lost its access"), "{}", e.message());

        // Its lease went with it: two takes the slave; one is refused.
        pd.acquire_lease(with_token(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 0 }, two))
            .await
            .expect("one's lease ended at the reload");
        let e = pd.get_layout(with_token(pb::GetLayoutRequest {}, one)).await.unwrap_err();
        assert_eq!(e.code(), Code::Unauthenticated, "{e:?}");
        // Two, still in the configuration, streams on.
        for _ in 0..5 {
            streamed_two.next().await.expect("two's stream goes on").expect("a sample");
        }
        assert!(d.log().contains("output lease ended"), "the lease's end is logged:\n{}", d.log());
        assert_eq!(d.stop(), Some(0), "{}", d.log());
    });
}
