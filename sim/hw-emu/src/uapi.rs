//! The kernel ABI the emulation answers: the spidev ioctls
//! (`<linux/spi/spidev.h>`) and the GPIO character device's uAPI v2
//! (`<linux/gpio.h>`), written from the kernel headers, not from the crates
//! under test (`spidev`, `gpiocdev-uapi`), so a mistake in theirs shows.

use std::mem::size_of;

/// `_IOC` direction bits (asm-generic/ioctl.h; x86-64 and arm64 use it).
const IOC_WRITE: u64 = 1;
const IOC_READ: u64 = 2;

const fn ioc(dir: u64, ty: u8, nr: u8, size: usize) -> u64 {
    (dir << 30) | ((size as u64) << 16) | ((ty as u64) << 8) | nr as u64
}

/// The parts of an ioctl request number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IoctlNumber {
    /// Direction bits (1 write, 2 read, 3 both).
    pub dir: u64,
    /// The driver's magic.
    pub ty: u8,
    /// The command.
    pub nr: u8,
    /// The argument's size in bytes.
    pub size: usize,
}

impl IoctlNumber {
    /// Splits a request number.
    pub fn of(request: u64) -> Self {
        Self {
            dir: (request >> 30) & 3,
            ty: (request >> 8) as u8,
            nr: request as u8,
            size: ((request >> 16) & 0x3FFF) as usize,
        }
    }
}

/// `SPI_IOC_MAGIC`.
pub const SPI_MAGIC: u8 = b'k';
/// `SPI_IOC_RD_MODE` / `SPI_IOC_WR_MODE` (u8).
pub const SPI_RD_MODE: u64 = ioc(IOC_READ, SPI_MAGIC, 1, 1);
/// Write form.
pub const SPI_WR_MODE: u64 = ioc(IOC_WRITE, SPI_MAGIC, 1, 1);
/// `SPI_IOC_RD_LSB_FIRST` (u8).
pub const SPI_RD_LSB_FIRST: u64 = ioc(IOC_READ, SPI_MAGIC, 2, 1);
/// Write form.
pub const SPI_WR_LSB_FIRST: u64 = ioc(IOC_WRITE, SPI_MAGIC, 2, 1);
/// `SPI_IOC_RD_BITS_PER_WORD` (u8).
pub const SPI_RD_BITS_PER_WORD: u64 = ioc(IOC_READ, SPI_MAGIC, 3, 1);
/// Write form.
pub const SPI_WR_BITS_PER_WORD: u64 = ioc(IOC_WRITE, SPI_MAGIC, 3, 1);
/// `SPI_IOC_RD_MAX_SPEED_HZ` (u32).
pub const SPI_RD_MAX_SPEED_HZ: u64 = ioc(IOC_READ, SPI_MAGIC, 4, 4);
/// Write form.
pub const SPI_WR_MAX_SPEED_HZ: u64 = ioc(IOC_WRITE, SPI_MAGIC, 4, 4);
/// `SPI_IOC_RD_MODE32` (u32).
pub const SPI_RD_MODE32: u64 = ioc(IOC_READ, SPI_MAGIC, 5, 4);
/// Write form.
pub const SPI_WR_MODE32: u64 = ioc(IOC_WRITE, SPI_MAGIC, 5, 4);

/// `SPI_IOC_MESSAGE(n)`: `n` transfers, or `None` for another request.
pub fn spi_message_count(request: u64) -> Option<usize> {
    let n = IoctlNumber::of(request);
    let one = size_of::<SpiIocTransfer>();
    (n.ty == SPI_MAGIC && n.nr == 0 && n.dir == IOC_WRITE && n.size % one == 0).then_some(n.size / one)
}

/// `SPI_IOC_MESSAGE(n)`'s request number.
pub const fn spi_message(n: usize) -> u64 {
    ioc(IOC_WRITE, SPI_MAGIC, 0, n * size_of::<SpiIocTransfer>())
}

/// `struct spi_ioc_transfer`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct SpiIocTransfer {
    /// User address of the bytes out (0: zeros).
    pub tx_buf: u64,
    /// User address for the bytes in (0: discarded).
    pub rx_buf: u64,
    /// Bytes.
    pub len: u32,
    /// Clock for this transfer (0: the device's).
    pub speed_hz: u32,
    /// Delay after it.
    pub delay_usecs: u16,
    /// Word size for this transfer (0: the device's).
    pub bits_per_word: u8,
    /// Deselect after it.
    pub cs_change: u8,
    /// Lines for tx (dual/quad); 0 = 1.
    pub tx_nbits: u8,
    /// Lines for rx.
    pub rx_nbits: u8,
    /// Delay between words.
    pub word_delay_usecs: u8,
    /// Padding.
    pub pad: u8,
}

