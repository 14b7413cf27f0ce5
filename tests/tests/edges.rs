//! Exact at the edges (a client must never get a half-written value or an
//! error it cannot read): a value that does not fit its target is
//! refused whole, naming target, given and expected size, and nothing is
//! written (checked by reading the target back); a request larger than any
//! legitimate one gets the documented code; server streams end with
//! UNAVAILABLE "STOPPING" when the daemon is stopped, and `ecmxfctl
//! events` ends with exit 0 instead of a broken-connection error.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, ctl_binary, run};
use ecmxf_proto::v1 as pb;
use pb::process_data_client::ProcessDataClient;
use pb::sdo_client::SdoClient;
use pb::value::Kind;
use tokio_stream::StreamExt;
use tonic::Code;

fn value(kind: Kind) -> Option<pb::Value> {
    Some(pb::Value { kind: Some(kind) })
}

use ecmxf_e2e::by_entry as write;

#[test]
fn a_write_that_does_not_fit_its_target_is_refused_whole_and_nothing_changes() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut pd = ProcessDataClient::new(ch.clone());
        let layout = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        let output = |pred: &dyn Fn(&pb::ImageEntry) -> bool| {
            layout.entries.iter().find(|e| e.direction == pb::Direction::Output as i32 && pred(e)).cloned()
        };
        // The demo's IO slave has 8-bit outputs; 1-bit entries are checked
        // by daemon/src/api/pdo.rs's unit test.
        let byte = output(&|e| e.slave == 2 && e.bit_length == 8).expect("an 8-bit output (the IO slave's)");
        let word = output(&|e| e.slave == 1 && e.bit_length == 16).expect("a 16-bit output (a controlword)");
        let slaves = vec![byte.slave, word.slave];
        let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves, ttl_ms: 5000 }).await.unwrap().into_inner();
        pd.write_outputs(pb::WriteOutputsRequest {
            lease_id: lease.id.clone(),
            writes: vec![write(&byte.name, Kind::Unsigned(0xA5)), write(&word.name, Kind::Unsigned(0x1234))],
        })
        .await
        .unwrap();
        let read_back = |pd: &mut ProcessDataClient<tonic::transport::Channel>| {
            let names = vec![byte.name.clone(), word.name.clone()];
            let mut pd = pd.clone();
            async move {
                let r = pd.read_outputs(pb::ReadOutputsRequest { entries: names }).await.unwrap().into_inner();
                r.values.into_iter().map(|v| v.value.and_then(|v| v.kind)).collect::<Vec<_>>()
            }
        };
        let before = read_back(&mut pd).await;
        assert_eq!(before, [Some(Kind::Unsigned(0xA5)), Some(Kind::Unsigned(0x1234))]);

        // 200 KiB: within the request limit, far beyond the entry.
        let big = vec![0u8; 200 << 10];
        let cases: Vec<(pb::OutputWrite, &str)> = vec![
            (write(&byte.name, Kind::Raw(big)), "204800 raw bytes given for a UNSIGNED8 object, which has 1"),
            (write(&byte.name, Kind::Raw(vec![1, 2])), "2 raw bytes given for a UNSIGNED8 object, which has 1"),
            (write(&byte.name, Kind::Unsigned(256)), "does not fit UNSIGNED8"),
            (write(&word.name, Kind::Raw(vec![1, 2, 3])), "3 raw bytes given for a UNSIGNED16 object, which has 2"),
            (write(&word.name, Kind::Raw(vec![1])), "1 raw bytes given for a UNSIGNED16 object, which has 2"),
            (write(&word.name, Kind::Unsigned(70_000)), "does not fit UNSIGNED16"),
            (write(&word.name, Kind::Text("ab".into())), "text \"ab\" given for a UNSIGNED16 object"),
        ];
        for (w, says) in cases {
            let target = match &w.target {
                Some(pb::output_write::Target::Entry(n)) => n.clone(),
                _ => unreachable!(),
            };
            // Together with a good write: the whole request is refused.
            let good = write(&word.name, Kind::Unsigned(0x0F0F));
            let e = pd
                .write_outputs(pb::WriteOutputsRequest { lease_id: lease.id.clone(), writes: vec![good, w] })
                .await
                .unwrap_err();
            assert_eq!(e.code(), Code::InvalidArgument, "{says}: {e:?}");
            assert!(e.message().contains(says), "wanted {says:?} in {:?}", e.message());
            assert!(e.message().contains(&target) || e.message().contains("object"), "names the target: {e:?}");
            assert_eq!(read_back(&mut pd).await, before, "nothing written after {says:?}");
        }

        // SDO: text to a UDINT object, raw bytes of the wrong size, text to
        // an object whose type is not known; the value stays as it was.
        let mut sdo = SdoClient::new(ch.clone());
        let upload = |index: u32| pb::SdoUploadRequest { slave: 1, index, subindex: 0, ..Default::default() };
        let accel_before = sdo.upload(upload(0x6083)).await.unwrap().into_inner().raw;
        for (index, kind, says) in [
            (0x6083, Kind::Text("abcd".into()), "text \"abcd\" given for a UNSIGNED32 object"),
            (0x6083, Kind::Raw(vec![0; 8]), "8 raw bytes given for a UNSIGNED32 object, which has 4"),
            (0x2FFF, Kind::Text("abcd".into()), "text goes only to string objects"),
        ] {
            let e = sdo
                .download(pb::SdoDownloadRequest {
                    slave: 1,
                    index,
                    subindex: 0,
                    complete_access: false,
                    data_type: 0,
                    value: value(kind),
                })
                .await
                .unwrap_err();
            assert_eq!(e.code(), Code::InvalidArgument, "{says}: {e:?}");
            assert!(e.message().contains(says), "wanted {says:?} in {:?}", e.message());
        }
        assert_eq!(sdo.upload(upload(0x6083)).await.unwrap().into_inner().raw, accel_before);

        // Larger than any legitimate request (a whole 256 KiB FoE file):
        // the documented OUT_OF_RANGE, and the daemon still answers.
        let huge = write(&word.name, Kind::Raw(vec![0; 1 << 20]));
        let e = pd
            .write_outputs(pb::WriteOutputsRequest { lease_id: lease.id.clone(), writes: vec![huge.clone(), huge] })
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::OutOfRange, "{e:?}");
        assert_eq!(read_back(&mut pd).await, before);
    });
}

