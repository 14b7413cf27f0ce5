//! `Foe` and `Registers` services (admin only): firmware files, raw
//! datagrams and ESC registers.

use std::sync::Arc;
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use ecmxf_proto::v1::foe_server::Foe as FoeApi;
use ecmxf_proto::v1::registers_server::Registers as RegistersApi;
use tonic::{Request, Response, Status};

use super::auth::Role;
use super::bounded;
use super::status::bad_argument;
use super::{BoxStream, Context};
use crate::master::TransferProgress;
use crate::master::transactions::{DatagramCommand, RawAnswer};

/// FoE transfers may take long: the default deadline when the client sets none.
const FOE_TIMEOUT: Duration = Duration::from_secs(120);
/// How often progress is reported.
const PROGRESS_EVERY: Duration = Duration::from_millis(50);

/// The `Foe` service.
#[derive(Debug, Clone)]
pub(crate) struct FoeService(pub Arc<Context>);

type ProgressStream = BoxStream<pb::FoeProgress>;

/// Runs a transfer in a task and streams its progress; the last message
/// carries the result. A client that goes away cancels the transfer (the
/// engine finishes or abandons the chip operation cleanly).
fn stream_transfer<F>(progress: Arc<TransferProgress>, work: F) -> ProgressStream
where
    F: std::future::Future<Output = Result<Vec<u8>, Status>> + Send + 'static,
{
    let (tx, rx) = tokio::sync::mpsc::channel(16);
    tokio::spawn(async move {
        let mut work = std::pin::pin!(work);
        let mut tick = tokio::time::interval(PROGRESS_EVERY);
        let mut last = (u32::MAX, u32::MAX);
        loop {
            tokio::select! {
                result = &mut work => {
                    let (done, total) = progress.get();
                    let msg = result.map(|data| pb::FoeProgress {
                        bytes_done: total.max(done).max(data.len() as u32),
                        bytes_total: total.max(data.len() as u32),
                        done: true,
                        data,
                    });
                    let _ = tx.send(msg).await;
                    return;
                }
                _ = tick.tick() => {
                    let now = progress.get();
                    if now != last {
                        last = now;
                        let msg = pb::FoeProgress { bytes_done: now.0, bytes_total: now.1, done: false, data: Vec::new() };
                        if tx.send(Ok(msg)).await.is_err() {
                            return; // Client gone: dropping `work` cancels it.
                        }
                    }
                }
            }
        }
    });
    Box::pin(tokio_stream::wrappers::ReceiverStream::new(rx))
}

#[tonic::async_trait]
impl FoeApi for FoeService {
    type WriteStream = ProgressStream;
    type ReadStream = ProgressStream;

    async fn write(&self, request: Request<pb::FoeWriteRequest>) -> Result<Response<ProgressStream>, Status> {
        let caller = self.0.authorize(&request, Role::Admin)?;
        let call = caller.call.or_within(FOE_TIMEOUT);
        let r = request.into_inner();
        let s = self.0.slave(r.slave)?;
        tracing::warn!(who = %caller.who, slave = s, name = %r.name, bytes = r.data.len(), "FoE write");
        let progress = Arc::new(TransferProgress::default());
        let ctx = Arc::clone(&self.0);
        let p = Arc::clone(&progress);
        let streamed_for = caller.clone();
        let work = async move {
            bounded(&caller, ctx.master.foe_write(s, &r.name, r.password, r.data, Some(p), call))
                .await
                .map(|()| Vec::new())
        };
        Ok(Response::new(self.0.serve_stream(&streamed_for, stream_transfer(progress, work))))
    }

    async fn read(&self, request: Request<pb::FoeReadRequest>) -> Result<Response<ProgressStream>, Status> {
        let caller = self.0.authorize(&request, Role::Admin)?;
        let call = caller.call.or_within(FOE_TIMEOUT);
        let r = request.into_inner();
        let s = self.0.slave(r.slave)?;
        if r.max_bytes == 0 {
            return Err(bad_argument("max_bytes", "0; give the largest file accepted"));
        }
        let progress = Arc::new(TransferProgress::default());
        let ctx = Arc::clone(&self.0);
        let p = Arc::clone(&progress);
        let streamed_for = caller.clone();
        let work = async move {
            bounded(&caller, ctx.master.foe_read(s, &r.name, r.password, r.max_bytes, Some(p), call)).await
        };
        Ok(Response::new(self.0.serve_stream(&streamed_for, stream_transfer(progress, work))))
    }
}

/// The `Registers` service.
#[derive(Debug, Clone)]
pub(crate) struct RegistersService(pub Arc<Context>);

fn u16_field(v: u32, field: &'static str) -> Result<u16, Status> {
    u16::try_from(v).map_err(|_| bad_argument(field, format!("{v:#x} is outside 0..=0xFFFF")))
}

fn answer_pb(a: RawAnswer) -> pb::DatagramResponse {
    pb::DatagramResponse { working_counter: a.working_counter.into(), data: a.data }
}

fn length_field(length: usize) -> Result<u16, Status> {
    u16::try_from(length).map_err(|_| bad_argument("length", format!("{length} bytes")))
}

#[tonic::async_trait]
impl RegistersApi for RegistersService {
    async fn datagram(&self, request: Request<pb::DatagramRequest>) -> Result<Response<pb::DatagramResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Admin)?;
        let r = request.into_inner();
        let command = match DatagramCommand::from_u8(u8::try_from(r.command).unwrap_or(0xFF)) {
            DatagramCommand::Other(c) => {
                return Err(bad_argument("command", format!("{c} is not a datagram command the chip sends")));
            }
            c => c,
        };
        let (adp, ado) = (u16_field(r.adp, "adp")?, u16_field(r.ado, "ado")?);
        let length = length_field(if command.writes() { r.data.len() } else { r.length as usize })?;
        let data = if command.writes() { r.data } else { Vec::new() };
        let a = bounded(&caller, self.0.master.datagram(command, adp, ado, length, data, caller.call)).await?;
        Ok(Response::new(answer_pb(a)))
    }

    async fn read_registers(
        &self,
        request: Request<pb::ReadRegistersRequest>,
    ) -> Result<Response<pb::DatagramResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Admin)?;
        let r = request.get_ref();
        let s = self.0.slave(r.slave)?;
        if r.length == 0 {
            return Err(bad_argument("length", "0 bytes"));
        }
        let address = u16_field(r.address, "address")?;
        let length = length_field(r.length as usize)?;
        let a = bounded(&caller, self.0.master.read_registers(s, address, length, caller.call)).await?;
        Ok(Response::new(answer_pb(a)))
    }

    async fn write_registers(
        &self,
        request: Request<pb::WriteRegistersRequest>,
    ) -> Result<Response<pb::DatagramResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Admin)?;
        let r = request.get_ref();
        let s = self.0.slave(r.slave)?;
        if r.data.is_empty() {
            return Err(bad_argument("data", "no bytes to write"));
        }
        let address = u16_field(r.address, "address")?;
        let data = r.data.clone();
        let a = bounded(&caller, self.0.master.write_registers(s, address, data, caller.call)).await?;
        Ok(Response::new(answer_pb(a)))
    }
}
