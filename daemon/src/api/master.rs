//! `Master`, `Slaves` and `State` services: the chip and engine, the slaves
//! found, their EtherCAT states.

use std::sync::Arc;
use std::time::Instant;

use ecmxf_proto::v1 as pb;
use ecmxf_proto::v1::master_server::Master as MasterApi;
use ecmxf_proto::v1::slaves_server::Slaves as SlavesApi;
use ecmxf_proto::v1::state_server::State as StateApi;
use tonic::{Request, Response, Status};

use super::auth::Role;
use super::bounded;
use super::convert::{phase_to_pb, state_from_pb, state_to_pb};
use super::status::to_status;
use super::{Context, LogFilter, LogFilterRefusal, NETWORK_WAIT, wait_budget};
use crate::config::SlaveConfig;
use crate::master::diagnostics::{ErrorFlags, StatusFlags};
use crate::master::states::{SlaveSelector, selector};
use crate::master::{Call, EngineError, Master, al_status_text};

/// The longest log filter taken (a filter names a few modules; the text is
/// logged when set).
const MAX_LOG_FILTER: usize = 1024;

/// The `Master` service.
#[derive(Debug, Clone)]
pub(crate) struct MasterService(pub Arc<Context>);

/// The status message from the engine's snapshot.
pub(crate) fn status_pb(m: &Master) -> pb::MasterStatus {
    let s = m.status();
    let v = m.verdict(&s);
    let latency = m.output_latency();
    let age = v.input_age;
    pb::MasterStatus {
        phase: phase_to_pb(s.phase) as i32,
        ecat_state: state_to_pb(s.ecat_state) as i32,
        error_flags: s.error_byte.into(),
        status_flags: s.status_byte.into(),
        link_pin: s.error_flags().contains(ErrorFlags::LINK_PIN),
        dc_stable: s.status_flags().contains(StatusFlags::DC_STABLE),
        blocking_busy: s.status_flags().contains(StatusFlags::BLOCKING_BUSY),
        rx_fifo_level: s.rx_fifo.into(),
        tx_fifo_level: s.tx_fifo.into(),
        counters: Some(counters_pb(&s)),
        last_error: m.last_error().map(|f| f.to_string()).unwrap_or_default(),
        output_writers: m.output_writers() as u32,
        config_generation: s.config_generation,
        process_data_flowing: v.flowing(),
        input_age_us: age.map_or(0, |(a, _)| a.as_micros() as u64),
        flow_limit_us: age.map_or(0, |(_, l)| l.as_micros() as u64),
        health: v.health.to_string(),
        output_latency_budget_us: m.output_latency_budget_us().unwrap_or(0),
        output_latency_p50_us: latency.map_or(0, |l| l.p50_us.into()),
        output_latency_p99_us: latency.map_or(0, |l| l.p99_us.into()),
        sparkplug: sparkplug_pb(m),
    }
}

/// The counters from the engine's snapshot.
pub(crate) fn counters_pb(s: &crate::master::Snapshot) -> pb::Counters {
    pb::Counters {
        crc_errors: s.crc_errors,
        wkc_errors: s.wkc_errors,
        exchanges: s.exchanges,
        corrupt_answers: s.corrupt,
        not_ready_answers: s.not_ready,
        input_batches_lost: s.input_batches_lost,
        transactions: s.transactions,
        input_frames: s.input_frames,
        output_frames: s.output_frames,
        fifo_alarms: s.fifo_alarms,
        recoveries: s.recoveries,
        max_fifo_gap_us: s.max_fifo_gap_us,
        ring_overflows: s.ring_overflows,
        output_latency_misses: s.output_latency_misses,
        inputs_dropped_by_chip: s.inputs_dropped_by_chip,
    }
}

