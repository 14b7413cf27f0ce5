//! `ProcessData` service: mapping, the named image, streamed inputs and
//! leased output writes.

use std::sync::Arc;
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use ecmxf_proto::v1::process_data_server::ProcessData as ProcessDataApi;
use tokio_stream::StreamExt;
use tonic::{Request, Response, Status, Streaming};

use super::auth::Role;
use super::bounded;
use super::convert::{encode_entry, existing_slave, pb_type};
use super::image::entry_value;
use super::leases;
use super::status::{bad_argument, to_status};
use super::{Context, NETWORK_WAIT};
use crate::config::PdoConfig;
use crate::master::entry_writes::{Staging, WriteError, output_entry};
use crate::master::image::{Entry, Image};
use crate::master::pdos::{PdoDescription, PdoSource};
use crate::master::{Call, EngineError};

/// The `ProcessData` service.
#[derive(Debug, Clone)]
pub(crate) struct ProcessDataService(pub Arc<Context>);

fn mapping_pb(list: &[PdoDescription]) -> Vec<pb::Pdo> {
    list.iter()
        .map(|p| pb::Pdo {
            index: p.index.into(),
            name: p.name.clone(),
            sync_manager: p.sync_manager.map(u32::from),
            entries: p
                .entries
                .iter()
                .map(|e| pb::PdoEntry {
                    index: e.index.into(),
                    subindex: e.subindex.into(),
                    bit_length: e.bits.into(),
                    name: e.name.clone(),
                    data_type: e.data_type.map_or(pb::DataType::Unspecified, pb_type) as i32,
                })
                .collect(),
        })
        .collect()
}

fn source_pb(s: PdoSource) -> pb::PdoSource {
    match s {
        PdoSource::Coe => pb::PdoSource::Coe,
        PdoSource::Sii => pb::PdoSource::Sii,
        PdoSource::Esi => pb::PdoSource::Esi,
        PdoSource::None => pb::PdoSource::None,
    }
}

fn pdos_from_pb(list: &[pb::Pdo], field: &'static str) -> Result<Vec<PdoConfig>, Status> {
    // Subindex 0 counts them in a byte; beyond PDO_CONFIG_SET's 3 PDOs of 8
    // entries, bring-up writes them over CoE.
    if list.len() > 254 {
        return Err(bad_argument(field, format!("{} PDOs; an assignment holds 254", list.len())));
    }
    if let Some(twice) =
        list.iter().enumerate().find_map(|(k, p)| list[..k].iter().any(|q| q.index == p.index).then_some(p.index))
    {
        return Err(bad_argument(field, format!("PDO {twice:#06x} is assigned twice")));
    }
    list.iter()
        .map(|p| {
            let index = u16::try_from(p.index).map_err(|_| bad_argument(field, format!("PDO index {:#x}", p.index)))?;
            if p.entries.len() > 254 {
                return Err(bad_argument(field, format!("PDO {index:#06x} has {} entries; 254 fit", p.entries.len())));
            }
            let entries = p
                .entries
                .iter()
                .map(|e| {
                    if e.index > 0xFFFF || e.subindex > 0xFF || e.bit_length == 0 || e.bit_length > 64 {
                        return Err(bad_argument(
                            field,
                            format!("entry {:#x}:{:#x} of {} bits is out of range", e.index, e.subindex, e.bit_length),
                        ));
                    }
                    Ok([e.index, e.subindex, e.bit_length])
                })
                .collect::<Result<Vec<_>, _>>()?;
            Ok(PdoConfig { index, entries })
        })
        .collect()
}

/// Applies client writes to the shadow image and sends the touched span as
/// one write under the lease (so it reaches the slaves in one frame). A bad
/// write rejects the whole request and changes nothing.
pub(crate) fn apply_writes(
    ctx: &Context,
    image: &Image,
    lease_id: &str,
    who: &str,
    writes: &[pb::OutputWrite],
) -> Result<(), Status> {
    if writes.is_empty() {
        return Ok(());
    }
    let mut staging = Staging::new(&ctx.master, image);
    for w in writes {
        let value = w.value.as_ref().ok_or_else(|| bad_argument("writes.value", "no value given"))?;
        match &w.target {
            Some(pb::output_write::Target::Entry(name)) => {
                let e = output_entry(image, name).map_err(write_status)?;
                let bytes = encode_entry(e, value)
                    .map_err(|(_, why)| bad_argument("writes.value", format!("entry {name:?}: {why}")))?;
                staging.entry(e, &bytes).map_err(write_status)?;
            }
            Some(pb::output_write::Target::Offset(o)) => {
                let Some(pb::value::Kind::Raw(bytes)) = &value.kind else {
                    return Err(bad_argument("writes.value", "a write by offset takes raw bytes"));
                };
                staging.raw(*o as usize, bytes).map_err(write_status)?;
            }
            None => return Err(bad_argument("writes.target", "give an entry name or an offset")),
        }
    }
    staging.commit(ctx.master.leases(), lease_id, who).map_err(write_status)
}

