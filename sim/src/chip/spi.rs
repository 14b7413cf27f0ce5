//! The chip's SPI side as a byte stream (v049 SPI 命令傳送與回應接收說明;
//! docs/protocol.md §6 and §3).
//!
//! A transfer may have any length. Incoming bytes collect until a whole
//! packet (of the size in force) has arrived; only then is the command taken.
//! Meanwhile the chip shifts out, byte for byte, the packet it prepared: the
//! answer to the previous command. A packet whose first byte arrives while
//! the chip is still processing is not taken: the chip shifts out a packet
//! whose check word is 0x87654321 and the pending answer waits for the next
//! packet that is taken.

use ecmxf_wire::check::CHECK_NOT_READY;
use ecmxf_wire::framing::{END_WORD, OVERHEAD, START_WORD};
use ecmxf_wire::header::HEADER_LEN;

/// The byte-stream state of the SPI port.
#[derive(Clone, Debug)]
pub struct SpiPort {
    /// Data-section size in force.
    pub data_size: usize,
    incoming: Vec<u8>,
    outgoing: Vec<u8>,
    out_pos: usize,
    taking: bool,
    /// The answer that goes out with the next packet taken.
    pub pending: Vec<u8>,
}

/// What happened at a packet boundary.
#[derive(Debug)]
pub enum Boundary {
    /// A whole packet arrived and is taken: process these bytes.
    Taken(Vec<u8>),
    /// A whole packet arrived but the chip was not ready: it is lost.
    Lost,
}

impl SpiPort {
    /// A port with `data_size` and an initial answer (the NOP).
    pub fn new(data_size: usize, first_answer: Vec<u8>) -> Self {
        Self { data_size, incoming: Vec::new(), outgoing: Vec::new(), out_pos: 0, taking: false, pending: first_answer }
    }

    /// Whole packet length in force.
    pub fn packet_len(&self) -> usize {
        self.data_size + OVERHEAD
    }

    /// Whether a packet is partly received.
    pub fn mid_packet(&self) -> bool {
        !self.incoming.is_empty()
    }

    /// Exchanges one byte. `ready` says whether the chip would take a packet
    /// starting now. Returns the byte shifted out and, at the end of a
    /// packet, what became of it.
    pub fn exchange(&mut self, mosi: u8, ready: bool) -> (u8, Option<Boundary>) {
        if self.incoming.is_empty() {
            self.taking = ready;
            self.outgoing = if ready { self.pending.clone() } else { not_ready_packet(self.packet_len()) };
            self.out_pos = 0;
        }
        let miso = self.outgoing.get(self.out_pos).copied().unwrap_or(0);
        self.out_pos += 1;
        self.incoming.push(mosi);
        if self.incoming.len() < self.packet_len() {
            return (miso, None);
        }
        let packet = std::mem::take(&mut self.incoming);
        let boundary = if self.taking { Boundary::Taken(packet) } else { Boundary::Lost };
        (miso, Some(boundary))
    }

    /// Drops a partial packet (chip reset).
    pub fn reset(&mut self, data_size: usize, first_answer: Vec<u8>) {
        *self = Self::new(data_size, first_answer);
    }
}

/// The packet a chip clocked too early shifts out: framing words, zeros and
/// the "not ready" check word.
pub fn not_ready_packet(len: usize) -> Vec<u8> {
    let mut p = vec![0u8; len];
    p[..4].copy_from_slice(&START_WORD.to_le_bytes());
    let at = len - 8;
    debug_assert!(at >= HEADER_LEN);
    p[at..at + 4].copy_from_slice(&CHECK_NOT_READY.to_le_bytes());
    p[at + 4..].copy_from_slice(&END_WORD.to_le_bytes());
    p
}
