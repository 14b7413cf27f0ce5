//! `gpio`, `adc`, `dac`, `qei`: the chip's own peripherals (Peripherals
//! service; v049 GPIO_CONFIG_SET 31, GPIO_FUNC_OP 32, QEI 33, DAC 34, ADC 35).

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::cli::{GpioCommand, GpioMode, GpioPull, QeiAction};
use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Out, Report, Table};

/// `ecmxfctl gpio get|set|config --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct GpioReport {
    /// Bit n = line n high.
    pub levels: u32,
    /// Bit n = line n's edge interrupt flag.
    pub interrupt_flags: u32,
    /// The same, per line 0..=19.
    pub lines: Vec<GpioLine>,
}

#[derive(Debug, Serialize, JsonSchema)]
pub struct GpioLine {
    pub line: u32,
    pub high: bool,
    pub interrupt: bool,
}

impl From<pb::GpioLevels> for GpioReport {
    fn from(g: pb::GpioLevels) -> Self {
        Self {
            levels: g.levels,
            interrupt_flags: g.interrupt_flags,
            lines: (0..20)
                .map(|l| GpioLine { line: l, high: g.levels >> l & 1 == 1, interrupt: g.interrupt_flags >> l & 1 == 1 })
                .collect(),
        }
    }
}

impl Report for GpioReport {
    fn text(&self) -> String {
        let mut t = Table::new(&["LINE", "LEVEL", "IRQ"]);
        for l in &self.lines {
            t.row([l.line.to_string(), u8::from(l.high).to_string(), if l.interrupt { "yes" } else { "" }.to_owned()]);
        }
        format!("levels {:#07x}, interrupt flags {:#07x}\n{t}", self.levels, self.interrupt_flags)
    }
}

/// `ecmxfctl adc|dac|qei --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct ScalarReport {
    /// "adc", "dac" or "qei".
    pub device: String,
    /// ADC: the conversion 0..=4095; DAC: the value set; QEI: the count.
    pub value: u32,
}

impl Report for ScalarReport {
    fn text(&self) -> String {
        format!("{}: {}", self.device, self.value)
    }
}

async fn gpio_get(api: &Api) -> Result<pb::GpioLevels, CliError> {
    let r = api.peripherals().get_gpio(api.req(pb::GetGpioRequest {})).await;
    Ok(r.map_err(CliError::rpc("read GPIO"))?.into_inner())
}

/// `gpio ...`.
pub async fn gpio(api: &Api, out: Out, cmd: &GpioCommand) -> Result<(), CliError> {
    let levels = match cmd {
        GpioCommand::Get => gpio_get(api).await?,
        GpioCommand::Set { lines } => {
            let mut levels = gpio_get(api).await?.levels;
            for (line, high) in lines {
                if *high {
                    levels |= 1 << line;
                } else {
                    levels &= !(1 << line);
                }
            }
            let r = api.peripherals().set_gpio(api.req(pb::SetGpioRequest { levels })).await;
            r.map_err(CliError::rpc("set GPIO"))?.into_inner()
        }
        GpioCommand::Config { lines, mode, pull } => {
            let mode = match mode {
                GpioMode::Input => pb::GpioMode::Input,
                GpioMode::Output => pb::GpioMode::Output,
                GpioMode::OpenDrain => pb::GpioMode::OpenDrain,
                GpioMode::QuasiBidirectional => pb::GpioMode::QuasiBidirectional,
            };
            let pull = match pull {
                GpioPull::None => pb::GpioPull::None,
                GpioPull::Up => pb::GpioPull::Up,
                GpioPull::Down => pb::GpioPull::Down,
            };
            let req = pb::ConfigureGpioRequest { lines: *lines, mode: mode as i32, pull: pull as i32 };
            api.peripherals().configure_gpio(api.req(req)).await.map_err(CliError::rpc("configure GPIO"))?;
            gpio_get(api).await?
        }
    };
    out.report(&GpioReport::from(levels))?;
    Ok(())
}

/// `adc`.
pub async fn adc(api: &Api, differential: bool) -> Result<ScalarReport, CliError> {
    let r = api.peripherals().read_adc(api.req(pb::ReadAdcRequest { differential })).await;
    Ok(ScalarReport { device: "adc".into(), value: r.map_err(CliError::rpc("read ADC"))?.into_inner().value })
}

/// `dac`.
pub async fn dac(api: &Api, value: u32) -> Result<ScalarReport, CliError> {
    api.peripherals().write_dac(api.req(pb::WriteDacRequest { value })).await.map_err(CliError::rpc("set DAC"))?;
    Ok(ScalarReport { device: "dac".into(), value })
}

/// `qei`.
pub async fn qei(api: &Api, action: QeiAction) -> Result<ScalarReport, CliError> {
    let a = match action {
        QeiAction::Read => pb::QeiAction::Read,
        QeiAction::Start => pb::QeiAction::Start,
        QeiAction::Stop => pb::QeiAction::Stop,
    };
    let r = api.peripherals().qei(api.req(pb::QeiRequest { action: a as i32 })).await;
    Ok(ScalarReport { device: "qei".into(), value: r.map_err(CliError::rpc("encoder"))?.into_inner().count })
}
