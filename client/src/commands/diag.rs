//! `emergencies`, `events`, `diag`: supervision (Diagnostics service).
//! `diag` answers "which slave broke the working counter" and exits 8 when
//! anything is wrong, so it doubles as a health check.

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;
use tokio_stream::StreamExt;

use crate::commands::master::CountersReport;
use crate::commands::slaves::al_status;
use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Fields, Out, Report, Table};
use crate::values::{Hex, spaced_hex, state_name};

/// A CoE emergency.
#[derive(Debug, Serialize, JsonSchema)]
pub struct EmergencyReport {
    pub slave: u32,
    /// Running number since the chip started.
    pub number: u32,
    /// CiA 301 emergency error code.
    pub error_code: u32,
    /// 0x1001 error register.
    pub error_register: u32,
    /// Manufacturer-specific bytes, hex.
    pub data: Hex,
    /// "chip" (the chip's history) or "mailbox" (read by the daemon's own
    /// mailbox exchanges with the slave; number 0).
    pub source: String,
}

impl From<pb::Emergency> for EmergencyReport {
    fn from(e: pb::Emergency) -> Self {
        Self {
            slave: e.slave,
            number: e.number,
            error_code: e.error_code,
            error_register: e.error_register,
            data: Hex::of(&e.data),
            source: e.source,
        }
    }
}

/// `ecmxfctl emergencies --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct EmergenciesReport {
    /// Newest first.
    pub emergencies: Vec<EmergencyReport>,
}

impl Report for EmergenciesReport {
    fn text(&self) -> String {
        if self.emergencies.is_empty() {
            return "no emergencies\n".into();
        }
        let mut t = Table::new(&["#", "SLAVE", "ERROR CODE", "REGISTER", "DATA"]);
        for e in &self.emergencies {
            let data = crate::values::parse_hex_bytes(&e.data.0).unwrap_or_default();
            t.row([
                if e.source == "mailbox" { "mbx".into() } else { e.number.to_string() },
                e.slave.to_string(),
                format!("{:#06x}", e.error_code),
                format!("{:#04x}", e.error_register),
                spaced_hex(&data),
            ]);
        }
        t.to_string()
    }
}

/// `emergencies`.
pub async fn emergencies(api: &Api, count: u32) -> Result<EmergenciesReport, CliError> {
    let r = api.diagnostics().get_emergencies(api.req(pb::GetEmergenciesRequest { count })).await;
    let r = r.map_err(CliError::rpc("read emergencies"))?.into_inner();
    Ok(EmergenciesReport { emergencies: r.emergencies.into_iter().map(Into::into).collect() })
}

/// One line of `ecmxfctl events --json` (NDJSON).
#[derive(Debug, Serialize, JsonSchema)]
pub struct EventLine {
    /// PHASE, STATE_CHANGE, LINK, DC_STABLE, CRC_ERRORS, WKC_ERRORS,
    /// FIFO_UNDERRUN, BRING_UP_FAILED, RECOVERING, LAST_WRITER_GONE, LOST,
    /// EMERGENCY, UNKNOWN.
    pub kind: String,
    /// ns since the daemon started.
    pub time_ns: u64,
    /// One-line summary.
    pub text: String,
    pub detail: String,
    /// STATE_CHANGE: states (else null).
    pub from_state: Option<String>,
    pub to_state: Option<String>,
    /// LINK, DC_STABLE.
    pub flag: bool,
    /// Error counts, events lost.
    pub counter: u64,
    /// EMERGENCY only.
    pub emergency: Option<EmergencyReport>,
}

fn kind_name(k: i32) -> &'static str {
    crate::values::enum_name(k, pb::EventKind::as_str_name, "EVENT_KIND_")
}

impl From<pb::Event> for EventLine {
    fn from(e: pb::Event) -> Self {
        let change = e.kind == pb::EventKind::StateChange as i32;
        Self {
            kind: kind_name(e.kind).into(),
            time_ns: e.time_ns,
            text: e.text,
            detail: e.detail,
            from_state: change.then(|| state_name(e.from_state).into()),
            to_state: change.then(|| state_name(e.to_state).into()),
            flag: e.flag,
            counter: e.counter,
            emergency: e.emergency.map(Into::into),
        }
    }
}

/// `events`: prints until the count, the duration, Ctrl-C, or the daemon ends.
pub async fn events(
    api: &Api,
    out: Out,
    count: Option<u64>,
    duration: Option<std::time::Duration>,
) -> Result<(), CliError> {
    let r = api.diagnostics().stream_events(api.stream(pb::StreamEventsRequest {})).await;
    let mut s = r.map_err(CliError::rpc("follow events"))?.into_inner();
    let deadline = duration.map(|d| tokio::time::Instant::now() + d);
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    let mut n = 0u64;
    while count.is_none_or(|c| n < c) {
        let ev = tokio::select! {
            e = s.next() => e,
            _ = &mut ctrl_c => return Ok(()),
            _ = async { match deadline { Some(d) => tokio::time::sleep_until(d).await, None => std::future::pending().await } } => return Ok(()),
        };
        match ev {
            Some(Ok(e)) => {
                let line = EventLine::from(e);
                out.line(&line, || format!("{:>12.6}  {:<16} {}", line.time_ns as f64 / 1e9, line.kind, line.text))?;
                n += 1;
            }
            Some(Err(st)) if CliError::is_stopping(&st) => {
                eprintln!("ecmxfctl: the daemon is stopping; no more events");
                return Ok(());
            }
            Some(Err(st)) => return Err(CliError::rpc("follow events")(st)),
            None => {
                return Err(CliError::rpc("follow events")(tonic::Status::unavailable("the daemon ended the stream")));
            }
        }
    }
    Ok(())
}

