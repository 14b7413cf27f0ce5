//! `Peripherals` service: the chip's GPIO, ADC, DAC and encoder input.

use std::sync::Arc;
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use ecmxf_proto::v1::peripherals_server::Peripherals as PeripheralsApi;
use ecmxf_wire::flags::GpioMask;
use ecmxf_wire::payload::gpio::{GpioConfig, GpioFunc, GpioMode, GpioPull};
use ecmxf_wire::payload::periph::{AdcInput, AdcOp, DacOp, DacTrigger, QeiMode, QeiOp};
use tonic::{Request, Response, Status};

use super::Context;
use super::auth::Role;
use super::bounded;
use super::status::{bad_argument, to_status};

use crate::master::transactions::Immediate;

/// Lines 0..=19.
const ALL_LINES: u32 = 0x000F_FFFF;

/// The `Peripherals` service.
#[derive(Debug, Clone)]
pub struct PeripheralsService(pub Arc<Context>);

fn word(data: &[u8]) -> u32 {
    let mut b = [0u8; 4];
    let n = data.len().min(4);
    b[..n].copy_from_slice(&data[..n]);
    u32::from_le_bytes(b)
}

fn lines(v: u32, field: &'static str) -> Result<u32, Status> {
    if v & !ALL_LINES != 0 {
        return Err(bad_argument(field, format!("{v:#x} names lines above 19")));
    }
    Ok(v)
}

impl PeripheralsService {
    async fn call(&self, c: Immediate, t: Option<Duration>) -> Result<Vec<u8>, Status> {
        self.0.master.immediate(c, t).await.map(|(_, d)| d).map_err(to_status)
    }

    async fn levels(&self, t: Option<Duration>) -> Result<pb::GpioLevels, Status> {
        let levels = word(&self.call(Immediate::Gpio(GpioFunc::ExtGetValue), t).await?);
        let flags = word(&self.call(Immediate::Gpio(GpioFunc::ExtGetIntFlag), t).await?);
        Ok(pb::GpioLevels { levels: levels & ALL_LINES, interrupt_flags: flags & ALL_LINES })
    }
}

#[tonic::async_trait]
impl PeripheralsApi for PeripheralsService {
    async fn configure_gpio(
        &self,
        request: Request<pb::ConfigureGpioRequest>,
    ) -> Result<Response<pb::ConfigureGpioResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let r = request.get_ref();
        let l = lines(r.lines, "lines")?;
        let mode = match pb::GpioMode::try_from(r.mode) {
            Ok(pb::GpioMode::Input) => GpioMode::Input,
            Ok(pb::GpioMode::Output) => GpioMode::Output,
            Ok(pb::GpioMode::OpenDrain) => GpioMode::OpenDrain,
            Ok(pb::GpioMode::QuasiBidirectional) => GpioMode::QuasiBidirectional,
            _ => return Err(bad_argument("mode", format!("{} is not a GpioMode", r.mode))),
        };
        let pull = match pb::GpioPull::try_from(r.pull) {
            Ok(pb::GpioPull::Unspecified | pb::GpioPull::None) => GpioPull::None,
            Ok(pb::GpioPull::Up) => GpioPull::Up,
            Ok(pb::GpioPull::Down) => GpioPull::Down,
            Err(_) => return Err(bad_argument("pull", format!("{} is not a GpioPull", r.pull))),
        };
        let t = caller.deadline;
        bounded(&caller, async {
            if l & 0xFFFF != 0 {
                self.call(Immediate::GpioConfig(GpioConfig::SetMode { lines: l as u16, mode, pull }), t).await?;
            }
            if l >> 16 != 0 {
                self.call(Immediate::GpioConfig(GpioConfig::SetModeExt { lines: (l >> 16) as u8, mode, pull }), t)
                    .await?;
            }
            Ok::<_, Status>(())
        })
        .await?;
        Ok(Response::new(pb::ConfigureGpioResponse {}))
    }

    async fn set_gpio(&self, request: Request<pb::SetGpioRequest>) -> Result<Response<pb::GpioLevels>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let l = lines(request.get_ref().levels, "levels")?;
        let t = caller.deadline;
        let out = bounded(&caller, async {
            self.call(Immediate::Gpio(GpioFunc::ExtSetValue { values: GpioMask(l) }), t).await?;
            self.levels(t).await
        })
        .await?;
        Ok(Response::new(out))
    }

    async fn get_gpio(&self, request: Request<pb::GetGpioRequest>) -> Result<Response<pb::GpioLevels>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let t = caller.deadline;
        Ok(Response::new(bounded(&caller, self.levels(t)).await?))
    }

    async fn read_adc(&self, request: Request<pb::ReadAdcRequest>) -> Result<Response<pb::ReadAdcResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let input = if request.get_ref().differential { AdcInput::Differential } else { AdcInput::SingleEnded };
        let t = caller.deadline;
        let value = bounded(&caller, async {
            self.call(Immediate::Adc(AdcOp::Open(input)), t).await?;
            self.call(Immediate::Adc(AdcOp::ConfigSampleModule), t).await?;
            self.call(Immediate::Adc(AdcOp::StartConv), t).await?;
            for _ in 0..50 {
                if word(&self.call(Immediate::Adc(AdcOp::GetDataValidFlag), t).await?) != 0 {
                    return Ok(word(&self.call(Immediate::Adc(AdcOp::GetConvData), t).await?) & 0x0FFF);
                }
                // The chip raises no event for a finished conversion (v049
                // ADC commands): its flag is asked again after a ms, the
                // conversion's own time.
                tokio::time::sleep(Duration::from_millis(1)).await;
            }
            Err(Status::deadline_exceeded("the ADC conversion did not complete in 50 ms"))
        })
        .await?;
        Ok(Response::new(pb::ReadAdcResponse { value }))
    }

    async fn write_dac(&self, request: Request<pb::WriteDacRequest>) -> Result<Response<pb::WriteDacResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let v = request.get_ref().value;
        if v > 4095 {
            return Err(bad_argument("value", format!("{v} is outside 0..=4095")));
        }
        let t = caller.deadline;
        bounded(&caller, async {
            self.call(Immediate::Dac(DacOp::Open(DacTrigger::OnSetData)), t).await?;
            self.call(Immediate::Dac(DacOp::SetData(v as u16)), t).await
        })
        .await?;
        Ok(Response::new(pb::WriteDacResponse {}))
    }

    async fn qei(&self, request: Request<pb::QeiRequest>) -> Result<Response<pb::QeiResponse>, Status> {
        let action = pb::QeiAction::try_from(request.get_ref().action)
            .map_err(|_| bad_argument("action", format!("{} is not a QeiAction", request.get_ref().action)))?;
        let role = if action == pb::QeiAction::Read { Role::Observer } else { Role::Operator };
        let caller = self.0.authorize(&request, role)?;
        let t = caller.deadline;
        let count = bounded(&caller, async {
            match action {
                pb::QeiAction::Start => {
                    self.call(Immediate::Qei(QeiOp::Open(QeiMode::X4Free)), t).await?;
                    self.call(Immediate::Qei(QeiOp::Start), t).await?;
                }
                pb::QeiAction::Stop => {
                    self.call(Immediate::Qei(QeiOp::Stop), t).await?;
                }
                pb::QeiAction::Read => {}
                pb::QeiAction::Unspecified => return Err(bad_argument("action", "give READ, START or STOP")),
            }
            Ok(word(&self.call(Immediate::Qei(QeiOp::GetCount), t).await?))
        })
        .await?;
        Ok(Response::new(pb::QeiResponse { count }))
    }
}
