//! Packet framing (v049 封包格式, 圖三): header, data section, check word, end
//! word; both directions have the same length.
//!
//! | part | bytes |
//! | --- | --- |
//! | header | 24 |
//! | data section | D = 32..=1408, default 112 (ECM-XFU: fixed 992) |
//! | check word | 4 |
//! | end word | 4, 0x56575859 |

use crate::error::EncodeError;
use crate::header::HEADER_LEN;
pub use crate::header::START_WORD;

/// The end word, last four bytes of every packet.
pub const END_WORD: u32 = 0x5657_5859;
/// Smallest data section (v049 封包格式 item 7).
pub const DATA_MIN: usize = 32;
/// Largest data section.
pub const DATA_MAX: usize = 1408;
/// Data section after power-up.
pub const DATA_DEFAULT: usize = 112;
/// The ECM-XFU's data section, which cannot be changed.
pub const DATA_XFU: usize = 992;
/// Bytes after the data section: check word and end word.
pub const TRAILER_LEN: usize = 8;
/// Bytes around the data section.
pub const OVERHEAD: usize = HEADER_LEN + TRAILER_LEN;

/// The size of the packets exchanged now, from the data-section size.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PacketLayout {
    data_size: u16,
}

impl Default for PacketLayout {
    fn default() -> Self {
        Self { data_size: DATA_DEFAULT as u16 }
    }
}

impl PacketLayout {
    /// A layout with a data section of `data_size` bytes (32..=1408).
    pub const fn new(data_size: usize) -> Result<Self, EncodeError> {
        if data_size < DATA_MIN || data_size > DATA_MAX {
            return Err(EncodeError::FieldOutOfRange {
                field: "data section size",
                value: data_size as u32,
                min: DATA_MIN as u32,
                max: DATA_MAX as u32,
            });
        }
        Ok(Self { data_size: data_size as u16 })
    }

    /// The layout whose whole packet is `len` bytes, if there is one.
    pub const fn from_packet_len(len: usize) -> Option<Self> {
        if len < OVERHEAD + DATA_MIN || len > OVERHEAD + DATA_MAX {
            return None;
        }
        Some(Self { data_size: (len - OVERHEAD) as u16 })
    }

    /// The data section's size.
    pub const fn data_size(self) -> usize {
        self.data_size as usize
    }

    /// The whole packet's size.
    pub const fn packet_len(self) -> usize {
        self.data_size as usize + OVERHEAD
    }

    /// Byte offset of the check word.
    pub const fn check_offset(self) -> usize {
        HEADER_LEN + self.data_size as usize
    }
}

/// Finds the end of a packet in a byte stream clocked from a chip in an
/// unknown state: the position just after an end word that is directly
/// followed by a start word (docs/protocol.md §3; the vendor driver
/// clocks single bytes until it sees this). Returns the index where the next
/// packet starts.
pub fn find_packet_start(stream: &[u8]) -> Option<usize> {
    let end = END_WORD.to_le_bytes();
    let start = START_WORD.to_le_bytes();
    stream.windows(8).position(|w| w[..4] == end && w[4..] == start).map(|i| i + 4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_bounds() {
        assert_eq!(PacketLayout::default().packet_len(), 144);
        assert_eq!(PacketLayout::new(1408).unwrap().packet_len(), 1440);
        assert_eq!(PacketLayout::new(32).unwrap().packet_len(), 64);
        assert!(PacketLayout::new(31).is_err());
        assert!(PacketLayout::new(1409).is_err());
        assert_eq!(PacketLayout::from_packet_len(144), Some(PacketLayout::default()));
        assert_eq!(PacketLayout::from_packet_len(63), None);
        assert_eq!(PacketLayout::from_packet_len(1441), None);
        assert_eq!(PacketLayout::default().check_offset(), 136);
    }

    #[test]
    fn finds_boundary_between_packets() {
        let mut s = [0u8; 20];
        s[3..7].copy_from_slice(&END_WORD.to_le_bytes());
        s[7..11].copy_from_slice(&START_WORD.to_le_bytes());
        assert_eq!(find_packet_start(&s), Some(7));
        assert_eq!(find_packet_start(&s[..10]), None);
        assert_eq!(find_packet_start(&[]), None);
    }
}
