//! What the chip takes, as the manuals give it.

/// The chip's SPI clock range, Hz: up to 96 Mbit/s (v049 硬體規格
/// "傳輸率 96Mbps(max.)"); below 100 kHz one packet takes longer than a
/// DC cycle could ever wait, so a smaller figure is a typo.
pub const SPI_HZ: core::ops::RangeInclusive<u64> = 100_000..=96_000_000;
/// Slaves the chip takes (v049 簡介; docs/protocol.md §17).
pub const MAX_SLAVES: usize = 128;
