//! The chip's own peripherals: 20 GPIO lines, the quadrature encoder, DAC
//! and ADC (v049 GPIO/QEI/DAC/ADC sections; GPIOs power up as floating
//! inputs). Tests drive the outside world: input levels, encoder pulses, the
//! analog input.

use ecmxf_wire::payload::gpio::{DebounceSource, GpioConfig, GpioFunc, GpioMode, GpioPull, GpioTrigger};
use ecmxf_wire::payload::periph::{AdcInput, AdcOp, DacOp, DacTrigger, QeiMode, QeiOp};

/// Lines the model has.
pub const LINES: usize = 20;

/// A change of an input that waits out the debounce time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct PendingEdge {
    line: u8,
    level: bool,
    at_ns: u64,
}

/// GPIO, QEI, DAC and ADC state.
#[derive(Clone, Debug)]
pub struct Peripherals {
    mode: [GpioMode; LINES],
    pull: [GpioPull; LINES],
    trigger: [GpioTrigger; LINES],
    debounce: u32,
    debounce_cycles: u8,
    debounce_source: DebounceSource,
    /// Output latch (bit n = line n).
    pub outputs: u32,
    /// Level applied from outside to each pin (None = floating).
    external: [Option<bool>; LINES],
    /// Level the chip sees after debouncing.
    seen: u32,
    pending: Vec<PendingEdge>,
    /// GPIO interrupt flags.
    pub int_flags: u32,
    qei_mode: Option<QeiMode>,
    qei_running: bool,
    /// Encoder count.
    pub qei_count: i32,
    dac_trigger: Option<DacTrigger>,
    dac_latch: u16,
    /// DAC output code now (0..=4095 for 0..3.3 V).
    pub dac_output: u16,
    /// DAC delay setting.
    pub dac_delay: u16,
    adc_input: Option<AdcInput>,
    /// Analog input, volts, set by tests.
    pub adc_volts: f64,
    adc_data: Option<u32>,
}

impl Default for Peripherals {
    fn default() -> Self {
        Self {
            mode: [GpioMode::Input; LINES],
            pull: [GpioPull::None; LINES],
            trigger: [GpioTrigger::Disabled; LINES],
            debounce: 0,
            debounce_cycles: 0,
            debounce_source: DebounceSource::Clock192MHz,
            outputs: 0,
            external: [None; LINES],
            seen: 0,
            pending: Vec::new(),
            int_flags: 0,
            qei_mode: None,
            qei_running: false,
            qei_count: 0,
            dac_trigger: None,
            dac_latch: 0,
            dac_output: 0,
            dac_delay: 0,
            adc_input: None,
            adc_volts: 0.0,
            adc_data: None,
        }
    }
}

fn lines(mask: u32) -> impl Iterator<Item = usize> {
    (0..LINES).filter(move |i| mask & (1 << i) != 0)
}

impl Peripherals {
    fn debounce_ns(&self) -> u64 {
        let period_ns = match self.debounce_source {
            DebounceSource::Clock192MHz => 1e9 / 192e6,
            DebounceSource::Clock10kHz => 1e9 / 10e3,
        };
        (period_ns * f64::from(1u32 << self.debounce_cycles)) as u64
    }

    /// The level at a pin as seen from outside: driven outputs, else the
    /// external level, else the pull.
    fn pin_level(&self, line: usize) -> bool {
        match self.mode[line] {
            GpioMode::Output => self.outputs & (1 << line) != 0,
            GpioMode::OpenDrain | GpioMode::QuasiBidirectional if self.outputs & (1 << line) == 0 => false,
            _ => self.external[line].unwrap_or(self.pull[line] == GpioPull::Up),
        }
    }

    /// Drives a pin from outside at time `now_ns`.
    pub fn set_input(&mut self, line: u8, level: Option<bool>, now_ns: u64) {
        let Some(slot) = self.external.get_mut(usize::from(line)) else { return };
        *slot = level;
        let l = usize::from(line);
        let level = self.pin_level(l);
        if self.debounce & (1 << l) != 0 {
            self.pending.retain(|p| p.line != line);
            self.pending.push(PendingEdge { line, level, at_ns: now_ns + self.debounce_ns() });
        } else {
            self.see(l, level);
        }
    }

    fn see(&mut self, line: usize, level: bool) {
        let was = self.seen & (1 << line) != 0;
        if was == level {
            return;
        }
        self.seen = (self.seen & !(1 << line)) | (u32::from(level) << line);
        let fire = match self.trigger[line] {
            GpioTrigger::Disabled => false,
            GpioTrigger::BothEdges => true,
            GpioTrigger::Rising => level,
            GpioTrigger::Falling => !level,
        };
        if fire {
            self.int_flags |= 1 << line;
        }
    }

    /// Applies debounced changes due by `now_ns`.
    pub fn advance(&mut self, now_ns: u64) {
        let due: Vec<PendingEdge> = self.pending.iter().copied().filter(|p| p.at_ns <= now_ns).collect();
        self.pending.retain(|p| p.at_ns > now_ns);
        for p in due {
            // The change only counts if the pin still holds the level.
            if self.pin_level(usize::from(p.line)) == p.level {
                self.see(usize::from(p.line), p.level);
            }
        }
    }

