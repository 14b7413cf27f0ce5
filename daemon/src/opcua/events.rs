//! The daemon's events as OPC UA events (OPC 10000-5 6.4.2,
//! BaseEventType): each with the daemon's sentence as its message, a
//! severity (1..1000) by what it means for the plant, and as source the
//! slave it concerns (else the EtherCAT object). Notified on the EtherCAT
//! object, so a client subscribed there or on the Server object gets it.

use std::sync::atomic::{AtomicU64, Ordering};

use opcua::nodes::{BaseEventType, Event as UaEvent};
use opcua::server::SubscriptionCache;
use opcua::types::{ByteString, ObjectTypeId, UAString};

use super::space::Ids;
use super::values::{wall_now_ns, wall_time};
use crate::master::{Event, EventKind, Master};

/// Event ids: unique for this process's life (the start time and a count).
static NEXT_EVENT: AtomicU64 = AtomicU64::new(0);

/// Severity (OPC 10000-5: 1 low .. 1000 high) of an event of `kind`.
pub(super) fn severity(kind: &EventKind) -> u16 {
    match kind {
        EventKind::Emergency(_) => 700,
        EventKind::AlStatus { code: 0, .. } => 300,
        EventKind::AlStatus { .. } => 700,
        k if k.is_fault() => 800,
        _ => 300,
    }
}

/// The slave an event concerns, if one.
fn slave_of(kind: &EventKind) -> Option<u8> {
    match kind {
        EventKind::Emergency(r) => Some(r.slave),
        EventKind::AlStatus { slave, .. } => Some(*slave),
        _ => None,
    }
}

/// Notifies `event` to the clients subscribed to events.
pub(super) fn notify(subscriptions: &SubscriptionCache, ids: &Ids, master: &Master, event: &Event) {
    let (source, source_name) = match slave_of(&event.kind) {
        Some(p) => (ids.slave(p), format!("slave {p}")),
        None => (ids.master(), "EtherCAT".to_string()),
    };
    let n = NEXT_EVENT.fetch_add(1, Ordering::Relaxed);
    let wall_now = wall_now_ns();
    let mut id = wall_now.to_be_bytes().to_vec();
    id.extend_from_slice(&n.to_be_bytes());
    let time = wall_time(event.time_ns, master.now_ns(), wall_now);
    let ua = BaseEventType::new(ObjectTypeId::BaseEventType, ByteString::from(id), event.kind.to_string(), time)
        .set_source_node(source)
        .set_source_name(UAString::from(source_name))
        .set_severity(severity(&event.kind));
    let notifier = ids.master();
    subscriptions.notify_events([(&ua as &dyn UaEvent, &notifier)].into_iter());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_weigh_more_than_news() {
        assert_eq!(
            severity(&EventKind::AlStatus { slave: 1, state: crate::master::EcatState::SafeOp, code: 0x1A }),
            700
        );
        assert_eq!(severity(&EventKind::AlStatus { slave: 1, state: crate::master::EcatState::Op, code: 0 }), 300);
    }
}
