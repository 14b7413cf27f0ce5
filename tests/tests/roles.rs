//! Every RPC that changes something refuses a caller whose role is too low
//! (PERMISSION_DENIED naming both roles, nothing done), and the remaining
//! error cases not covered next to each service's tests.

use ecmxf_e2e::{Daemon, run, sdo_write, with_token};
use ecmxf_proto::v1 as pb;
use sha2::{Digest, Sha256};
use tokio_stream::StreamExt;
use tonic::{Code, Status};

fn denied<T: std::fmt::Debug>(what: &str, r: Result<T, Status>, needs: &str) {
    let e = r.expect_err(what);
    assert_eq!(e.code(), Code::PermissionDenied, "{what}: {e:?}");
    assert!(e.message().contains(needs), "{what}: {}", e.message());
    assert_eq!(ecmxf_e2e::full_status(&e), "PERMISSION_DENIED", "{what}");
}

#[test]
fn each_role_is_enforced_per_rpc() {
    run(async {
        let api = format!(
            "[api]\n[[api.token]]\nname = \"viewer\"\nsha256 = \"{}\"\nrole = \"observer\"\n[[api.token]]\nname = \"cell\"\nsha256 = \"{}\"\nrole = \"operator\"\n",
            hex::encode(Sha256::digest(b"view")),
            hex::encode(Sha256::digest(b"operate"))
        );
        let mut d =
            Daemon::with_config(&ecmxf_e2e::config("backend = \"sim\"", &format!("{api}{}", ecmxf_e2e::TI_AXIS)));
        let ch = d.connect().await;
        let (obs, op) = ("view", "operate");

        // Observer: reads work, every write is refused as needing operator.
        let mut master = pb::master_client::MasterClient::new(ch.clone());
        master.get_info(with_token(pb::GetInfoRequest {}, obs)).await.unwrap();
        let mut state = pb::state_client::StateClient::new(ch.clone());
        denied(
            "SetState",
            state
                .set_state(with_token(
                    pb::SetStateRequest { slave: Some(2), state: 4, wait: false, timeout_ms: 0 },
                    obs,
                ))
                .await,
            "operator",
        );
        let mut sdo = pb::sdo_client::SdoClient::new(ch.clone());
        denied("Sdo.Download", sdo.download(with_token(sdo_write(), obs)).await, "operator");
        let mut pd = pb::process_data_client::ProcessDataClient::new(ch.clone());
        denied(
            "AcquireLease",
            pd.acquire_lease(with_token(pb::AcquireLeaseRequest { slaves: vec![], ttl_ms: 0 }, obs)).await,
            "operator",
        );
        denied(
            "KeepAlive",
            pd.keep_alive(with_token(pb::KeepAliveRequest { lease_id: "x".into() }, obs)).await,
            "operator",
        );
        denied(
            "ReleaseLease",
            pd.release_lease(with_token(pb::ReleaseLeaseRequest { lease_id: "x".into() }, obs)).await,
            "operator",
        );
        denied("WriteOutputs", pd.write_outputs(with_token(pb::WriteOutputsRequest::default(), obs)).await, "operator");
        denied(
            "StreamOutputs",
            pd.stream_outputs(with_token(tokio_stream::iter(vec![pb::WriteOutputsRequest::default()]), obs)).await,
            "operator",
        );
        denied(
            "SetMapping",
            pd.set_mapping(with_token(pb::SetMappingRequest { mapping: None }, obs)).await,
            "operator",
        );
        let mut cia = pb::cia402_client::Cia402Client::new(ch.clone());
        cia.list_axes(with_token(pb::ListAxesRequest {}, obs)).await.unwrap();
        denied(
            "Cia402.Command",
            cia.command(with_token(pb::AxisCommandRequest { axis: 0, command: 2, wait: false, timeout_ms: 0 }, obs))
                .await,
            "operator",
        );
        denied(
            "SetMode",
            cia.set_mode(with_token(pb::SetModeRequest { axis: 0, mode: 8, lease_id: String::new() }, obs)).await,
            "operator",
        );
        denied("SetTarget", cia.set_target(with_token(pb::SetTargetRequest::default(), obs)).await, "operator");
        let mut p = pb::peripherals_client::PeripheralsClient::new(ch.clone());
        p.get_gpio(with_token(pb::GetGpioRequest {}, obs)).await.unwrap();
        denied(
            "ConfigureGpio",
            p.configure_gpio(with_token(pb::ConfigureGpioRequest { lines: 1, mode: 2, pull: 0 }, obs)).await,
            "operator",
        );
        denied("SetGpio", p.set_gpio(with_token(pb::SetGpioRequest { levels: 1 }, obs)).await, "operator");
        denied("WriteDac", p.write_dac(with_token(pb::WriteDacRequest { value: 1 }, obs)).await, "operator");
        denied(
            "Qei start",
            p.qei(with_token(pb::QeiRequest { action: pb::QeiAction::Start as i32 }, obs)).await,
            "operator",
        );
        p.qei(with_token(pb::QeiRequest { action: pb::QeiAction::Read as i32 }, obs)).await.unwrap();

        // Operator: everything above is allowed, admin actions are not.
        denied("Reinit", master.reinit(with_token(pb::ReinitRequest {}, op)).await, "admin");
        denied("WarmReset", master.warm_reset(with_token(pb::WarmResetRequest {}, op)).await, "admin");
        let mut slaves = pb::slaves_client::SlavesClient::new(ch.clone());
        slaves.scan(with_token(pb::ScanRequest { reinit: false }, obs)).await.unwrap();
        denied("Scan with re-init", slaves.scan(with_token(pb::ScanRequest { reinit: true }, op)).await, "admin");
        let mut sii = pb::sii_client::SiiClient::new(ch.clone());
        denied(
            "Sii.Write",
            sii.write(with_token(pb::SiiWriteRequest { slave: 1, word: 0x0E, data: vec![0, 0] }, op)).await,
            "admin",
        );
        let mut foe = pb::foe_client::FoeClient::new(ch.clone());
        denied(
            "Foe.Write",
            foe.write(with_token(pb::FoeWriteRequest { slave: 1, name: "f".into(), password: 0, data: vec![1] }, op))
                .await,
            "admin",
        );
        denied(
            "Foe.Read",
            foe.read(with_token(pb::FoeReadRequest { slave: 1, name: "f".into(), password: 0, max_bytes: 10 }, op))
                .await,
            "admin",
        );
        let mut reg = pb::registers_client::RegistersClient::new(ch.clone());
        denied("Datagram", reg.datagram(with_token(pb::DatagramRequest::default(), op)).await, "admin");
        denied(
            "ReadRegisters",
            reg.read_registers(with_token(pb::ReadRegistersRequest { slave: 0, address: 0x130, length: 2 }, op)).await,
            "admin",
        );
        denied(
            "WriteRegisters",
            reg.write_registers(with_token(pb::WriteRegistersRequest { slave: 0, address: 0x120, data: vec![2] }, op))
                .await,
            "admin",
        );

        // Nothing was done: the network is still in OP, no lease was taken.
        let s = master.get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
        assert_eq!((s.ecat_state, s.output_writers), (pb::EcatState::Op as i32, 0), "{s:?}");

        // Remaining error cases.
        let e = pd.release_lease(pb::ReleaseLeaseRequest { lease_id: "nope".into() }).await.unwrap_err();
        assert_eq!(e.code(), Code::NotFound);
        let lease =
            pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 0 }).await.unwrap().into_inner();
        let good = pb::WriteOutputsRequest {
            lease_id: lease.id.clone(),
            writes: vec![pb::OutputWrite {
                target: Some(pb::output_write::Target::Offset(52)),
                value: Some(pb::Value { kind: Some(pb::value::Kind::Raw(vec![1])) }),
            }],
        };
        let bad = pb::WriteOutputsRequest {
            lease_id: lease.id.clone(),
            writes: vec![pb::OutputWrite { target: None, value: None }],
        };
        let e = pd.stream_outputs(tokio_stream::iter(vec![good.clone(), bad, good])).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
        let e = sii.decode(pb::SiiDecodeRequest { slave: 200 }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);
        let e = master.get_info(with_token(pb::GetInfoRequest {}, "wrong")).await.unwrap_err();
        assert_eq!(e.code(), Code::Unauthenticated);
        let mut diag = pb::diagnostics_client::DiagnosticsClient::new(ch.clone());
        let mut events = diag.stream_events(with_token(pb::StreamEventsRequest {}, obs)).await.unwrap().into_inner();
        let _ = tokio::time::timeout(std::time::Duration::from_millis(100), events.next()).await;
    });
}
