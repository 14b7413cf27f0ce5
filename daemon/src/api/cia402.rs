//! `Cia402` service: the configured `[[axis]]` entries, driven through the
//! chip's CiA 402 helper (v049 commands 26-30, 74), which walks the drive
//! state machine in the process image by itself.

use std::sync::Arc;
use std::time::{Duration, Instant};

use ecmxf_proto::v1 as pb;
use ecmxf_proto::v1::cia402_server::Cia402 as Cia402Api;
use ecmxf_wire::payload::cia402::{Cia402Control, Cia402CtlSet, Cia402State, Cia402StateSet};
use tonic::{Request, Response, Status};

use super::auth::Role;
use super::bounded;
use super::convert::decode_value;
use super::image::entry_value;
use super::status::{bad_argument, to_status};
use super::{Context, wait_budget};
use crate::config::AxisConfig;
use crate::master::EngineError;
use crate::master::Master;
use crate::master::image::Image;
use crate::master::objects::axis_index;
use crate::master::transactions::Immediate;

/// The `Cia402` service.
#[derive(Debug, Clone)]
pub struct Cia402Service(pub Arc<Context>);

fn state_pb(s: Cia402State) -> pb::DriveState {
    match s {
        Cia402State::NotReadyToSwitchOn => pb::DriveState::NotReadyToSwitchOn,
        Cia402State::SwitchOnDisabled => pb::DriveState::SwitchOnDisabled,
        Cia402State::ReadyToSwitchOn => pb::DriveState::ReadyToSwitchOn,
        Cia402State::SwitchedOn => pb::DriveState::SwitchedOn,
        Cia402State::OperationEnabled => pb::DriveState::OperationEnabled,
        Cia402State::QuickStopActive => pb::DriveState::QuickStopActive,
        Cia402State::FaultReactionActive => pb::DriveState::FaultReactionActive,
        Cia402State::Fault => pb::DriveState::Fault,
        Cia402State::Other(_) => pb::DriveState::Unspecified,
    }
}

/// The axis' number within its slave (objects at 0x6000 + 0x800 n), from
/// the object mapped at its statusword offset; 0 when unknown.
fn slave_axis(image: &Image, master: &Master, a: &AxisConfig) -> u8 {
    let Some(s) = master.layout().slaves.get(usize::from(a.slave)).cloned() else { return 0 };
    let bit = ((s.tx_offset + usize::from(a.statusword_offset)) * 8) as u32;
    image
        .entries
        .iter()
        .find(|e| {
            !e.output && e.bit_offset == bit && (0x6041..0xA000).contains(&e.index) && (e.index - 0x6041) % 0x800 == 0
        })
        .map_or(0, |e| ((e.index - 0x6041) / 0x800) as u8)
}

impl Cia402Service {
    /// Writes CiA 402 object `base` (axis 0's index) of the axis: into the
    /// process image when mapped (under `lease_id`), else by SDO, which a
    /// mapped object would have overwritten. True when through the image.
    async fn write_object(
        &self,
        a: &AxisConfig,
        base: u16,
        value: i64,
        lease_id: &str,
        t: Option<Duration>,
    ) -> Result<bool, Status> {
        let image = self.0.master.image().await.map_err(to_status)?;
        let k = slave_axis(&image, &self.0.master, a);
        let index = axis_index(base, k);
        let v = pb::Value { kind: Some(pb::value::Kind::Integer(value)) };
        if let Some(e) = image.find(a.slave, index, true) {
            let write =
                pb::OutputWrite { target: Some(pb::output_write::Target::Entry(e.name.clone())), value: Some(v) };
            super::pdo::apply_writes(&self.0, &image, lease_id, &[write])?;
            return Ok(true);
        }
        let ty = crate::master::objects::lookup(index, 0)
            .map_or(pb::DataType::Integer32, |(o, _)| super::convert::pb_type(o.data_type));
        let bytes = super::convert::encode_value(ty, &v)?;
        self.0.master.sdo_write(a.slave, index, 0, false, bytes, t).await.map_err(to_status)?;
        Ok(false)
    }

    fn axis(&self, n: u32) -> Result<(u8, AxisConfig), Status> {
        let axes = self.0.master.config().axes;
        match axes.get(n as usize) {
            Some(a) => Ok((n as u8, a.clone())),
            None => Err(bad_argument("axis", format!("axis {n} is not configured ({} [[axis]] entries)", axes.len()))),
        }
    }