    /// Input register value: what each line reads.
    pub fn input_value(&self) -> u32 {
        let mut v = 0;
        for l in 0..LINES {
            let bit = match self.mode[l] {
                GpioMode::Input => self.seen & (1 << l) != 0,
                _ => self.pin_level(l),
            };
            v |= u32::from(bit) << l;
        }
        v
    }

    fn refresh_outputs(&mut self) {
        for l in 0..LINES {
            let level = self.pin_level(l);
            self.see(l, level);
        }
    }

    /// Header GPIO outputs (0x16/0x17): lines 0..=11, plus, from firmware
    /// 0x1E on, bits 12..15 where bit12 drives GPIO13 and bit13 GPIO12 (v049
    /// note under 表一).
    pub fn header_output(&mut self, value: u16, firmware: u8) {
        let mut v = u32::from(value & 0x0FFF);
        if firmware >= 0x1E {
            v |= u32::from(value & 0xC000);
            v |= u32::from(value >> 12 & 1) << 13 | u32::from(value >> 13 & 1) << 12;
        }
        let mask = if firmware >= 0x1E { 0xFFFF } else { 0x0FFF };
        self.outputs = (self.outputs & !mask) | v;
        self.refresh_outputs();
    }

    /// GPIO_CONFIG_SET.
    pub fn config(&mut self, op: GpioConfig) {
        match op {
            GpioConfig::SetMode { lines: m, mode, pull } => self.set_mode(u32::from(m), mode, pull),
            GpioConfig::SetModeExt { lines: m, mode, pull } => self.set_mode(u32::from(m) << 16, mode, pull),
            GpioConfig::EnableDebounce { lines: m, enable } => self.set_debounce(u32::from(m), enable),
            GpioConfig::EnableDebounceExt { lines: m, enable } => self.set_debounce(u32::from(m) << 16, enable),
            GpioConfig::SetDebounceClock { cycles, source } => {
                self.debounce_cycles = cycles;
                self.debounce_source = source;
            }
            GpioConfig::IntEnable { line, trigger } => {
                if let Some(t) = self.trigger.get_mut(usize::from(line)) {
                    *t = trigger;
                }
            }
            GpioConfig::IntClear { lines: m } => self.int_flags &= !u32::from(m),
            GpioConfig::IntClearExt { lines: m } => self.int_flags &= !m.0,
        }
    }

    fn set_mode(&mut self, mask: u32, mode: GpioMode, pull: GpioPull) {
        for l in lines(mask) {
            self.mode[l] = mode;
            self.pull[l] = pull;
        }
        self.refresh_outputs();
    }

    fn set_debounce(&mut self, mask: u32, on: bool) {
        self.debounce = if on { self.debounce | mask } else { self.debounce & !mask };
    }

    /// GPIO_FUNC_OP; returns the value a get operation answers, with
    /// whether it is the 4-byte form.
    pub fn func(&mut self, op: GpioFunc) -> Option<(u32, bool)> {
        match op {
            GpioFunc::SetValue { values } => {
                self.outputs = (self.outputs & !0xFFFF) | u32::from(values);
                self.refresh_outputs();
                None
            }
            GpioFunc::ExtSetValue { values } => {
                self.outputs = values.0 & 0xF_FFFF;
                self.refresh_outputs();
                None
            }
            GpioFunc::GetValue => Some((self.input_value() & 0xFFFF, false)),
            GpioFunc::ExtGetValue => Some((self.input_value(), true)),
            GpioFunc::GetIntFlag => Some((self.int_flags & 0xFFFF, false)),
            GpioFunc::ExtGetIntFlag => Some((self.int_flags, true)),
        }
    }

    /// Encoder pulses from outside, in X4 edges.
    pub fn qei_pulses(&mut self, edges: i32) {
        if !self.qei_running {
            return;
        }
        let counted = match self.qei_mode {
            Some(QeiMode::X2Free | QeiMode::X2Compare) => edges / 2,
            Some(_) => edges,
            None => 0,
        };
        self.qei_count = self.qei_count.wrapping_add(counted);
    }

    /// QEI_FUNC_OP; returns the count for GetCount.
    pub fn qei(&mut self, op: QeiOp) -> Option<i32> {
        match op {
            QeiOp::Open(mode) => {
                self.qei_mode = Some(mode);
                self.qei_count = 0;
                None
            }
            QeiOp::Start => {
                self.qei_running = self.qei_mode.is_some();
                None
            }
            QeiOp::Stop => {
                self.qei_running = false;
                None
            }
            QeiOp::GetCount => Some(self.qei_count),
        }
    }

    /// DAC_FUNC_OP.
    pub fn dac(&mut self, op: DacOp) {
        match op {
            DacOp::Open(t) => self.dac_trigger = Some(t),
            DacOp::Close => {
                self.dac_trigger = None;
                self.dac_output = 0;
            }
            DacOp::SetDelay(d) => self.dac_delay = d,
            DacOp::SetData(v) => {
                self.dac_latch = v;
                if self.dac_trigger == Some(DacTrigger::OnSetData) {
                    self.dac_output = v;
                }
            }
            DacOp::StartConv => {
                if self.dac_trigger == Some(DacTrigger::OnStartConv) {
                    self.dac_output = self.dac_latch;
                }
            }
        }
    }

