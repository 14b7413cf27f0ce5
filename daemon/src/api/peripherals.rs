//! `Peripherals` service: the chip's GPIO, ADC, DAC and encoder input.

use std::sync::Arc;

use ecmxf_proto::v1 as pb;
use ecmxf_proto::v1::peripherals_server::Peripherals as PeripheralsApi;
use tonic::{Request, Response, Status};

use super::Context;
use super::auth::Role;
use super::bounded;
use super::status::{bad_argument, to_status};
use crate::master::peripherals::{AdcError, DAC_MAX, GPIO_LINES, GpioLevels, GpioMode, GpioPull, QeiAction};

/// The `Peripherals` service.
#[derive(Debug, Clone)]
pub(crate) struct PeripheralsService(pub Arc<Context>);

fn lines(v: u32, field: &'static str) -> Result<u32, Status> {
    if v & !GPIO_LINES != 0 {
        return Err(bad_argument(field, format!("{v:#x} names lines above 19")));
    }
    Ok(v)
}

fn levels_pb(l: GpioLevels) -> pb::GpioLevels {
    pb::GpioLevels { levels: l.levels, interrupt_flags: l.interrupt_flags }
}

impl From<AdcError> for Status {
    fn from(e: AdcError) -> Self {
        match e {
            AdcError::Engine(e) => to_status(e),
            AdcError::NotComplete => Status::deadline_exceeded(e.to_string()),
        }
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
        bounded(&caller, self.0.master.configure_gpio(l, mode, pull, caller.call)).await?;
        Ok(Response::new(pb::ConfigureGpioResponse {}))
    }

    async fn set_gpio(&self, request: Request<pb::SetGpioRequest>) -> Result<Response<pb::GpioLevels>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let l = lines(request.get_ref().levels, "levels")?;
        let out = bounded(&caller, self.0.master.set_gpio(l, caller.call)).await?;
        Ok(Response::new(levels_pb(out)))
    }

    async fn get_gpio(&self, request: Request<pb::GetGpioRequest>) -> Result<Response<pb::GpioLevels>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        Ok(Response::new(levels_pb(bounded(&caller, self.0.master.gpio_levels(caller.call)).await?)))
    }

    async fn read_adc(&self, request: Request<pb::ReadAdcRequest>) -> Result<Response<pb::ReadAdcResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Observer)?;
        let differential = request.get_ref().differential;
        let value = bounded(&caller, self.0.master.read_adc(differential, caller.call)).await?;
        Ok(Response::new(pb::ReadAdcResponse { value: value.into() }))
    }

    async fn write_dac(&self, request: Request<pb::WriteDacRequest>) -> Result<Response<pb::WriteDacResponse>, Status> {
        let caller = self.0.authorize(&request, Role::Operator)?;
        let v = request.get_ref().value;
        if v > u32::from(DAC_MAX) {
            return Err(bad_argument("value", format!("{v} is outside 0..=4095")));
        }
        bounded(&caller, self.0.master.write_dac(v as u16, caller.call)).await?;
        Ok(Response::new(pb::WriteDacResponse {}))
    }

    async fn qei(&self, request: Request<pb::QeiRequest>) -> Result<Response<pb::QeiResponse>, Status> {
        let action = pb::QeiAction::try_from(request.get_ref().action)
            .map_err(|_| bad_argument("action", format!("{} is not a QeiAction", request.get_ref().action)))?;
        let role = if action == pb::QeiAction::Read { Role::Observer } else { Role::Operator };
        let caller = self.0.authorize(&request, role)?;
        let action = match action {
            pb::QeiAction::Read => QeiAction::Read,
            pb::QeiAction::Start => QeiAction::Start,
            pb::QeiAction::Stop => QeiAction::Stop,
            pb::QeiAction::Unspecified => return Err(bad_argument("action", "give READ, START or STOP")),
        };
        let count = bounded(&caller, self.0.master.qei(action, caller.call)).await?;
        Ok(Response::new(pb::QeiResponse { count }))
    }
}