#[test]
fn streams_end_with_stopping_and_ecmxfctl_events_exits_0_when_the_daemon_stops() {
    let mut d = Daemon::binary_sim();
    let socket = d.socket.display().to_string();
    run(async {
        let ch = d.connect().await;
        let mut events = pb::diagnostics_client::DiagnosticsClient::new(ch.clone())
            .stream_events(pb::StreamEventsRequest {})
            .await
            .unwrap()
            .into_inner();
        let mut inputs = ProcessDataClient::new(ch)
            .stream_inputs(pb::StreamInputsRequest { entries: vec![], decimation: 100, on_change: false })
            .await
            .unwrap()
            .into_inner();
        assert!(inputs.next().await.unwrap().is_ok(), "inputs flow before the stop");
        let mut follower = Command::new(ctl_binary())
            .args(["--socket", &socket, "events"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start ecmxfctl events");
        // ecmxfctl has its stream open once the daemon counts a subscriber;
        // a short wait is enough on this machine, and the result does not
        // depend on it (an ecmxfctl that connects too late sees no daemon).
        tokio::time::sleep(Duration::from_millis(500)).await;
        let pid = nix::unistd::Pid::from_raw(d.pid() as i32);
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).unwrap();

        for (what, end) in [("events", last_error(&mut events).await), ("inputs", last_error(&mut inputs).await)] {
            let status = end.unwrap_or_else(|| panic!("{what}: the stream ended without a status"));
            assert_eq!(status.code(), Code::Unavailable, "{what}: {status:?}");
            assert!(status.message().contains("daemon stopping"), "{what}: {status:?}");
        }
        let start = Instant::now();
        let code = loop {
            if let Some(s) = follower.try_wait().unwrap() {
                break s.code();
            }
            assert!(start.elapsed() < Duration::from_secs(10), "ecmxfctl events did not end");
            tokio::time::sleep(Duration::from_millis(20)).await;
        };
        let mut err = String::new();
        std::io::Read::read_to_string(follower.stderr.as_mut().unwrap(), &mut err).unwrap();
        assert_eq!(code, Some(0), "ecmxfctl events: {err}");
        assert!(err.contains("the daemon is stopping"), "{err}");
    });
    assert_eq!(d.stop(), Some(0), "the daemon stopped cleanly:\n{}", d.log());
}

/// Reads a stream to its end; the error it ended with, if any.
async fn last_error<T>(s: &mut tonic::Streaming<T>) -> Option<tonic::Status> {
    let give_up = Instant::now() + Duration::from_secs(10);
    while Instant::now() < give_up {
        match tokio::time::timeout(Duration::from_secs(10), s.next()).await {
            Ok(Some(Ok(_))) => continue,
            Ok(Some(Err(st))) => return Some(st),
            Ok(None) | Err(_) => return None,
        }
    }
    None
}

/// The chip's CiA 402 helper drives controlword bits 0-3 and 7 of every
/// `[[axis]]`: a client write that sets them would be overwritten without
/// a word, so it is refused naming the axis and the bits; the rest of the
/// controlword (new set-point, halt) stays the client's.
#[test]
fn a_write_to_the_bits_the_cia402_helper_drives_is_refused_naming_the_axis() {
    run(async {
        let link = "backend = \"sim\"\nnetwork = \"{repo}/config/demo-network.toml\"";
        let mut d = Daemon::with_config(&ecmxf_e2e::config(link, ecmxf_e2e::TI_AXIS));
        let ch = d.connect().await;
        let mut pd = ProcessDataClient::new(ch);
        let layout = pd.get_layout(pb::GetLayoutRequest {}).await.unwrap().into_inner();
        let cw = layout.entries.iter().find(|e| e.name == "1.controlword").expect("the TI drive's controlword");
        let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![1], ttl_ms: 5000 }).await.unwrap();
        let lease = lease.into_inner().id;
        let e = pd
            .write_outputs(pb::WriteOutputsRequest {
                lease_id: lease.clone(),
                writes: vec![write(&cw.name, Kind::Unsigned(0x000F))],
            })
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::FailedPrecondition, "{e:?}");
        assert!(e.message().contains("axis 0") && e.message().contains("bits 0-3 and 7"), "{}", e.message());
        let r = pd.read_outputs(pb::ReadOutputsRequest { entries: vec![cw.name.clone()] }).await.unwrap();
        assert_eq!(r.into_inner().values[0].value.as_ref().and_then(|v| v.kind.clone()), Some(Kind::Unsigned(0)));
        // Bit 4 (new set-point) is the client's.
        pd.write_outputs(pb::WriteOutputsRequest {
            lease_id: lease,
            writes: vec![write(&cw.name, Kind::Unsigned(0x0010))],
        })
        .await
        .unwrap();
    });
}