#[tonic::async_trait]
impl MasterApi for MasterService {
    async fn get_info(&self, request: Request<pb::GetInfoRequest>) -> Result<Response<pb::MasterInfo>, Status> {
        self.0.authorize(&request, Role::Observer)?;
        let m = &self.0.master;
        let layout = m.layout();
        let config = m.config();
        Ok(Response::new(pb::MasterInfo {
            firmware_version: layout.firmware.into(),
            data_size_bytes: config.chip.data_size as u32,
            packet_bytes: config.chip.data_size as u32 + 32,
            check_type: if config.chip.crc32 { pb::CheckType::Crc32 } else { pb::CheckType::Fixed } as i32,
            sync0_us: config.cycle.sync0_us,
            fifo_rx_depth: layout.fifo_rx_depth.into(),
            fifo_low: layout.fifo_low.into(),
            fifo_high: layout.fifo_high.into(),
            output_image_bytes: layout.rx_size as u32,
            input_image_bytes: layout.tx_size as u32,
            slave_count: layout.slaves.len() as u32,
            target_state: state_to_pb(config.cycle.target()) as i32,
            config_generation: m.status().config_generation,
            daemon_version: env!("CARGO_PKG_VERSION").into(),
            link_toml: config.link.to_toml(),
            dc_assign_activate: config.cycle.dc_assign_activate.into(),
            cycle_toml: config.cycle.to_toml(),
        }))
    }

    async fn get_status(&self, request: Request<pb::GetStatusRequest>) -> Result<Response<pb::MasterStatus>, Status> {
        self.0.authorize(&request, Role::Observer)?;
        Ok(Response::new(status_pb(&self.0.master)))
    }

    async fn reinit(&self, request: Request<pb::ReinitRequest>) -> Result<Response<pb::ReinitResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Admin)?;
        tracing::info!(who = %caller.who, "re-init requested");
        bounded(&caller, self.0.master.reinit(caller.call.or_within(NETWORK_WAIT))).await?;
        Ok(Response::new(pb::ReinitResponse { state: state_to_pb(self.0.master.layout().state) as i32 }))
    }

    async fn warm_reset(
        &self,
        request: Request<pb::WarmResetRequest>,
    ) -> Result<Response<pb::WarmResetResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Admin)?;
        tracing::info!(who = %caller.who, "warm reset requested");
        bounded(&caller, self.0.master.warm_reset(caller.call.or_within(NETWORK_WAIT))).await?;
        Ok(Response::new(pb::WarmResetResponse { state: state_to_pb(self.0.master.layout().state) as i32 }))
    }

    async fn get_log_filter(
        &self,
        request: Request<pb::GetLogFilterRequest>,
    ) -> Result<Response<pb::LogFilter>, Status> {
        self.0.authorize(&request, Role::Observer)?;
        let (filter, from_env) = self.log_filter()?.current();
        Ok(Response::new(pb::LogFilter { filter, from_env }))
    }

    async fn set_log_filter(
        &self,
        request: Request<pb::SetLogFilterRequest>,
    ) -> Result<Response<pb::LogFilter>, Status> {
        let caller = self.0.authorize(&request, Role::Admin)?;
        let control = self.log_filter()?;
        let filter = request.into_inner().filter;
        let bad = |reason: String| to_status(EngineError::BadArgument { field: "filter", reason });
        if filter.trim().is_empty() {
            return Err(bad("an empty log filter; give a level (\"debug\") or directives".into()));
        }
        if filter.len() > MAX_LOG_FILTER {
            return Err(bad(format!("{} bytes; a log filter is at most {MAX_LOG_FILTER}", filter.len())));
        }
        control.set(&filter).map_err(|why| match why {
            LogFilterRefusal::FromEnv => Status::failed_precondition(format!(
                "RUST_LOG={:?} is in force and wins over any other filter: unset it and restart the daemon",
                control.current().0
            )),
            LogFilterRefusal::Invalid(why) => bad(format!("{filter:?} is not a log filter: {why}")),
        })?;
        tracing::info!(who = %caller.who, filter, "log filter set (until the next reload or restart)");
        let (filter, from_env) = control.current();
        Ok(Response::new(pb::LogFilter { filter, from_env }))
    }
}

