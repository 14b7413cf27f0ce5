//! `Master`, `Slaves`, `State`, health and reflection against `ecmxfd --sim`.

use ecmxf_e2e::{Daemon, run};
use ecmxf_proto::v1 as pb;
use pb::master_client::MasterClient;
use pb::slaves_client::SlavesClient;
use pb::state_client::StateClient;
use tonic::Code;

#[test]
fn master_slaves_and_states() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut master = MasterClient::new(ch.clone());
        let info = master.get_info(pb::GetInfoRequest {}).await.unwrap().into_inner();
        assert_eq!(info.firmware_version, 0x24);
        assert_eq!(info.slave_count, 3);
        assert_eq!(info.check_type, pb::CheckType::Crc32 as i32);
        assert_eq!(info.packet_bytes, info.data_size_bytes + 32);
        assert!(info.output_image_bytes > 0 && info.input_image_bytes > 0, "{info:?}");
        assert_eq!(info.target_state, pb::EcatState::Op as i32);

        let status = master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
        assert_eq!(status.phase, pb::EnginePhase::Running as i32);
        assert_eq!(status.ecat_state, pb::EcatState::Op as i32);
        assert!(status.process_data_flowing && status.health.starts_with("healthy"), "{status:?}");
        assert!(status.flow_limit_us > 0 && status.input_age_us <= status.flow_limit_us, "{status:?}");
        let counters = status.counters.unwrap();
        assert!(counters.exchanges > 0 && counters.input_frames > 0, "{counters:?}");

        let mut slaves = SlavesClient::new(ch.clone());
        let list = slaves.list_slaves(pb::ListSlavesRequest {}).await.unwrap().into_inner();
        assert_eq!(list.slaves.len(), 3);
        assert!(list.matches_config, "{list:?}");
        let ti = &list.slaves[1];
        assert_eq!((ti.vendor_id, ti.product_code), (0x59D, 0x402));
        assert_eq!(ti.state, pb::EcatState::Op as i32);
        assert_eq!((ti.al_status_code, ti.al_status_text.as_str()), (0, "no error"));
        assert_eq!(ti.alias, 2);
        assert!(ti.dc.unwrap().supported && ti.output_bytes > 0);
        assert!(!list.slaves[2].dc.unwrap().active, "the IO slave has no DC");
        let scan = slaves.scan(pb::ScanRequest { reinit: false }).await.unwrap().into_inner();
        assert_eq!(
            scan.slaves.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(),
            list.slaves.iter().map(|s| s.name.as_str()).collect::<Vec<_>>()
        );

        let mut state = StateClient::new(ch.clone());
        let all = state.get_state(pb::GetStateRequest { slave: None }).await.unwrap().into_inner();
        assert_eq!(all.state, pb::EcatState::Op as i32);
        assert_eq!(all.slaves.len(), 3);
        let r = state
            .set_state(pb::SetStateRequest {
                slave: Some(2),
                state: pb::EcatState::SafeOp as i32,
                wait: true,
                timeout_ms: 3000,
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(r.state, pb::EcatState::SafeOp as i32);
        let one = state
            .get_state(pb::GetStateRequest { slave: Some(2) })
            .await
            .unwrap_or_else(|e| panic!("{e:?}\n{}", d.log()))
            .into_inner();
        assert_eq!(one.state, pb::EcatState::SafeOp as i32);
        // A slave held in SAFE-OP on request reports no AL error, and says so.
        assert_eq!(one.al_status_code, 0, "{one:?}");
        assert!(!one.al_status_text.is_empty(), "{one:?}");
        let r = state
            .set_state(pb::SetStateRequest {
                slave: Some(2),
                state: pb::EcatState::Op as i32,
                wait: true,
                timeout_ms: 3000,
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(r.state, pb::EcatState::Op as i32);

        // Errors name the field.
        let e = state.get_state(pb::GetStateRequest { slave: Some(9) }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);
        assert!(e.message().contains("slave"), "{e:?}");
        let e = state
            .set_state(pb::SetStateRequest { slave: None, state: 0, wait: false, timeout_ms: 0 })
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);
        assert!(e.message().contains("state"), "{e:?}");
        let e = state
            .set_state(pb::SetStateRequest { slave: Some(200), state: 8, wait: false, timeout_ms: 0 })
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);

        // Re-init and warm reset come back running.
        let r = master.reinit(pb::ReinitRequest {}).await.unwrap().into_inner();
        assert_eq!(r.state, pb::EcatState::Op as i32);
        let r = master.warm_reset(pb::WarmResetRequest {}).await.unwrap().into_inner();
        assert_eq!(r.state, pb::EcatState::Op as i32);
        let scan = slaves.scan(pb::ScanRequest { reinit: true }).await.unwrap().into_inner();
        assert_eq!(scan.slaves.len(), 3);
        assert_eq!(d.stop(), Some(0), "{}", d.log());
    });
}

