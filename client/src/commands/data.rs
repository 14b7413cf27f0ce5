//! `data` and `watch`: process data by entry name. Inputs come from the
//! input stream (ProcessData.StreamInputs), outputs from the daemon's copy
//! of the output image (ReadOutputs).

use std::collections::BTreeMap;

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;
use tokio_stream::StreamExt;

use crate::cli::Watch;
use crate::commands::pdo::{EntryReport, LayoutReport, layout};
use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Out, Report, Table};
use crate::values::{Hex, value_json, value_text};

/// `ecmxfctl data --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct DataReport {
    /// Input frame sequence number the inputs come from (null: no inputs read).
    pub seq: Option<u64>,
    /// Entries (empty with --raw).
    pub entries: Vec<EntryValueReport>,
    /// The whole images as hex (--raw only; else null).
    pub input_image: Option<Hex>,
    pub output_image: Option<Hex>,
}

/// One entry's value.
#[derive(Debug, Serialize, JsonSchema)]
pub struct EntryValueReport {
    pub name: String,
    /// "input" or "output".
    pub direction: String,
    /// ecmxfctl type name.
    pub data_type: String,
    /// Number, bool, or hex string for raw bytes.
    pub value: serde_json::Value,
    #[serde(skip)]
    #[schemars(skip)]
    text: String,
}

impl Report for DataReport {
    fn text(&self) -> String {
        if self.entries.is_empty() {
            let mut out = String::new();
            for (what, img) in [("inputs", &self.input_image), ("outputs", &self.output_image)] {
                if let Some(h) = img {
                    let bytes = crate::values::parse_hex_bytes(&h.0).unwrap_or_default();
                    out.push_str(&format!("{what} ({} bytes):\n", bytes.len()));
                    out.push_str(&crate::commands::sii::hexdump(0, &bytes));
                }
            }
            return out;
        }
        let mut t = Table::new(&["ENTRY", "DIR", "TYPE", "VALUE"]);
        for e in &self.entries {
            let dir = if e.direction == "output" { "out" } else { "in" };
            t.row([e.name.clone(), dir.to_owned(), e.data_type.clone(), e.text.clone()]);
        }
        t.to_string()
    }
}

/// The entries named (all when none), checked against the layout. An
/// entry asked for by its variable name is shown under that name (its
/// `name` stays the daemon's, to ask for its value by).
fn select(layout: &LayoutReport, names: &[String], default_outputs: bool) -> Result<Vec<Chosen>, CliError> {
    if names.is_empty() {
        let all = layout.entries.iter().filter(|e| default_outputs || !e.is_output());
        return Ok(all.map(|e| Chosen { shown: e.name.clone(), entry: e.clone() }).collect());
    }
    names
        .iter()
        .map(|n| {
            let e = layout.entries.iter().find(|e| e.is_named(n)).ok_or_else(|| {
                CliError::Usage(format!("no process data entry or variable {n:?}; `ecmxfctl pdos` lists them"))
            })?;
            Ok(Chosen { shown: n.clone(), entry: e.clone() })
        })
        .collect()
}

/// A selected entry and the name it is shown under.
struct Chosen {
    entry: EntryReport,
    shown: String,
}

impl std::ops::Deref for Chosen {
    type Target = EntryReport;
    fn deref(&self) -> &EntryReport {
        &self.entry
    }
}

/// One input sample with the selected inputs (None when nothing selected).
async fn inputs(api: &Api, names: Vec<String>, whole: bool) -> Result<Option<pb::InputSample>, CliError> {
    if names.is_empty() && !whole {
        return Ok(None);
    }
    let req = api.stream(pb::StreamInputsRequest { entries: names, decimation: 1, on_change: false });
    let mut s = api.pdo().stream_inputs(req).await.map_err(CliError::rpc("read inputs"))?.into_inner();
    let first = tokio::time::timeout(api.timeout(), s.next()).await;
    match first {
        Ok(Some(Ok(sample))) => Ok(Some(sample)),
        Ok(Some(Err(st))) => Err(CliError::rpc("read inputs")(st)),
        Ok(None) => Err(CliError::rpc("read inputs")(tonic::Status::unavailable("the input stream ended"))),
        Err(_) => Err(CliError::rpc("read inputs")(tonic::Status::deadline_exceeded(
            "no input frame arrived (is the network in SAFEOP or OP?)",
        ))),
    }
}

pub(super) async fn outputs(api: &Api, names: Vec<String>) -> Result<pb::OutputImage, CliError> {
    let r = api.pdo().read_outputs(api.req(pb::ReadOutputsRequest { entries: names })).await;
    Ok(r.map_err(CliError::rpc("read outputs"))?.into_inner())
}

fn entry_value(e: &Chosen, v: Option<&pb::Value>) -> EntryValueReport {
    EntryValueReport {
        name: e.shown.clone(),
        direction: e.direction.clone(),
        data_type: e.data_type.clone(),
        value: value_json(v),
        text: value_text(v, e.bit_length.div_ceil(8) as usize),
    }
}

/// Values of `values` for `names`, in the order of `names`.
fn pick<'a>(values: &'a [pb::EntryValue], name: &str) -> Option<&'a pb::Value> {
    values.iter().find(|v| v.name == name).and_then(|v| v.value.as_ref())
}

