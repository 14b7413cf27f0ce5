//! `Cia402` service: the configured `[[axis]]` entries, driven by the
//! master ([`crate::master::axes`]) through the chip's CiA 402 helper. This
//! checks the request, calls the master and maps its answers.

use std::sync::Arc;

use ecmxf_proto::v1 as pb;
use ecmxf_proto::v1::cia402_server::Cia402 as Cia402Api;
use tonic::{Request, Response, Status};

use super::auth::Role;
use super::status::{bad_argument, to_status};
use super::{Context, bounded, leases, wait_budget};
use crate::master::axes::{AxisCommand, AxisError, AxisInfo, AxisStatus, AxisTarget, COMMAND_WAIT, Cia402State};
use crate::master::entry_writes::WriteError;

/// The `Cia402` service.
#[derive(Debug, Clone)]
pub(crate) struct Cia402Service(pub Arc<Context>);

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

fn status_pb(s: AxisStatus) -> pb::AxisStatus {
    pb::AxisStatus {
        axis: s.axis.into(),
        state: state_pb(s.state) as i32,
        statusword: s.statusword.into(),
        mode_display: s.mode_display,
        position_actual: s.position_actual,
        velocity_actual: s.velocity_actual,
        torque_actual: s.torque_actual,
        error_code: s.error_code,
    }
}

fn axis_pb(a: AxisInfo) -> pb::Axis {
    pb::Axis {
        axis: a.number,
        slave: a.config.slave.into(),
        slave_axis: a.slave_axis.into(),
        controlword_offset: a.config.controlword_offset.into(),
        statusword_offset: a.config.statusword_offset.into(),
        auto_fault_reset: a.config.auto_fault_reset,
    }
}

/// The code of a failed axis operation: the caller's field INVALID_ARGUMENT;
/// a refused write as WriteOutputs answers it (the lease's own codes, a
/// span another stream or the helper owns FAILED_PRECONDITION); a drive
/// that stays in FAULT FAILED_PRECONDITION; one that does not arrive in
/// time DEADLINE_EXCEEDED.
impl From<AxisError> for Status {
    fn from(e: AxisError) -> Self {
        match e {
            AxisError::Engine(e) => to_status(e),
            AxisError::Write(WriteError::Lease(e)) => leases::status(e),
            AxisError::NotArrived { .. } | AxisError::ModeNotShown { .. } => Status::deadline_exceeded(e.to_string()),
            e => match e.field() {
                Some(field) => bad_argument(field, e.to_string()),
                None => Status::failed_precondition(e.to_string()),
            },
        }
    }
}

/// [`bounded`], except that a drive that did not arrive or show its mode
/// says so whichever deadline ended the wait (the command's own or the
/// caller's): one answer for one situation, naming what the drive shows.
async fn bounded_wait<T>(
    caller: &crate::api::auth::Caller,
    work: impl std::future::Future<Output = Result<T, AxisError>>,
) -> Result<T, Status> {
    match work.await {
        Err(e @ (AxisError::NotArrived { .. } | AxisError::ModeNotShown { .. })) => Err(e.into()),
        other => bounded(caller, async { other }).await,
    }
}

#[tonic::async_trait]
impl Cia402Api for Cia402Service {
    async fn list_axes(&self, request: Request<pb::ListAxesRequest>) -> Result<Response<pb::ListAxesResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let axes = bounded(&caller, self.0.master.axes(caller.call)).await?;
        Ok(Response::new(pb::ListAxesResponse { axes: axes.into_iter().map(axis_pb).collect() }))
    }

    async fn get_axis(&self, request: Request<pb::GetAxisRequest>) -> Result<Response<pb::AxisStatus>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let axis = self.0.master.axis(request.get_ref().axis)?;
        Ok(Response::new(status_pb(bounded(&caller, self.0.master.axis_status(&axis, caller.call)).await?)))
    }

    async fn command(&self, request: Request<pb::AxisCommandRequest>) -> Result<Response<pb::AxisStatus>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let r = request.get_ref();
        let axis = self.0.master.axis(r.axis)?;
        let command = match pb::AxisCommand::try_from(r.command) {
            Ok(pb::AxisCommand::Enable) => AxisCommand::Enable,
            Ok(pb::AxisCommand::Disable) => AxisCommand::Disable,
            Ok(pb::AxisCommand::FaultReset) => AxisCommand::FaultReset,
            Ok(pb::AxisCommand::Shutdown) => AxisCommand::Shutdown,
            Ok(pb::AxisCommand::QuickStop) => AxisCommand::QuickStop,
            _ => return Err(bad_argument("command", format!("{} is not an AxisCommand", r.command))),
        };
        let call = wait_budget(&caller, r.timeout_ms, COMMAND_WAIT);
        tracing::info!(who = %caller.who, axis = axis.number, target = ?command.target(), "axis command");
        let status = bounded_wait(&caller, self.0.master.axis_command(&axis, command, r.wait, call)).await?;
        Ok(Response::new(status_pb(status)))
    }

    async fn set_mode(&self, request: Request<pb::SetModeRequest>) -> Result<Response<pb::AxisStatus>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let r = request.get_ref();
        let axis = self.0.master.axis(r.axis)?;
        let mode =
            i8::try_from(r.mode).map_err(|_| bad_argument("mode", format!("{} is outside -128..=127", r.mode)))?;
        let status =
            bounded_wait(&caller, self.0.master.set_axis_mode(&axis, mode, &r.lease_id, &caller.who, caller.call))
                .await?;
        Ok(Response::new(status_pb(status)))
    }

    async fn set_target(
        &self,
        request: Request<pb::SetTargetRequest>,
    ) -> Result<Response<pb::SetTargetResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let r = request.get_ref();
        let axis = self.0.master.axis(r.axis)?;
        let target = match r.target {
            Some(pb::set_target_request::Target::Position(v)) => AxisTarget::Position(v),
            Some(pb::set_target_request::Target::Velocity(v)) => AxisTarget::Velocity(v),
            Some(pb::set_target_request::Target::Torque(v)) => AxisTarget::Torque(v),
            None => return Err(bad_argument("target", "give a position, velocity or torque")),
        };
        let via_process_image =
            bounded(&caller, self.0.master.set_axis_target(&axis, target, &r.lease_id, &caller.who, caller.call))
                .await?;
        Ok(Response::new(pb::SetTargetResponse { via_process_image }))
    }
}
