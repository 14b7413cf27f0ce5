//! NCMD and DCMD (Sparkplug 3.0 section 6.4.5/6.4.6), as
//! `sparkplug.commands` allows, like a gRPC caller of that role:
//! - observer: NCMD `Node Control/Rebirth` (true): births again.
//! - operator: also DCMD writes of `Outputs/*` metrics, staged together
//!   and sent as one write under an output lease the node holds per slave
//!   (the same table as gRPC's: a slave another client leased is refused,
//!   and when the node's lease lapses without commands the engine applies
//!   `outputs.on_last_writer_gone`).
//!
//! Everything else (Reboot, unknown metrics, values that do not fit) is
//! refused: logged with what and why, and counted.

use std::collections::HashMap;
use std::time::Duration;

use ecmxf_proto::sparkplug::Payload;
use ecmxf_proto::sparkplug::payload::Metric;

use super::node::{self, Node};
use crate::config::Role;
use crate::master::entry_writes::{Staging, WriteError};
use crate::master::{LeaseError, Master};

/// What a command asks of the session.
#[derive(Debug, PartialEq, Eq)]
pub(super) enum Action {
    /// Nothing more.
    None,
    /// Publish the births again.
    Rebirth,
}

/// The node's output leases, one per slave it wrote.
#[derive(Debug)]
pub(super) struct Writer {
    held: HashMap<u8, String>,
    ttl: Duration,
}

impl Writer {
    /// Leases of `ttl` (`api.lease_ttl_ms`).
    pub(super) fn new(ttl: Duration) -> Self {
        Self { held: HashMap::new(), ttl }
    }
}

/// A refused command: what, and why.
#[derive(Debug, PartialEq, Eq)]
pub(super) struct Refusal(pub String);

/// NCMD: Rebirth, when `role` allows it.
pub(super) fn node_command(node: &Node, role: Option<Role>, payload: &Payload) -> Result<Action, Refusal> {
    let mut action = Action::None;
    for m in &payload.metrics {
        let name = node.node_metric(m);
        match name {
            Some(node::REBIRTH) if truthy(m) => {
                if role.is_none() {
                    return Err(Refusal(
                        "NCMD Node Control/Rebirth refused: sparkplug.commands is \"none\" (\"observer\" allows it)"
                            .into(),
                    ));
                }
                action = Action::Rebirth;
            }
            Some(node::REBIRTH) => {}
            Some(node::REBOOT) => {
                return Err(Refusal("NCMD Node Control/Reboot refused: ecmxfd is not rebooted over MQTT".into()));
            }
            Some(other) => return Err(Refusal(format!("NCMD {other} refused: the node's metrics are read-only"))),
            None => return Err(Refusal(format!("NCMD refused: no node metric {}", describe(m)))),
        }
    }
    Ok(action)
}

/// DCMD to device `position`: writes its output metrics, when `role` is
/// operator or more. All the command's metrics or none.
pub(super) fn device_command(
    node: &Node,
    role: Option<Role>,
    position: u8,
    payload: &Payload,
    master: &Master,
    writer: &mut Writer,
) -> Result<usize, Refusal> {
    if role < Some(Role::Operator) {
        return Err(Refusal(format!(
            "DCMD to slave-{position} refused: sparkplug.commands is {}, writing outputs needs \"operator\"",
            role.map_or_else(|| "\"none\"".to_string(), |r| format!("\"{r}\""))
        )));
    }
    let refuse = |why: String| Refusal(format!("DCMD to slave-{position} refused: {why}"));
    let mut targets = Vec::with_capacity(payload.metrics.len());
    for m in &payload.metrics {
        let (index, image) = node.output_target(position, m).map_err(refuse)?;
        let e = &image.entries[index];
        let value = m.value.as_ref().ok_or_else(|| refuse(format!("{} has no value", e.name)))?;
        let bytes = super::value::encode(e.data_type, e.bit_length, value)
            .map_err(|why| refuse(format!("{}: {why}", e.name)))?;
        targets.push((index, image, bytes));
    }
    let Some((_, image, _)) = targets.first() else { return Ok(0) };
    let image = std::sync::Arc::clone(image);
    for attempt in 0..2 {
        let lease = match writer.held.get(&position) {
            Some(id) => id.clone(),
            None => {
                let l = master
                    .acquire_lease(&[position], Some(writer.ttl), "sparkplug")
                    .map_err(|e| refuse(e.to_string()))?;
                writer.held.insert(position, l.id.clone());
                l.id
            }
        };
        let mut staging = Staging::new(master, &image);
        for (index, _, bytes) in &targets {
            staging.entry(&image.entries[*index], bytes).map_err(|e| refuse(e.to_string()))?;
        }
        match staging.commit(master.leases(), &lease, "sparkplug") {
            Ok(()) => return Ok(targets.len()),
            // The lease lapsed between commands: take a new one, once.
            Err(WriteError::Lease(LeaseError::NotALease(_))) if attempt == 0 => {
                writer.held.remove(&position);
            }
            Err(e) => return Err(refuse(e.to_string())),
        }
    }
    Err(refuse("the output lease could not be kept".into()))
}

fn truthy(m: &Metric) -> bool {
    use ecmxf_proto::sparkplug::payload::metric::Value;
    match &m.value {
        Some(Value::BooleanValue(b)) => *b,
        Some(Value::IntValue(v)) => *v != 0,
        Some(Value::LongValue(v)) => *v != 0,
        Some(Value::StringValue(s)) => s.eq_ignore_ascii_case("true"),
        _ => false,
    }
}

fn describe(m: &Metric) -> String {
    match (&m.name, m.alias) {
        (Some(n), _) => format!("{n:?}"),
        (None, Some(a)) => format!("with alias {a}"),
        (None, None) => "without name or alias".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ecmxf_proto::sparkplug::payload::metric::Value;

    fn ncmd(name: &str, value: Value) -> Payload {
        Payload {
            metrics: vec![Metric { name: Some(name.into()), value: Some(value), ..Metric::default() }],
            ..Payload::default()
        }
    }

    #[test]
    fn rebirth_needs_a_role_and_reboot_is_always_refused() {
        let node = Node::new(node::Settings::default());
        let rebirth = ncmd(node::REBIRTH, Value::BooleanValue(true));
        assert_eq!(node_command(&node, Some(Role::Observer), &rebirth), Ok(Action::Rebirth));
        let e = node_command(&node, None, &rebirth).unwrap_err();
        assert!(e.0.contains("sparkplug.commands is \"none\""), "{e:?}");
        let reboot = ncmd(node::REBOOT, Value::BooleanValue(true));
        assert!(node_command(&node, Some(Role::Admin), &reboot).unwrap_err().0.contains("Reboot refused"));
        let other = ncmd("Counters/Exchanges", Value::LongValue(0));
        assert!(node_command(&node, Some(Role::Admin), &other).unwrap_err().0.contains("read-only"));
        let unknown = ncmd("Nope", Value::BooleanValue(true));
        assert!(node_command(&node, Some(Role::Admin), &unknown).unwrap_err().0.contains("no node metric \"Nope\""));
        // By alias too: Rebirth is the second node metric.
        let by_alias = Payload {
            metrics: vec![Metric { alias: Some(2), value: Some(Value::BooleanValue(true)), ..Metric::default() }],
            ..Payload::default()
        };
        assert_eq!(node_command(&node, Some(Role::Observer), &by_alias), Ok(Action::Rebirth));
        assert_eq!(
            node_command(&node, Some(Role::Observer), &ncmd(node::REBIRTH, Value::BooleanValue(false))),
            Ok(Action::None)
        );
    }
}