/// `ecmxfctl diag --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct DiagReport {
    /// No problem found (the exit code is 0; else 8).
    pub healthy: bool,
    /// What is wrong, one sentence each.
    pub problems: Vec<String>,
    /// Network state now.
    pub state: String,
    /// The state bring-up drives to.
    pub target_state: String,
    pub counters: CountersReport,
    pub slaves: Vec<SlaveDiagReport>,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct SlaveDiagReport {
    pub position: u32,
    pub name: String,
    pub state: String,
    pub al_status_code: u32,
    pub al_status_text: String,
    /// This slave is why the working counter is wrong (not in the target
    /// state, or an AL status code).
    pub suspect: bool,
}

impl Report for DiagReport {
    fn text(&self) -> String {
        let mut f = Fields::default();
        f.add("State", format!("{} (target {})", self.state, self.target_state));
        self.counters.add_to(&mut f);
        let mut t = Table::new(&["POS", "STATE", "AL STATUS", "NAME", ""]);
        for s in &self.slaves {
            t.row([
                s.position.to_string(),
                s.state.clone(),
                al_status(s.al_status_code, &s.al_status_text),
                s.name.clone(),
                if s.suspect { "<-- suspect" } else { "" }.to_owned(),
            ]);
        }
        let mut out = format!("{f}\n{t}\n");
        if self.healthy {
            out.push_str(
                "healthy: process data flowing, every slave in the target state, no AL status code, configuration matches\n",
            );
        } else {
            for p in &self.problems {
                out.push_str(&format!("PROBLEM: {p}\n"));
            }
        }
        out
    }
}

/// `diag`.
pub async fn diag(api: &Api) -> Result<DiagReport, CliError> {
    // Counters come with the status and per-slave state with the slave list:
    // Diagnostics.GetCounters would read every slave from the chip a second time.
    let info = api.master().get_info(api.req(pb::GetInfoRequest {})).await.map_err(CliError::rpc("master info"))?;
    let target = info.into_inner().target_state;
    let status = api.master().get_status(api.req(pb::GetStatusRequest {})).await;
    let status = status.map_err(CliError::rpc("master status"))?.into_inner();
    let mut problems = Vec::new();
    let running = status.phase == pb::EnginePhase::Running as i32;
    // While the engine brings the network up or recovers, the slaves cannot
    // be read: that is the diagnosis, not a failure of diag.
    let list = match api.slaves().list_slaves(api.req(pb::ListSlavesRequest {})).await {
        Ok(l) => l.into_inner(),
        Err(e) if e.code() == tonic::Code::Unavailable => {
            if running {
                // It stopped running between the two calls.
                problems.push(format!("the engine stopped serving the slaves: {}", e.message()));
            }
            pb::ListSlavesResponse::default()
        }
        Err(e) => return Err(CliError::rpc("list slaves")(e)),
    };
    if !running {
        let why = if status.last_error.is_empty() { String::new() } else { format!(" ({})", status.last_error) };
        problems.push(format!("the engine is {}{why}", crate::values::phase_name(status.phase)));
    } else if (status.flow_limit_us > 0 && !status.process_data_flowing) || status.health.starts_with("degraded") {
        // The daemon's own verdict: OP on paper is not OP when no input
        // frame arrives, and a network missing a slave it had at the start
        // is degraded however well the rest runs.
        problems.push(status.health.clone());
    }
    let slaves: Vec<SlaveDiagReport> = list
        .slaves
        .iter()
        .map(|s| {
            let wrong_state = s.state != target;
            let suspect = wrong_state || s.al_status_code != 0;
            if wrong_state {
                problems.push(format!(
                    "slave {} ({}) is in {}, not {}",
                    s.position,
                    s.name,
                    state_name(s.state),
                    state_name(target)
                ));
            }
            if s.al_status_code != 0 {
                problems.push(format!(
                    "slave {} ({}) reports AL status {:#06x}: {}",
                    s.position, s.name, s.al_status_code, s.al_status_text
                ));
            }
            SlaveDiagReport {
                position: s.position,
                name: s.name.clone(),
                state: state_name(s.state).into(),
                al_status_code: s.al_status_code,
                al_status_text: s.al_status_text.clone(),
                suspect,
            }
        })
        .collect();
    for s in list.slaves.iter().filter(|s| !s.mismatch.is_empty()) {
        problems.push(format!("slave {} is not what the configuration expects: {}", s.position, s.mismatch));
    }
    for m in &list.missing {
        problems.push(format!("configured slave {m} is missing"));
    }
    Ok(DiagReport {
        healthy: problems.is_empty(),
        problems,
        state: state_name(status.ecat_state).into(),
        target_state: state_name(target).into(),
        counters: status.counters.into(),
        slaves,
    })
}
