//! The daemon's node manager: the address space ([`super::space`]) kept
//! in memory, its values read when asked, and the two things a client does
//! to the plant (writing an output, calling a method) done with the
//! session's identity, which async-opcua's ready-made manager never sees.
//!
//! - Reads and monitored items call the node's reading: a closure over
//!   what the engine already publishes (input frame, output shadow,
//!   status). Monitored items are sampled by the library's sampler at
//!   their interval; nothing runs per input frame.
//! - Writes to an output variable go to [`super::writes`]: under the
//!   session's output lease, as the session's role allows.
//! - Method calls go to [`super::methods`]: SDO transfers and state
//!   requests, awaited on the master's door like a gRPC call's.

use std::collections::{HashMap, HashSet};
use std::sync::atomic::Ordering::Relaxed;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use async_trait::async_trait;
use opcua::server::address_space::{AddressSpace, HasNodeId, NodeType, read_node_value};
use opcua::server::diagnostics::NamespaceMetadata;
use opcua::server::node_manager::memory::{
    InMemoryNodeManager, InMemoryNodeManagerBuilder, InMemoryNodeManagerImpl, InMemoryNodeManagerImplBuilder,
};
use opcua::server::node_manager::{
    MethodCall, MonitoredItemRef, MonitoredItemUpdateRef, NodeManagerBuilder, ParsedReadValueId, RequestContext,
    ServerContext, SyncSampler, WriteNode,
};
use opcua::server::{CreateMonitoredItem, MonitoredItemHandle, address_space};
use opcua::sync::RwLock;
use opcua::types::{AttributeId, DataValue, MonitoringMode, NodeId, NumericRange, StatusCode, TimestampsToReturn};

use super::access::Access;
use super::dictionary::{self, DictionaryEntry, Uploaded};
use super::methods::{self, Method};
use super::refusal::Refusal;
use super::writes::{OutputTarget, SessionLeases};
use crate::master::Master;
use crate::master::opcua_state::OpcuaState;

/// The fastest a monitored item is sampled, ms: the sampler's tick.
pub(super) const SAMPLING_FLOOR_MS: f64 = 50.0;

/// A node's value as it is now.
pub(super) type Reading = Arc<dyn Fn() -> DataValue + Send + Sync>;

/// The daemon's node manager.
pub(super) type Plant = InMemoryNodeManager<PlantImpl>;

/// Builds [`Plant`] for a server of `master`'s, its nodes in namespace
/// `uri`.
pub(super) fn plant(uri: &'static str, master: Arc<Master>, access: Arc<Access>) -> impl NodeManagerBuilder {
    InMemoryNodeManagerBuilder::new(PlantBuilder { uri, master, access })
}

struct PlantBuilder {
    uri: &'static str,
    master: Arc<Master>,
    access: Arc<Access>,
}

impl InMemoryNodeManagerImplBuilder for PlantBuilder {
    type Impl = PlantImpl;

    fn build(self, context: ServerContext, address_space: &mut AddressSpace) -> PlantImpl {
        let index = context.type_tree.write().namespaces_mut().add_namespace(self.uri);
        address_space.add_namespace(self.uri, index);
        let namespace =
            NamespaceMetadata { namespace_uri: self.uri.into(), namespace_index: index, ..Default::default() };
        PlantImpl {
            namespaces: vec![namespace],
            readings: RwLock::new(HashMap::new()),
            outputs: RwLock::new(HashMap::new()),
            methods: RwLock::new(HashMap::new()),
            dictionary: RwLock::new(HashMap::new()),
            uploaded: Uploaded::default(),
            samplers: SyncSampler::new(),
            tick_ms: std::sync::atomic::AtomicU64::new(SAMPLING_FLOOR_MS as u64),
            leases: SessionLeases::new(Arc::clone(&self.master)),
            counters: Arc::clone(self.master.opcua_state()),
            watched: Mutex::new(HashSet::new()),
            master: self.master,
            access: self.access,
        }
    }
}

/// What the daemon's nodes do when read, written or called.
pub(crate) struct PlantImpl {
    namespaces: Vec<NamespaceMetadata>,
    readings: RwLock<HashMap<NodeId, Reading>>,
    outputs: RwLock<HashMap<NodeId, OutputTarget>>,
    methods: RwLock<HashMap<NodeId, Method>>,
    /// Dictionary entries, read and written over SDO.
    dictionary: RwLock<HashMap<NodeId, DictionaryEntry>>,
    /// Their values uploaded last (a Read with a MaxAge takes them).
    uploaded: Uploaded,
    samplers: SyncSampler,
    /// The sampler's tick, ms.
    tick_ms: std::sync::atomic::AtomicU64,
    leases: SessionLeases,
    /// Sessions, items, samples, writes and calls, for the metrics.
    counters: Arc<OpcuaState>,
    /// The monitored items sampled, by handle.
    watched: Mutex<HashSet<MonitoredItemHandle>>,
    master: Arc<Master>,
    access: Arc<Access>,
}

