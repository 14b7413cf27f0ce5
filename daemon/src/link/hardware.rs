//! The real chip: `/dev/spidevX.Y` (SPI mode 0, 8-bit words, MSB first:
//! v049 SPI模式) and INT0/INT1 through the GPIO character device (uAPI v2,
//! via `gpiocdev`), with edge events timestamped by the kernel.
//!
//! Lines are requested active-high, so a line's logical value is its
//! electrical level; the polarity the chip was given with command 58 decides
//! which level means "active" (INT0 active-high, INT1 active-low after
//! reset).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use gpiocdev::Request;
use gpiocdev::line::{EdgeDetection, EdgeKind, EventClock, Value};
use spidev::{SpiModeFlags, Spidev, SpidevOptions, SpidevTransfer};

use super::{Link, LinkError};

/// Where the chip is wired.
#[derive(Clone, Debug, PartialEq)]
pub struct HardwareConfig {
    /// SPI device, e.g. `/dev/spidev0.0`.
    pub spi_device: PathBuf,
    /// SPI clock in Hz (the chip takes up to 96 MHz).
    pub spi_hz: u32,
    /// GPIO chip of the interrupt lines, e.g. `/dev/gpiochip0`.
    pub gpio_chip: Option<PathBuf>,
    /// Line offset of INT0, when wired.
    pub int0_line: Option<u32>,
    /// Line offset of INT1, when wired.
    pub int1_line: Option<u32>,
    /// Kernel debounce on INT1 (never on INT0, whose pulses are shorter).
    pub debounce: Option<Duration>,
    /// Wait after each transfer when INT0 is not wired (vendor: 150-200 us).
    pub idle: Duration,
}

/// The link.
#[derive(Debug)]
pub struct HardwareLink {
    config: HardwareConfig,
    spi: Spidev,
    int0: Option<Request>,
    int1: Option<Request>,
    int0_active_high: bool,
    int1_active_high: bool,
    last_transfer: Instant,
    /// Kernel timestamp (CLOCK_MONOTONIC, ns) of the last INT0 edge seen.
    pub last_int0_edge_ns: u64,
    /// INT0 edges seen: events read, or the kernel's `line_seqno` of the
    /// newest when larger (it counts events that overflowed the queue; uAPI
    /// v1 leaves it 0).
    int0_edge_count: u64,
    /// Where edge events are read to (no allocation per read).
    events: Box<EventBuffer>,
}

/// Edge events taken from the kernel in one `read` (the line request's
/// queue holds 16 per line by default).
const EVENTS_PER_READ: usize = 16;

/// Room for [`EVENTS_PER_READ`] v2 events (48 bytes each), as u64s for
/// their alignment.
type EventBuffer = [u64; EVENTS_PER_READ * 6];

/// Reads the INT0 edge events queued now, in one system call, into the
/// link's record of edges; the level the newest one left the line at
/// (`None`: none was queued). The kernel drops the oldest events of a full
/// queue, never the newest, so the newest says the level now.
fn drain_int0_edges(
    req: &Request,
    line: u32,
    buf: &mut EventBuffer,
    last_ns: &mut u64,
    count: &mut u64,
) -> Result<Option<bool>, LinkError> {
    let words =
        req.read_edge_events_into_slice(buf).map_err(|e| gpio_err(format!("read INT0 line {line} events"), e))?;
    let size = req.edge_event_u64_size().max(1);
    let mut newest = None;
    for chunk in buf[..words].chunks_exact(size) {
        let ev = req.edge_event_from_slice(chunk).map_err(|e| gpio_err(format!("read INT0 line {line} event"), e))?;
        *last_ns = ev.timestamp_ns;
        *count = (*count + 1).max(u64::from(ev.line_seqno));
        newest = Some(ev.kind == EdgeKind::Rising);
    }
    Ok(newest)
}

