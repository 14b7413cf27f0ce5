//! The slaves (docs/web.md): the list as `ecmxfctl --json slaves` has it,
//! a slave's page, its object dictionary and SDO transfers, the topology,
//! and the network as files to download.
//!
//! The list is read from the chip (state, AL status, addresses and clock:
//! eight readings per slave) at most once in [`LIST_FRESH`] for every
//! browser together. A slave's SII and dictionary are read once in the
//! background, as the daemon's own work, never inside a page's request.

use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{StatusCode, header};
use axum::response::IntoResponse;
use serde::Deserialize;
use serde_json::{Value, json};

use super::json_body::JsonBody;
use super::overview::{lost, mismatch};
use super::refusal::Refusal;
use super::shared::{SlaveTable, Web};
use super::values::{entry_value, typed, value_json};
use super::visitors::Visitor;
use crate::config::api::Role;
use crate::master::device_dictionary::DeviceDictionary;
use crate::master::sii::Categories;
use crate::master::value::{DataType, Value as Typed, type_name};
use crate::master::{Call, Master, al_status_text};

/// How long a list read from the chip is shown before it is read again.
const LIST_FRESH: Duration = Duration::from_millis(1500);
/// How long an SDO transfer may take.
const TRANSFER_WITHIN: Duration = Duration::from_secs(5);
/// How long a request waits for a dictionary before saying it is pending.
const DICTIONARY_WAIT: Duration = Duration::from_millis(300);

impl SlaveTable {
    /// The names of the slaves the network has, and of those it lost
    /// (kept from when it had them; "slave P" if never seen by name).
    pub(super) fn remember(&self, master: &Master) -> Vec<String> {
        let layout = master.layout();
        let seen = master.status().slaves_seen as usize;
        let mut names = self.names.lock().unwrap_or_else(|e| e.into_inner());
        for (p, s) in layout.slaves.iter().enumerate() {
            match names.get_mut(p) {
                Some(n) => n.clone_from(&s.name),
                None => names.push(s.name.clone()),
            }
        }
        // A re-init or a new configuration takes the network as it is.
        let count = layout.slaves.len().max(seen);
        names.truncate(count);
        while names.len() < count {
            let p = names.len();
            names.push(format!("slave {p}"));
        }
        names.clone()
    }

    /// The list, read from the chip unless a fresh one is at hand.
    async fn list(&self, master: &Master) -> Result<Arc<Value>, Refusal> {
        let mut held = self.list.lock().await;
        if let Some((at, list)) = held.as_ref().filter(|(at, _)| at.elapsed() < LIST_FRESH) {
            let _ = at;
            return Ok(Arc::clone(list));
        }
        let list = Arc::new(read_list(master).await?);
        *held = Some((Instant::now(), Arc::clone(&list)));
        Ok(list)
    }
}

