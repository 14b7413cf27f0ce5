//! Health says what flows, judged by the real `ecmxfd` on `ecmxf-sim serve`
//! with faults injected from outside:
//!
//! - the RxFIFO running dry (`rx-fifo starve`) makes health degraded with
//!   the count, while the phase stays RUNNING and data flows, and health is
//!   healthy again by itself once a quiet window passed;
//! - unplugging the slave an `[[axis]]` drives names the missing slaves
//!   first, not the CiA 402 helper's refusal that would follow from it;
//! - a call that needs the running network, made while it is still coming
//!   up, is UNAVAILABLE (a client retries), not INVALID_ARGUMENT.

use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, Simulator, run};
use ecmxf_proto::v1 as pb;
use tonic::Code;

async fn status(ch: &tonic::transport::Channel) -> pb::MasterStatus {
    let mut m = pb::master_client::MasterClient::new(ch.clone());
    m.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner()
}

/// Polls the status until `done` holds, for at most `limit`; the status
/// that did, and when.
async fn until(
    ch: &tonic::transport::Channel,
    limit: Duration,
    what: &str,
    done: impl Fn(&pb::MasterStatus) -> bool,
) -> (pb::MasterStatus, Duration) {
    let start = Instant::now();
    loop {
        let s = status(ch).await;
        if done(&s) {
            return (s, start.elapsed());
        }
        assert!(start.elapsed() < limit, "{what}: not within {limit:?}: {s:?}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[test]
fn a_dry_rxfifo_degrades_health_with_its_count_until_a_quiet_window_passes() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("health-flow");
        let sim = Simulator::serve(&dir, &[]);
        // A TxFIFO deep enough for 150 ms of inputs: a shared test host
        // that stalls the daemon for tens of ms must not make the chip drop
        // inputs, a trouble of its own that would keep health degraded.
        let config = ecmxf_e2e::config(&sim.link(), "").replace(
            "fifo_rx_depth = 255\nfifo_tx_depth = 40\nfifo_low = 128\nfifo_high = 240",
            "fifo_rx_depth = 128\nfifo_tx_depth = 160\nfifo_low = 48\nfifo_high = 96",
        );
        assert!(config.contains("fifo_tx_depth = 160"), "the harness configuration changed: {config}");
        let mut d = Daemon::binary_with_config(&config);
        let ch = d.connect().await;
        let (healthy, _) =
            until(&ch, Duration::from_secs(10), "healthy at the start", |s| s.health.starts_with("healthy")).await;
        let alarms = healthy.counters.as_ref().map_or(0, |c| c.fifo_alarms);

        sim.ctl("rx-fifo starve 20");
        let starved = Instant::now();
        let (s, took) = until(&ch, Duration::from_secs(2), "degraded after the RxFIFO ran dry", |s| {
            s.health.starts_with("degraded: the RxFIFO ran dry")
        })
        .await;
        eprintln!("degraded after {took:?}: {}", s.health);
        assert!(s.counters.as_ref().is_some_and(|c| c.fifo_alarms > alarms), "{s:?}");
        assert!(s.health.contains("healthy again after 10 s without"), "{}", s.health);
        assert_eq!(s.phase, pb::EnginePhase::Running as i32, "the network runs on: {s:?}");
        assert!(s.process_data_flowing, "data flows: {s:?}");
        // `ecmxfctl diag` says it, and exits 8 (not healthy) for scripts.
        let diag = d.ctl(&["diag"]);
        diag.fails(8);
        assert!(diag.stdout.contains("RxFIFO ran dry"), "ecmxfctl diag says it: {}", diag.stdout);

        // Healthy again by itself, a quiet window after the last alarm.
        let (s, _) =
            until(&ch, Duration::from_secs(40), "healthy after the window", |s| s.health.starts_with("healthy")).await;
        let after = starved.elapsed();
        eprintln!("healthy again {after:?} after the starving: {}", s.health);
        assert!(after >= Duration::from_secs(9), "healed before a whole window passed ({after:?})");
        assert_eq!(d.stop(), Some(0), "{}", d.log());
    });
}