impl MasterService {
    /// The daemon's log filter, or why there is none to reach.
    fn log_filter(&self) -> Result<&Arc<dyn LogFilter>, Status> {
        self.0.log_filter.get().ok_or_else(|| {
            Status::failed_precondition("this daemon does not own its logging (it runs embedded in another program)")
        })
    }
}

/// The Sparkplug node's status, while one is configured.
fn sparkplug_pb(m: &Master) -> Option<pb::SparkplugStatus> {
    use std::sync::atomic::Ordering::Relaxed;
    let s = m.sparkplug_state();
    s.enabled.load(Relaxed).then(|| pb::SparkplugStatus {
        connected: s.connected.load(Relaxed) == 1,
        broker: s.broker(),
        bd_seq: s.next_bd_seq.load(Relaxed).saturating_sub(1),
        published: s.published.load(Relaxed),
        dropped: s.dropped.load(Relaxed),
        commands: s.commands.load(Relaxed),
        refused: s.refused.load(Relaxed),
        connects: s.connects.load(Relaxed),
    })
}

/// The `Slaves` service.
#[derive(Debug, Clone)]
pub(crate) struct SlavesService(pub Arc<Context>);

/// What differs between a found slave and its expectation ("" if nothing).
fn mismatch(found: &pb::Slave, expected: &SlaveConfig) -> String {
    let mut out = Vec::new();
    for (what, want, got) in [
        ("vendor id", expected.vendor_id, found.vendor_id),
        ("product code", expected.product_code, found.product_code),
        ("revision", expected.revision, found.revision),
    ] {
        if let Some(w) = want {
            if w != got {
                out.push(format!("{what} {got:#010x}, expected {w:#010x}"));
            }
        }
    }
    out.join("; ")
}

/// Every slave, read live from the chip, compared with the configuration.
pub(crate) async fn list_slaves(
    ctx: &Context,
    fresh_identity: bool,
    call: Call,
) -> Result<pb::ListSlavesResponse, Status> {
    let m = &ctx.master;
    let layout = m.layout();
    let config = m.config();
    // No bring-up has found the network yet: nothing is known of the
    // slaves, so none is "missing"; the reason is bring-up's (which names
    // the slave that refused).
    let phase = m.status().phase;
    if layout.slaves.is_empty() && phase != crate::master::Phase::Running {
        let why = crate::master::NotRunning::Phase { phase, last_error: m.last_error() };
        return Err(to_status(crate::master::EngineError::Unavailable(why)));
    }
    let readings = m.slave_readings(layout.slaves.len(), fresh_identity, call).await.map_err(to_status)?;
    let mut slaves = Vec::with_capacity(layout.slaves.len());
    for (i, (s, live)) in layout.slaves.iter().zip(readings).enumerate() {
        let ((vendor_id, product_code, revision), name) =
            live.identity.unwrap_or_else(|| ((s.vendor_id, s.product_code, s.revision), s.name.clone()));
        let mut slave = pb::Slave {
            position: i as u32,
            alias: live.setup.alias,
            configured_address: live.setup.configured_address,
            vendor_id,
            product_code,
            revision,
            name,
            state: state_to_pb(live.state) as i32,
            al_status_code: live.al_status.into(),
            al_status_text: al_status_text(live.al_status).into(),
            output_bytes: s.rx_bytes as u32,
            output_offset: s.rx_offset as u32,
            input_bytes: s.tx_bytes as u32,
            input_offset: s.tx_offset as u32,
            dc: Some(pb::DcInfo {
                supported: live.setup.dc_supported,
                active: live.setup.dc_active,
                cycle_ns: live.setup.dc_cycle_ns,
                shift_ns: live.setup.dc_shift_ns,
            }),
            expected: None,
            mismatch: String::new(),
        };
        if let Some(e) = config.slaves.get(i) {
            slave.mismatch = mismatch(&slave, e);
            slave.expected = Some(pb::ExpectedSlave {
                name: e.name.clone().unwrap_or_default(),
                vendor_id: e.vendor_id.unwrap_or(0),
                product_code: e.product_code.unwrap_or(0),
                revision: e.revision.unwrap_or(0),
                esi: e.esi.as_ref().map(|p| p.display().to_string()).unwrap_or_default(),
            });
        }
        slaves.push(slave);
    }
    let missing: Vec<u32> = (slaves.len()..config.slaves.len()).map(|i| i as u32).collect();
    let matches_config = missing.is_empty() && slaves.iter().all(|s| s.mismatch.is_empty());
    Ok(pb::ListSlavesResponse { slaves, missing, matches_config })
}

