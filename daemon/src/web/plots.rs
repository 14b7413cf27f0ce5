//! Plots (docs/web.md, "Plots"): the newest input frame taken 50 times a
//! second while a plot is open, with the outputs as written then, shared
//! by every plot (one `Arc`: no copy per browser); each plot sends the
//! values of its variables in those samples every 200 ms, with each
//! frame's `seq` and receive time, the ones StreamInputs gives the same
//! frame.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::Json;
use axum::extract::{Query, State};
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use futures_util::Stream;
use serde::Deserialize;
use serde_json::{Value, json};
use tokio::sync::{Notify, broadcast};

use super::refusal::Refusal;
use super::shared::{Sample, Sampler, Web};
use super::values::entry_value;
use super::visitors::Visitor;
use crate::master::image::Image;
use crate::master::value::type_name;

/// How often a frame is taken for the plots.
const SAMPLE_EVERY: Duration = Duration::from_millis(20);
/// How often a plot is sent what it gathered.
const SEND_EVERY: Duration = Duration::from_millis(200);
/// Variables one plot may show.
const MAX_VARS: usize = 32;

impl Sampler {
    pub(super) fn new() -> Self {
        // A plot that falls 50 frames (a second) behind skips ahead.
        Self { frames: broadcast::Sender::new(50), wanted: Notify::new() }
    }
}

/// Takes the newest input frame every [`SAMPLE_EVERY`] while a plot is
/// open; runs while the dashboard serves.
pub(super) async fn sample(web: Web) {
    let mut tick = tokio::time::interval(SAMPLE_EVERY);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last = None;
    loop {
        if web.plots.frames.receiver_count() == 0 {
            web.plots.wanted.notified().await;
            tick.reset_immediately();
        }
        tick.tick().await;
        let Some(frame) = web.master.latest_inputs() else { continue };
        if last != Some(frame.seq) {
            last = Some(frame.seq);
            // The output image is small (bytes per slave) and copied only
            // while a plot is open.
            let outputs = web.master.output_shadow().clone();
            let _ = web.plots.frames.send(Arc::new(Sample { inputs: frame, outputs }));
        }
    }
}

/// The laid-out image, or why there is none.
fn image(web: &Web) -> Result<Arc<Image>, Refusal> {
    match web.master.current_image() {
        Some(Ok(i)) => Ok(i),
        Some(Err(e)) => Err(e.into()),
        None => Err(Refusal::new(axum::http::StatusCode::SERVICE_UNAVAILABLE, "the process image is being laid out")),
    }
}

pub(super) async fn entries(State(web): State<Web>, _v: Visitor) -> Result<Json<Value>, Refusal> {
    let image = image(&web)?;
    let frame = web.master.latest_inputs();
    let shadow = web.master.output_shadow().clone();
    let list: Vec<Value> = image
        .entries
        .iter()
        .map(|e| {
            json!({
                "name": e.name,
                "label": e.label,
                "slave": e.slave,
                "index": e.index,
                "subindex": e.subindex,
                "direction": if e.output { "output" } else { "input" },
                "data_type": type_name(e.data_type),
                "bit_length": e.bit_length,
                "value": entry_value(e, frame.as_deref().map(|f| f.data.as_slice()), &shadow),
            })
        })
        .collect();
    Ok(Json(json!({ "entries": list })))
}

#[derive(Deserialize)]
pub(super) struct Asked {
    #[serde(default)]
    vars: String,
}

/// What one plot gathered since it last sent.
#[derive(Default)]
struct Batch {
    time_ns: Vec<u64>,
    seq: Vec<u64>,
    values: Vec<Vec<Value>>,
}

impl Batch {
    fn take(&mut self, sample: &Sample, image: &Image, chosen: &[usize]) {
        let frame = &sample.inputs;
        self.time_ns.push(frame.time_ns);
        self.seq.push(frame.seq);
        self.values.resize(chosen.len(), Vec::new());
        for (column, &i) in self.values.iter_mut().zip(chosen) {
            column.push(entry_value(&image.entries[i], Some(&frame.data), &sample.outputs));
        }
    }

    fn json(&mut self, image: &Image, chosen: &[usize]) -> String {
        let values: serde_json::Map<String, Value> = chosen
            .iter()
            .zip(std::mem::take(&mut self.values))
            .map(|(&i, column)| (image.entries[i].name.clone(), Value::Array(column)))
            .collect();
        let out = json!({
            "time_ns": std::mem::take(&mut self.time_ns),
            "seq": std::mem::take(&mut self.seq),
            "values": values,
        });
        out.to_string()
    }
}

pub(super) async fn plot(
    State(web): State<Web>,
    _v: Visitor,
    Query(asked): Query<Asked>,
) -> Result<Sse<impl Stream<Item = Result<SseEvent, Infallible>>>, Refusal> {
    let image = image(&web)?;
    let names: Vec<&str> = asked.vars.split(',').map(str::trim).filter(|n| !n.is_empty()).collect();
    if names.is_empty() {
        return Err(Refusal::bad("no variable asked: give vars=NAME,NAME (the names /api/entries lists)"));
    }
    if names.len() > MAX_VARS {
        return Err(Refusal::bad(format!("{} variables asked; a plot shows {MAX_VARS} at most", names.len())));
    }
    let mut chosen = Vec::new();
    for n in &names {
        let i = image.entries.iter().position(|e| e.name == *n);
        match i {
            Some(i) => chosen.push(i),
            None => return Err(Refusal::not_found(format!("no entry {n:?} in the process image (see /api/entries)"))),
        }
    }
    let frames = web.plots.frames.subscribe();
    web.plots.wanted.notify_one();
    let mut send = tokio::time::interval(SEND_EVERY);
    send.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let state = (frames, send, image, chosen);
    let stream = futures_util::stream::unfold(state, |(mut frames, mut send, image, chosen)| async move {
        let mut batch = Batch::default();
        loop {
            tokio::select! {
                f = frames.recv() => match f {
                    Ok(f) => batch.take(&f, &image, &chosen),
                    Err(broadcast::error::RecvError::Lagged(_)) => {}
                    Err(broadcast::error::RecvError::Closed) => return None,
                },
                _ = send.tick() => if !batch.seq.is_empty() { break },
            }
        }
        let data = batch.json(&image, &chosen);
        Some((Ok(SseEvent::default().event("points").data(data)), (frames, send, image, chosen)))
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()))
}
