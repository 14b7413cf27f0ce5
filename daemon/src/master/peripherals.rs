//! The chip's own peripherals: GPIO, ADC, DAC and the encoder input
//! (GPIO_CONFIG_SET 31, GPIO_FUNC_OP 32, QEI_FUNC_OP 33, DAC_FUNC_OP 34,
//! ADC_FUNC_OP 35). Each operation is one or a few non-blocking chip
//! commands; the caller's deadline bounds them all.

use std::time::Duration;

use ecmxf_wire::flags::GpioMask;
use ecmxf_wire::payload::gpio::{GpioConfig, GpioFunc};
pub(crate) use ecmxf_wire::payload::gpio::{GpioMode, GpioPull};
use ecmxf_wire::payload::periph::{AdcInput, AdcOp, DacOp, DacTrigger, QeiMode, QeiOp};

use super::{Call, Master};
use crate::engine::error::EngineError;
use crate::engine::slot::Immediate;

/// The chip's GPIO lines, 0..=19, as a mask.
pub(crate) const GPIO_LINES: u32 = 0x000F_FFFF;
/// The largest DAC value (12 bits: 0..3.3 V).
pub(crate) const DAC_MAX: u16 = 4095;
/// How many times a conversion's flag is asked, a ms apart.
const ADC_POLLS: u32 = 50;

/// GPIO line levels, bit n = line n.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct GpioLevels {
    /// The lines' levels.
    pub levels: u32,
    /// The lines whose interrupt flag is set.
    pub interrupt_flags: u32,
}

/// What to do with the encoder input before its count is read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum QeiAction {
    /// Read the count only.
    Read,
    /// Open it in X4 free counting and start counting.
    Start,
    /// Stop counting.
    Stop,
}

/// Why an ADC reading failed.
#[derive(Clone, Debug)]
pub enum AdcError {
    /// A chip command failed.
    Engine(EngineError),
    /// The conversion's flag did not come up in time.
    NotComplete,
}

impl From<EngineError> for AdcError {
    fn from(e: EngineError) -> Self {
        Self::Engine(e)
    }
}

impl std::fmt::Display for AdcError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Engine(e) => e.fmt(f),
            Self::NotComplete => write!(f, "the ADC conversion did not complete in {ADC_POLLS} ms"),
        }
    }
}

impl std::error::Error for AdcError {}

/// The little-endian word at the start of an answer (missing bytes 0).
fn word(data: &[u8]) -> u32 {
    let mut b = [0u8; 4];
    let n = data.len().min(4);
    b[..n].copy_from_slice(&data[..n]);
    u32::from_le_bytes(b)
}

/// `lines` if it names GPIO lines only; else the error names `field`.
fn gpio_lines(lines: u32, field: &'static str) -> Result<u32, EngineError> {
    if lines & !GPIO_LINES != 0 {
        return Err(EngineError::BadArgument { field, reason: format!("{lines:#x} names lines above 19") });
    }
    Ok(lines)
}

impl Master {
    /// One peripheral command: the word its data starts with.
    async fn peripheral(&self, command: Immediate, call: Call) -> Result<u32, EngineError> {
        self.immediate(command, call).await.map(|(_, d)| word(&d))
    }

    /// Sets the mode and pull of `lines` (bit n = line n, 0..=19): lines
    /// 0..=15 and 16..=19 take one command each (SetMode, SetModeExt).
    pub(crate) async fn configure_gpio(
        &self,
        lines: u32,
        mode: GpioMode,
        pull: GpioPull,
        call: Call,
    ) -> Result<(), EngineError> {
        let l = gpio_lines(lines, "lines")?;
        if l & 0xFFFF != 0 {
            self.peripheral(Immediate::GpioConfig(GpioConfig::SetMode { lines: l as u16, mode, pull }), call).await?;
        }
        if l >> 16 != 0 {
            let ext = GpioConfig::SetModeExt { lines: (l >> 16) as u8, mode, pull };
            self.peripheral(Immediate::GpioConfig(ext), call).await?;
        }
        Ok(())
    }

    /// Sets the output levels of lines 0..=19 (bit n = line n high), then
    /// reads the levels back.
    pub(crate) async fn set_gpio(&self, levels: u32, call: Call) -> Result<GpioLevels, EngineError> {
        let l = gpio_lines(levels, "levels")?;
        self.peripheral(Immediate::Gpio(GpioFunc::ExtSetValue { values: GpioMask(l) }), call).await?;
        self.gpio_levels(call).await
    }

    /// The levels and interrupt flags of lines 0..=19.
    pub(crate) async fn gpio_levels(&self, call: Call) -> Result<GpioLevels, EngineError> {
        let levels = self.peripheral(Immediate::Gpio(GpioFunc::ExtGetValue), call).await?;
        let flags = self.peripheral(Immediate::Gpio(GpioFunc::ExtGetIntFlag), call).await?;
        Ok(GpioLevels { levels: levels & GPIO_LINES, interrupt_flags: flags & GPIO_LINES })
    }

    /// One ADC conversion, 0..=4095 for 0..3.3 V, of the single-ended or
    /// the differential input.
    pub(crate) async fn read_adc(&self, differential: bool, call: Call) -> Result<u16, AdcError> {
        let input = if differential { AdcInput::Differential } else { AdcInput::SingleEnded };
        self.peripheral(Immediate::Adc(AdcOp::Open(input)), call).await?;
        self.peripheral(Immediate::Adc(AdcOp::ConfigSampleModule), call).await?;
        self.peripheral(Immediate::Adc(AdcOp::StartConv), call).await?;
        for _ in 0..ADC_POLLS {
            if self.peripheral(Immediate::Adc(AdcOp::GetDataValidFlag), call).await? != 0 {
                let data = self.peripheral(Immediate::Adc(AdcOp::GetConvData), call).await?;
                return Ok((data & 0x0FFF) as u16);
            }
            // The chip raises no event for a finished conversion (v049
            // ADC commands): its flag is asked again after a ms, the
            // conversion's own time.
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        Err(AdcError::NotComplete)
    }

    /// Sets the DAC output, 0..=4095 for 0..3.3 V (opened to convert on
    /// each value set).
    pub(crate) async fn write_dac(&self, value: u16, call: Call) -> Result<(), EngineError> {
        if value > DAC_MAX {
            return Err(EngineError::BadArgument { field: "value", reason: format!("{value} is outside 0..=4095") });
        }
        self.peripheral(Immediate::Dac(DacOp::Open(DacTrigger::OnSetData)), call).await?;
        self.peripheral(Immediate::Dac(DacOp::SetData(value)), call).await?;
        Ok(())
    }

    /// Starts, stops or only reads the encoder input: its count after
    /// `action`.
    pub(crate) async fn qei(&self, action: QeiAction, call: Call) -> Result<u32, EngineError> {
        match action {
            QeiAction::Start => {
                self.peripheral(Immediate::Qei(QeiOp::Open(QeiMode::X4Free)), call).await?;
                self.peripheral(Immediate::Qei(QeiOp::Start), call).await?;
            }
            QeiAction::Stop => {
                self.peripheral(Immediate::Qei(QeiOp::Stop), call).await?;
            }
            QeiAction::Read => {}
        }
        self.peripheral(Immediate::Qei(QeiOp::GetCount), call).await
    }
}