impl PlantImpl {
    /// `id` reads as `reading` gives it.
    pub(super) fn read_by(&self, id: NodeId, reading: Reading) {
        self.readings.write().insert(id, reading);
    }

    /// `id` is an output entry: writable as `target` says.
    pub(super) fn write_to(&self, id: NodeId, target: OutputTarget) {
        self.outputs.write().insert(id, target);
    }

    /// `id` is a method doing `method`.
    pub(super) fn calls(&self, id: NodeId, method: Method) {
        self.methods.write().insert(id, method);
    }

    /// `entries` are dictionary entries: read and written over SDO.
    pub(super) fn read_from_device(&self, entries: Vec<(NodeId, DictionaryEntry)>) {
        self.dictionary.write().extend(entries);
    }

    /// Forgets what the nodes `ids` did (they were removed).
    pub(super) fn forget(&self, ids: &[NodeId]) {
        {
            let (mut r, mut o, mut m) = (self.readings.write(), self.outputs.write(), self.methods.write());
            let mut d = self.dictionary.write();
            for id in ids {
                r.remove(id);
                o.remove(id);
                m.remove(id);
                d.remove(id);
            }
        }
        self.uploaded.forget(ids);
    }

    /// What the sampler is told for an item sampled every `interval_ms`.
    /// It samples on its ticks, skipping a tick less than the interval
    /// after the last sample; a tick a hair early would skip a whole
    /// period (a 100 ms item sampled every 150 ms). Half a tick of slack
    /// keeps it on the period.
    fn sampled_every(&self, interval_ms: f64) -> Duration {
        let tick = self.tick_ms.load(Relaxed) as f64;
        Duration::from_micros(((interval_ms - tick / 2.0).max(tick / 2.0) * 1000.0) as u64)
    }

    /// Counts item `handle` in or out of the monitored items.
    fn note_watched(&self, handle: MonitoredItemHandle, added: bool) {
        let mut watched = self.watched.lock().unwrap_or_else(|e| e.into_inner());
        if added {
            watched.insert(handle);
        } else {
            watched.remove(&handle);
        }
        self.counters.monitored_items.store(watched.len() as u64, Relaxed);
    }

    /// The session leases (kept alive and ended by [`super::serve`]).
    pub(super) fn leases(&self) -> &SessionLeases {
        &self.leases
    }

    fn read_one(
        &self,
        ctx: &RequestContext,
        space: &AddressSpace,
        n: &ParsedReadValueId,
        max_age: f64,
        timestamps: TimestampsToReturn,
    ) -> DataValue {
        let Some(node) = space.find(&n.node_id) else {
            return DataValue { status: Some(StatusCode::BadNodeIdUnknown), ..Default::default() };
        };
        if let Err(e) = address_space::validate_node_read(node, ctx, n) {
            return DataValue { status: Some(e), ..Default::default() };
        }
        if n.attribute_id == AttributeId::Value
            && let Some(reading) = self.readings.read().get(&n.node_id)
        {
            // Every value read this way is a scalar: no range of it exists.
            if n.index_range != NumericRange::None {
                return DataValue { status: Some(StatusCode::BadIndexRangeNoData), ..Default::default() };
            }
            return stamped(reading(), timestamps);
        }
        read_node_value(node, ctx, n, max_age, timestamps)
    }
}

/// `v` with the timestamps a client asked for (OPC 10000-4 5.10.2.2).
fn stamped(mut v: DataValue, timestamps: TimestampsToReturn) -> DataValue {
    match timestamps {
        TimestampsToReturn::Source => (v.server_timestamp, v.server_picoseconds) = (None, None),
        TimestampsToReturn::Server => (v.source_timestamp, v.source_picoseconds) = (None, None),
        TimestampsToReturn::Both => {}
        TimestampsToReturn::Neither | TimestampsToReturn::Invalid => {
            (v.source_timestamp, v.source_picoseconds, v.server_timestamp, v.server_picoseconds) =
                (None, None, None, None)
        }
    }
    v
}

#[async_trait]
impl InMemoryNodeManagerImpl for PlantImpl {
    async fn init(&self, _space: &mut AddressSpace, context: ServerContext) {
        // The sampler's tick: the fastest any monitored item is sampled
        // (docs/opcua.md, "Subscriptions").
        let tick = context.info.config.limits.subscriptions.min_sampling_interval_ms.max(SAMPLING_FLOOR_MS);
        self.tick_ms.store(tick as u64, Relaxed);
        self.samplers.run(Duration::from_micros((tick * 1000.0) as u64), context.subscriptions.clone());
    }