/// `SPI_CPHA`, `SPI_CPOL`, `SPI_CS_HIGH`, `SPI_LSB_FIRST`, `SPI_3WIRE`,
/// `SPI_NO_CS` (uapi/linux/spi/spi.h).
pub const SPI_CPHA: u32 = 0x01;
/// Clock idles high.
pub const SPI_CPOL: u32 = 0x02;
/// Chip select active high.
pub const SPI_CS_HIGH: u32 = 0x04;
/// Bit order in the mode word.
pub const SPI_LSB_FIRST: u32 = 0x08;
/// One data line both ways.
pub const SPI_3WIRE: u32 = 0x10;
/// No chip select.
pub const SPI_NO_CS: u32 = 0x40;

/// GPIO ioctl magic.
pub const GPIO_MAGIC: u8 = 0xB4;
/// Longest chip, line and consumer name.
pub const NAME_SIZE: usize = 32;
/// Lines in one request.
pub const LINES_MAX: usize = 64;
/// Attributes in a line config.
pub const NUM_ATTRS_MAX: usize = 10;

/// `struct gpiochip_info`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct ChipInfo {
    /// Kernel name (`gpiochip0`).
    pub name: [u8; NAME_SIZE],
    /// Functional name (`pinctrl-bcm2711`).
    pub label: [u8; NAME_SIZE],
    /// Lines.
    pub lines: u32,
}

/// `struct gpio_v2_line_attribute`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct LineAttribute {
    /// `GPIO_V2_LINE_ATTR_ID_*`.
    pub id: u32,
    /// Zero.
    pub padding: u32,
    /// Flags, output values or the debounce period (us), as `id` says.
    pub value: u64,
}

/// `struct gpio_v2_line_config_attribute`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct LineConfigAttribute {
    /// The attribute.
    pub attr: LineAttribute,
    /// The lines (bits of the request's line index) it applies to.
    pub mask: u64,
}

/// `struct gpio_v2_line_config`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct LineConfig {
    /// Flags of the lines no attribute overrides.
    pub flags: u64,
    /// Attributes used.
    pub num_attrs: u32,
    /// Zero.
    pub padding: [u32; 5],
    /// Attributes.
    pub attrs: [LineConfigAttribute; NUM_ATTRS_MAX],
}

/// `struct gpio_v2_line_request`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LineRequest {
    /// Offsets of the lines.
    pub offsets: [u32; LINES_MAX],
    /// Consumer label.
    pub consumer: [u8; NAME_SIZE],
    /// Configuration.
    pub config: LineConfig,
    /// Lines used in `offsets`.
    pub num_lines: u32,
    /// Edge events kept (0: 16 per line).
    pub event_buffer_size: u32,
    /// Zero.
    pub padding: [u32; 5],
    /// Out: the request's file descriptor.
    pub fd: i32,
}

/// `struct gpio_v2_line_info`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct LineInfo {
    /// Line name.
    pub name: [u8; NAME_SIZE],
    /// Consumer, when requested.
    pub consumer: [u8; NAME_SIZE],
    /// In: the offset.
    pub offset: u32,
    /// Attributes filled.
    pub num_attrs: u32,
    /// `GPIO_V2_LINE_FLAG_*`.
    pub flags: u64,
    /// Attributes.
    pub attrs: [LineAttribute; NUM_ATTRS_MAX],
    /// Zero.
    pub padding: [u32; 4],
}

/// `struct gpio_v2_line_values`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct LineValues {
    /// Values, by line index.
    pub bits: u64,
    /// Lines asked for.
    pub mask: u64,
}

/// `struct gpio_v2_line_event`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LineEvent {
    /// When (the request's event clock), ns.
    pub timestamp_ns: u64,
    /// [`EVENT_RISING`] or [`EVENT_FALLING`].
    pub id: u32,
    /// The line.
    pub offset: u32,
    /// Events of the request so far, this one included.
    pub seqno: u32,
    /// Events of the line so far, this one included.
    pub line_seqno: u32,
    /// Zero.
    pub padding: [u32; 6],
}

/// `GPIO_V2_LINE_EVENT_RISING_EDGE`.
pub const EVENT_RISING: u32 = 1;
/// `GPIO_V2_LINE_EVENT_FALLING_EDGE`.
pub const EVENT_FALLING: u32 = 2;

