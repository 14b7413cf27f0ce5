//! `Cia402` and `Peripherals` against `ecmxfd` with a configuration that
//! gives the TI-like drive's first axis to the chip's CiA 402 helper.

use std::time::Duration;

use ecmxf_e2e::{Daemon, run};
use ecmxf_proto::v1 as pb;
use pb::cia402_client::Cia402Client;
use pb::peripherals_client::PeripheralsClient;
use pb::process_data_client::ProcessDataClient;
use tonic::Code;

fn config() -> String {
    ecmxf_e2e::config("backend = \"sim\"\nnetwork = \"{repo}/config/demo-network.toml\"", ecmxf_e2e::TI_AXIS)
}

fn command(axis: u32, c: pb::AxisCommand) -> pb::AxisCommandRequest {
    pb::AxisCommandRequest { axis, command: c as i32, wait: true, timeout_ms: 3000 }
}

#[test]
fn cia402_axis_walks_the_state_machine() {
    run(async {
        let mut d = Daemon::with_config(&config());
        let ch = d.connect().await;
        let mut cia = Cia402Client::new(ch.clone());
        let axes = cia.list_axes(pb::ListAxesRequest {}).await.unwrap().into_inner();
        assert_eq!(axes.axes.len(), 1);
        assert_eq!((axes.axes[0].slave, axes.axes[0].slave_axis), (1, 0));

        // Bring-up enabled it (target state OP).
        let s = cia.command(command(0, pb::AxisCommand::Enable)).await.unwrap().into_inner();
        assert_eq!(s.state, pb::DriveState::OperationEnabled as i32, "{s:?}");
        assert_eq!(s.statusword & 0x6F, 0x27, "{s:?}");

        let s = cia.command(command(0, pb::AxisCommand::Disable)).await.unwrap().into_inner();
        assert_eq!(s.state, pb::DriveState::SwitchOnDisabled as i32, "{s:?}");
        let s = cia.command(command(0, pb::AxisCommand::Shutdown)).await.unwrap().into_inner();
        assert_eq!(s.state, pb::DriveState::ReadyToSwitchOn as i32, "{s:?}");

        // Cyclic synchronous velocity, a target through the process image or
        // by SDO, and the drive moving.
        let mut pd = ProcessDataClient::new(ch.clone());
        let lease =
            pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![1], ttl_ms: 5000 }).await.unwrap().into_inner();
        let s = cia
            .set_mode(pb::SetModeRequest { axis: 0, mode: 9, lease_id: lease.id.clone() })
            .await
            .unwrap()
            .into_inner();
        assert_eq!((s.axis, s.mode_display), (0, 9));
        let s = cia.command(command(0, pb::AxisCommand::Enable)).await.unwrap().into_inner();
        assert_eq!(s.state, pb::DriveState::OperationEnabled as i32);
        let r = cia
            .set_target(pb::SetTargetRequest {
                axis: 0,
                target: Some(pb::set_target_request::Target::Velocity(50_000)),
                lease_id: lease.id.clone(),
            })
            .await
            .unwrap()
            .into_inner();
        let before = cia.get_axis(pb::GetAxisRequest { axis: 0 }).await.unwrap().into_inner();
        tokio::time::sleep(Duration::from_millis(300)).await;
        let after = cia.get_axis(pb::GetAxisRequest { axis: 0 }).await.unwrap().into_inner();
        assert_eq!(after.mode_display, 9, "{after:?}");
        assert!(
            after.position_actual != before.position_actual,
            "no motion: {before:?} {after:?} (via image: {})",
            r.via_process_image
        );
        let e = cia
            .set_target(pb::SetTargetRequest {
                axis: 0,
                target: Some(pb::set_target_request::Target::Velocity(1)),
                lease_id: "x".into(),
            })
            .await;
        if r.via_process_image {
            assert_eq!(e.unwrap_err().code(), Code::PermissionDenied);
        }

        // Quick stop, then back to enabled through fault reset.
        let s = cia.command(command(0, pb::AxisCommand::QuickStop)).await.unwrap().into_inner();
        assert!(
            [pb::DriveState::QuickStopActive as i32, pb::DriveState::SwitchOnDisabled as i32].contains(&s.state),
            "{s:?}"
        );
        let s = cia.command(command(0, pb::AxisCommand::FaultReset)).await.unwrap().into_inner();
        assert_eq!(s.state, pb::DriveState::SwitchOnDisabled as i32);
        let s = cia.command(command(0, pb::AxisCommand::Enable)).await.unwrap().into_inner();
        assert_eq!(s.state, pb::DriveState::OperationEnabled as i32);

        // Errors.
        let e = cia.get_axis(pb::GetAxisRequest { axis: 3 }).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument);
        assert!(e.message().contains("axis"), "{}", e.message());
        let e =
            cia.command(pb::AxisCommandRequest { axis: 0, command: 0, wait: false, timeout_ms: 0 }).await.unwrap_err();
        assert!(e.message().contains("command"), "{}", e.message());
        let e = cia.set_mode(pb::SetModeRequest { axis: 0, mode: 300, lease_id: String::new() }).await.unwrap_err();
        assert!(e.message().contains("mode"), "{}", e.message());
        let e =
            cia.set_target(pb::SetTargetRequest { axis: 0, target: None, lease_id: String::new() }).await.unwrap_err();
        assert!(e.message().contains("target"), "{}", e.message());
    });
}

