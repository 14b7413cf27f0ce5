//! `libecmxf_hw_emu.so`: the kernel's `/dev/spidevB.C` and
//! `/dev/gpiochipN` emulated in user space, backed by the ECM-XF simulator,
//! so ecmxfd's hardware link (`link.backend = "spidev"`: daemon/src/link/
//! hardware.rs, the `spidev` and `gpiocdev` crates, and `ecmxfd probe`)
//! runs on a machine without the chip, SPI or GPIO.
//!
//! ```sh
//! ecmxf-sim serve --socket /tmp/sim.sock --network config/demo-network.toml &
//! LD_PRELOAD=target/debug/libecmxf_hw_emu.so ECMXF_SIM_SOCKET=/tmp/sim.sock \
//!     ecmxfd probe --config config/ecmxfd-rpi.toml
//! ```
//!
//! The library replaces libc's `open`/`open64`/`openat`/`openat64`,
//! `ioctl`, `read`, `ppoll`/`poll`, `close` and `realpath` (interpose.rs)
//! for the nodes it emulates, and passes every other call to libc:
//! - SPI ([`spi`]): `SPI_IOC_MESSAGE(n)` full-duplex transfers become the
//!   simulator's byte stream, returning when the clock would have shifted
//!   them; mode, word size, bit order and clock are kept and anything but
//!   what the chip needs garbles the bytes as the wires would.
//! - GPIO uAPI v2 ([`uapi`], [`lines`]): chip and line info, line requests
//!   (flags checked as the kernel checks them; EBUSY for a line another
//!   request holds, in any process on the same simulator), values, edge
//!   events with CLOCK_MONOTONIC (or REALTIME) timestamps and sequence
//!   numbers, software debounce, a bounded event queue; INT0 and INT1
//!   follow the simulated chip, `ecmxf-sim ctl int0 stuck` included.
//! - Errors as the kernel gives them: ENOENT for a node not emulated (the
//!   kernel's own answer, as there is none), EACCES for paths named in
//!   `ECMXF_EMU_DENY`, EBUSY, EINVAL, ENOTTY for unknown requests,
//!   EMSGSIZE above spidev's 4096-byte buffer.
//!
//! Environment ([`config`]): `ECMXF_SIM_SOCKET` (required; without it
//! nothing is emulated), `ECMXF_EMU_SPIDEV`, `ECMXF_EMU_GPIOCHIP`,
//! `ECMXF_EMU_GPIO_LINES`, `ECMXF_EMU_INT0_LINE`, `ECMXF_EMU_INT1_LINE`
//! (defaults: config/ecmxfd-rpi.toml's wiring), and the faults
//! `ECMXF_EMU_DENY`, `ECMXF_EMU_MISO=high|low`, `ECMXF_EMU_FORCE_MODE=N`;
//! `ECMXF_EMU_STATS=FILE` writes the call counters when the SPI device is
//! closed and at exit.
//!
//! Not modelled: DMA and its thresholds, the kernel's scheduling and
//! interrupt latency (the transfer's time is slept, a wake-up's jitter is
//! this machine's), signal integrity beyond the bit errors of a clock
//! above 96 MHz, `write` on spidev (not intercepted: `write` is every
//! socket's hot path), `dup` of an emulated descriptor, `poll` on a mix of
//! emulated and other descriptors, uAPI v1, line-info watches.
//!
//! Why not umockdev: it emulates spidev ioctls from recorded scripts and
//! has no GPIO v2 line requests at all; the chip's answers here depend on
//! what the host sent, which only the simulator can give, and INT0's edges
//! on the packets the chip took. A packaged umockdev would also be a
//! system install, which the build must not need.

pub mod config;
pub mod device;
pub mod lines;
pub mod spi;
pub mod uapi;

#[cfg(not(test))]
mod interpose;
