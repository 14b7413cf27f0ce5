//! `Diagnostics` service: the event stream, the CoE emergency history, and
//! counters with per-slave AL status.

use std::sync::Arc;

use ecmxf_proto::v1 as pb;
use ecmxf_proto::v1::diagnostics_server::Diagnostics as DiagnosticsApi;
use tonic::{Request, Response, Status};

use super::auth::Role;
use super::bounded;
use super::convert::{phase_to_pb, state_to_pb};
use super::master::{counters_pb, list_slaves};
use super::status::{bad_argument, to_status};
use super::{BoxStream, Context};
use crate::master::diagnostics::{EmergencyRecord, HistoryError};
use crate::master::{Event, EventKind, al_status_text};

/// The `Diagnostics` service.
#[derive(Debug, Clone)]
pub(crate) struct DiagnosticsService(pub Arc<Context>);

fn emergency_pb(r: &EmergencyRecord) -> pb::Emergency {
    pb::Emergency {
        slave: r.slave.into(),
        number: r.number.into(),
        error_code: r.error_code.into(),
        error_register: r.error_register.into(),
        data: r.data.to_vec(),
        ..pb::Emergency::default()
    }
}

impl From<HistoryError> for Status {
    fn from(e: HistoryError) -> Self {
        match e {
            HistoryError::Engine(e) => to_status(e),
            HistoryError::Unreadable(_) => Status::internal(e.to_string()),
        }
    }
}

/// An engine event as a message: its sentence as `text`, its numbers in
/// the typed fields.
pub(crate) fn event_pb(e: &Event) -> pb::Event {
    use pb::EventKind as K;
    let mut out = pb::Event { time_ns: e.time_ns, text: e.kind.to_string(), ..pb::Event::default() };
    let kind = match &e.kind {
        EventKind::Phase(p) => {
            out.detail = phase_to_pb(*p).as_str_name().into();
            K::Phase
        }
        EventKind::EcatState { from, to } => {
            out.from_state = state_to_pb(*from) as i32;
            out.to_state = state_to_pb(*to) as i32;
            K::StateChange
        }
        EventKind::LinkPin(v) => {
            out.flag = *v;
            K::Link
        }
        EventKind::DcStable(v) => {
            out.flag = *v;
            K::DcStable
        }
        EventKind::CrcErrors { total } => {
            out.counter = *total;
            K::CrcErrors
        }
        EventKind::WkcErrors { total } => {
            out.counter = *total;
            K::WkcErrors
        }
        EventKind::FifoUnderrun => K::FifoUnderrun,
        EventKind::BringUpFailed(why) => {
            out.detail = why.to_string();
            K::BringUpFailed
        }
        EventKind::Recovering(why) => {
            out.detail = why.to_string();
            out.cause = why.name().into();
            K::Recovering
        }
        EventKind::Recovered { axes_disabled, outputs } => {
            out.counter = *axes_disabled as u64;
            out.detail = outputs.as_str().into();
            K::Recovered
        }
        EventKind::LastWriterGone(action) => {
            out.detail = action.as_str().into();
            K::LastWriterGone
        }
        EventKind::Lost(n) => {
            out.counter = *n;
            K::Lost
        }
        EventKind::Emergency(r) => {
            out.emergency = Some(emergency_pb(r));
            K::Emergency
        }
        EventKind::AlStatus { slave, state, code } => {
            out.slave = (*slave).into();
            out.to_state = state_to_pb(*state) as i32;
            out.al_status_code = (*code).into();
            out.detail = al_status_text(*code).into();
            K::AlStatus
        }
        EventKind::FramesDry { pushed, action } => {
            out.counter = *pushed;
            out.detail = action.as_str().into();
            K::FramesDry
        }
        EventKind::OutputLate { latency_us, .. } => {
            out.counter = (*latency_us).into();
            K::OutputLate
        }
        EventKind::ProcessData { flowing, age_us } => {
            out.flag = *flowing;
            out.counter = *age_us;
            K::ProcessData
        }
    };
    out.kind = kind as i32;
    out
}

#[tonic::async_trait]
impl DiagnosticsApi for DiagnosticsService {
    type StreamEventsStream = BoxStream<pb::Event>;

    async fn stream_events(
        &self,
        request: Request<pb::StreamEventsRequest>,
    ) -> Result<Response<Self::StreamEventsStream>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        // Read straight from the engine's broadcast: no task or buffer per
        // subscriber, so a subscriber that leaves (even on a quiet bus, with
        // no event to notice it by) leaves nothing behind.
        use tokio_stream::StreamExt as _;
        use tokio_stream::wrappers::errors::BroadcastStreamRecvError;
        let events = tokio_stream::wrappers::BroadcastStream::new(self.0.master.events()).map(|received| {
            Ok(match received {
                Ok(e) => event_pb(&e),
                Err(BroadcastStreamRecvError::Lagged(n)) => pb::Event {
                    kind: pb::EventKind::Lost as i32,
                    counter: n,
                    text: format!("{n} events missed"),
                    ..Default::default()
                },
            })
        });
        Ok(Response::new(self.0.serve_stream(&caller, Box::pin(events))))
    }

    async fn get_emergencies(
        &self,
        request: Request<pb::GetEmergenciesRequest>,
    ) -> Result<Response<pb::GetEmergenciesResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let n = match request.get_ref().count {
            0 => None,
            c @ 1..=8 => Some(c as u8),
            c => return Err(bad_argument("count", format!("{c} records; the chip keeps 1..=8"))),
        };
        let records = bounded(&caller, self.0.master.emergency_history(n, caller.call)).await?;
        let from =
            |source: &'static str, r: &EmergencyRecord| pb::Emergency { source: source.into(), ..emergency_pb(r) };
        let mut out: Vec<pb::Emergency> = records.iter().map(|r| from("chip", r)).collect();
        out.extend(self.0.master.mailbox_emergencies().iter().map(|r| from("mailbox", r)));
        Ok(Response::new(pb::GetEmergenciesResponse { emergencies: out }))
    }

    async fn get_counters(
        &self,
        request: Request<pb::GetCountersRequest>,
    ) -> Result<Response<pb::GetCountersResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let list = bounded(&caller, list_slaves(&self.0, false, caller.call)).await?;
        let slaves = list
            .slaves
            .into_iter()
            .map(|s| pb::SlaveDiagnosis {
                position: s.position,
                name: s.name,
                state: s.state,
                al_status_code: s.al_status_code,
                al_status_text: s.al_status_text,
            })
            .collect();
        Ok(Response::new(pb::GetCountersResponse { counters: Some(counters_pb(&self.0.master.status())), slaves }))
    }
}