    fn namespaces(&self) -> Vec<NamespaceMetadata> {
        self.namespaces.clone()
    }

    fn name(&self) -> &str {
        "ecmxfd"
    }

    async fn read_values(
        &self,
        context: &RequestContext,
        space: &RwLock<AddressSpace>,
        nodes: &[&ParsedReadValueId],
        max_age: f64,
        timestamps: TimestampsToReturn,
    ) -> Vec<DataValue> {
        // Dictionary entries are read from the device (an SDO upload,
        // awaited with the address space unlocked) unless a value young
        // enough for `max_age` was uploaded.
        let mut out = Vec::with_capacity(nodes.len());
        let mut from_device = Vec::new();
        {
            let space = space.read();
            let dictionary = self.dictionary.read();
            for (i, n) in nodes.iter().enumerate() {
                let entry = dictionary.get(&n.node_id).filter(|_| n.attribute_id == AttributeId::Value);
                let Some(&entry) = entry else {
                    out.push(self.read_one(context, &space, n, max_age, timestamps));
                    continue;
                };
                let checked = match space.find(&n.node_id) {
                    None => Err(StatusCode::BadNodeIdUnknown),
                    Some(node) => address_space::validate_node_read(node, context, n),
                };
                // Every entry is a scalar: no range of it exists.
                let checked = checked.and(match n.index_range {
                    NumericRange::None => Ok(()),
                    _ => Err(StatusCode::BadIndexRangeNoData),
                });
                if let Err(e) = checked {
                    out.push(DataValue { status: Some(e), ..Default::default() });
                    continue;
                }
                let young = Duration::from_secs_f64(max_age.clamp(0.0, 1e9) / 1000.0);
                match self.uploaded.within(&n.node_id, young).filter(|_| max_age > 0.0) {
                    Some(v) => out.push(stamped(v, timestamps)),
                    None => {
                        out.push(DataValue::null());
                        from_device.push((i, entry, n.node_id.clone()));
                    }
                }
            }
        }
        let client = methods::client(context.session_id);
        for (i, entry, id) in from_device {
            let v = dictionary::upload(&self.master, entry, client).await;
            if v.status().is_good() {
                self.uploaded.store(id, v.clone());
            }
            out[i] = stamped(v, timestamps);
        }
        out
    }

    async fn create_value_monitored_items(
        &self,
        context: &RequestContext,
        space: &RwLock<AddressSpace>,
        items: &mut [&mut &mut CreateMonitoredItem],
    ) {
        let wanted: Vec<_> = items.iter().map(|i| i.item_to_monitor()).collect();
        let values = self.read_values(context, space, &wanted, 0.0, TimestampsToReturn::Both).await;
        let readings = self.readings.read();
        for (value, item) in values.into_iter().zip(items.iter_mut()) {
            if value.status() != StatusCode::BadAttributeIdInvalid {
                item.set_initial_value(value);
            }
            item.set_status(StatusCode::Good);
            let watched = item.item_to_monitor();
            if watched.attribute_id != AttributeId::Value {
                continue;
            }
            if let Some(reading) = readings.get(&watched.node_id).cloned() {
                let every = self.sampled_every(item.sampling_interval());
                self.note_watched(item.handle(), true);
                let counters = Arc::clone(&self.counters);
                self.samplers.add_sampler(
                    watched.node_id.clone(),
                    AttributeId::Value,
                    move || {
                        counters.samples.fetch_add(1, Relaxed);
                        Some(reading())
                    },
                    item.monitoring_mode(),
                    item.handle(),
                    every,
                );
            }
        }
    }

    async fn modify_monitored_items(&self, _context: &RequestContext, items: &[&MonitoredItemUpdateRef]) {
        for it in items {
            let every = self.sampled_every(it.update().revised_sampling_interval);
            self.samplers.update_sampler(it.node_id(), it.attribute(), it.handle(), every);
        }
    }

    async fn set_monitoring_mode(&self, _context: &RequestContext, mode: MonitoringMode, items: &[&MonitoredItemRef]) {
        for it in items {
            self.samplers.set_sampler_mode(it.node_id(), it.attribute(), it.handle(), mode);
        }
    }

    async fn delete_monitored_items(&self, _context: &RequestContext, items: &[&MonitoredItemRef]) {
        for it in items {
            self.samplers.remove_sampler(it.node_id(), it.attribute(), it.handle());
            self.note_watched(it.handle(), false);
        }
    }