/// `GPIO_V2_LINE_FLAG_*`.
pub mod flag {
    /// Requested by someone.
    pub const USED: u64 = 1 << 0;
    /// Logical value inverted.
    pub const ACTIVE_LOW: u64 = 1 << 1;
    /// Input.
    pub const INPUT: u64 = 1 << 2;
    /// Output.
    pub const OUTPUT: u64 = 1 << 3;
    /// Rising edges make events.
    pub const EDGE_RISING: u64 = 1 << 4;
    /// Falling edges make events.
    pub const EDGE_FALLING: u64 = 1 << 5;
    /// Open drain.
    pub const OPEN_DRAIN: u64 = 1 << 6;
    /// Open source.
    pub const OPEN_SOURCE: u64 = 1 << 7;
    /// Pull-up.
    pub const BIAS_PULL_UP: u64 = 1 << 8;
    /// Pull-down.
    pub const BIAS_PULL_DOWN: u64 = 1 << 9;
    /// No bias.
    pub const BIAS_DISABLED: u64 = 1 << 10;
    /// Event timestamps from CLOCK_REALTIME.
    pub const EVENT_CLOCK_REALTIME: u64 = 1 << 11;
    /// Event timestamps from a hardware engine.
    pub const EVENT_CLOCK_HTE: u64 = 1 << 12;
    /// Every flag the kernel knows.
    pub const ALL: u64 = (1 << 13) - 1;
}

/// `GPIO_V2_LINE_ATTR_ID_FLAGS`.
pub const ATTR_FLAGS: u32 = 1;
/// `GPIO_V2_LINE_ATTR_ID_OUTPUT_VALUES`.
pub const ATTR_OUTPUT_VALUES: u32 = 2;
/// `GPIO_V2_LINE_ATTR_ID_DEBOUNCE`.
pub const ATTR_DEBOUNCE: u32 = 3;

/// `GPIO_GET_CHIPINFO_IOCTL`.
pub const GPIO_GET_CHIPINFO: u64 = ioc(IOC_READ, GPIO_MAGIC, 0x01, size_of::<ChipInfo>());
/// `GPIO_V2_GET_LINEINFO_IOCTL`.
pub const GPIO_V2_GET_LINEINFO: u64 = ioc(IOC_READ | IOC_WRITE, GPIO_MAGIC, 0x05, size_of::<LineInfo>());
/// `GPIO_V2_GET_LINE_IOCTL`.
pub const GPIO_V2_GET_LINE: u64 = ioc(IOC_READ | IOC_WRITE, GPIO_MAGIC, 0x07, size_of::<LineRequest>());
/// `GPIO_V2_LINE_SET_CONFIG_IOCTL`.
pub const GPIO_V2_LINE_SET_CONFIG: u64 = ioc(IOC_READ | IOC_WRITE, GPIO_MAGIC, 0x0D, size_of::<LineConfig>());
/// `GPIO_V2_LINE_GET_VALUES_IOCTL`.
pub const GPIO_V2_LINE_GET_VALUES: u64 = ioc(IOC_READ | IOC_WRITE, GPIO_MAGIC, 0x0E, size_of::<LineValues>());
/// `GPIO_V2_LINE_SET_VALUES_IOCTL`.
pub const GPIO_V2_LINE_SET_VALUES: u64 = ioc(IOC_READ | IOC_WRITE, GPIO_MAGIC, 0x0F, size_of::<LineValues>());

// The sizes the kernel's headers give (and its ioctl numbers encode).
const _: () = assert!(size_of::<SpiIocTransfer>() == 32);
const _: () = assert!(size_of::<ChipInfo>() == 68);
const _: () = assert!(size_of::<LineAttribute>() == 16);
const _: () = assert!(size_of::<LineConfigAttribute>() == 24);
const _: () = assert!(size_of::<LineConfig>() == 272);
const _: () = assert!(size_of::<LineRequest>() == 592);
const _: () = assert!(size_of::<LineInfo>() == 256);
const _: () = assert!(size_of::<LineEvent>() == 48);
const _: () = assert!(size_of::<LineValues>() == 16);

#[cfg(test)]
mod tests {
    use super::*;

    /// Numbers as the kernel headers expand them (checked with a C
    /// compiler against <linux/spi/spidev.h> and <linux/gpio.h>).
    #[test]
    fn request_numbers_are_the_kernels() {
        assert_eq!(SPI_WR_MODE, 0x4001_6b01);
        assert_eq!(SPI_RD_MODE, 0x8001_6b01);
        assert_eq!(SPI_WR_MAX_SPEED_HZ, 0x4004_6b04);
        assert_eq!(SPI_WR_MODE32, 0x4004_6b05);
        assert_eq!(spi_message(1), 0x4020_6b00);
        assert_eq!(spi_message_count(spi_message(3)), Some(3));
        assert_eq!(spi_message_count(SPI_WR_MODE), None);
        assert_eq!(GPIO_GET_CHIPINFO, 0x8044_b401);
        assert_eq!(GPIO_V2_GET_LINEINFO, 0xc100_b405);
        assert_eq!(GPIO_V2_GET_LINE, 0xc250_b407);
        assert_eq!(GPIO_V2_LINE_SET_CONFIG, 0xc110_b40d);
        assert_eq!(GPIO_V2_LINE_GET_VALUES, 0xc010_b40e);
    }
}