/// A GPIO error as an `io::Error` that keeps what the kernel said: the
/// errno of a failed system call (EACCES, EBUSY, ENOENT, EINVAL...), or
/// [`NotGpioChip`] for a path that is no GPIO chip, so `ecmxfd probe`
/// diagnoses from the cause, not from the text (message words change; a
/// "busy" in another cause's text must not read as a held line).
fn gpio_err(what: String, e: gpiocdev::Error) -> LinkError {
    use gpiocdev::Error as G;
    let source = match &e {
        G::Os(errno) | G::Uapi(_, gpiocdev_uapi::Error::Os(errno)) => std::io::Error::from_raw_os_error(errno.0),
        G::GpioChip(path, _) => std::io::Error::other(NotGpioChip(path.display().to_string(), e.to_string())),
        _ => std::io::Error::other(e.to_string()),
    };
    LinkError::io(what, source)
}

/// The path configured as the GPIO chip is not one (not a character
/// device, or not a GPIO one): the path, and gpiocdev's words for it.
#[derive(Debug)]
pub struct NotGpioChip(pub String, pub String);

impl std::fmt::Display for NotGpioChip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.1)
    }
}

impl std::error::Error for NotGpioChip {}

impl HardwareLink {
    /// Opens and configures the SPI device and requests the lines.
    pub fn open(config: HardwareConfig) -> Result<Self, LinkError> {
        let spi_name = config.spi_device.display().to_string();
        let mut spi = Spidev::open(&config.spi_device).map_err(|e| LinkError::io(format!("open {spi_name}"), e))?;
        let options = SpidevOptions::new()
            .bits_per_word(8)
            .max_speed_hz(config.spi_hz)
            .lsb_first(false)
            .mode(SpiModeFlags::SPI_MODE_0)
            .build();
        spi.configure(&options)
            .map_err(|e| LinkError::io(format!("configure {spi_name} (mode 0, {} Hz)", config.spi_hz), e))?;
        let request = |line: Option<u32>, name: &str| -> Result<Option<Request>, LinkError> {
            let (Some(line), Some(chip)) = (line, config.gpio_chip.as_ref()) else { return Ok(None) };
            let mut b = Request::builder();
            b.on_chip(chip)
                .with_consumer(format!("ecmxfd-{name}"))
                .with_line(line)
                .as_input()
                .as_active_high()
                .with_edge_detection(EdgeDetection::BothEdges)
                .with_event_clock(EventClock::Monotonic);
            // INT1 only: INT0's busy pulse lasts the chip's processing time
            // (tens of us), and a debounce as long erases both its edges
            // (the emulated devices showed probe step 2 failing with 100 us).
            if let Some(d) = config.debounce.filter(|_| name == "int1") {
                b.with_debounce_period(d);
            }
            b.request().map(Some).map_err(|e| gpio_err(format!("request {name} line {line} on {}", chip.display()), e))
        };
        let int0 = request(config.int0_line, "int0")?;
        let int1 = request(config.int1_line, "int1")?;
        Ok(Self {
            config,
            spi,
            int0,
            int1,
            int0_active_high: true,
            int1_active_high: false,
            last_transfer: Instant::now(),
            last_int0_edge_ns: 0,
            int0_edge_count: 0,
            events: Box::new([0; EVENTS_PER_READ * 6]),
        })
    }

    fn level(req: &Request, line: u32, what: &str) -> Result<bool, LinkError> {
        req.value(line).map(|v| v == Value::Active).map_err(|e| gpio_err(format!("read {what} line {line}"), e))
    }
}

