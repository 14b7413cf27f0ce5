//! The overview (docs/web.md, "The overview") and the live feed: one
//! summary made every 250 ms while a browser watches, and at once after
//! an event that changes it (a phase, a state, an AL status), shared by
//! all of them (one JSON text, never one message per cycle or per
//! browser), and the daemon's events as they come.
//!
//! The summary is what `ecmxfctl diag` concludes, made from the engine's
//! status and the AL status events (no chip reads): the engine not
//! running, process data not flowing or the network degraded, a slave out
//! of the target state or with an AL status code, one that is not what the
//! configuration expects, a configured one missing.

use std::collections::{HashMap, VecDeque};
use std::convert::Infallible;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::Json;
use axum::extract::State;
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use futures_util::Stream;
use serde_json::{Value, json};
use tokio::sync::{Notify, broadcast, watch};

use super::refusal::Refusal;
use super::shared::{Feed, TrendPoint, Web};
use super::visitors::{Visitor, watching};
use crate::config::SlaveConfig;
use crate::master::axes::Cia402State;
use crate::master::{EcatState, Event, EventKind, Master, Phase, SlaveSummary, Snapshot, al_status_text};

/// How often the summary is sent while someone watches.
const EVERY: Duration = Duration::from_millis(250);
/// Seconds of chart figures kept (the overview's charts span 5 minutes).
pub(super) const TREND_KEPT: usize = 300;
/// Events kept for `/api/events`.
const KEPT_EVENTS: usize = 1000;

impl Feed {
    pub(super) fn new() -> Self {
        Self {
            overview: watch::Sender::new(Arc::from("{}")),
            events: broadcast::Sender::new(256),
            log: Mutex::new(VecDeque::new()),
            reported: Mutex::new(HashMap::new()),
            emergencies: Mutex::new(VecDeque::new()),
            wanted: Notify::new(),
            trend: Mutex::new(VecDeque::with_capacity(TREND_KEPT)),
        }
    }

    /// The figures now, kept for the charts.
    fn sample(&self, master: &Master) {
        let s = master.status();
        let point = TrendPoint {
            time_ns: master.now_ns(),
            exchanges: s.exchanges,
            fifo_alarms: s.fifo_alarms,
            rx_fifo: s.rx_fifo,
            tx_fifo: s.tx_fifo,
        };
        let mut trend = self.trend.lock().unwrap_or_else(|e| e.into_inner());
        if trend.len() == TREND_KEPT {
            trend.pop_front();
        }
        trend.push_back(point);
    }

    /// What slave `p` last reported, if it did since bring-up.
    pub(crate) fn reported(&self, p: u8) -> Option<(EcatState, u16)> {
        self.reported.lock().unwrap_or_else(|e| e.into_inner()).get(&p).copied()
    }

    /// The emergencies slave `p` sent since the daemon started (the last
    /// [`KEPT_EVENTS`] of all slaves'), oldest first.
    pub(crate) fn emergencies(&self, p: u8) -> Vec<Value> {
        let held = self.emergencies.lock().unwrap_or_else(|e| e.into_inner());
        held.iter().filter(|(s, _)| *s == p).map(|(_, v)| v.clone()).collect()
    }

    fn record(&self, e: &Event) {
        if let EventKind::Emergency(r) = &e.kind {
            let mut held = self.emergencies.lock().unwrap_or_else(|e| e.into_inner());
            if held.len() == KEPT_EVENTS {
                held.pop_front();
            }
            let v = json!({
                "time_ns": e.time_ns,
                "code": format!("{:#06x}", r.error_code),
                "register": format!("{:#04x}", r.error_register),
                "data": hex::encode(r.data),
                "text": e.kind.to_string(),
            });
            held.push_back((r.slave, v));
        }
        {
            let mut reported = self.reported.lock().unwrap_or_else(|e| e.into_inner());
            match &e.kind {
                EventKind::AlStatus { slave, state, code } => {
                    reported.insert(*slave, (*state, *code));
                }
                EventKind::Phase(Phase::Running) => reported.clear(),
                _ => {}
            }
        }
        let v = event_json(e);
        let _ = self.events.send(Arc::from(v.to_string()));
        let mut log = self.log.lock().unwrap_or_else(|e| e.into_inner());
        if log.len() == KEPT_EVENTS {
            log.pop_front();
        }
        log.push_back(v);
    }
}

/// An event as the page shows it.
fn event_json(e: &Event) -> Value {
    let slave = match &e.kind {
        EventKind::Emergency(r) => Some(r.slave),
        EventKind::AlStatus { slave, .. } => Some(*slave),
        _ => None,
    };
    // As the OPC UA events rate them (1 low .. 1000 high).
    let severity = match &e.kind {
        EventKind::Emergency(_) => 700,
        EventKind::AlStatus { code: 0, .. } => 300,
        EventKind::AlStatus { .. } => 700,
        k if k.is_fault() => 800,
        _ => 300,
    };
    json!({
        "time_ns": e.time_ns,
        "kind": e.kind.name(),
        "slave": slave,
        "text": e.kind.to_string(),
        "severity": severity,
    })
}