/// `ecmxfd --sim` in a terminal: closing the terminal (SIGHUP, with no
/// configuration file to read again) stops it cleanly, its socket gone, so
/// the next start finds no daemon in the way. Under `nohup` (SIGHUP
/// ignored) it lives on.
#[test]
fn a_foreground_sim_daemon_stops_when_its_terminal_hangs_up() {
    use nix::sys::signal::{Signal, kill};
    let dir = ecmxf_e2e::temp_dir("hangup");
    let socket = dir.join("ecmxfd.sock");
    let start = |nohup: bool| {
        let mut cmd = if nohup { Command::new("nohup") } else { Command::new(ecmxf_e2e::daemon_binary()) };
        if nohup {
            cmd.arg(ecmxf_e2e::daemon_binary());
        }
        let child = cmd
            .args(["--sim", "--socket"])
            .arg(&socket)
            .current_dir(&dir)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start ecmxfd --sim");
        let t = Instant::now();
        while !socket.exists() {
            assert!(t.elapsed() < Duration::from_secs(30), "no socket");
            std::thread::sleep(Duration::from_millis(20));
        }
        std::thread::sleep(Duration::from_millis(300));
        child
    };
    let mut child = start(false);
    kill(nix::unistd::Pid::from_raw(child.id() as i32), Signal::SIGHUP).unwrap();
    let t = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(t.elapsed() < Duration::from_secs(2), "SIGHUP did not stop it");
        std::thread::sleep(Duration::from_millis(10));
    };
    assert!(status.success(), "{status:?}");
    assert!(!socket.exists(), "the socket is gone");

    let mut child = start(true);
    kill(nix::unistd::Pid::from_raw(child.id() as i32), Signal::SIGHUP).unwrap();
    std::thread::sleep(Duration::from_millis(500));
    assert!(child.try_wait().unwrap().is_none(), "under nohup a hang-up is not for it");
    kill(nix::unistd::Pid::from_raw(child.id() as i32), Signal::SIGTERM).unwrap();
    assert!(child.wait().unwrap().success());
    let _ = std::fs::remove_dir_all(&dir);
}