#[test]
fn health_follows_the_bus_and_reflection_lists_the_services() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut health = tonic_health::pb::health_client::HealthClient::new(ch.clone());
        let start = std::time::Instant::now();
        loop {
            let r = health.check(tonic_health::pb::HealthCheckRequest { service: String::new() }).await.unwrap();
            if r.get_ref().status == tonic_health::pb::health_check_response::ServingStatus::Serving as i32 {
                break;
            }
            assert!(start.elapsed().as_secs() < 5, "health never SERVING");
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        }
        let r = health.check(tonic_health::pb::HealthCheckRequest { service: "ecmxf.v1.Sdo".into() }).await.unwrap();
        assert_eq!(r.get_ref().status, tonic_health::pb::health_check_response::ServingStatus::Serving as i32);

        // A slave out of OP: NOT_SERVING until the network is back.
        let mut state = StateClient::new(ch.clone());
        let set =
            |s: pb::EcatState| pb::SetStateRequest { slave: Some(2), state: s as i32, wait: true, timeout_ms: 3000 };
        state.set_state(set(pb::EcatState::SafeOp)).await.unwrap();
        let changed = std::time::Instant::now();
        let wait_for = |want: tonic_health::pb::health_check_response::ServingStatus| {
            let mut health = health.clone();
            async move {
                let start = std::time::Instant::now();
                loop {
                    let r =
                        health.check(tonic_health::pb::HealthCheckRequest { service: String::new() }).await.unwrap();
                    if r.get_ref().status == want as i32 {
                        return;
                    }
                    assert!(start.elapsed().as_secs() < 5, "health never {want:?}");
                    tokio::time::sleep(std::time::Duration::from_millis(20)).await;
                }
            }
        };
        wait_for(tonic_health::pb::health_check_response::ServingStatus::NotServing).await;
        // Health follows the engine's snapshots, not a slow timer: it
        // flips within a few ms of the state change (20 ms between looks
        // here; 250 ms allows for a loaded host).
        let lag = changed.elapsed();
        println!("health NOT_SERVING {} ms after SetState returned", lag.as_millis());
        assert!(lag < std::time::Duration::from_millis(250), "health lagged the state change by {lag:?}");
        // Held there on purpose: no recovery undoes it.
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        let one = state
            .get_state(pb::GetStateRequest { slave: Some(2) })
            .await
            .unwrap_or_else(|e| panic!("{e:?}\n{}", d.log()))
            .into_inner();
        assert_eq!(one.state, pb::EcatState::SafeOp as i32);
        // A slave held in SAFE-OP on request reports no AL error, and says so.
        assert_eq!(one.al_status_code, 0, "{one:?}");
        assert!(!one.al_status_text.is_empty(), "{one:?}");
        state.set_state(set(pb::EcatState::Op)).await.unwrap_or_else(|e| panic!("{e:?}\n{}", d.log()));
        wait_for(tonic_health::pb::health_check_response::ServingStatus::Serving).await;

        // Reflection, both versions, via the raw protocol (what grpcurl does).
        for path in [
            "/grpc.reflection.v1.ServerReflection/ServerReflectionInfo",
            "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo",
        ] {
            let services = reflection_list(ch.clone(), path).await;
            for s in
                ["ecmxf.v1.Master", "ecmxf.v1.Sdo", "ecmxf.v1.ProcessData", "ecmxf.v1.Cia402", "grpc.health.v1.Health"]
            {
                assert!(services.iter().any(|x| x == s), "{path}: {s} missing from {services:?}");
            }
        }
    });
}