/// Every slave, read live from the chip, compared with the configuration:
/// the fields `ecmxfctl --json slaves` prints, and the positions lost.
async fn read_list(master: &Master) -> Result<Value, Refusal> {
    let layout = master.layout();
    let config = master.config();
    let status = master.status();
    if layout.slaves.is_empty() && status.phase != crate::master::Phase::Running {
        let why = crate::master::NotRunning::Phase { phase: status.phase, last_error: master.last_error() };
        return Err(crate::master::EngineError::Unavailable(why).into());
    }
    let call = Call::anonymous(Some(Duration::from_secs(5)));
    let present = (status.slaves as usize).min(layout.slaves.len()).max(if lost(&status).is_empty() {
        layout.slaves.len()
    } else {
        0
    });
    let readings = master.slave_readings(present, false, call).await?;
    let mut slaves = Vec::new();
    for (i, (s, live)) in layout.slaves.iter().zip(readings).enumerate() {
        // The ESC's error counters: one datagram; a slave that does not
        // answer it shows none rather than zeros.
        let errors = match master.esc_errors(i as u8, call).await {
            Ok(Some(e)) => json!({
                "total": e.total(),
                "ports": e.ports.iter().map(|p| json!([p.invalid_frames, p.rx_errors, p.forwarded])).collect::<Vec<_>>(),
                "processing_unit": e.processing_unit,
                "pdi": e.pdi,
            }),
            _ => Value::Null,
        };
        let differs = config.slaves.get(i).map(|e| mismatch(s, e)).unwrap_or_default();
        let expected = config.slaves.get(i).map(|e| {
            json!({
                "name": e.name.clone().unwrap_or_default(),
                "vendor_id": e.vendor_id.unwrap_or(0),
                "product_code": e.product_code.unwrap_or(0),
                "revision": e.revision.unwrap_or(0),
                "esi": e.esi.as_ref().map(|p| p.display().to_string()).unwrap_or_default(),
            })
        });
        slaves.push(json!({
            "position": i,
            "alias": live.setup.alias,
            "configured_address": live.setup.configured_address,
            "vendor_id": s.vendor_id,
            "product_code": s.product_code,
            "revision": s.revision,
            "name": s.name,
            "state": live.state.to_string(),
            "al_status_code": live.al_status,
            "al_status_text": al_status_text(live.al_status),
            "output_bytes": s.rx_bytes,
            "output_offset": s.rx_offset,
            "input_bytes": s.tx_bytes,
            "input_offset": s.tx_offset,
            "dc": {
                "supported": live.setup.dc_supported,
                "active": live.setup.dc_active,
                "cycle_ns": live.setup.dc_cycle_ns,
                "shift_ns": live.setup.dc_shift_ns,
            },
            "expected": expected,
            "mismatch": differs.join("; "),
            "errors": errors,
        }));
    }
    let missing: Vec<usize> = (layout.slaves.len()..config.slaves.len()).collect();
    // A network that lost slaves is not the one it was brought up as,
    // whatever the configuration lists.
    let lost = lost(&status);
    let matches = missing.is_empty() && lost.is_empty() && slaves.iter().all(|s| s["mismatch"] == "");
    Ok(json!({ "slaves": slaves, "missing": missing, "matches_config": matches, "lost": lost }))
}

pub(super) async fn list(State(web): State<Web>, _v: Visitor) -> Result<Json<Value>, Refusal> {
    Ok(Json((*web.slaves.list(&web.master).await?).clone()))
}

/// A slave position from the path, refused when no such slave runs.
fn position(master: &Master, p: &str) -> Result<u8, Refusal> {
    let n = number(p, "slave", 0xFF).map_err(|_| Refusal::bad(format!("slave {p:?}: give a position, 0..=255")))? as u8;
    let count = master.layout().slaves.len();
    if usize::from(n) >= count {
        return Err(Refusal::not_found(format!("slave {n} does not exist: the network has {count} slave(s)")));
    }
    Ok(n)
}

pub(super) async fn one(State(web): State<Web>, _v: Visitor, Path(p): Path<String>) -> Result<Json<Value>, Refusal> {
    // A slave the network lost keeps its page: where it was, by the name
    // it had, with its emergencies (its data and dictionary went with it).
    if let Ok(n) = number(&p, "slave", 0xFF)
        && lost(&web.master.status()).contains(&u64::from(n))
    {
        let names = web.slaves.remember(&web.master);
        let name = names.get(n as usize).cloned().unwrap_or_else(|| format!("slave {n}"));
        let emergencies: Vec<Value> = web.overview.emergencies(n as u8).into_iter().rev().take(50).collect();
        return Ok(Json(json!({
            "slave": { "position": n, "name": name, "lost": true },
            "lost": true,
            "entries": [],
            "emergencies": emergencies,
            "sii": Value::Null,
        })));
    }
    let p = position(&web.master, &p)?;
    let list = web.slaves.list(&web.master).await?;
    let slave = list["slaves"].as_array().and_then(|s| s.get(usize::from(p))).cloned().unwrap_or(Value::Null);
    let entries = match web.master.current_image().and_then(Result::ok) {
        Some(image) => {
            let frame = web.master.latest_inputs();
            let shadow = web.master.output_shadow().clone();
            image
                .entries
                .iter()
                .filter(|e| e.slave == p)
                .map(|e| {
                    let value = entry_value(e, frame.as_deref().map(|f| f.data.as_slice()), &shadow);
                    json!({
                        "name": e.name,
                        "label": e.label,
                        "index": e.index,
                        "subindex": e.subindex,
                        "direction": if e.output { "output" } else { "input" },
                        "data_type": type_name(e.data_type),
                        "bit_length": e.bit_length,
                        "value": value,
                    })
                })
                .collect()
        }
        None => Vec::new(),
    };
    // The newest 50, newest first.
    let emergencies: Vec<Value> = web.overview.emergencies(p).into_iter().rev().take(50).collect();
    Ok(Json(json!({
        "slave": slave,
        "entries": entries,
        "emergencies": emergencies,
        "sii": sii(&web, p),
    })))
}

