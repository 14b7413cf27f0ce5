//! The node's MQTT sessions: connect (brokers in order, fail-over), the
//! will NDEATH with this connection's `bdSeq`, subscribe to commands (and
//! the primary host's STATE), births once the host is online, then
//! publish on the configured periods and on engine changes until the
//! connection is lost; then the next broker after a growing pause, with
//! the next `bdSeq` and births again. At shutdown NDEATH goes out before
//! the disconnect.
//!
//! The MQTT connection itself is `connection`'s. Messages go into the client's queue without
//! waiting (`try_publish`): a full queue drops the message and counts it
//! rather than holding up the node, and nothing of the engine's cyclic
//! path ever waits on the network.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Duration;

use crate::master::EcatState;
use ecmxf_proto::sparkplug::Payload;
use prost::Message;
use rumqttc::{AsyncClient, QoS};
use tokio::sync::{broadcast, mpsc, watch};
use tracing::{info, warn};

use super::SharedStats;
use super::commands::{self, Action, Writer};
use super::connection::{self, Incoming, Prepared};
use super::node::{Node, Outgoing, Settings};
use super::seen::{RateMeter, Seen, now_ms, status_key, track_al};
use super::topic::{self, Kind, NodeTopics};
use crate::master::Master;

/// Pause after a lost connection: doubles up to [`MAX_BACKOFF`].
const FIRST_BACKOFF: Duration = Duration::from_secs(1);
/// The longest pause between connection attempts.
const MAX_BACKOFF: Duration = Duration::from_secs(30);
/// How long a CONNACK may take.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);
/// How long NDEATH and the disconnect get at shutdown.
const GOODBYE: Duration = Duration::from_secs(1);
/// Births on request at most this often: a host repeating Rebirth gets
/// one set of births per interval, not one per request.
const REBIRTH_SPACING: Duration = Duration::from_secs(1);

/// How a session ended.
enum Ended {
    /// The daemon stops.
    Stop,
    /// The connection was lost or refused: why, and whether it had been
    /// up (a broker that never answered makes the node try the next one).
    Lost { why: String, was_up: bool },
}

/// Runs the node until `stop` fires.
pub async fn serve(master: Arc<Master>, prepared: Prepared, stats: SharedStats, mut stop: watch::Receiver<()>) {
    let c = &prepared.config;
    let topics = NodeTopics { group: c.group_id.clone(), node: prepared.node_id.clone() };
    let settings = Settings {
        data_deadband: c.data_deadband,
        diagnostics_deadband: c.diagnostics_deadband,
        slaves: c.slaves.clone(),
        variables: c.variables.clone(),
        names: c.metric_names,
    };
    let mut node = Node::new(settings);
    node.resume(stats.next_bd_seq.load(Relaxed));
    let mut writer = Writer::new(master.lease_ttl());
    let mut backoff = FIRST_BACKOFF;
    let mut broker = 0usize;
    info!(group = %topics.group, node = %topics.node, brokers = c.broker.len(), "sparkplug: edge node starting");
    loop {
        let b = &c.broker[broker % c.broker.len()];
        let bd_seq = node.next_connection();
        stats.next_bd_seq.store(bd_seq + 1, Relaxed);
        let session = Session { master: &master, prepared: &prepared, topics: &topics, stats: &stats };
        match session.run(&mut node, &mut writer, b, bd_seq, &mut stop).await {
            Ended::Stop => return,
            Ended::Lost { why, was_up } => {
                stats.connected.store(0, Relaxed);
                if was_up {
                    backoff = FIRST_BACKOFF;
                } else {
                    broker += 1;
                }
                warn!(broker = %b, "sparkplug: {why}; connecting again in {} s", backoff.as_secs());
            }
        }
        tokio::select! {
            _ = stop.changed() => return,
            () = tokio::time::sleep(backoff) => {}
        }
        backoff = (backoff * 2).min(MAX_BACKOFF);
    }
}

/// One connection's borrowings.
struct Session<'a> {
    master: &'a Arc<Master>,
    prepared: &'a Prepared,
    topics: &'a NodeTopics,
    stats: &'a SharedStats,
}