/// `data`.
pub async fn data(api: &Api, names: &[String], raw: bool) -> Result<DataReport, CliError> {
    let layout = layout(api).await?;
    if raw {
        // An output-only network has no input frame to wait for.
        let i = if layout.input_bytes > 0 { inputs(api, Vec::new(), true).await? } else { None };
        let o = outputs(api, Vec::new()).await?;
        return Ok(DataReport {
            seq: i.as_ref().map(|s| s.seq),
            entries: Vec::new(),
            input_image: Some(i.map_or_else(|| Hex::of(&[]), |s| Hex::of(&s.image))),
            output_image: Some(Hex::of(&o.image)),
        });
    }
    let chosen = select(&layout, names, true)?;
    let (outs, ins): (Vec<&Chosen>, Vec<&Chosen>) = chosen.iter().partition(|e| e.is_output());
    let sample = inputs(api, ins.iter().map(|e| e.name.clone()).collect(), false).await?;
    let o =
        if outs.is_empty() { None } else { Some(outputs(api, outs.iter().map(|e| e.name.clone()).collect()).await?) };
    let entries = chosen
        .iter()
        .map(|e| {
            let v = if e.is_output() {
                o.as_ref().and_then(|o| pick(&o.values, &e.name))
            } else {
                sample.as_ref().and_then(|s| pick(&s.values, &e.name))
            };
            entry_value(e, v)
        })
        .collect();
    Ok(DataReport { seq: sample.map(|s| s.seq), entries, input_image: None, output_image: None })
}

/// One line of `ecmxfctl watch --json` (NDJSON: one object per line).
#[derive(Debug, Serialize, JsonSchema)]
pub struct WatchLine {
    /// Input frame sequence number.
    pub seq: u64,
    /// When the daemon received the frame: ns since it started, and on the host's CLOCK_MONOTONIC.
    pub time_ns: u64,
    pub monotonic_ns: u64,
    /// Frames this client skipped because it fell behind.
    pub lost: u64,
    /// Entry name -> value (number, bool, or hex string for raw bytes).
    pub values: BTreeMap<String, serde_json::Value>,
}

/// `watch`.
pub async fn watch(api: &Api, out: Out, w: &Watch) -> Result<(), CliError> {
    let layout = layout(api).await?;
    let names: Vec<String> = w.entries.iter().chain(&w.variables).cloned().collect();
    let chosen = select(&layout, &names, false)?;
    let (outs, ins): (Vec<&Chosen>, Vec<&Chosen>) = chosen.iter().partition(|e| e.is_output());
    let cycle_us = u128::from(layout.cycle_us.max(1));
    let decimation = (w.interval.as_micros() / cycle_us).clamp(1, u128::from(u32::MAX)) as u32;
    let req = pb::StreamInputsRequest {
        // With only outputs chosen, still one input entry keeps the pace.
        entries: if ins.is_empty() {
            layout.entries.iter().filter(|e| !e.is_output()).take(1).map(|e| e.name.clone()).collect()
        } else {
            ins.iter().map(|e| e.name.clone()).collect()
        },
        decimation,
        on_change: w.on_change && outs.is_empty(),
    };
    let mut stream =
        api.pdo().stream_inputs(api.stream(req)).await.map_err(CliError::rpc("watch inputs"))?.into_inner();
    let widths: Vec<usize> = chosen.iter().map(|e| e.shown.len().max(12)).collect();
    if !out.json {
        let mut header = format!("{:>10}  {:>9}", "SEQ", "T(s)");
        for (e, w) in chosen.iter().zip(&widths) {
            header.push_str(&format!("  {:>w$}", e.shown));
        }
        println!("{header}");
    }
    let mut printed = 0u64;
    let mut last_values: Option<BTreeMap<String, serde_json::Value>> = None;
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    loop {
        let sample = tokio::select! {
            s = stream.next() => s,
            _ = &mut ctrl_c => return Ok(()),
        };
        let sample = match sample {
            Some(Ok(s)) => s,
            Some(Err(st)) if CliError::is_stopping(&st) => {
                eprintln!("ecmxfctl: the daemon is stopping; no more samples");
                return Ok(());
            }
            Some(Err(st)) => return Err(CliError::rpc("watch inputs")(st)),
            None => {
                return Err(CliError::rpc("watch inputs")(tonic::Status::unavailable("the daemon ended the stream")));
            }
        };
        let o = if outs.is_empty() {
            None
        } else {
            Some(outputs(api, outs.iter().map(|e| e.name.clone()).collect()).await?)
        };
        let mut values = BTreeMap::new();
        let mut text = format!("{:>10}  {:>9.3}", sample.seq, sample.time_ns as f64 / 1e9);
        for (e, w) in chosen.iter().zip(&widths) {
            let v = if e.is_output() {
                o.as_ref().and_then(|o| pick(&o.values, &e.name))
            } else {
                pick(&sample.values, &e.name)
            };
            values.insert(e.shown.clone(), value_json(v));
            text.push_str(&format!("  {:>w$}", value_json(v).to_string()));
        }
        if w.on_change && !outs.is_empty() && last_values.as_ref() == Some(&values) {
            continue;
        }
        last_values = Some(values.clone());
        let line = WatchLine {
            seq: sample.seq,
            time_ns: sample.time_ns,
            monotonic_ns: sample.monotonic_ns,
            lost: sample.lost,
            values,
        };
        out.line(&line, || text)?;
        printed += 1;
        if w.count.is_some_and(|n| printed >= n) {
            return Ok(());
        }
    }
}