/// Slave `p`'s SII, decoded; `{"pending": true}` while it is read (once,
/// in the background).
fn sii(web: &Web, p: u8) -> Value {
    let mut held = web.slaves.sii.lock().unwrap_or_else(|e| e.into_inner());
    match held.get(&p) {
        Some(Some(v)) => return (**v).clone(),
        Some(None) => return json!({ "pending": true }),
        None => {}
    }
    held.insert(p, None);
    let web = Arc::clone(web);
    tokio::spawn(async move {
        let read = web.master.sii(p, Categories::All, Call::daemon()).await;
        let v = match read {
            Ok(s) => sii_json(&s),
            Err(e) => json!({ "error": e.to_string() }),
        };
        web.slaves.sii.lock().unwrap_or_else(|e| e.into_inner()).insert(p, Some(Arc::new(v)));
    });
    json!({ "pending": true })
}

/// The SII as the slave page lists it.
fn sii_json(s: &ecmxf_devices::sii::Sii) -> Value {
    let text = |i: u8| {
        (i > 0)
            .then(|| s.strings.get(usize::from(i) - 1))
            .flatten()
            .map(|b| String::from_utf8_lossy(b).into_owned())
            .unwrap_or_default()
    };
    let general = s.general.as_ref().map(|g| {
        json!({
            "name": text(g.name),
            "group": text(g.group),
            "order": text(g.order),
            "coe_details": format!("{:#04x}", g.coe_details),
            "foe_details": format!("{:#04x}", g.foe_details),
            "ebus_current_ma": g.ebus_current_ma,
        })
    });
    let pdos = |list: &[ecmxf_devices::sii::PdoRecord]| {
        list.iter()
            .map(|p| {
                json!({
                    "index": format!("{:#06x}", p.index),
                    "name": text(p.name),
                    "sync_manager": p.sm,
                    "entries": p.entries.len(),
                })
            })
            .collect::<Vec<_>>()
    };
    json!({
        "vendor_id": format!("{:#010x}", s.vendor_id),
        "product_code": format!("{:#010x}", s.product_code),
        "revision": format!("{:#010x}", s.revision),
        "serial": s.serial,
        "mailbox_protocols": format!("{:#06x}", s.protocols),
        "eeprom_bytes": (u32::from(s.size_word) + 1) * 128,
        "general": general,
        "sync_managers": s.sync_managers.iter().map(|m| json!({
            "start": format!("{:#06x}", m.start), "length": m.length, "type": m.kind,
        })).collect::<Vec<_>>(),
        "rx_pdos": pdos(&s.rx_pdos),
        "tx_pdos": pdos(&s.tx_pdos),
        "distributed_clocks": s.dc.is_some(),
    })
}