    /// ADC_FUNC_OP; returns the valid flag or the data for the get ops.
    pub fn adc(&mut self, op: AdcOp) -> Option<u32> {
        match op {
            AdcOp::Open(input) => {
                self.adc_input = Some(input);
                None
            }
            AdcOp::Close => {
                self.adc_input = None;
                self.adc_data = None;
                None
            }
            AdcOp::ConfigSampleModule => None,
            AdcOp::StartConv => {
                if self.adc_input.is_some() {
                    let code = (self.adc_volts / 3.3 * 4095.0).round().clamp(0.0, 4095.0);
                    self.adc_data = Some(code as u32);
                }
                None
            }
            AdcOp::GetDataValidFlag => Some(u32::from(self.adc_data.is_some())),
            AdcOp::GetConvData => Some(self.adc_data.unwrap_or(0)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ecmxf_wire::GpioMask;

    #[test]
    fn power_up_floating_inputs_and_pulls() {
        let mut p = Peripherals::default();
        assert_eq!(p.input_value(), 0);
        p.config(GpioConfig::SetMode { lines: 0b11, mode: GpioMode::Input, pull: GpioPull::Up });
        assert_eq!(p.input_value() & 0b11, 0b11);
        p.set_input(0, Some(false), 0);
        assert_eq!(p.input_value() & 0b11, 0b10);
    }

    #[test]
    fn outputs_and_header_quirk() {
        let mut p = Peripherals::default();
        p.config(GpioConfig::SetMode { lines: 0xFFFF, mode: GpioMode::Output, pull: GpioPull::None });
        p.func(GpioFunc::SetValue { values: 0x00A5 });
        assert_eq!(p.func(GpioFunc::GetValue), Some((0x00A5, false)));
        // Firmware >= 0x1E: header bit12 drives GPIO13.
        p.header_output(0x1001, 0x24);
        assert_eq!(p.outputs & 0xFFFF, 0x2001);
        p.header_output(0x1001, 0x10);
        assert_eq!(p.outputs & 0x0FFF, 0x0001);
    }

    #[test]
    fn edge_interrupts_with_debounce() {
        let mut p = Peripherals::default();
        p.config(GpioConfig::IntEnable { line: 2, trigger: GpioTrigger::Rising });
        p.config(GpioConfig::IntEnable { line: 3, trigger: GpioTrigger::Falling });
        p.set_input(2, Some(true), 0);
        assert_eq!(p.int_flags, 0b100);
        p.config(GpioConfig::IntClear { lines: 0b100 });
        assert_eq!(p.int_flags, 0);
        // Debounce at 10 kHz x 2^3 = 800 us: a 100 us glitch is filtered.
        p.config(GpioConfig::SetDebounceClock { cycles: 3, source: DebounceSource::Clock10kHz });
        p.config(GpioConfig::EnableDebounce { lines: 0b1000, enable: true });
        p.set_input(3, Some(true), 0);
        p.advance(1_000_000);
        p.set_input(3, Some(false), 2_000_000);
        p.set_input(3, Some(true), 2_100_000);
        p.advance(3_000_000);
        assert_eq!(p.int_flags & 0b1000, 0, "glitch filtered");
        p.set_input(3, Some(false), 4_000_000);
        p.advance(4_500_000);
        assert_eq!(p.int_flags & 0b1000, 0, "not yet");
        p.advance(4_800_000);
        assert_eq!(p.int_flags & 0b1000, 0b1000);
        p.config(GpioConfig::IntClearExt { lines: GpioMask(0b1000) });
        assert_eq!(p.int_flags, 0);
    }

    #[test]
    fn qei_dac_adc() {
        let mut p = Peripherals::default();
        p.qei_pulses(10);
        assert_eq!(p.qei(QeiOp::GetCount), Some(0), "closed encoder counts nothing");
        p.qei(QeiOp::Open(QeiMode::X2Free));
        p.qei(QeiOp::Start);
        p.qei_pulses(10);
        assert_eq!(p.qei(QeiOp::GetCount), Some(5));
        p.qei(QeiOp::Stop);
        p.qei_pulses(10);
        assert_eq!(p.qei_count, 5);

        p.dac(DacOp::Open(DacTrigger::OnStartConv));
        p.dac(DacOp::SetData(2048));
        assert_eq!(p.dac_output, 0);
        p.dac(DacOp::StartConv);
        assert_eq!(p.dac_output, 2048);

        p.adc_volts = 1.65;
        assert_eq!(p.adc(AdcOp::GetDataValidFlag), Some(0));
        p.adc(AdcOp::Open(AdcInput::SingleEnded));
        p.adc(AdcOp::StartConv);
        assert_eq!(p.adc(AdcOp::GetDataValidFlag), Some(1));
        assert_eq!(p.adc(AdcOp::GetConvData), Some(2048));
    }
}
