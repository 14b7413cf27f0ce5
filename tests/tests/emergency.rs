//! A drive fault raised in the simulator (served on its own socket, the
//! daemon attached with `backend = "sim-socket"`) reaches API clients as an
//! EMERGENCY event and in the emergency history; the axis shows FAULT and
//! comes back with FAULT_RESET once the cause is gone.

use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, run};
use ecmxf_proto::v1 as pb;
use pb::cia402_client::Cia402Client;
use pb::diagnostics_client::DiagnosticsClient;
use tokio_stream::StreamExt;

#[test]
fn a_drive_fault_arrives_as_an_emergency_event() {
    run(async {
        let dir = ecmxf_e2e::temp_dir("emcy");
        let sim = ecmxf_e2e::Simulator::serve(&dir, &[]);
        let config = ecmxf_e2e::config(&sim.link(), ecmxf_e2e::TI_AXIS);
        let mut d = Daemon::with_config(&config);
        let ch = d.connect().await;
        let mut diag = DiagnosticsClient::new(ch.clone());
        let mut events = diag.stream_events(pb::StreamEventsRequest {}).await.unwrap().into_inner();
        tokio::time::sleep(Duration::from_millis(50)).await;
        sim.ctl("drive-fault 1 0 0x2310");
        // From when the fault is raised (ctl has answered): the engine reads
        // the chip's records every 6-7 ms, and the next exchange brings them.
        let start = Instant::now();
        let (event, latency) = loop {
            let e =
                tokio::time::timeout(Duration::from_secs(5), events.next()).await.expect("no event").unwrap().unwrap();
            if e.kind == pb::EventKind::Emergency as i32 {
                break (e, start.elapsed());
            }
            assert!(start.elapsed() < Duration::from_secs(5), "no EMERGENCY event");
        };
        println!("emergency event {:.1} ms after the fault was raised (1 ms cycle)", latency.as_secs_f64() * 1000.0);
        assert!(latency <= Duration::from_millis(10), "the emergency took {latency:?} to arrive");
        assert!(event.time_ns > 0, "the event says when it was read: {event:?}");
        let emcy = event.emergency.unwrap();
        assert_eq!((emcy.slave, emcy.error_code), (1, 0x2310), "{emcy:?}");
        let history = diag.get_emergencies(pb::GetEmergenciesRequest { count: 8 }).await.unwrap().into_inner();
        assert_eq!(history.emergencies[0].error_code, 0x2310, "{history:?}");

        let mut cia = Cia402Client::new(ch);
        let s = cia.get_axis(pb::GetAxisRequest { axis: 0 }).await.unwrap().into_inner();
        assert_eq!(s.state, pb::DriveState::Fault as i32, "{s:?}");
        assert_eq!(s.error_code, 0x2310, "{s:?}");
        let e = cia
            .command(pb::AxisCommandRequest {
                axis: 0,
                command: pb::AxisCommand::Enable as i32,
                wait: true,
                timeout_ms: 1000,
            })
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition, "{e:?}");
        assert!(e.message().contains("0x2310"), "{e:?}");
        sim.ctl("clear-fault 1 0");
        let s = cia
            .command(pb::AxisCommandRequest {
                axis: 0,
                command: pb::AxisCommand::FaultReset as i32,
                wait: true,
                timeout_ms: 3000,
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(s.state, pb::DriveState::SwitchOnDisabled as i32, "{s:?}");
        // A second fault, then ENABLE walks through the fault reset itself.
        sim.ctl("drive-fault 1 0 0x7500");
        tokio::time::sleep(Duration::from_millis(100)).await;
        sim.ctl("clear-fault 1 0");
        let s = cia
            .command(pb::AxisCommandRequest {
                axis: 0,
                command: pb::AxisCommand::Enable as i32,
                wait: true,
                timeout_ms: 3000,
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(s.state, pb::DriveState::OperationEnabled as i32, "{s:?}");
        drop(d);
        drop(sim);
        let _ = std::fs::remove_dir_all(&dir);
    });
}