impl Session<'_> {
    async fn run(
        &self,
        node: &mut Node,
        writer: &mut Writer,
        b: &crate::config::sparkplug::BrokerUrl,
        bd_seq: u64,
        stop: &mut watch::Receiver<()>,
    ) -> Ended {
        let c = &self.prepared.config;
        let client_id = format!("ecmxfd-{}-{}", self.topics.group, self.topics.node);
        let will = (self.topics.node(Kind::NDeath), node.death(now_ms()).encode_to_vec());
        let (client, mut incoming) = connection::open(self.prepared, client_id, b, will);
        match tokio::time::timeout(CONNECT_TIMEOUT, incoming.recv()).await {
            Ok(Some(Incoming::Connected(Ok(())))) => {}
            Ok(Some(Incoming::Connected(Err(why)) | Incoming::Lost(why))) => return Ended::Lost { why, was_up: false },
            Ok(Some(Incoming::Publish { .. }) | None) => {
                return Ended::Lost { why: "the connection ended before CONNACK".into(), was_up: false };
            }
            Err(_) => {
                return Ended::Lost {
                    why: format!("no CONNACK within {} s", CONNECT_TIMEOUT.as_secs()),
                    was_up: false,
                };
            }
        }
        self.stats.connects.fetch_add(1, Relaxed);
        self.stats.set_broker(b.to_string());
        info!(broker = %b, bd_seq, "sparkplug: connected");
        // Commands before births (spec 7.1.1: NCMD subscription first).
        for t in self.topics.commands() {
            let _ = client.try_subscribe(t, QoS::AtLeastOnce);
        }
        let mut host_online = c.primary_host_id.is_none();
        if let Some(host) = &c.primary_host_id {
            let _ = client.try_subscribe(topic::host_state(host), QoS::AtLeastOnce);
            info!(host = %host, "sparkplug: waiting for the primary host's STATE online before births");
        }
        let mut born = false;
        let mut al: BTreeMap<u8, (EcatState, u16)> = BTreeMap::new();
        let mut status = self.master.watch_status();
        let mut events = self.master.events();
        let mut events_open = true;
        let mut meter = RateMeter::default();
        let mut last_births = tokio::time::Instant::now();
        let mut rebirth_due: Option<tokio::time::Instant> = None;
        // First ticks one period after the births, which carry every value.
        let period = |ms: u32| Duration::from_millis(ms.into());
        let first = |ms: u32| tokio::time::Instant::now() + period(ms);
        let mut data = tokio::time::interval_at(first(c.data_period_ms), period(c.data_period_ms));
        let mut diagnostics = tokio::time::interval_at(first(c.diagnostics_period_ms), period(c.diagnostics_period_ms));
        data.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        diagnostics.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let role = c.commands.role();
        let mut key = status_key(&status.borrow_and_update());
        if host_online {
            self.births(node, &client, &al, &mut meter);
            born = true;
        }
        loop {
            tokio::select! {
                _ = stop.changed() => {
                    self.goodbye(node, &client, &mut incoming).await;
                    return Ended::Stop;
                }
                msg = incoming.recv() => match msg {
                    Some(Incoming::Publish { topic, payload }) => {
                        if let Some(host) = &c.primary_host_id && topic == topic::host_state(host) {
                            match topic::host_online(&payload) {
                                Some(true) if !born => {
                                    info!(host = %host, "sparkplug: primary host online");
                                    host_online = true;
                                    self.births(node, &client, &al, &mut meter);
                                    last_births = tokio::time::Instant::now();
                                    born = true;
                                }
                                Some(false) if host_online => {
                                    // Spec 7.3: the node leaves and comes back when the host does.
                                    self.goodbye(node, &client, &mut incoming).await;
                                    return Ended::Lost { why: format!("primary host {host} went offline"), was_up: true };
                                }
                                _ => {}
                            }
                            continue;
                        }
                        if born && self.command(node, writer, role, &topic, &payload) {
                            let at = last_births + REBIRTH_SPACING;
                            if tokio::time::Instant::now() >= at {
                                self.births(node, &client, &al, &mut meter);
                                last_births = tokio::time::Instant::now();
                            } else {
                                rebirth_due = Some(at);
                            }
                        }
                    }
                    Some(Incoming::Connected(_)) => {}
                    Some(Incoming::Lost(why)) => return Ended::Lost { why, was_up: true },
                    None => return Ended::Lost { why: "the MQTT task ended".into(), was_up: true },
                },
                () = tokio::time::sleep_until(rebirth_due.unwrap_or_else(tokio::time::Instant::now)), if rebirth_due.is_some() => {
                    rebirth_due = None;
                    self.births(node, &client, &al, &mut meter);
                    last_births = tokio::time::Instant::now();
                }
                _ = data.tick(), if born => {
                    let seen = Seen::now(self.master, &mut meter);
                    let out = node.update(&seen.view(&al, self.stats), true);
                    self.send(&client, out);
                }
                _ = diagnostics.tick(), if born => {
                    let seen = Seen::now(self.master, &mut meter);
                    if let Some(out) = node.node_data(&seen.view(&al, self.stats)) {
                        self.send(&client, vec![out]);
                    }
                }
                r = status.changed() => {
                    if r.is_err() {
                        self.goodbye(node, &client, &mut incoming).await;
                        return Ended::Stop;
                    }
                    // Only what births and deaths hang on: phase, state,
                    // recoveries, slaves (snapshots come every few ms).
                    let now = status_key(&status.borrow_and_update());
                    if now != key {
                        key = now;
                        if born {
                            let seen = Seen::now(self.master, &mut meter);
                            let out = node.update(&seen.view(&al, self.stats), false);
                            self.send(&client, out);
                        }
                    }
                }
                e = events.recv(), if events_open => {
                    let changed = match e {
                        Ok(e) => track_al(&mut al, &e.kind),
                        Err(broadcast::error::RecvError::Lagged(_)) => true,
                        Err(broadcast::error::RecvError::Closed) => {
                            events_open = false;
                            false
                        }
                    };
                    if changed && born {
                        let seen = Seen::now(self.master, &mut meter);
                        let out = node.update(&seen.view(&al, self.stats), false);
                        self.send(&client, out);
                    }
                }
            }
        }
    }

    /// NBIRTH and every live device's DBIRTH.
    fn births(
        &self,
        node: &mut Node,
        client: &AsyncClient,
        al: &BTreeMap<u8, (EcatState, u16)>,
        meter: &mut RateMeter,
    ) {
        let seen = Seen::now(self.master, meter);
        let out = node.birth(&seen.view(al, self.stats));
        let devices = out.len() - 1;
        self.send(client, out);
        self.stats.connected.store(1, Relaxed);
        if devices == 0 {
            info!("sparkplug: node born (NBIRTH); its devices are born once the network runs in OP with data flowing");
        } else {
            info!(devices, "sparkplug: node and {devices} devices born (NBIRTH, DBIRTH)");
        }
    }

    /// NDEATH, then the disconnect, both given [`GOODBYE`] to go out.
    async fn goodbye(&self, node: &Node, client: &AsyncClient, incoming: &mut mpsc::Receiver<Incoming>) {
        let death = node.death(now_ms()).encode_to_vec();
        let _ = client.try_publish(self.topics.node(Kind::NDeath), QoS::AtLeastOnce, false, death);
        let _ = client.try_disconnect();
        let _ = tokio::time::timeout(GOODBYE, async {
            while let Some(m) = incoming.recv().await {
                if matches!(m, Incoming::Lost(_)) {
                    break;
                }
            }
        })
        .await;
        self.stats.connected.store(0, Relaxed);
    }

    /// Applies an NCMD or DCMD; whether it asks for births.
    fn command(
        &self,
        node: &mut Node,
        writer: &mut Writer,
        role: Option<crate::config::Role>,
        topic: &str,
        payload: &[u8],
    ) -> bool {
        let Some((kind, device)) = self.topics.parse(topic) else { return false };
        let refused = |why: String| {
            self.stats.refused.fetch_add(1, Relaxed);
            warn!(topic, "sparkplug: {why}");
            false
        };
        let Ok(payload) = Payload::decode(payload) else {
            return refused(format!("{kind} refused: the payload is not a Sparkplug B payload"));
        };
        match (kind, device) {
            (Kind::NCmd, None) => match commands::node_command(node, role, &payload) {
                Ok(Action::Rebirth) => {
                    self.stats.commands.fetch_add(1, Relaxed);
                    info!("sparkplug: rebirth requested");
                    true
                }
                Ok(Action::None) => false,
                Err(e) => refused(e.0),
            },
            (Kind::DCmd, Some(device)) => {
                let Some(p) = topic::device_position(device) else {
                    return refused(format!("DCMD refused: no device {device:?} (devices are slave-<position>)"));
                };
                match commands::device_command(node, role, p, &payload, self.master, writer) {
                    Ok(n) => {
                        self.stats.commands.fetch_add(1, Relaxed);
                        info!(device, metrics = n, "sparkplug: DCMD written");
                        false
                    }
                    Err(e) => refused(e.0),
                }
            }
            _ => false,
        }
    }

    /// Hands messages to the client's queue; a full queue drops them.
    fn send(&self, client: &AsyncClient, out: Vec<Outgoing>) {
        for o in out {
            if let (Some(p), false) = (o.device, o.why.is_empty()) {
                info!(slave = p, "sparkplug: {} slave-{p}: {}", o.kind, o.why);
            }
            let topic = match o.device {
                None => self.topics.node(o.kind),
                Some(p) => self.topics.device(o.kind, &topic::device_id(p)),
            };
            match client.try_publish(topic, QoS::AtMostOnce, false, o.payload.encode_to_vec()) {
                Ok(()) => self.stats.published.fetch_add(1, Relaxed),
                Err(_) => self.stats.dropped.fetch_add(1, Relaxed),
            };
        }
    }
}