    /// One fault reset through the helper (402_CTL_SET with bit3; the
    /// chip raises controlword bit7 once and clears the request itself).
    async fn fault_reset(&self, axis: u8, a: &AxisConfig, t: Option<Duration>) -> Result<(), Status> {
        let mut control = Cia402Control::ENABLE | Cia402Control::FAULT_RESET;
        control.set(Cia402Control::AUTO_FAULT_RESET, a.auto_fault_reset);
        let axis_count = self.0.master.config().axes.len() as u8;
        let set = Cia402CtlSet { axis, control, axis_count, slave: a.slave };
        self.0.master.immediate(Immediate::Cia402CtlSet(set), t).await.map_err(to_status)?;
        Ok(())
    }

    async fn drive_state(&self, axis: u8, t: Option<Duration>) -> Result<Cia402State, Status> {
        let (v, _) = self.0.master.immediate(Immediate::Cia402StateGet(axis), t).await.map_err(to_status)?;
        Ok(Cia402State::from_u8(v))
    }

    /// A CiA 402 value: from the newest input frame when mapped, else by SDO.
    async fn actual(
        &self,
        image: &Image,
        a: &AxisConfig,
        k: u8,
        base: u16,
        t: Option<Duration>,
    ) -> Result<i64, Status> {
        let index = axis_index(base, k);
        let value = match (image.find(a.slave, index, false), self.0.master.latest_inputs()) {
            (Some(e), Some(frame)) => entry_value(e, &frame.data),
            _ => {
                let raw = match self.0.master.sdo_read(a.slave, index, 0, false, t).await {
                    Ok(raw) => raw,
                    // Not every drive has every object (a CST drive has no
                    // target position...): report 0, not an error.
                    Err(EngineError::SdoAbort { .. }) => return Ok(0),
                    Err(e) => return Err(to_status(e)),
                };
                let ty = crate::master::objects::lookup(index, 0)
                    .map_or(pb::DataType::Integer32, |(k, _)| super::convert::pb_type(k.data_type));
                decode_value(ty, &raw).ok().flatten().unwrap_or_default()
            }
        };
        Ok(match value.kind {
            Some(pb::value::Kind::Integer(i)) => i,
            Some(pb::value::Kind::Unsigned(u)) => u as i64,
            Some(pb::value::Kind::Boolean(b)) => b.into(),
            _ => 0,
        })
    }

    async fn status(&self, axis: u8, a: &AxisConfig, t: Option<Duration>) -> Result<pb::AxisStatus, Status> {
        let image = self.0.master.image().await.map_err(to_status)?;
        let k = slave_axis(&image, &self.0.master, a);
        let state = self.drive_state(axis, t).await?;
        let (_, sw) = self.0.master.immediate(Immediate::Cia402Statusword(axis), t).await.map_err(to_status)?;
        Ok(pb::AxisStatus {
            axis: axis.into(),
            state: state_pb(state) as i32,
            statusword: u16::from_le_bytes([sw.first().copied().unwrap_or(0), sw.get(1).copied().unwrap_or(0)]).into(),
            mode_display: self.actual(&image, a, k, 0x6061, t).await? as i32,
            position_actual: self.actual(&image, a, k, 0x6064, t).await?,
            velocity_actual: self.actual(&image, a, k, 0x606C, t).await?,
            torque_actual: self.actual(&image, a, k, 0x6077, t).await?,
            error_code: self.actual(&image, a, k, 0x603F, t).await? as u32,
        })
    }
}

