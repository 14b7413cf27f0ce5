//! What the emulation emulates, from the environment (read once, at the
//! first call that needs it). Defaults are config/ecmxfd-rpi.toml's wiring
//! on a Raspberry Pi 4: `/dev/spidev0.0`, `/dev/gpiochip0` with 58 lines,
//! INT0 on line 24, INT1 on line 25.

use std::path::PathBuf;

use crate::spi::Wiring;

/// The emulation's settings.
#[derive(Clone, Debug)]
pub struct Config {
    /// `ECMXF_SIM_SOCKET`: the simulator (`ecmxf-sim serve --socket`).
    pub socket: PathBuf,
    /// `ECMXF_EMU_SPIDEV` (comma-separated): SPI devices emulated.
    pub spidev: Vec<String>,
    /// `ECMXF_EMU_GPIOCHIP`: the GPIO chip emulated.
    pub gpiochip: String,
    /// `ECMXF_EMU_GPIO_LABEL`: its label.
    pub gpio_label: String,
    /// `ECMXF_EMU_GPIO_LINES`: its lines.
    pub gpio_lines: u32,
    /// `ECMXF_EMU_INT0_LINE`: the line INT0 is wired to.
    pub int0_line: u32,
    /// `ECMXF_EMU_INT1_LINE`: the line INT1 is wired to.
    pub int1_line: u32,
    /// `ECMXF_EMU_DENY` (comma-separated): paths this user may not open
    /// (EACCES).
    pub deny: Vec<String>,
    /// `ECMXF_EMU_MISO=high|low`, `ECMXF_EMU_FORCE_MODE=0..3`.
    pub wiring: Wiring,
    /// `ECMXF_EMU_STATS`: a file the call counters are written to when an
    /// SPI device is closed and when the process exits.
    pub stats: Option<PathBuf>,
}

fn var(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.is_empty())
}

fn list(name: &str, default: &str) -> Vec<String> {
    var(name)
        .unwrap_or_else(|| default.into())
        .split(',')
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

fn number(name: &str, default: u32) -> u32 {
    var(name).and_then(|v| v.parse().ok()).unwrap_or(default)
}

impl Config {
    /// From the environment; `None` without `ECMXF_SIM_SOCKET` (then
    /// nothing is emulated and every call goes to libc).
    pub fn from_env() -> Option<Self> {
        let socket = PathBuf::from(var("ECMXF_SIM_SOCKET")?);
        Some(Self {
            socket,
            spidev: list("ECMXF_EMU_SPIDEV", "/dev/spidev0.0"),
            gpiochip: var("ECMXF_EMU_GPIOCHIP").unwrap_or_else(|| "/dev/gpiochip0".into()),
            gpio_label: var("ECMXF_EMU_GPIO_LABEL").unwrap_or_else(|| "pinctrl-bcm2711".into()),
            gpio_lines: number("ECMXF_EMU_GPIO_LINES", 58),
            int0_line: number("ECMXF_EMU_INT0_LINE", 24),
            int1_line: number("ECMXF_EMU_INT1_LINE", 25),
            deny: list("ECMXF_EMU_DENY", ""),
            wiring: Wiring {
                miso_stuck: match var("ECMXF_EMU_MISO").as_deref() {
                    Some("high") => Some(true),
                    Some("low") => Some(false),
                    _ => None,
                },
                forced_mode: var("ECMXF_EMU_FORCE_MODE").and_then(|v| v.parse().ok()).map(|m: u32| m & 3),
            },
            stats: var("ECMXF_EMU_STATS").map(PathBuf::from),
        })
    }

    /// What `path` is here.
    pub fn node(&self, path: &str) -> Option<Node> {
        if self.spidev.iter().any(|p| p == path) {
            Some(Node::Spi)
        } else if self.gpiochip == path {
            Some(Node::GpioChip)
        } else {
            None
        }
    }
}

/// An emulated device node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Node {
    /// `/dev/spidevB.C`.
    Spi,
    /// `/dev/gpiochipN`.
    GpioChip,
}