#[test]
fn peripherals_gpio_adc_dac_qei() {
    run(async {
        let mut d = Daemon::sim();
        let ch = d.connect().await;
        let mut p = PeripheralsClient::new(ch);
        p.configure_gpio(pb::ConfigureGpioRequest { lines: 0x0000F, mode: pb::GpioMode::Output as i32, pull: 0 })
            .await
            .unwrap();
        p.configure_gpio(pb::ConfigureGpioRequest {
            lines: 0x30000,
            mode: pb::GpioMode::Output as i32,
            pull: pb::GpioPull::Up as i32,
        })
        .await
        .unwrap();
        let l = p.set_gpio(pb::SetGpioRequest { levels: 0x10005 }).await.unwrap().into_inner();
        assert_eq!(l.levels & 0x3000F, 0x10005, "{l:?}");
        let l = p.get_gpio(pb::GetGpioRequest {}).await.unwrap().into_inner();
        assert_eq!(l.levels & 0x3000F, 0x10005, "{l:?}");

        let a = p.read_adc(pb::ReadAdcRequest { differential: false }).await.unwrap().into_inner();
        assert!(a.value <= 4095);
        p.write_dac(pb::WriteDacRequest { value: 2048 }).await.unwrap();
        let q = p.qei(pb::QeiRequest { action: pb::QeiAction::Start as i32 }).await.unwrap().into_inner();
        let q2 = p.qei(pb::QeiRequest { action: pb::QeiAction::Read as i32 }).await.unwrap().into_inner();
        assert!(q2.count >= q.count);
        p.qei(pb::QeiRequest { action: pb::QeiAction::Stop as i32 }).await.unwrap();

        for (e, field) in [
            (
                p.configure_gpio(pb::ConfigureGpioRequest { lines: 1 << 20, mode: 2, pull: 0 }).await.unwrap_err(),
                "lines",
            ),
            (p.configure_gpio(pb::ConfigureGpioRequest { lines: 1, mode: 0, pull: 0 }).await.unwrap_err(), "mode"),
            (p.set_gpio(pb::SetGpioRequest { levels: 1 << 24 }).await.unwrap_err(), "levels"),
            (p.write_dac(pb::WriteDacRequest { value: 4096 }).await.unwrap_err(), "value"),
            (p.qei(pb::QeiRequest { action: 0 }).await.unwrap_err(), "action"),
        ] {
            assert_eq!(e.code(), Code::InvalidArgument, "{field}: {e:?}");
            assert!(e.message().contains(field), "{field}: {}", e.message());
        }
    });
}

/// A mode the drive does not take (homing on a CSP/CSV/CST drive) gets one
/// answer, whichever deadline ends the wait: the daemon's own 2 s or a
/// caller's shorter one. It names the mode the drive shows.
#[test]
fn a_mode_the_drive_does_not_show_is_one_answer_whatever_the_deadline() {
    run(async {
        let mut d = Daemon::with_config(&config());
        let ch = d.connect().await;
        // The process image is the daemon's own work after bring-up; a
        // loaded machine may take seconds over it, which no mode's answer
        // is about, so it is built before the deadlines are put to test.
        ProcessDataClient::new(ch).get_layout(pb::GetLayoutRequest {}).await.expect("the process image");
        for args in [&["cia402", "mode", "-a", "0", "hm"][..], &["--timeout", "1s", "cia402", "mode", "-a", "0", "hm"]]
        {
            let out = d.ctl(args);
            assert_ne!(out.code, 0, "{args:?}");
            assert!(
                out.stderr.contains("axis 0 shows mode 8 (0x6061), not 6, at the deadline"),
                "{args:?}: {}",
                out.stderr
            );
        }
        d.stop();
    });
}