pub(super) async fn objects(
    State(web): State<Web>,
    _v: Visitor,
    Path(p): Path<String>,
) -> Result<Json<Value>, Refusal> {
    let p = position(&web.master, &p)?;
    let known = web.master.known_device_dictionary(p);
    let dictionary = match known {
        Some(d) => d,
        None => {
            // Read as the daemon's own work: a browser that gives up does
            // not stop it, and the next asks find it done.
            let master = Arc::clone(&web.master);
            let reading = tokio::spawn(async move { master.device_dictionary(p, Call::daemon()).await });
            match tokio::time::timeout(DICTIONARY_WAIT, reading).await {
                Ok(Ok(Ok(d))) => d,
                Ok(Ok(Err(e))) => return Err(Refusal::new(StatusCode::CONFLICT, e.to_string())),
                Ok(Err(_)) => return Err(Refusal::new(StatusCode::INTERNAL_SERVER_ERROR, "the read stopped")),
                Err(_) => return Ok(Json(json!({ "pending": true }))),
            }
        }
    };
    Ok(Json(json!({ "objects": objects_json(&dictionary) })))
}

fn objects_json(d: &DeviceDictionary) -> Vec<Value> {
    let od = d.to_od();
    od.objects()
        .map(|(index, o)| {
            let entries: Vec<Value> = o
                .entries
                .iter()
                .map(|(sub, e)| {
                    let read = e.access.read.preop || e.access.read.safeop || e.access.read.op;
                    let write = e.access.write.preop || e.access.write.safeop || e.access.write.op;
                    json!({
                        "subindex": sub,
                        "name": e.name,
                        "type": type_name(e.dtype),
                        "bits": e.dtype.bits(),
                        "access": match (read, write) { (true, true) => "rw", (true, false) => "ro", (false, true) => "wo", _ => "" },
                    })
                })
                .collect();
            json!({ "index": index, "name": o.name, "entries": entries })
        })
        .collect()
}

/// An index or subindex from the path: hex with 0x, else decimal.
fn number(text: &str, what: &str, max: u32) -> Result<u32, Refusal> {
    let t = text.trim();
    let n = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16),
        None => t.parse(),
    };
    n.ok().filter(|n| *n <= max).ok_or_else(|| Refusal::bad(format!("{what} {text:?}: give 0..={max:#x} (0x for hex)")))
}

/// The object's type: the device's own dictionary's (read now, as the
/// daemon's work, if the daemon has not read it yet: a string's length
/// and a vendor object's type are only there), else as the master knows
/// it (ESI, the standard's table), else the type of the process-data
/// entry mapping it.
async fn object_type(master: &Arc<Master>, p: u8, index: u16, sub: u8) -> Option<DataType> {
    if master.known_device_dictionary(p).is_none() {
        let m = Arc::clone(master);
        let reading = tokio::spawn(async move { m.device_dictionary(p, Call::daemon()).await });
        let _ = tokio::time::timeout(TRANSFER_WITHIN, reading).await;
    }
    if let Some(t) = master.object_type(p, index, sub).await {
        return Some(t);
    }
    let image = master.current_image().and_then(Result::ok)?;
    image.entries.iter().find(|e| e.slave == p && e.index == index && e.subindex == sub).map(|e| e.data_type)
}

pub(super) async fn upload(
    State(web): State<Web>,
    v: Visitor,
    Path((p, index, sub)): Path<(String, String, String)>,
) -> Result<Json<Value>, Refusal> {
    let p = position(&web.master, &p)?;
    let index = number(&index, "index", 0xFFFF)? as u16;
    let sub = number(&sub, "subindex", 0xFF)? as u8;
    let call = Call::new(v.client(), None).or_within(TRANSFER_WITHIN);
    let raw = web.master.sdo_read(p, index, sub, false, call).await?;
    let (value, t) = match object_type(&web.master, p, index, sub).await {
        Some(t) => (value_json(Typed::decode(t, &raw)), type_name(t)),
        None => (json!(hex::encode(&raw)), "OCTET_STRING"),
    };
    Ok(Json(json!({ "value": value, "type": t, "raw": hex::encode(&raw) })))
}

#[derive(Deserialize)]
pub(super) struct Written {
    value: Value,
}

