//! The SPI controller and the wires between it and the chip: what
//! `/dev/spidevB.C` keeps from the ioctls (mode, word size, bit order,
//! clock) and what those settings do to the bytes on their way.
//!
//! The chip needs SPI mode 0 (CPOL 0, CPHA 0), 8-bit words, MSB first, at
//! most 96 MHz (v049 SPI模式). A host that sets anything else does not get
//! an error from a real kernel, it gets garbled bytes; so it does here:
//! - another clock phase or polarity (modes 1-3): each side samples a bit
//!   early or late, so the chip sees the host's bits one place later and
//!   the host sees the chip's one place earlier;
//! - LSB first: every byte bit-reversed both ways;
//! - 16- or 32-bit words: the controller shifts the buffer's (little-
//!   endian) words MSB first, so the bytes of each word arrive swapped;
//!   other word sizes are refused with EINVAL, as the Raspberry Pi's
//!   controller (spi-bcm2835) refuses them;
//! - chip select active high, or no chip select: the chip is never
//!   selected: it sees nothing and MISO floats high (0xFF);
//! - above 96 MHz: bit errors (one bit of one byte in 16 flipped).
//!
//! Wiring faults the tests inject ([`Wiring`]): MISO stuck high or low, and
//! a controller that clocks another mode than the one asked for.

/// The chip's fastest clock (v049: 96 Mbit/s).
pub const MAX_HZ: u32 = 96_000_000;

/// Settings of one open SPI device, as the ioctls left them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Settings {
    /// `SPI_IOC_WR_MODE32` bits (CPHA, CPOL, CS_HIGH, LSB_FIRST...).
    pub mode: u32,
    /// Word size.
    pub bits_per_word: u8,
    /// Clock.
    pub max_speed_hz: u32,
}

impl Default for Settings {
    /// A freshly opened spidev: what the device tree gave it (the Pi's
    /// overlay: mode 0, 8 bits, 125 MHz maximum; the kernel default is
    /// the controller's maximum, far above the chip's).
    fn default() -> Self {
        Self { mode: 0, bits_per_word: 8, max_speed_hz: 125_000_000 }
    }
}

/// Faults of the wires and controller, from the environment.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Wiring {
    /// MISO held at a level (`Some(true)`: 0xFF).
    pub miso_stuck: Option<bool>,
    /// The controller clocks this mode (0..3) whatever was asked.
    pub forced_mode: Option<u32>,
}

/// What the wire does to a transfer under these settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Effect {
    /// The chip is not selected: it sees nothing, MISO floats high.
    pub deselected: bool,
    /// Clock phase or polarity differs from the chip's.
    pub phase_shift: bool,
    /// Bits reversed.
    pub lsb_first: bool,
    /// Bytes per word (1, 2 or 4), swapped within a word.
    pub word_bytes: usize,
    /// Clock above the chip's maximum.
    pub too_fast: bool,
    /// MISO stuck.
    pub miso_stuck: Option<bool>,
}

impl Effect {
    /// The effect of `settings` for one transfer (its own clock and word
    /// size when given, else the device's), or EINVAL for a word size the
    /// controller does not take.
    pub fn of(settings: &Settings, wiring: &Wiring, speed_hz: u32, bits_per_word: u8) -> Result<Self, i32> {
        let bits = if bits_per_word == 0 { settings.bits_per_word } else { bits_per_word };
        let word_bytes = match bits {
            8 => 1,
            16 => 2,
            32 => 4,
            _ => return Err(libc::EINVAL),
        };
        let speed = if speed_hz == 0 { settings.max_speed_hz } else { speed_hz };
        let mode = wiring.forced_mode.unwrap_or(settings.mode & (super::uapi::SPI_CPHA | super::uapi::SPI_CPOL));
        Ok(Self {
            deselected: settings.mode & (super::uapi::SPI_CS_HIGH | super::uapi::SPI_NO_CS) != 0,
            phase_shift: mode != 0,
            lsb_first: settings.mode & super::uapi::SPI_LSB_FIRST != 0,
            word_bytes,
            too_fast: speed > MAX_HZ,
            miso_stuck: wiring.miso_stuck,
        })
    }

    /// The bytes as the chip receives them.
    pub fn to_chip(&self, mosi: &mut [u8], noise: &mut Noise) {
        self.reorder(mosi);
        if self.phase_shift {
            // The chip samples each bit one place late: it sees a 0 first.
            shift_right(mosi);
        }
        if self.too_fast {
            noise.flip(mosi);
        }
    }

    /// The bytes as the host receives them.
    pub fn to_host(&self, miso: &mut [u8], noise: &mut Noise) {
        if let Some(level) = self.miso_stuck.or(self.deselected.then_some(true)) {
            miso.fill(if level { 0xFF } else { 0 });
            return;
        }
        if self.phase_shift {
            shift_left(miso);
        }
        if self.too_fast {
            noise.flip(miso);
        }
        self.reorder(miso);
    }