    async fn write(
        &self,
        context: &RequestContext,
        space: &RwLock<AddressSpace>,
        nodes: &mut [&mut WriteNode],
    ) -> Result<(), StatusCode> {
        for w in nodes.iter_mut() {
            // The checks every server makes (the node exists, its access
            // level for this user, the value's type) before ours.
            let checked = {
                let space = space.read();
                let type_tree = context.type_tree.read();
                match space.find(&w.value().node_id) {
                    None => Err(StatusCode::BadNodeIdUnknown),
                    Some(node) => check_write(context, node, w, &*type_tree),
                }
            };
            if let Err(e) = checked {
                self.counters.refused.fetch_add(1, Relaxed);
                w.set_status(e);
                if e == StatusCode::BadUserAccessDenied {
                    let token = context.user_token();
                    let who =
                        if token.is_anonymous() { "an anonymous session".into() } else { format!("user {}", token.0) };
                    let role = self.access.role(token).map_or("refused".into(), |r| r.to_string());
                    let refusal = Refusal::denied(format!("writing needs the operator role; {who} is {role}"));
                    w.set_diagnostic_info(refusal.diagnostic());
                }
                continue;
            }
            let entry = self.dictionary.read().get(&w.value().node_id).copied();
            if let Some(entry) = entry {
                let client = methods::client(context.session_id);
                match dictionary::download(&self.master, entry, client, &w.value().value).await {
                    Ok(()) => {
                        self.counters.writes.fetch_add(1, Relaxed);
                        w.set_status(StatusCode::Good);
                    }
                    Err(refusal) => {
                        self.counters.refused.fetch_add(1, Relaxed);
                        tracing::info!(user = %context.user_token().0, "OPC UA dictionary write refused: {}", refusal.why);
                        w.set_status(refusal.status);
                        w.set_diagnostic_info(refusal.diagnostic());
                    }
                }
                continue;
            }
            let target = self.outputs.read().get(&w.value().node_id).cloned();
            let Some(target) = target else {
                w.set_status(StatusCode::BadNotWritable);
                continue;
            };
            match self.leases.write(context, &target, &w.value().value).await {
                Ok(()) => {
                    self.counters.writes.fetch_add(1, Relaxed);
                    w.set_status(StatusCode::Good);
                }
                Err(refusal) => {
                    self.counters.refused.fetch_add(1, Relaxed);
                    tracing::info!(user = %context.user_token().0, entry = %target.name(), "OPC UA write refused: {}", refusal.why);
                    w.set_status(refusal.status);
                    w.set_diagnostic_info(refusal.diagnostic());
                }
            }
        }
        Ok(())
    }

    async fn call(
        &self,
        context: &RequestContext,
        _space: &RwLock<AddressSpace>,
        calls: &mut [&mut &mut MethodCall],
    ) -> Result<(), StatusCode> {
        for call in calls.iter_mut() {
            let method = self.methods.read().get(call.method_id()).copied();
            let Some(method) = method else {
                call.set_status(StatusCode::BadMethodInvalid);
                continue;
            };
            let role = self.access.role(context.user_token());
            match methods::run(&self.master, &self.leases, context, method, role, call.arguments()).await {
                Ok(outputs) => {
                    self.counters.calls.fetch_add(1, Relaxed);
                    call.set_outputs(outputs);
                    call.set_status(StatusCode::Good);
                }
                Err(refusal) => {
                    self.counters.refused.fetch_add(1, Relaxed);
                    tracing::info!(user = %context.user_token().0, method = ?method, "OPC UA call refused: {}", refusal.why);
                    if let Some(bad) = refusal.argument {
                        let mut results = vec![StatusCode::Good; call.arguments().len()];
                        if let Some(r) = results.get_mut(bad) {
                            *r = refusal.status;
                        }
                        call.set_argument_error(results);
                    }
                    call.set_status(refusal.status);
                    call.set_diagnostic_info(refusal.diagnostic());
                }
            }
        }
        Ok(())
    }
}

/// What the library checks of a write to a value (the node is a variable,
/// the user's access level lets them write, the value has its type), for
/// the Value attribute only: no other attribute of the daemon's nodes is
/// writable.
fn check_write(
    context: &RequestContext,
    node: &NodeType,
    w: &WriteNode,
    type_tree: &dyn opcua::nodes::TypeTree,
) -> Result<(), StatusCode> {
    let write = w.value();
    let NodeType::Variable(variable) = node else { return Err(StatusCode::BadNotWritable) };
    if write.attribute_id != AttributeId::Value || write.index_range != NumericRange::None {
        return Err(StatusCode::BadNotWritable);
    }
    // Read-only for everyone (inputs, counters) is not a matter of who
    // asks.
    if !variable.access_level().contains(opcua::server::address_space::AccessLevel::CURRENT_WRITE) {
        return Err(StatusCode::BadNotWritable);
    }
    address_space::is_writable(context, node, write.attribute_id)?;
    let Some(value) = &write.value.value else { return Err(StatusCode::BadNothingToDo) };
    address_space::validate_value_to_write(variable, value, type_tree)?;
    debug_assert_eq!(node.node_id(), &write.node_id);
    Ok(())
}