pub(super) async fn download(
    State(web): State<Web>,
    v: Visitor,
    Path((p, index, sub)): Path<(String, String, String)>,
    JsonBody(body): JsonBody<Written>,
) -> Result<Json<Value>, Refusal> {
    v.needs(Role::Operator, "an SDO download")?;
    let p = position(&web.master, &p)?;
    let index = number(&index, "index", 0xFFFF)? as u16;
    let sub = number(&sub, "subindex", 0xFF)? as u8;
    let Some(t) = object_type(&web.master, p, index, sub).await else {
        return Err(Refusal::bad(format!(
            "{index:#06x}:{sub:02x} of slave {p}: its type is not known (no dictionary entry), so no value can be \
             encoded for it"
        )));
    };
    let value = typed(&body.value).map_err(Refusal::bad)?;
    let bytes = value
        .encode(t, t.bits().max(8))
        .map_err(|e| Refusal::bad(format!("{index:#06x}:{sub:02x} of slave {p} is {}: {e}", type_name(t))))?;
    tracing::info!(who = %v.name, slave = p, object = format_args!("{index:#06x}:{sub:02x}"), "SDO download from the dashboard");
    let call = Call::new(v.client(), None).or_within(TRANSFER_WITHIN);
    web.master.sdo_write(p, index, sub, false, bytes, call).await?;
    Ok(Json(json!({ "written": value_json(value) })))
}

pub(super) async fn topology(State(web): State<Web>, _v: Visitor) -> Json<Value> {
    let status = web.master.status();
    let lost = lost(&status);
    let names = web.slaves.remember(&web.master);
    let slaves: Vec<Value> = names
        .iter()
        .enumerate()
        .map(|(p, name)| {
            let gone = lost.contains(&(p as u64));
            let state = match web.overview.reported(p as u8) {
                _ if gone => "LOST".to_string(),
                Some((state, _)) => state.to_string(),
                None => status.ecat_state.to_string(),
            };
            json!({ "position": p, "name": name, "state": state, "lost": gone })
        })
        .collect();
    Json(json!({ "slaves": slaves }))
}

/// The network as a configuration ecmxfd takes: its link and cycle, and
/// one `[[slave]]` per slave with the identity checked at bring-up.
pub(super) async fn config_toml(State(web): State<Web>, _v: Visitor) -> impl IntoResponse {
    let config = web.master.config();
    let mut out = String::from(
        "# The network ecmxfd runs, as its dashboard wrote it: the link, the cycle and each slave's\n\
         # identity (checked at bring-up). `ecmxfctl config` writes the PDO mapping as well.\nversion = 1\n\n[link]\n",
    );
    out.push_str(&config.link.to_toml());
    out.push_str("\n[cycle]\n");
    out.push_str(&config.cycle.to_toml());
    for (p, s) in web.master.layout().slaves.iter().enumerate() {
        out.push_str(&format!(
            "\n# position {p}\n[[slave]]\nname = {:?}\nvendor_id = {:#010x}\nproduct_code = {:#010x}\nrevision = {:#010x}\n",
            s.name, s.vendor_id, s.product_code, s.revision
        ));
        if let Some(esi) = config.slaves.get(p).and_then(|c| c.esi.as_ref()) {
            out.push_str(&format!("esi = {:?}\n", esi.display().to_string()));
        }
    }
    (
        [
            (header::CONTENT_TYPE, "application/toml; charset=utf-8"),
            (header::CONTENT_DISPOSITION, "attachment; filename=\"ecmxfd.toml\""),
        ],
        out,
    )
}

/// The ENI file the network runs from.
pub(super) async fn config_eni(State(web): State<Web>, _v: Visitor) -> Result<impl IntoResponse, Refusal> {
    let Some(path) = web.master.config().eni else {
        return Err(Refusal::not_found(
            "this network runs from no ENI file; `ecmxfctl config --format eni > network.xml` writes one",
        ));
    };
    let text = tokio::fs::read(&path)
        .await
        .map_err(|e| Refusal::new(StatusCode::INTERNAL_SERVER_ERROR, format!("{}: {e}", path.display())))?;
    Ok((
        [
            (header::CONTENT_TYPE, "application/xml"),
            (header::CONTENT_DISPOSITION, "attachment; filename=\"network.xml\""),
        ],
        text,
    ))
}
