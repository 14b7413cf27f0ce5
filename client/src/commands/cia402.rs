//! `cia402 status|enable|disable|quickstop|reset|mode|move`: CiA 402 drives
//! through the chip's drive-state helper (Cia402 service). Targets written
//! into the process image need the output lease of the axis' slave: `move`
//! takes one for the write and gives it back (the daemon's
//! `outputs.on_last_writer_gone` then decides what the outputs do).

use std::time::{Duration, Instant};

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::cli::{AxisCommandArgs, Cia402Command, Move};
use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Out, Report, Table};
use crate::values::drive_state_name;

/// `ecmxfctl cia402 status --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct AxesReport {
    pub axes: Vec<AxisReport>,
}

/// One axis (also the --json output of enable, disable, quickstop, reset and mode).
#[derive(Debug, Serialize, JsonSchema)]
pub struct AxisReport {
    pub axis: u32,
    pub slave: u32,
    /// Axis within its slave.
    pub slave_axis: u32,
    /// NOT_READY_TO_SWITCH_ON, SWITCH_ON_DISABLED, READY_TO_SWITCH_ON,
    /// SWITCHED_ON, OPERATION_ENABLED, QUICK_STOP_ACTIVE,
    /// FAULT_REACTION_ACTIVE, FAULT, UNKNOWN.
    pub state: String,
    pub statusword: u32,
    /// 0x6061, signed.
    pub mode_display: i32,
    pub position_actual: i64,
    pub velocity_actual: i64,
    pub torque_actual: i64,
    /// 0x603F (0: none).
    pub error_code: u32,
}

impl AxisReport {
    fn row(&self) -> Vec<String> {
        vec![
            self.axis.to_string(),
            format!("{}.{}", self.slave, self.slave_axis),
            self.state.clone(),
            format!("{:#06x}", self.statusword),
            mode_name(self.mode_display),
            self.position_actual.to_string(),
            self.velocity_actual.to_string(),
            self.torque_actual.to_string(),
            if self.error_code == 0 { "-".into() } else { format!("{:#06x}", self.error_code) },
        ]
    }
}

const HEADER: &[&str] = &["AXIS", "SLAVE", "STATE", "STATUSWORD", "MODE", "POSITION", "VELOCITY", "TORQUE", "ERROR"];

/// 0x6060/0x6061 names.
fn mode_name(m: i32) -> String {
    match m {
        0 => "none".into(),
        1 => "PP".into(),
        3 => "PV".into(),
        4 => "PT".into(),
        6 => "HM".into(),
        7 => "IP".into(),
        8 => "CSP".into(),
        9 => "CSV".into(),
        10 => "CST".into(),
        other => other.to_string(),
    }
}

impl Report for AxesReport {
    fn text(&self) -> String {
        let mut t = Table::new(HEADER);
        for a in &self.axes {
            t.row(a.row());
        }
        t.to_string()
    }
}

impl Report for AxisReport {
    fn text(&self) -> String {
        let mut t = Table::new(HEADER);
        t.row(self.row());
        t.to_string()
    }
}

/// `ecmxfctl cia402 move --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct MoveReport {
    pub axis: u32,
    /// "position", "velocity" or "torque".
    pub target: String,
    pub value: i64,
    /// Written into the process image (true) or by SDO (false).
    pub via_process_image: bool,
    /// With --wait-within: the actual position when it was reached.
    pub reached_position: Option<i64>,
}

impl Report for MoveReport {
    fn text(&self) -> String {
        let how = if self.via_process_image { "process image" } else { "SDO" };
        let mut s = format!("axis {}: target {} {} set ({how})", self.axis, self.target, self.value);
        if let Some(p) = self.reached_position {
            s.push_str(&format!("; reached, position actual {p}"));
        }
        s
    }
}

async fn axes(api: &Api) -> Result<Vec<pb::Axis>, CliError> {
    let r = api.cia402().list_axes(api.req(pb::ListAxesRequest {})).await.map_err(CliError::rpc("list axes"))?;
    Ok(r.into_inner().axes)
}

fn report(s: pb::AxisStatus, axes: &[pb::Axis]) -> AxisReport {
    let a = axes.iter().find(|a| a.axis == s.axis).cloned().unwrap_or_default();
    AxisReport {
        axis: s.axis,
        slave: a.slave,
        slave_axis: a.slave_axis,
        state: drive_state_name(s.state).into(),
        statusword: s.statusword,
        mode_display: s.mode_display,
        position_actual: s.position_actual,
        velocity_actual: s.velocity_actual,
        torque_actual: s.torque_actual,
        error_code: s.error_code,
    }
}

async fn axis_of(api: &Api, axis: u32) -> Result<(pb::Axis, Vec<pb::Axis>), CliError> {
    let all = axes(api).await?;
    let a = all.iter().find(|a| a.axis == axis).cloned().ok_or_else(|| {
        if all.is_empty() {
            CliError::Usage("no CiA 402 axes: the daemon's configuration has no [[axis]]".into())
        } else {
            CliError::Usage(format!("no axis {axis} (axes 0..={})", all.len() - 1))
        }
    })?;
    Ok((a, all))
}

