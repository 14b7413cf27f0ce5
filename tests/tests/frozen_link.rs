//! A link that stops answering is a fault, not a RUNNING daemon waiting
//! for ever: with the simulator's process stopped (SIGSTOP, its socket
//! still open) an event names the stall within 100 ms of its limit, the
//! phase leaves RUNNING and the last error names the stalled link; once it
//! goes on, data flows again; and SIGTERM stops the daemon within a second
//! with the link frozen, during a bring-up against a peer that accepts and
//! never answers, and during a recovery's back-off.

use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, Simulator, run};
use ecmxf_proto::v1 as pb;

async fn status(ch: &tonic::transport::Channel) -> pb::MasterStatus {
    let mut m = pb::master_client::MasterClient::new(ch.clone());
    m.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner()
}

fn input_frames(s: &pb::MasterStatus) -> u64 {
    s.counters.as_ref().map_or(0, |c| c.input_frames)
}

/// SIGTERM, then the time until the process exited and its status.
fn stop_timed(d: &mut Daemon) -> (Duration, Option<i32>) {
    let t = Instant::now();
    let code = d.stop();
    (t.elapsed(), code)
}

#[test]
fn a_frozen_link_is_a_fault_that_recovers_and_never_holds_up_a_stop() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("frozen");
        let sim = Simulator::serve(&dir, &[]);
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config(&sim.link(), ""));
        let ch = d.connect().await;
        let before = status(&ch).await;
        assert_eq!(before.phase, pb::EnginePhase::Running as i32, "{before:?}");

        // Frozen: an event names the stall within 100 ms of its limit,
        // though the engine is held in a link call that cannot return;
        // then the phase leaves RUNNING, the error names the stalled link.
        let mut diag = pb::diagnostics_client::DiagnosticsClient::new(ch.clone());
        let mut events = diag.stream_events(pb::StreamEventsRequest {}).await.unwrap().into_inner();
        let limit = Duration::from_micros(before.flow_limit_us);
        assert!(limit > Duration::ZERO, "{before:?}");
        sim.freeze();
        let frozen = Instant::now();
        let stall = tokio::time::timeout(Duration::from_secs(2), async {
            loop {
                let e = events.message().await.unwrap().expect("the event stream goes on");
                if e.kind == pb::EventKind::ProcessData as i32 && !e.flag {
                    return (frozen.elapsed(), e);
                }
            }
        })
        .await
        .expect("a stall event");
        eprintln!("stall event {:?} after the freeze (limit {limit:?}): {}", stall.0, stall.1.text);
        assert!(stall.0 < limit + Duration::from_millis(100), "stall event after {:?}, limit {limit:?}", stall.0);
        assert!(stall.1.text.contains("process data stalled"), "{:?}", stall.1);
        let left = loop {
            let s = status(&ch).await;
            if s.phase != pb::EnginePhase::Running as i32 {
                break s;
            }
            assert!(frozen.elapsed() < Duration::from_secs(2), "still RUNNING with the link frozen: {s:?}");
            tokio::time::sleep(Duration::from_millis(10)).await;
        };
        let took = frozen.elapsed();
        assert!(left.last_error.contains("link stalled"), "{left:?}");
        assert!(!left.process_data_flowing, "{left:?}");
        eprintln!("frozen link: phase {:?} after {took:?}: {}", left.phase, left.last_error);
        tokio::time::sleep(Duration::from_secs(2)).await;
        let s = status(&ch).await;
        assert_ne!(s.phase, pb::EnginePhase::Running as i32, "never RUNNING while frozen: {s:?}");

        // Going on: running again, and input frames flow.
        sim.thaw();
        let thawed = Instant::now();
        loop {
            let s = status(&ch).await;
            if s.phase == pb::EnginePhase::Running as i32 && s.process_data_flowing {
                let n = input_frames(&s);
                tokio::time::sleep(Duration::from_millis(100)).await;
                assert!(input_frames(&status(&ch).await) > n, "input frames flow again");
                break;
            }
            assert!(thawed.elapsed() < Duration::from_secs(10), "not running again after the thaw: {s:?}\n{}", d.log());
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        eprintln!("thawed: data flows again after {:?}", thawed.elapsed());

        // SIGTERM with the link frozen: out within a second, cleanly.
        sim.freeze();
        tokio::time::sleep(Duration::from_millis(300)).await;
        let (took, code) = stop_timed(&mut d);
        sim.thaw();
        assert_eq!(code, Some(0), "{}", d.log());
        assert!(took < Duration::from_secs(1), "stop took {took:?} with the link frozen\n{}", d.log());
    });
}

#[test]
fn sigterm_stops_a_bring_up_against_a_peer_that_never_answers() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("mute");
        let socket = dir.join("mute.sock");
        // Accepts every connection, reads, never answers.
        let listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
        std::thread::spawn(move || {
            let mut held = Vec::new();
            for c in listener.incoming().flatten() {
                held.push(c);
            }
        });
        let link = format!("backend = \"sim-socket\"\nsocket = \"{}\"", socket.display());
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config(&link, ""));
        // Well into bring-up (and its first retries).
        tokio::time::sleep(Duration::from_millis(1500)).await;
        assert!(d.log().contains("link stalled"), "bring-up says why it fails:\n{}", d.log());
        let (took, code) = stop_timed(&mut d);
        assert_eq!(code, Some(0), "{}", d.log());
        assert!(took < Duration::from_secs(1), "stop took {took:?} during bring-up\n{}", d.log());
    });
}

/// SIGTERM while the daemon recovers (the simulator's process gone, the
/// link reopened again and again with the back-off): out within a second.
#[test]
fn sigterm_stops_a_recovery_within_a_second() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("recovering");
        let mut sim = Simulator::serve(&dir, &[]);
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config(&sim.link(), ""));
        let ch = d.connect().await;
        sim.kill();
        let gone = Instant::now();
        loop {
            let s = status(&ch).await;
            if s.phase == pb::EnginePhase::Recovering as i32 {
                break;
            }
            assert!(gone.elapsed() < Duration::from_secs(2), "not recovering with the chip gone: {s:?}");
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        // Into the back-off between attempts.
        tokio::time::sleep(Duration::from_millis(700)).await;
        assert_eq!(status(&ch).await.phase, pb::EnginePhase::Recovering as i32);
        let (took, code) = stop_timed(&mut d);
        assert_eq!(code, Some(0), "{}", d.log());
        assert!(took < Duration::from_secs(1), "stop took {took:?} during recovery\n{}", d.log());
    });
}