impl Link for HardwareLink {
    fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        let mut t = SpidevTransfer::read_write(tx, rx);
        let result = self.spi.transfer(&mut t);
        self.last_transfer = Instant::now();
        result.map_err(|e| {
            LinkError::io(format!("SPI transfer of {} bytes on {}", tx.len(), self.config.spi_device.display()), e)
        })
    }

    fn wait_ready(&mut self, timeout: Duration) -> Result<bool, LinkError> {
        let Some(req) = &self.int0 else {
            // No INT0: the vendor driver's fixed idle time after a transfer.
            let due = self.last_transfer + self.config.idle;
            let now = Instant::now();
            if due > now {
                std::thread::sleep((due - now).min(timeout));
            }
            return Ok(Instant::now() >= due);
        };
        let line = self.config.int0_line.unwrap_or(0);
        let deadline = Instant::now() + timeout;
        // The level once; then the edges say it: the newest queued edge
        // leaves the line where it is now, so no second level read follows
        // a wait (on a chip still busy: a level read, a poll and a read).
        let mut ready = Self::level(req, line, "INT0")? == self.int0_active_high;
        loop {
            if ready {
                return Ok(true);
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(false);
            }
            let edge =
                req.wait_edge_event(deadline - now).map_err(|e| gpio_err(format!("wait for INT0 line {line}"), e))?;
            if edge {
                let newest = drain_int0_edges(
                    req,
                    line,
                    &mut self.events,
                    &mut self.last_int0_edge_ns,
                    &mut self.int0_edge_count,
                )?;
                if let Some(rising) = newest {
                    ready = rising == self.int0_active_high;
                }
            }
        }
    }

    fn int1_active(&mut self) -> Result<bool, LinkError> {
        match &self.int1 {
            Some(req) => Ok(Self::level(req, self.config.int1_line.unwrap_or(0), "INT1")? == self.int1_active_high),
            None => Ok(false),
        }
    }

    /// Reads the edge events queued since the last wait (a chip that is
    /// done before the host looks leaves both edges of a packet queued).
    fn int0_edges(&mut self) -> Result<Option<u64>, LinkError> {
        let Some(req) = &self.int0 else { return Ok(None) };
        let line = self.config.int0_line.unwrap_or(0);
        while req.has_edge_event().map_err(|e| gpio_err(format!("poll INT0 line {line}"), e))? {
            drain_int0_edges(req, line, &mut self.events, &mut self.last_int0_edge_ns, &mut self.int0_edge_count)?;
        }
        Ok(Some(self.int0_edge_count))
    }

    fn set_polarity(&mut self, int0_active_high: bool, int1_active_high: bool) {
        self.int0_active_high = int0_active_high;
        self.int1_active_high = int1_active_high;
    }

    /// Opens the SPI device and requests the lines again (a device node
    /// that went away and came back, a GPIO request the kernel revoked),
    /// keeping the polarities the chip was told.
    fn reopen(&mut self) -> Result<(), LinkError> {
        let mut fresh = Self::open(self.config.clone())?;
        fresh.int0_active_high = self.int0_active_high;
        fresh.int1_active_high = self.int1_active_high;
        *self = fresh;
        Ok(())
    }

    fn clock_hz(&self) -> Option<u64> {
        Some(u64::from(self.config.spi_hz))
    }

    fn describe(&self) -> String {
        let line = |l: Option<u32>| l.map_or("not wired".to_string(), |l| format!("line {l}"));
        format!(
            "{} at {} Hz, INT0 {}, INT1 {}",
            self.config.spi_device.display(),
            self.config.spi_hz,
            line(self.config.int0_line),
            line(self.config.int1_line)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> HardwareConfig {
        HardwareConfig {
            spi_device: "/dev/ecmxf-no-such-spidev".into(),
            spi_hz: 20_000_000,
            gpio_chip: Some("/dev/ecmxf-no-such-gpiochip".into()),
            int0_line: Some(17),
            int1_line: None,
            debounce: None,
            idle: Duration::from_micros(200),
        }
    }

    #[test]
    fn a_missing_device_is_named_in_the_error() {
        let e = HardwareLink::open(config()).unwrap_err().to_string();
        assert!(e.contains("open /dev/ecmxf-no-such-spidev"), "{e}");
    }
}