/// ServerReflectionRequest { list_services = 7 } / response
/// { list_services_response = 6 { service = 1 { name = 1 } } }: the same
/// wire format in v1 and v1alpha.
async fn reflection_list(ch: tonic::transport::Channel, path: &'static str) -> Vec<String> {
    #[derive(Clone, PartialEq, prost::Message)]
    struct Req {
        #[prost(string, tag = "7")]
        list_services: String,
    }
    #[derive(Clone, PartialEq, prost::Message)]
    struct Name {
        #[prost(string, tag = "1")]
        name: String,
    }
    #[derive(Clone, PartialEq, prost::Message)]
    struct List {
        #[prost(message, repeated, tag = "1")]
        service: Vec<Name>,
    }
    #[derive(Clone, PartialEq, prost::Message)]
    struct Resp {
        #[prost(message, optional, tag = "6")]
        list_services_response: Option<List>,
    }
    let mut client = tonic::client::Grpc::new(ch);
    client.ready().await.unwrap();
    let codec = tonic_prost::ProstCodec::<Req, Resp>::default();
    let req = tokio_stream::iter(vec![Req { list_services: "*".into() }]);
    let mut stream = client
        .streaming(tonic::Request::new(req), tonic::codegen::http::uri::PathAndQuery::from_static(path), codec)
        .await
        .unwrap()
        .into_inner();
    let first = stream.message().await.unwrap().unwrap();
    first.list_services_response.unwrap().service.into_iter().map(|s| s.name).collect()
}

/// `states preop` then `states op`, and `states init` then `states op`,
/// walk the state machine one step at a time (PRE-OP -> SAFE-OP -> OP):
/// each succeeds, no recovery starts, and process data flows afterwards
/// (OP asked for directly once made every slave refuse with AL status
/// 0x0011, and the engine recovered on its own while the call failed).
#[test]
fn op_from_preop_or_init_walks_the_state_machine_without_a_recovery() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut state = StateClient::new(ch.clone());
        let mut master = MasterClient::new(ch.clone());
        let request = |slave: Option<u32>, s: pb::EcatState| pb::SetStateRequest {
            slave,
            state: s as i32,
            wait: true,
            timeout_ms: 5000,
        };
        let before = master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
        for (down, slave) in [(pb::EcatState::PreOp, None), (pb::EcatState::Init, None), (pb::EcatState::Init, Some(1))]
        {
            let r = state.set_state(request(slave, down)).await.unwrap().into_inner();
            assert_eq!(r.state, down as i32, "{slave:?} down to {down:?}");
            let r = state.set_state(request(slave, pb::EcatState::Op)).await;
            let r = r.unwrap_or_else(|e| panic!("{slave:?} from {down:?} to OP: {e:?}")).into_inner();
            assert_eq!(r.state, pb::EcatState::Op as i32, "{slave:?} from {down:?}");
        }
        // Running, flowing, and never recovered.
        let frames = before.counters.as_ref().unwrap().input_frames;
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        let s = master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
        assert_eq!(s.phase, pb::EnginePhase::Running as i32, "{s:?}");
        assert!(s.process_data_flowing, "{s:?}");
        let c = s.counters.unwrap();
        assert!(c.input_frames > frames, "{c:?}");
        assert_eq!(c.recoveries, before.counters.unwrap().recoveries, "a step was refused and the engine recovered");
    });
}