/// The status of a refused write: the caller's field INVALID_ARGUMENT, a
/// span another stream or the CiA 402 helper owns FAILED_PRECONDITION, the
/// lease's own codes.
fn write_status(e: WriteError) -> Status {
    match e {
        WriteError::Lease(e) => leases::status(e),
        e => match e.field() {
            Some(field) => bad_argument(field, e.to_string()),
            None => Status::failed_precondition(e.to_string()),
        },
    }
}

type SampleStream = super::BoxStream<pb::InputSample>;

/// Keeps a stream from falling behind silently: a sample older than the
/// bound when its turn comes is dropped (and counted as lost by the
/// caller), so what a slow subscriber gets is always recent, never a queue
/// of seconds-old frames.
#[derive(Clone, Copy, Debug)]
pub(crate) struct AgeGate {
    max_age_ns: u64,
}

impl AgeGate {
    /// A gate that admits samples up to `max_age` old.
    pub(crate) fn new(max_age: Duration) -> Self {
        Self { max_age_ns: max_age.as_nanos() as u64 }
    }

    /// Whether a frame received at `time_ns` may still go out at `now_ns`
    /// (both on the engine's clock).
    pub(crate) fn admit(&self, time_ns: u64, now_ns: u64) -> bool {
        now_ns.saturating_sub(time_ns) <= self.max_age_ns
    }
}