    fn reorder(&self, bytes: &mut [u8]) {
        if self.lsb_first {
            for b in bytes.iter_mut() {
                *b = b.reverse_bits();
            }
        }
        if self.word_bytes > 1 {
            for w in bytes.chunks_exact_mut(self.word_bytes) {
                w.reverse();
            }
        }
    }
}

/// The bit stream one place later (a 0 enters first).
fn shift_right(bytes: &mut [u8]) {
    let mut carry = 0u8;
    for b in bytes.iter_mut() {
        let next = *b & 1;
        *b = (*b >> 1) | (carry << 7);
        carry = next;
    }
}

/// The bit stream one place earlier (the line's idle-high bit enters last).
fn shift_left(bytes: &mut [u8]) {
    let n = bytes.len();
    for i in 0..n {
        let next = bytes.get(i + 1).map_or(1, |b| b >> 7);
        bytes[i] = (bytes[i] << 1) | next;
    }
}

/// Bit errors of a clock too fast for the wires: a reproducible stream.
#[derive(Clone, Copy, Debug)]
pub struct Noise(u64);

impl Default for Noise {
    fn default() -> Self {
        Self(0x9E37_79B9_7F4A_7C15)
    }
}

impl Noise {
    /// Flips one bit in about one byte of 16.
    pub fn flip(&mut self, bytes: &mut [u8]) {
        for b in bytes.iter_mut() {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            if self.0 % 16 == 0 {
                *b ^= 1 << ((self.0 >> 8) % 8);
            }
        }
    }
}

/// Nanoseconds the clock needs for `bytes` at `hz`.
pub fn wire_ns(bytes: usize, hz: u32) -> u64 {
    (bytes as u64 * 8).saturating_mul(1_000_000_000) / u64::from(hz.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn effect(settings: Settings) -> Effect {
        Effect::of(&settings, &Wiring::default(), 0, 0).unwrap()
    }

    const MODE0: Settings = Settings { mode: 0, bits_per_word: 8, max_speed_hz: 20_000_000 };

    #[test]
    fn mode_0_msb_first_8_bits_leaves_bytes_alone() {
        let e = effect(MODE0);
        let mut b = [0x5A, 0x01, 0xFF, 0x80];
        e.to_chip(&mut b, &mut Noise::default());
        assert_eq!(b, [0x5A, 0x01, 0xFF, 0x80]);
        e.to_host(&mut b, &mut Noise::default());
        assert_eq!(b, [0x5A, 0x01, 0xFF, 0x80]);
    }

    #[test]
    fn every_other_setting_garbles() {
        let original = [0x5A, 0x01, 0xC3, 0x80];
        for (what, s) in [
            ("mode 1", Settings { mode: 1, ..MODE0 }),
            ("mode 3", Settings { mode: 3, ..MODE0 }),
            ("lsb first", Settings { mode: crate::uapi::SPI_LSB_FIRST, ..MODE0 }),
            ("16-bit words", Settings { bits_per_word: 16, ..MODE0 }),
            ("cs high", Settings { mode: crate::uapi::SPI_CS_HIGH, ..MODE0 }),
        ] {
            let e = effect(s);
            let (mut to_chip, mut to_host) = (original, original);
            e.to_chip(&mut to_chip, &mut Noise::default());
            e.to_host(&mut to_host, &mut Noise::default());
            assert!(to_chip != original || e.deselected, "{what}: the chip saw the host's bytes");
            assert_ne!(to_host, original, "{what}: the host saw the chip's bytes");
        }
        assert_eq!(Effect::of(&Settings { bits_per_word: 9, ..MODE0 }, &Wiring::default(), 0, 0), Err(libc::EINVAL));
    }

    #[test]
    fn a_phase_error_moves_every_bit_by_one_place() {
        let mut b = [0b1000_0001, 0b0000_0001];
        shift_right(&mut b);
        assert_eq!(b, [0b0100_0000, 0b1000_0000]);
        let mut b = [0b1000_0001, 0b1000_0000];
        shift_left(&mut b);
        assert_eq!(b, [0b0000_0011, 0b0000_0001]);
    }

    #[test]
    fn too_fast_a_clock_flips_bits_and_stuck_miso_wins() {
        let fast = effect(Settings { max_speed_hz: 100_000_000, ..MODE0 });
        let mut b = [0u8; 256];
        fast.to_host(&mut b, &mut Noise::default());
        let flipped = b.iter().filter(|&&x| x != 0).count();
        assert!((4..=40).contains(&flipped), "{flipped} of 256 bytes");
        let stuck = Effect::of(&MODE0, &Wiring { miso_stuck: Some(false), forced_mode: None }, 0, 0).unwrap();
        let mut b = [0xA5u8; 4];
        stuck.to_host(&mut b, &mut Noise::default());
        assert_eq!(b, [0; 4]);
        let forced = Effect::of(&MODE0, &Wiring { miso_stuck: None, forced_mode: Some(1) }, 0, 0).unwrap();
        assert!(forced.phase_shift);
    }

    #[test]
    fn wire_time_is_bits_over_clock() {
        assert_eq!(wire_ns(544, 20_000_000), 217_600);
    }
}