/// Records the daemon's events and makes the summary while browsers
/// watch; runs while the dashboard serves.
pub(super) async fn produce(web: Web) {
    let mut events = web.master.events();
    web.slaves.remember(&web.master);
    let mut tick = tokio::time::interval(EVERY);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    // The charts' figures, watched or not: a page opens with its past.
    let mut second = tokio::time::interval(Duration::from_secs(1));
    second.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        let watched = web.overview.overview.receiver_count() > 0;
        tokio::select! {
            e = events.recv() => match e {
                Ok(e) => {
                    // The slaves' names, while the network has them all.
                    if e.kind == EventKind::Phase(Phase::Running) {
                        web.slaves.remember(&web.master);
                    }
                    web.overview.record(&e);
                    // A lost slave or a state change shows without
                    // waiting for the tick (these events are rare: a
                    // phase, a state change, an AL status).
                    if watched && changes_summary(&e.kind) {
                        publish(&web);
                        tick.reset();
                    }
                }
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    web.overview.record(&Event { time_ns: web.master.now_ns(), kind: EventKind::Lost(n) });
                }
                Err(broadcast::error::RecvError::Closed) => return,
            },
            _ = tick.tick(), if watched => publish(&web),
            _ = second.tick() => web.overview.sample(&web.master),
            // Nobody watches: nothing is made until someone does.
            _ = web.overview.wanted.notified(), if !watched => tick.reset_immediately(),
        }
    }
}

/// Makes the summary now and hands it to every watching browser.
fn publish(web: &Web) {
    let text = summary(&web.master, &web.overview).to_string();
    web.overview.overview.send_replace(Arc::from(text));
}

/// Whether the summary says something else after this event.
fn changes_summary(kind: &EventKind) -> bool {
    matches!(
        kind,
        EventKind::Phase(_)
            | EventKind::EcatState { .. }
            | EventKind::AlStatus { .. }
            | EventKind::ProcessData { .. }
            | EventKind::BringUpFailed(_)
            | EventKind::Recovering(_)
            | EventKind::Recovered { .. }
    )
}

/// A phase as the API names it (`ENGINE_PHASE_` left out).
pub(super) fn phase_word(p: Phase) -> &'static str {
    match p {
        Phase::Starting => "STARTING",
        Phase::BringUp => "BRINGING_UP",
        Phase::Running => "RUNNING",
        Phase::Recovering => "RECOVERING",
        Phase::Stopping => "STOPPING",
        Phase::Stopped => "STOPPED",
    }
}

/// Positions the network had and has no more: those past the slaves it
/// runs now, up to the most it ran with (a break in the line loses every
/// slave behind it).
pub(super) fn lost(s: &Snapshot) -> Vec<u64> {
    if s.phase != Phase::Running {
        return Vec::new();
    }
    (s.slaves..s.slaves_seen).collect()
}

/// The summary now.
pub(super) fn summary(master: &Master, feed: &Feed) -> Value {
    let s = master.status();
    let v = master.verdict(&s);
    let config = master.config();
    let target = config.cycle.target();
    let layout = master.layout();
    let running = s.phase == Phase::Running;
    let mut problems = Vec::new();
    if !running {
        let why = master.last_error().map(|f| format!(" ({f})")).unwrap_or_default();
        problems.push(format!("the engine is {}{why}", phase_word(s.phase)));
    } else if (v.input_age.is_some() && !v.flowing()) || v.health.to_string().starts_with("degraded") {
        problems.push(v.health.to_string());
    }
    let present = if running { (s.slaves as usize).min(layout.slaves.len()) } else { 0 };
    let mut op = 0;
    for (p, slave) in layout.slaves.iter().enumerate().take(present) {
        let (state, code) = feed.reported(p as u8).unwrap_or((s.ecat_state, 0));
        op += usize::from(state == EcatState::Op);
        if state != target {
            problems.push(format!("slave {p} ({}) is in {state}, not {target}", slave.name));
        }
        if code != 0 {
            problems.push(format!(
                "slave {p} ({}) reports AL status {code:#06x}: {}",
                slave.name,
                al_status_text(code)
            ));
        }
    }
    for (p, (slave, expected)) in layout.slaves.iter().zip(&config.slaves).enumerate().take(present) {
        let differs = mismatch(slave, expected);
        if !differs.is_empty() {
            problems.push(format!("slave {p} is not what the configuration expects: {}", differs.join("; ")));
        }
    }
    if running {
        for m in layout.slaves.len()..config.slaves.len() {
            problems.push(format!("configured slave {m} is missing"));
        }
    }
    let (axes_total, axes_enabled) = axes_enabled(master);
    json!({
        "healthy": problems.is_empty(),
        "problems": problems,
        "phase": phase_word(s.phase),
        "state": s.ecat_state.to_string(),
        "target_state": target.to_string(),
        "health": v.health.to_string(),
        "flowing": v.flowing(),
        "slaves": {
            "op": op,
            "present": present,
            "expected": config.slaves.len().max(s.slaves_seen as usize).max(layout.slaves.len()),
            "lost": lost(&s),
        },
        "axes": { "enabled": axes_enabled, "total": axes_total },
        "cycle_us": config.cycle.sync0_us,
        // The link's share per exchange: the charts' link use.
        "packet_ns": layout.packet_ns,
        "rx_fifo": s.rx_fifo,
        "tx_fifo": s.tx_fifo,
        "counters": {
            "exchanges": s.exchanges,
            "input_frames": s.input_frames,
            "output_frames": s.output_frames,
            "crc_errors": s.crc_errors,
            "wkc_errors": s.wkc_errors,
            "fifo_alarms": s.fifo_alarms,
            "recoveries": s.recoveries,
            "transactions": s.transactions,
            "max_fifo_gap_us": s.max_fifo_gap_us,
        },
        "time_ns": master.now_ns(),
    })
}

