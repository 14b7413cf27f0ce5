//! What operators do from the dashboard (docs/web.md, "Who may do what"):
//! output writes, each under an output lease the browser's session takes
//! on the entry's slave (the lease table gRPC, Sparkplug and OPC UA write
//! through, so a slave has one writer at a time and a refusal names the
//! holder), kept alive while the session lives and released when it logs
//! out or ends; and the CiA 402 axes.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::Json;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use serde::Deserialize;
use serde_json::{Value, json};

use super::json_body::JsonBody;
use super::refusal::Refusal;
use super::shared::{Held, Web, WebLeases};
use super::values::{entry_value, typed};
use super::visitors::Visitor;
use crate::config::api::Role;
use crate::master::axes::{AxisCommand, AxisError, Cia402State};
use crate::master::entry_writes::{Staging, WriteError};
use crate::master::{Call, LeaseError, Master};

/// How long an axis command may take (the drive walks its states).
const AXIS_WITHIN: Duration = Duration::from_secs(5);

impl WebLeases {
    pub(super) fn new(master: Arc<Master>) -> Self {
        Self { master, held: Mutex::new(HashMap::new()) }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<(u64, u8), Held>> {
        self.held.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The visitor's lease on `slave` and its holder name, taken now if it
    /// has none.
    fn lease(&self, v: &Visitor, slave: u8) -> Result<(String, String), Refusal> {
        let (Some(session), Some(who)) = (v.session, v.holder()) else {
            return Err(Refusal::forbidden("writing outputs needs a login"));
        };
        let mut held = self.lock();
        if let Some(h) = held.get(&(session, slave)) {
            return Ok((h.lease.clone(), h.who.clone()));
        }
        let lease = self
            .master
            .acquire_lease(&[slave], None, &who)
            .map_err(|e| Refusal::new(StatusCode::CONFLICT, e.to_string()))?;
        held.insert((session, slave), Held { who: who.clone(), lease: lease.id.clone() });
        Ok((lease.id, who))
    }

    /// Forgets the visitor's lease on `slave` (it lapsed).
    fn forget(&self, session: u64, slave: u8) {
        self.lock().remove(&(session, slave));
    }

    /// Releases every lease of session `n` (it logged out).
    pub(crate) fn release_session(&self, n: u64) {
        self.lock().retain(|(session, _), h| {
            if *session == n {
                let _ = self.master.leases().release(&h.lease, &h.who, false);
                return false;
            }
            true
        });
    }
}

/// Keeps the leases of sessions with a page open alive and releases the
/// others', four times per lease time-to-live; runs while the dashboard
/// serves.
pub(super) async fn keep(web: Web) {
    let mut tick = tokio::time::interval(web.master.lease_ttl() / 4);
    loop {
        tick.tick().await;
        let ttl = web.master.lease_ttl();
        let mut held = web.control.lock();
        held.retain(|(session, _), h| {
            // Ended, logged out, or no page open for a lease time (the
            // browser was closed): the slave is free for others.
            if !web.visitors.is_open(*session) || !web.visitors.is_present(*session, ttl) {
                let _ = web.master.leases().release(&h.lease, &h.who, false);
                return false;
            }
            web.master.leases().keep_alive(&h.lease, &h.who).is_ok()
        });
    }
}

#[derive(Deserialize)]
pub(super) struct Written {
    value: Value,
}

pub(super) async fn write_output(
    State(web): State<Web>,
    v: Visitor,
    Path(name): Path<String>,
    JsonBody(body): JsonBody<Written>,
) -> Result<Json<Value>, Refusal> {
    v.needs(Role::Operator, "writing outputs")?;
    let image = match web.master.current_image() {
        Some(Ok(i)) => i,
        Some(Err(e)) => return Err(e.into()),
        None => return Err(Refusal::new(StatusCode::SERVICE_UNAVAILABLE, "the process image is being laid out")),
    };
    let Some(e) = image.get(&name) else {
        return Err(Refusal::not_found(format!("no entry {name:?} in the process image (see /api/entries)")));
    };
    if !e.output {
        return Err(Refusal::bad(format!("{name} is an input; only outputs are written")));
    }
    let value = typed(&body.value).map_err(|why| Refusal::bad(format!("{name}: {why}")))?;
    let bytes = value.encode(e.data_type, e.bit_length).map_err(|why| Refusal::bad(format!("{name}: {why}")))?;
    let session = v.session.unwrap_or_default();
    web.visitors.acted(session);
    for attempt in 0..2 {
        let (lease, who) = web.control.lease(&v, e.slave)?;
        let mut staging = Staging::new(&web.master, &image);
        staging.entry(e, &bytes).map_err(|w| Refusal::bad(w.to_string()))?;
        match staging.commit(web.master.leases(), &lease, &who) {
            Ok(()) => {
                tracing::debug!(who, entry = name, "output written from the dashboard");
                return Ok(Json(json!({ "written": name, "holder": who })));
            }
            // The lease lapsed (the daemon stalled past its time-to-live):
            // take a new one, once.
            Err(WriteError::Lease(LeaseError::NotALease(_))) if attempt == 0 => web.control.forget(session, e.slave),
            Err(WriteError::Lease(l @ LeaseError::Held { .. })) => {
                return Err(Refusal::new(StatusCode::CONFLICT, l.to_string()));
            }
            Err(w) => return Err(Refusal::new(StatusCode::CONFLICT, w.to_string())),
        }
    }
    Err(Refusal::new(StatusCode::CONFLICT, "the output lease could not be kept"))
}

/// An axis error mapped for the dashboard.
fn axis_refusal(e: AxisError) -> Refusal {
    let status = match &e {
        AxisError::NotConfigured { .. } => StatusCode::NOT_FOUND,
        AxisError::Engine(inner) => return inner.clone().into(),
        AxisError::Value { .. } => StatusCode::BAD_REQUEST,
        _ => StatusCode::CONFLICT,
    };
    Refusal::new(status, e.to_string())
}

pub(super) async fn axes(State(web): State<Web>, _v: Visitor) -> Result<Json<Value>, Refusal> {
    let m = &web.master;
    let infos = m.axes(Call::anonymous(Some(Duration::from_secs(2)))).await?;
    let layout = m.layout();
    let image = m.current_image().and_then(Result::ok);
    let frame = m.latest_inputs();
    let list: Vec<Value> = infos
        .iter()
        .map(|a| {
            let c = &a.config;
            let at = layout.slaves.get(usize::from(c.slave)).map(|s| s.tx_offset + usize::from(c.statusword_offset));
            let sw = at
                .zip(frame.as_ref())
                .and_then(|(at, f)| f.data.get(at..at + 2))
                .map(|b| u16::from_le_bytes([b[0], b[1]]));
            let state = sw.map(Cia402State::from_statusword);
            // Modes of operation display (0x6061 of the slave's axis), when
            // mapped.
            let mode_index = 0x6061 + 0x800 * u16::from(a.slave_axis);
            let mode = image.as_ref().zip(frame.as_ref()).and_then(|(i, f)| {
                let e = i.find(c.slave, mode_index, false)?;
                entry_value(e, Some(&f.data), &[]).as_i64()
            });
            json!({
                "axis": a.number,
                "slave": c.slave,
                "state": state.map(|s| s.to_string()),
                "statusword": sw,
                "mode_display": mode,
                "enabled": state == Some(Cia402State::OperationEnabled),
                "fault": matches!(state, Some(Cia402State::Fault | Cia402State::FaultReactionActive)),
            })
        })
        .collect();
    Ok(Json(json!({ "axes": list })))
}

/// An axis number from the path.
fn axis_number(text: &str) -> Result<u32, Refusal> {
    text.parse().map_err(|_| Refusal::bad(format!("axis {text:?}: give the number of an [[axis]] entry, 0 on")))
}

#[derive(Deserialize)]
pub(super) struct Commanded {
    command: String,
}

pub(super) async fn axis_command(
    State(web): State<Web>,
    v: Visitor,
    Path(n): Path<String>,
    JsonBody(body): JsonBody<Commanded>,
) -> Result<Json<Value>, Refusal> {
    v.needs(Role::Operator, "an axis command")?;
    let n = axis_number(&n)?;
    let command = match body.command.as_str() {
        "enable" => AxisCommand::Enable,
        "disable" => AxisCommand::Disable,
        "fault_reset" => AxisCommand::FaultReset,
        other => return Err(Refusal::bad(format!("command {other:?}: give enable, disable or fault_reset"))),
    };
    let axis = web.master.axis(n).map_err(axis_refusal)?;
    tracing::info!(who = %v.name, axis = n, ?command, "axis command from the dashboard");
    let call = Call::new(v.client(), None).or_within(AXIS_WITHIN);
    let s = web.master.axis_command(&axis, command, true, call).await.map_err(axis_refusal)?;
    Ok(Json(json!({ "axis": n, "state": s.state.to_string(), "statusword": s.statusword })))
}

#[derive(Deserialize)]
pub(super) struct ModeAsked {
    mode: i64,
}

pub(super) async fn axis_mode(
    State(web): State<Web>,
    v: Visitor,
    Path(n): Path<String>,
    JsonBody(body): JsonBody<ModeAsked>,
) -> Result<Json<Value>, Refusal> {
    v.needs(Role::Operator, "setting a mode of operation")?;
    let n = axis_number(&n)?;
    let mode = i8::try_from(body.mode).map_err(|_| Refusal::bad(format!("mode {}: give -128..=127", body.mode)))?;
    let axis = web.master.axis(n).map_err(axis_refusal)?;
    let (lease, who) = web.control.lease(&v, axis.config.slave)?;
    tracing::info!(axis = n, mode, who, "mode of operation set from the dashboard");
    let call = Call::new(v.client(), None).or_within(AXIS_WITHIN);
    let s = web.master.set_axis_mode(&axis, mode, &lease, &who, call).await.map_err(axis_refusal)?;
    Ok(Json(json!({ "axis": n, "state": s.state.to_string(), "mode_display": s.mode_display })))
}