#[tonic::async_trait]
impl SlavesApi for SlavesService {
    async fn list_slaves(
        &self,
        request: Request<pb::ListSlavesRequest>,
    ) -> Result<Response<pb::ListSlavesResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        Ok(Response::new(bounded(&caller, list_slaves(&self.0, false, caller.call)).await?))
    }

    async fn scan(&self, request: Request<pb::ScanRequest>) -> Result<Response<pb::ScanResponse>, Status> {
        let needed = if request.get_ref().reinit { Role::Admin } else { Role::Observer };
        let caller = self.0.authorize(&request, needed)?;
        let ctx = &self.0;
        let reinit = request.get_ref().reinit;
        let r = bounded(&caller, async {
            if reinit {
                ctx.master.reinit(caller.call.until(Instant::now() + NETWORK_WAIT)).await?;
            }
            list_slaves(ctx, true, caller.call).await
        })
        .await?;
        Ok(Response::new(pb::ScanResponse { slaves: r.slaves, missing: r.missing, matches_config: r.matches_config }))
    }
}

/// The `State` service.
#[derive(Debug, Clone)]
pub(crate) struct StateService(pub Arc<Context>);

fn target(slave_field: Option<u32>, m: &Master) -> Result<SlaveSelector, Status> {
    let slave = slave_field.map(|v| super::convert::existing_slave(m, v, "slave")).transpose()?;
    Ok(selector(slave))
}

#[tonic::async_trait]
impl StateApi for StateService {
    async fn get_state(&self, request: Request<pb::GetStateRequest>) -> Result<Response<pb::GetStateResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let m = &self.0.master;
        let target = target(request.get_ref().slave, m)?;
        let report = bounded(&caller, m.state_report(target, caller.call)).await?;
        let slaves = report
            .slaves
            .iter()
            .map(|s| pb::SlaveState {
                position: s.position.into(),
                state: state_to_pb(s.state) as i32,
                al_status_code: s.al_status.into(),
                al_status_text: al_status_text(s.al_status).into(),
            })
            .collect();
        Ok(Response::new(pb::GetStateResponse {
            state: state_to_pb(report.state) as i32,
            slaves,
            al_status_code: report.al_status.map_or(0, u32::from),
            al_status_text: report.al_status.map(|al| al_status_text(al).into()).unwrap_or_default(),
        }))
    }

    async fn set_state(&self, request: Request<pb::SetStateRequest>) -> Result<Response<pb::SetStateResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let m = &self.0.master;
        let r = request.get_ref();
        let target = target(r.slave, m)?;
        let state = state_from_pb(r.state, "state")?;
        let call = wait_budget(&caller, r.timeout_ms, m.default_timeout);
        let wait = r.wait;
        tracing::info!(who = %caller.who, ?target, %state, "state requested");
        let reached = bounded(&caller, async {
            let end = call.deadline.unwrap_or_else(Instant::now);
            let mut changes = m.watch_status();
            m.set_state(target, state, call).await.map_err(to_status)?;
            loop {
                let now = m.get_state(target, call).await.map_err(to_status)?;
                if !wait || now == state {
                    return Ok::<_, Status>(now);
                }
                if Instant::now() >= end {
                    return Err(Status::deadline_exceeded(format!("{target} is {now}, not {state}, at the deadline")));
                }
                // Look again when the engine has news (its snapshot).
                let _ = tokio::time::timeout_at(end.into(), changes.changed()).await;
            }
        })
        .await?;
        Ok(Response::new(pb::SetStateResponse { state: state_to_pb(reached) as i32 }))
    }
}