/// What differs between a slave found and the one its `[[slave]]` entry
/// expects, as `ecmxfctl slaves` says it.
pub(super) fn mismatch(found: &SlaveSummary, expected: &SlaveConfig) -> Vec<String> {
    let mut out = Vec::new();
    for (what, want, got) in [
        ("vendor id", expected.vendor_id, found.vendor_id),
        ("product code", expected.product_code, found.product_code),
        ("revision", expected.revision, found.revision),
    ] {
        if let Some(w) = want.filter(|w| *w != got) {
            out.push(format!("{what} {got:#010x}, expected {w:#010x}"));
        }
    }
    out
}

/// (configured axes, those whose statusword in the newest input frame says
/// OPERATION ENABLED).
fn axes_enabled(master: &Master) -> (usize, usize) {
    let layout = master.layout();
    let frame = master.latest_inputs();
    master.with_axes(|axes| {
        let enabled = axes
            .iter()
            .filter(|a| {
                let at =
                    layout.slaves.get(usize::from(a.slave)).map(|s| s.tx_offset + usize::from(a.statusword_offset));
                let sw = at.zip(frame.as_ref()).and_then(|(at, f)| f.data.get(at..at + 2));
                sw.is_some_and(|b| {
                    Cia402State::from_statusword(u16::from_le_bytes([b[0], b[1]])) == Cia402State::OperationEnabled
                })
            })
            .count();
        (axes.len(), enabled)
    })
}

pub(super) async fn overview(State(web): State<Web>, _v: Visitor) -> Result<Json<Value>, Refusal> {
    Ok(Json(summary(&web.master, &web.overview)))
}

/// The charts' last [`TREND_KEPT`] seconds, oldest first.
pub(super) async fn trend(State(web): State<Web>, _v: Visitor) -> Json<Value> {
    let trend = web.overview.trend.lock().unwrap_or_else(|e| e.into_inner());
    Json(json!({ "trend": trend.iter().collect::<Vec<_>>() }))
}

pub(super) async fn events(State(web): State<Web>, _v: Visitor) -> Json<Value> {
    let log = web.overview.log.lock().unwrap_or_else(|e| e.into_inner());
    Json(json!({ "events": log.iter().collect::<Vec<_>>() }))
}

/// `overview` every 250 ms (the shared text), `event` as they come.
pub(super) async fn live(State(web): State<Web>, v: Visitor) -> Sse<impl Stream<Item = Result<SseEvent, Infallible>>> {
    let overviews = web.overview.overview.subscribe();
    let events = web.overview.events.subscribe();
    web.overview.wanted.notify_one();
    // A logged-in page is present while its feed is open: its session's
    // output leases are kept that long (`control::keep`).
    let present = v.session.map(|n| watching(&web, n));
    let state = (overviews, events, present);
    let stream = futures_util::stream::unfold(state, |(mut overviews, mut events, present)| async move {
        let next = tokio::select! {
            changed = overviews.changed() => match changed {
                Ok(()) => SseEvent::default().event("overview").data(&*overviews.borrow_and_update().clone()),
                Err(_) => return None,
            },
            e = events.recv() => match e {
                Ok(text) => SseEvent::default().event("event").data(&*text),
                // A browser that fell behind misses events, never the
                // summary; it reads them again from /api/events.
                Err(broadcast::error::RecvError::Lagged(_)) => SseEvent::default().comment("events skipped"),
                Err(broadcast::error::RecvError::Closed) => return None,
            },
        };
        Some((Ok(next), (overviews, events, present)))
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}