async fn command(api: &Api, a: &AxisCommandArgs, c: pb::AxisCommand, verb: &str) -> Result<AxisReport, CliError> {
    let axis = a.axis.axis;
    let (_, all) = axis_of(api, axis).await?;
    let (timeout_ms, deadline) = api.wait_and_deadline();
    let req = pb::AxisCommandRequest { axis, command: c as i32, wait: !a.no_wait, timeout_ms };
    let r = api.cia402().command(api.req_for(req, deadline)).await;
    Ok(report(r.map_err(CliError::rpc(format!("{verb} axis {axis}")))?.into_inner(), &all))
}

/// Takes the lease of `slave`'s outputs for one call.
async fn with_lease<T, F: std::future::Future<Output = Result<T, CliError>>>(
    api: &Api,
    slave: u32,
    body: impl FnOnce(String) -> F,
) -> Result<T, CliError> {
    let req = pb::AcquireLeaseRequest { slaves: vec![slave], ttl_ms: 0 };
    let lease = api.pdo().acquire_lease(api.req(req)).await;
    let lease = lease.map_err(CliError::rpc(format!("take the output lease of slave {slave}")))?.into_inner();
    let r = body(lease.id.clone()).await;
    let _ = api.pdo().release_lease(api.req(pb::ReleaseLeaseRequest { lease_id: lease.id })).await;
    r
}

/// Runs a `cia402` subcommand.
pub async fn run(api: &Api, out: Out, cmd: &Cia402Command) -> Result<(), CliError> {
    use pb::AxisCommand as C;
    match cmd {
        Cia402Command::Status { axis } => {
            let all = axes(api).await?;
            let mut list = Vec::new();
            for a in all.iter().filter(|a| axis.is_none_or(|x| x == a.axis)) {
                let r = api.cia402().get_axis(api.req(pb::GetAxisRequest { axis: a.axis })).await;
                list.push(report(r.map_err(CliError::rpc(format!("read axis {}", a.axis)))?.into_inner(), &all));
            }
            if let (Some(x), true) = (axis, list.is_empty()) {
                return Err(CliError::Usage(format!("no axis {x} ({} configured)", all.len())));
            }
            out.report(&AxesReport { axes: list })?;
        }
        Cia402Command::Enable(a) => out.report(&command(api, a, C::Enable, "enable").await?)?,
        Cia402Command::Disable(a) => out.report(&command(api, a, C::Disable, "disable").await?)?,
        Cia402Command::Quickstop(a) => out.report(&command(api, a, C::QuickStop, "quick stop").await?)?,
        Cia402Command::Reset(a) => out.report(&command(api, a, C::FaultReset, "fault reset").await?)?,
        Cia402Command::Mode { axis, mode } => {
            let (a, all) = axis_of(api, axis.axis).await?;
            let s = with_lease(api, a.slave, |lease_id| async move {
                let req = pb::SetModeRequest { axis: a.axis, mode: mode.code(), lease_id };
                let r = api.cia402().set_mode(api.req(req)).await;
                Ok(r.map_err(CliError::rpc(format!("set mode of axis {}", a.axis)))?.into_inner())
            })
            .await?;
            out.report(&report(s, &all))?;
        }
        Cia402Command::Move(m) => out.report(&move_axis(api, m).await?)?,
    }
    Ok(())
}

async fn move_axis(api: &Api, m: &Move) -> Result<MoveReport, CliError> {
    use pb::set_target_request::Target;
    let (a, _) = axis_of(api, m.axis.axis).await?;
    let (target, name, value) = match (m.position, m.velocity, m.torque) {
        (Some(p), _, _) => (Target::Position(p), "position", p),
        (_, Some(v), _) => (Target::Velocity(v), "velocity", v),
        (_, _, Some(t)) => (Target::Torque(t), "torque", t),
        _ => return Err(CliError::Usage("move: give --position, --velocity or --torque".into())),
    };
    if m.wait_within.is_some() && name != "position" {
        return Err(CliError::Usage("--wait-within goes with --position".into()));
    }
    with_lease(api, a.slave, |lease_id| async move {
        let req = pb::SetTargetRequest { axis: a.axis, target: Some(target), lease_id: lease_id.clone() };
        let r = api.cia402().set_target(api.req(req)).await;
        let via = r.map_err(CliError::rpc(format!("set target of axis {}", a.axis)))?.into_inner().via_process_image;
        let mut reached = None;
        if let Some(window) = m.wait_within {
            // Hold the lease while the drive gets there.
            let start = Instant::now();
            loop {
                let keep = api.req(pb::KeepAliveRequest { lease_id: lease_id.clone() });
                api.pdo().keep_alive(keep).await.map_err(CliError::rpc("keep the output lease"))?;
                let s = api.cia402().get_axis(api.req(pb::GetAxisRequest { axis: a.axis })).await;
                let s = s.map_err(CliError::rpc(format!("read axis {}", a.axis)))?.into_inner();
                if s.position_actual.abs_diff(value) <= window {
                    reached = Some(s.position_actual);
                    break;
                }
                if start.elapsed() > api.timeout() {
                    return Err(CliError::rpc(format!("move axis {}", a.axis))(tonic::Status::deadline_exceeded(
                        format!("position actual {} not within {window} of {value}", s.position_actual),
                    )));
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        }
        Ok(MoveReport { axis: a.axis, target: name.into(), value, via_process_image: via, reached_position: reached })
    })
    .await
}
