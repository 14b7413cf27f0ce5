//! `Foe`, `Registers` and `Diagnostics` against `ecmxfd --sim`.

use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, run};
use ecmxf_proto::v1 as pb;
use pb::diagnostics_client::DiagnosticsClient;
use pb::foe_client::FoeClient;
use pb::registers_client::RegistersClient;
use pb::state_client::StateClient;
use tokio_stream::StreamExt;
use tonic::Code;

#[test]
fn foe_round_trip_with_progress() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut foe = FoeClient::new(ch.clone());
        let file: Vec<u8> = (0..100_000u32).map(|i| (i * 7 % 251) as u8).collect();
        let mut s = foe
            .write(pb::FoeWriteRequest { slave: 1, name: "firmware.bin".into(), password: 0, data: file.clone() })
            .await
            .unwrap()
            .into_inner();
        let mut progress = Vec::new();
        while let Some(m) = s.next().await {
            progress.push(m.unwrap());
        }
        let last = progress.last().unwrap();
        assert!(last.done && last.bytes_total == 100_000, "{last:?}");
        assert!(progress.len() >= 2, "progress before the end: {progress:?}");
        assert!(progress.windows(2).all(|w| w[0].bytes_done <= w[1].bytes_done));

        let mut s = foe
            .read(pb::FoeReadRequest { slave: 1, name: "firmware.bin".into(), password: 0, max_bytes: 200_000 })
            .await
            .unwrap()
            .into_inner();
        let mut data = None;
        while let Some(m) = s.next().await {
            let m = m.unwrap();
            if m.done {
                data = Some(m.data);
            }
        }
        assert_eq!(data.unwrap(), file);

        // A file longer than allowed, a missing file, bad arguments.
        let mut s = foe
            .read(pb::FoeReadRequest { slave: 1, name: "firmware.bin".into(), password: 0, max_bytes: 100 })
            .await
            .unwrap()
            .into_inner();
        let mut err = None;
        while let Some(m) = s.next().await {
            if let Err(e) = m {
                err = Some(e);
            }
        }
        assert!(err.is_some(), "a 100 kB file read with max 100 bytes must fail");
        let e =
            foe.read(pb::FoeReadRequest { slave: 1, name: "x".into(), password: 0, max_bytes: 0 }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);
        let mut s = foe
            .write(pb::FoeWriteRequest { slave: 1, name: String::new(), password: 0, data: vec![1] })
            .await
            .unwrap()
            .into_inner();
        // A progress message may come first; the stream ends with the error.
        let e = loop {
            match s.next().await.expect("the stream ended without an error") {
                Ok(p) => assert!(!p.done, "{p:?}"),
                Err(e) => break e,
            }
        };
        assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
        // A file the slave does not have: the slave's refusal, named; a slave
        // without FoE (the IO slave's SII lists CoE only): said at once.
        let ctl = d.ctl(&["foe", "read", "-p", "1", "no-such-file", "-o", "/dev/null"]);
        assert_ne!(ctl.code, 0);
        assert!(ctl.stderr.contains("slave 1 did not complete the FoE read of \"no-such-file\""), "{}", ctl.stderr);
        let started = std::time::Instant::now();
        let ctl = d.ctl(&["foe", "read", "-p", "2", "x", "-o", "/dev/null"]);
        assert!(ctl.stderr.contains("slave 2 has no FoE (the mailbox protocols its SII lists: CoE)"), "{}", ctl.stderr);
        assert!(started.elapsed() < std::time::Duration::from_secs(1), "at once");
    });
}

#[test]
fn registers_and_raw_datagrams() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut reg = RegistersClient::new(ch);
        // AL status of slave 1: OP.
        let r = reg
            .read_registers(pb::ReadRegistersRequest { slave: 1, address: 0x0130, length: 2 })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(r.working_counter, 1);
        assert_eq!(r.data[0] & 0x0F, 8, "{r:?}");
        // Broadcast read: every slave counts.
        let r = reg
            .datagram(pb::DatagramRequest {
                command: pb::DatagramCommand::Brd as i32,
                adp: 0,
                ado: 0x0130,
                length: 2,
                data: vec![],
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(r.working_counter, 3);
        // AL control: request SAFE-OP of slave 2 through the register.
        let r = reg
            .write_registers(pb::WriteRegistersRequest { slave: 2, address: 0x0120, data: vec![4, 0] })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(r.working_counter, 1);
        let start = Instant::now();
        loop {
            let r = reg
                .read_registers(pb::ReadRegistersRequest { slave: 2, address: 0x0130, length: 2 })
                .await
                .unwrap()
                .into_inner();
            if r.data[0] & 0x0F == 4 {
                break;
            }
            assert!(start.elapsed() < Duration::from_secs(3), "{r:?}");
        }
        let e = reg
            .datagram(pb::DatagramRequest {
                command: pb::DatagramCommand::Aprw as i32,
                adp: 0,
                ado: 0,
                length: 1,
                data: vec![],
            })
            .await
            .unwrap_err();
        assert!(e.message().contains("command"), "{e:?}");
        let e =
            reg.read_registers(pb::ReadRegistersRequest { slave: 1, address: 0x1_0000, length: 2 }).await.unwrap_err();
        assert!(e.message().contains("address"), "{e:?}");
        let e = reg
            .write_registers(pb::WriteRegistersRequest { slave: 1, address: 0x120, data: vec![] })
            .await
            .unwrap_err();
        assert!(e.message().contains("data"), "{e:?}");
    });
}

#[test]
fn events_emergencies_and_counters() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut diag = DiagnosticsClient::new(ch.clone());
        let mut events = diag.stream_events(pb::StreamEventsRequest {}).await.unwrap().into_inner();
        // Drop slave 0 to SAFE-OP and back: the network state changes.
        let mut state = StateClient::new(ch.clone());
        let set =
            |s: pb::EcatState| pb::SetStateRequest { slave: Some(0), state: s as i32, wait: true, timeout_ms: 3000 };
        state.set_state(set(pb::EcatState::SafeOp)).await.unwrap();
        let start = Instant::now();
        loop {
            let e = tokio::time::timeout(Duration::from_secs(3), events.next())
                .await
                .expect("no event in 3 s")
                .unwrap()
                .unwrap();
            if e.kind == pb::EventKind::StateChange as i32 && e.to_state == pb::EcatState::SafeOp as i32 {
                assert_eq!(e.from_state, pb::EcatState::Op as i32, "{e:?}");
                break;
            }
            assert!(start.elapsed() < Duration::from_secs(5));
        }
        // The counters name the slave that is not in OP.
        let c = diag.get_counters(pb::GetCountersRequest {}).await.unwrap().into_inner();
        assert!(c.counters.unwrap().exchanges > 0);
        assert_eq!(c.slaves[0].state, pb::EcatState::SafeOp as i32, "{c:?}");
        assert_eq!(c.slaves[1].state, pb::EcatState::Op as i32);
        state.set_state(set(pb::EcatState::Op)).await.unwrap();

        let em = diag.get_emergencies(pb::GetEmergenciesRequest { count: 0 }).await.unwrap().into_inner();
        assert!(em.emergencies.windows(2).all(|w| w[0].number >= w[1].number), "{em:?}");
        let e = diag.get_emergencies(pb::GetEmergenciesRequest { count: 9 }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);
    });
}