#[test]
fn an_unplugged_axis_slave_is_named_missing_before_anything_else() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("health-unplug");
        let sim = Simulator::serve(&dir, &[]);
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config(&sim.link(), ecmxf_e2e::TI_AXIS));
        let ch = d.connect().await;
        until(&ch, Duration::from_secs(10), "healthy at the start", |s| s.health.starts_with("healthy")).await;

        // Slave 1 (the drive the axis is on) out: the ring ends before it.
        sim.ctl("unplug 1");
        let (s, took) =
            until(&ch, Duration::from_secs(10), "the missing slaves named", |s| s.last_error.contains("missing")).await;
        eprintln!("after {took:?}: {}", s.last_error);
        assert!(s.last_error.contains("slaves 1-2 are missing: 1 slave answers, 3 did before"), "{}", s.last_error);
        assert!(!s.last_error.contains("CiA402 helper"), "the helper's refusal is not the cause: {}", s.last_error);
        assert_ne!(s.phase, pb::EnginePhase::Running as i32, "{s:?}");

        // Plugged back: running and healthy again.
        sim.ctl("replug 1");
        until(&ch, Duration::from_secs(20), "healthy after the replug", |s| s.health.starts_with("healthy")).await;
        assert_eq!(d.stop(), Some(0), "{}", d.log());
    });
}

#[test]
fn calls_that_need_the_network_are_unavailable_while_it_comes_up() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("health-bringup");
        let sim = Simulator::serve(&dir, &[]);
        // The chip does not answer: bring-up cannot get anywhere.
        sim.freeze();
        let mut d = Daemon::binary_with_config(&ecmxf_e2e::config(&sim.link(), ""));
        // Served while the network is not up (`Daemon::connect` waits for
        // RUNNING).
        let start = Instant::now();
        let ch = loop {
            if let Ok(ch) = ecmxf_proto::connect_unix(&d.socket).await {
                let mut m = pb::master_client::MasterClient::new(ch.clone());
                if m.get_status(pb::GetStatusRequest {}).await.is_ok() {
                    break ch;
                }
            }
            assert!(start.elapsed() < Duration::from_secs(10), "the API is not served:\n{}", d.log());
            tokio::time::sleep(Duration::from_millis(50)).await;
        };
        let s = status(&ch).await;
        assert_ne!(s.phase, pb::EnginePhase::Running as i32, "{s:?}");

        let mut pd = pb::process_data_client::ProcessDataClient::new(ch.clone());
        let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 0 }).await.unwrap_err();
        assert_eq!(lease.code(), Code::Unavailable, "AcquireLease: {lease:?}");
        let mut sdo = pb::sdo_client::SdoClient::new(ch.clone());
        let up = pb::SdoUploadRequest { slave: 1, index: 0x1000, ..Default::default() };
        let e = sdo.upload(up).await.unwrap_err();
        assert_eq!(e.code(), Code::Unavailable, "SDO upload: {e:?}");
        let mut state = pb::state_client::StateClient::new(ch.clone());
        let e = state.get_state(pb::GetStateRequest { slave: Some(2) }).await.unwrap_err();
        assert_eq!(e.code(), Code::Unavailable, "GetState: {e:?}");

        // Once up, the same lease is granted; a slave that is not there is
        // a mistake in the request.
        sim.thaw();
        until(&ch, Duration::from_secs(20), "running after the thaw", |s| s.phase == pb::EnginePhase::Running as i32)
            .await;
        pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 0 }).await.expect("granted once running");
        let e = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![9], ttl_ms: 0 }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
        assert!(e.message().contains("slave 9 does not exist (3 found)"), "{e:?}");
        assert_eq!(d.stop(), Some(0), "{}", d.log());
    });
}