#[tonic::async_trait]
impl Cia402Api for Cia402Service {
    async fn list_axes(&self, request: Request<pb::ListAxesRequest>) -> Result<Response<pb::ListAxesResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let image = bounded(&caller, self.0.master.image()).await?;
        let axes = self
            .0
            .master
            .config()
            .axes
            .iter()
            .enumerate()
            .map(|(n, a)| pb::Axis {
                axis: n as u32,
                slave: a.slave.into(),
                slave_axis: slave_axis(&image, &self.0.master, a).into(),
                controlword_offset: a.controlword_offset.into(),
                statusword_offset: a.statusword_offset.into(),
                auto_fault_reset: a.auto_fault_reset,
            })
            .collect();
        Ok(Response::new(pb::ListAxesResponse { axes }))
    }

    async fn get_axis(&self, request: Request<pb::GetAxisRequest>) -> Result<Response<pb::AxisStatus>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let (axis, a) = self.axis(request.get_ref().axis)?;
        let t = caller.deadline;
        Ok(Response::new(bounded(&caller, self.status(axis, &a, t)).await?))
    }

    async fn command(&self, request: Request<pb::AxisCommandRequest>) -> Result<Response<pb::AxisStatus>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let r = request.get_ref();
        let (axis, a) = self.axis(r.axis)?;
        let command = pb::AxisCommand::try_from(r.command).unwrap_or(pb::AxisCommand::Unspecified);
        let target = match pb::AxisCommand::try_from(r.command) {
            Ok(pb::AxisCommand::Enable) => Cia402State::OperationEnabled,
            Ok(pb::AxisCommand::Disable | pb::AxisCommand::FaultReset) => Cia402State::SwitchOnDisabled,
            Ok(pb::AxisCommand::Shutdown) => Cia402State::ReadyToSwitchOn,
            Ok(pb::AxisCommand::QuickStop) => Cia402State::QuickStopActive,
            _ => return Err(bad_argument("command", format!("{} is not an AxisCommand", r.command))),
        };
        let budget = wait_budget(&request, r.timeout_ms, Duration::from_secs(5));
        let wait = r.wait;
        tracing::info!(who = %caller.who, axis, ?target, "axis command");
        let status = bounded(&caller, async {
            let end = Instant::now() + budget;
            let m = &self.0.master;
            // Walking the FSA for the caller: from FAULT, enabling starts
            // with a fault reset, as FAULT_RESET itself does.
            let faulted = matches!(self.drive_state(axis, Some(budget)).await?, Cia402State::Fault);
            if command == pb::AxisCommand::FaultReset || (command == pb::AxisCommand::Enable && faulted) {
                self.fault_reset(axis, &a, Some(budget)).await?;
            }
            m.immediate(Immediate::Cia402StateSet(Cia402StateSet { axis, state: target }), Some(budget))
                .await
                .map_err(to_status)?;
            if wait {
                loop {
                    let now = self.drive_state(axis, Some(budget)).await?;
                    // A quick stop may end in SWITCH ON DISABLED (option code).
                    let arrived = now == target
                        || (target == Cia402State::QuickStopActive && now == Cia402State::SwitchOnDisabled);
                    if arrived {
                        break;
                    }
                    if now == Cia402State::Fault && Instant::now() + budget / 2 >= end {
                        let image = m.image().await.map_err(to_status)?;
                        let k = slave_axis(&image, m, &a);
                        let code = self.actual(&image, &a, k, 0x603F, Some(budget)).await?;
                        return Err(Status::failed_precondition(format!(
                            "axis {axis} stays in FAULT (error code {code:#06x}): its cause is still there"
                        )));
                    }
                    if Instant::now() >= end {
                        return Err(Status::deadline_exceeded(format!(
                            "axis {axis} is {now}, not {target}, at the deadline"
                        )));
                    }
                    self.0.master.next_inputs(end.saturating_duration_since(Instant::now())).await;
                }
            }
            self.status(axis, &a, Some(budget)).await
        })
        .await?;
        Ok(Response::new(status))
    }

    async fn set_mode(&self, request: Request<pb::SetModeRequest>) -> Result<Response<pb::AxisStatus>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let r = request.get_ref();
        let (axis, a) = self.axis(r.axis)?;
        let mode =
            i8::try_from(r.mode).map_err(|_| bad_argument("mode", format!("{} is outside -128..=127", r.mode)))?;
        let t = caller.deadline;
        let status = bounded(&caller, async {
            self.write_object(&a, 0x6060, mode.into(), &r.lease_id, t).await?;
            // The drive takes the mode over within a few cycles.
            let end = Instant::now() + t.unwrap_or(Duration::from_secs(2));
            loop {
                let s = self.status(axis, &a, t).await?;
                if s.mode_display == i32::from(mode) {
                    return Ok::<_, Status>(s);
                }
                if Instant::now() >= end {
                    return Err(Status::deadline_exceeded(format!(
                        "axis {axis} shows mode {} (0x6061), not {mode}, at the deadline",
                        s.mode_display
                    )));
                }
                self.0.master.next_inputs(end.saturating_duration_since(Instant::now())).await;
            }
        })
        .await?;
        Ok(Response::new(status))
    }

    async fn set_target(
        &self,
        request: Request<pb::SetTargetRequest>,
    ) -> Result<Response<pb::SetTargetResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let r = request.get_ref();
        let (_, a) = self.axis(r.axis)?;
        let (base, value) = match r.target {
            Some(pb::set_target_request::Target::Position(v)) => (0x607A, v),
            Some(pb::set_target_request::Target::Velocity(v)) => (0x60FF, v),
            Some(pb::set_target_request::Target::Torque(v)) => (0x6071, v),
            None => return Err(bad_argument("target", "give a position, velocity or torque")),
        };
        let t = caller.deadline;
        let via_process_image = bounded(&caller, self.write_object(&a, base, value, &r.lease_id, t)).await?;
        Ok(Response::new(pb::SetTargetResponse { via_process_image }))
    }
}