#[tonic::async_trait]
impl ProcessDataApi for ProcessDataService {
    async fn get_mapping(
        &self,
        request: Request<pb::GetMappingRequest>,
    ) -> Result<Response<pb::GetMappingResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let m = &self.0.master;
        let count = m.layout().slaves.len();
        let which: Vec<u8> = match request.get_ref().slave {
            Some(s) => vec![existing_slave(m, s, "slave")?],
            None => (0..count as u8).collect(),
        };
        let image = bounded(&caller, m.image(caller.call)).await?;
        let slaves = which
            .into_iter()
            .filter_map(|s| image.mappings.get(usize::from(s)).map(|p| (s, p)))
            .map(|(s, p)| pb::SlaveMapping {
                slave: s.into(),
                rx_pdos: mapping_pb(&p.rx),
                tx_pdos: mapping_pb(&p.tx),
                source: source_pb(p.source) as i32,
                note: p.note.clone(),
                names_from: p.names_from.as_str().to_string(),
            })
            .collect();
        Ok(Response::new(pb::GetMappingResponse { slaves }))
    }

    async fn set_mapping(
        &self,
        request: Request<pb::SetMappingRequest>,
    ) -> Result<Response<pb::SetMappingResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let mapping = request.get_ref().mapping.clone().ok_or_else(|| bad_argument("mapping", "no mapping given"))?;
        let m = &self.0.master;
        let s = usize::from(existing_slave(m, mapping.slave, "mapping.slave")?);
        let count = m.layout().slaves.len().max(s + 1);
        let rx = pdos_from_pb(&mapping.rx_pdos, "mapping.rx_pdos")?;
        let tx = pdos_from_pb(&mapping.tx_pdos, "mapping.tx_pdos")?;
        let previous = m.config();
        let mut config = previous.clone();
        // An expected-network list shorter than the ring would be read as
        // "fewer slaves expected": pad it with "any slave" entries.
        if config.slaves.len() < count {
            config.slaves.resize_with(count, Default::default);
        }
        config.slaves[s].rx_pdos = rx;
        config.slaves[s].tx_pdos = tx;
        tracing::info!(who = %caller.who, slave = s, "PDO mapping change");
        let call = caller.call.or_within(NETWORK_WAIT);
        if let Err(e) = bounded(&caller, m.apply_config(config, call)).await {
            // Never leave the bus down on a mapping the slave refused: go
            // back to the configuration that ran.
            tracing::warn!(who = %caller.who, slave = s, "PDO mapping refused ({}); restoring the previous one", e.message());
            // The daemon's repair, whatever the caller's deadline.
            let restored = m.apply_config(previous, Call::anonymous(Some(NETWORK_WAIT))).await;
            let how = if restored.is_ok() {
                "the previous mapping is back"
            } else {
                "restoring the previous mapping failed too"
            };
            return Err(Status::new(e.code(), format!("{}; {how}", e.message())));
        }
        let image = m.image(Call::anonymous(None)).await.map_err(to_status)?;
        Ok(Response::new(pb::SetMappingResponse { image: Some(super::image::to_pb(&image)) }))
    }

    async fn read_outputs(
        &self,
        request: Request<pb::ReadOutputsRequest>,
    ) -> Result<Response<pb::OutputImage>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let image = bounded(&caller, self.0.master.image(caller.call)).await?;
        // Each value named as asked for: by entry or by variable name.
        let mut selected: Vec<(&String, &Entry)> = Vec::with_capacity(request.get_ref().entries.len());
        for name in &request.get_ref().entries {
            let e = image.get(name).ok_or_else(|| bad_argument("entries", format!("no entry {name:?}")))?;
            if !e.output {
                return Err(bad_argument("entries", format!("{name:?} is an input (see StreamInputs)")));
            }
            selected.push((name, e));
        }
        let mut bytes = self.0.master.output_shadow().clone();
        bytes.resize(image.output_bytes as usize, 0);
        let values = selected
            .into_iter()
            .map(|(name, e)| pb::EntryValue { name: name.clone(), value: Some(super::image::entry_value(e, &bytes)) })
            .collect();
        Ok(Response::new(pb::OutputImage { image: bytes, values }))
    }

    async fn get_layout(&self, request: Request<pb::GetLayoutRequest>) -> Result<Response<pb::ProcessImage>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let image = bounded(&caller, self.0.master.image(caller.call)).await?;
        Ok(Response::new(super::image::to_pb(&image)))
    }

    type StreamInputsStream = SampleStream;

    async fn stream_inputs(
        &self,
        request: Request<pb::StreamInputsRequest>,
    ) -> Result<Response<Self::StreamInputsStream>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let r = request.into_inner();
        let image = bounded(&caller, self.0.master.image(caller.call)).await?;
        if image.input_bytes == 0 {
            // No input frame will ever come: say so instead of a stream
            // that never yields (an output-only network).
            return Err(EngineError::WrongState(crate::master::WrongState::NoInputs).into());
        }
        let mut selected: Vec<Entry> = Vec::with_capacity(r.entries.len());
        for name in &r.entries {
            let e = image.get(name).ok_or_else(|| bad_argument("entries", format!("no entry {name:?}")))?;
            // Its values are named as asked for: by entry or variable name.
            selected.push(Entry { name: name.clone(), ..e.clone() });
        }
        // Straight from the broadcast channel to the HTTP/2 stream: no task
        // and no queue in between, so a frame costs one wake-up per
        // subscriber on its way out.
        let decimation = u64::from(r.decimation.max(1));
        let on_change = r.on_change;
        let master = Arc::clone(&self.0.master);
        let epoch = master.epoch_monotonic_ns();
        let mut n = 0u64;
        let mut lost = 0u64;
        let mut gap = 0u64;
        let fresh = AgeGate::new(self.0.stream_max_age);
        let mut last: Option<Vec<u8>> = None;
        let frames = tokio_stream::wrappers::BroadcastStream::new(master.subscribe());
        let samples = frames.filter_map(move |frame| {
            let frame = match frame {
                Ok(f) => f,
                Err(tokio_stream::wrappers::errors::BroadcastStreamRecvError::Lagged(k)) => {
                    lost += k;
                    return None;
                }
            };
            // Frames the daemon never received are told with the next
            // sample, whatever is skipped in between.
            gap += frame.gap;
            if !fresh.admit(frame.time_ns, master.now_ns()) {
                lost += 1;
                return None;
            }
            n += 1;
            if n % decimation != 0 {
                return None;
            }
            let input = &frame.data;
            if on_change {
                let key: Vec<u8> = if selected.is_empty() {
                    input.clone()
                } else {
                    selected
                        .iter()
                        .flat_map(|e| crate::master::image::read_bits(input, e.bit_offset, e.bit_length))
                        .collect()
                };
                if last.as_ref() == Some(&key) {
                    return None;
                }
                last = Some(key);
            }
            let (image, values) = if selected.is_empty() {
                (input.clone(), Vec::new())
            } else {
                let values = selected
                    .iter()
                    .map(|e| pb::EntryValue { name: e.name.clone(), value: Some(entry_value(e, input)) })
                    .collect();
                (Vec::new(), values)
            };
            let sample = pb::InputSample {
                seq: frame.seq,
                time_ns: frame.time_ns,
                image,
                values,
                lost: std::mem::take(&mut lost),
                monotonic_ns: epoch + frame.time_ns,
                gap: std::mem::take(&mut gap),
            };
            Some(Ok(sample))
        });
        Ok(Response::new(self.0.serve_stream(&caller, Box::pin(super::paced::Paced::new(samples)))))
    }

    async fn acquire_lease(&self, request: Request<pb::AcquireLeaseRequest>) -> Result<Response<pb::Lease>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let r = request.get_ref();
        let ttl = match r.ttl_ms {
            0 => None,
            100..=60_000 => Some(Duration::from_millis(r.ttl_ms.into())),
            v => return Err(bad_argument("ttl_ms", format!("{v} ms is outside 100..=60000"))),
        };
        let m = &self.0.master;
        let slaves = r.slaves.iter().map(|&s| existing_slave(m, s, "slaves")).collect::<Result<Vec<u8>, _>>()?;
        let lease = self.0.master.acquire_lease(&slaves, ttl, &caller.who).map_err(leases::status)?;
        self.0.note_lease_holder(&caller);
        Ok(Response::new(leases::to_pb(&lease)))
    }

    async fn keep_alive(&self, request: Request<pb::KeepAliveRequest>) -> Result<Response<pb::Lease>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let lease =
            self.0.master.leases().keep_alive(&request.get_ref().lease_id, &caller.who).map_err(leases::status)?;
        Ok(Response::new(leases::to_pb(&lease)))
    }

    async fn release_lease(
        &self,
        request: Request<pb::ReleaseLeaseRequest>,
    ) -> Result<Response<pb::ReleaseLeaseResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        // An admin may break another identity's lease (logged with both).
        let may_break = caller.role >= Role::Admin;
        self.0.master.leases().release(&request.get_ref().lease_id, &caller.who, may_break).map_err(leases::status)?;
        Ok(Response::new(pb::ReleaseLeaseResponse {}))
    }

    async fn write_outputs(
        &self,
        request: Request<pb::WriteOutputsRequest>,
    ) -> Result<Response<pb::WriteOutputsResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let image = bounded(&caller, self.0.master.image(caller.call)).await?;
        let r = request.get_ref();
        apply_writes(&self.0, &image, &r.lease_id, &caller.who, &r.writes)?;
        Ok(Response::new(pb::WriteOutputsResponse { applied: 1 }))
    }

    type StreamFramesStream = super::BoxStream<pb::FrameReport>;

    async fn stream_frames(
        &self,
        request: Request<Streaming<pb::FrameBatch>>,
    ) -> Result<Response<Self::StreamFramesStream>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let frames = super::frames::serve(Arc::clone(&self.0), caller.who.clone(), request.into_inner()).await?;
        Ok(Response::new(self.0.serve_stream(&caller, frames)))
    }

    async fn stream_outputs(
        &self,
        request: Request<Streaming<pb::WriteOutputsRequest>>,
    ) -> Result<Response<pb::WriteOutputsResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let image = bounded(&caller, self.0.master.image(caller.call)).await?;
        let mut stream = request.into_inner();
        let mut applied = 0;
        while let Some(msg) = stream.next().await {
            let msg = msg?;
            apply_writes(&self.0, &image, &msg.lease_id, &caller.who, &msg.writes)?;
            applied += 1;
        }
        Ok(Response::new(pb::WriteOutputsResponse { applied }))
    }
}

#[cfg(test)]
mod age_tests {
    use super::*;

    #[test]
    fn samples_older_than_the_bound_are_not_sent() {
        let g = AgeGate::new(Duration::from_millis(100));
        assert!(g.admit(1_000_000, 1_000_000));
        assert!(g.admit(1_000_000, 101_000_000), "exactly the bound");
        assert!(!g.admit(1_000_000, 101_000_001));
        assert!(g.admit(5_000_000, 1_000_000), "a clock read before the frame is not an age");
    }
}
