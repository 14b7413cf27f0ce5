//! Whether the SPI link can carry the process data at the configured
//! cycle. The chip consumes one RxPDO frame and produces one TxPDO frame per
//! DC cycle (v049 PDO_DATA_FIFO_OP); the host moves them in packets whose
//! data section holds `data_size / frame size` frames (both directions in
//! the same packet: outputs on MOSI, inputs on MISO). A packet takes its
//! clocking time plus the chip's processing time, and SDO, SII and state
//! requests share the same packets. A process image larger than a packet,
//! or one whose frames need more packet time than the cycle leaves, can
//! never be fed: said at bring-up, with the numbers, instead of a network
//! that reaches OP and then runs its RxFIFO dry while every request times
//! out (an EL2262 oversampling terminal's ~1 KB of outputs at 1 ms).
//!
//! Each FIFO call costs two packets: it is guarded (see `port`), because
//! its reads take the input frames out of the chip's TxFIFO and a lost
//! answer would lose them. So a plan needs two packets per `frames per
//! packet` cycles at least, and that is the load counted here (counted as
//! one packet, a network that needed 94 % of the link was once let through
//! with no warning and ran its RxFIFO dry every 45 ms). Above
//! [`MAX_LOAD`] the network is refused: what is left cannot absorb the
//! host's jitter, let alone requests.
//!
//! The decision takes the measured packet time as a parameter so it is
//! unit-tested without a link.

use std::fmt;

/// Above this share of the link's time the cyclic exchange leaves requests
/// (SDO, SII, state) too little room: a warning, not a refusal.
pub const WARN_LOAD: f64 = 0.5;
/// Above this share the network is refused.
pub const MAX_LOAD: f64 = 0.9;
/// Packets one FIFO call takes: the call and its guarded resend.
pub const PACKETS_PER_CALL: u64 = 2;

/// What the cyclic exchange costs the link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkBudget {
    /// Cycles of frames one packet carries (both directions); `usize::MAX`
    /// when there is no process data (nothing to carry).
    pub frames_per_packet: usize,
    /// Measured time of one packet, ns.
    pub packet_ns: u64,
    /// DC cycle, ns.
    pub cycle_ns: u64,
}

impl LinkBudget {
    /// Share of the link's time the cyclic exchange alone takes at least
    /// (1.0: all): [`PACKETS_PER_CALL`] packets per `frames_per_packet`
    /// cycles.
    pub fn load(&self) -> f64 {
        self.min_exchanges_per_s() * self.packet_ns as f64 / 1e9
    }

    /// Exchanges per second the plan needs at least (0: no process data).
    pub fn min_exchanges_per_s(&self) -> f64 {
        if self.frames_per_packet == usize::MAX {
            return 0.0;
        }
        (PACKETS_PER_CALL as f64) * 1e9 / (self.frames_per_packet as f64 * self.cycle_ns.max(1) as f64)
    }
}

/// The time the bits of a packet with a `data_size`-byte data section take
/// at `hz`: a lower bound of the packet's time (the chip's processing and
/// the host's wake-up come on top).
pub fn clocked_ns(data_size: usize, hz: u64) -> u64 {
    ((data_size + ecmxf_wire::framing::OVERHEAD) * 8) as u64 * 1_000_000_000 / hz.max(1)
}

/// Why the link cannot carry the process data.
#[derive(Clone, Debug, PartialEq)]
pub enum BudgetError {
    /// One frame is bigger than a packet's data section.
    FrameTooBig {
        /// "output" or "input".
        direction: &'static str,
        /// Frame bytes.
        frame: usize,
        /// Packet data section bytes.
        data_size: usize,
    },
    /// The frames need more packet time than the cycle has.
    TooSlow(LinkBudget),
}

impl fmt::Display for BudgetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::FrameTooBig { direction, frame, data_size } => write!(
                f,
                "one {direction} frame is {frame} bytes and an SPI packet carries {data_size}: \
                 raise chip.data_size (up to 1408) or map fewer PDOs"
            ),
            Self::TooSlow(b) => write!(
                f,
                "the process data needs {:.0}% of the SPI link (at most {:.0}% can work): a FIFO call takes {} \
                 packets of {} us and carries {} cycle(s) of frames, the cycle is {} us; lengthen \
                 cycle.sync0_us, raise link.spi_hz or chip.data_size, or map fewer PDOs",
                b.load() * 100.0,
                MAX_LOAD * 100.0,
                PACKETS_PER_CALL,
                b.packet_ns / 1000,
                b.frames_per_packet,
                b.cycle_ns / 1000
            ),
        }
    }
}

/// Checks the link against the process data: `rx_size`/`tx_size` are the
/// frame sizes (0: that direction has no process data), `packet_ns` the
/// measured time of one packet.
pub fn check(
    data_size: usize,
    rx_size: usize,
    tx_size: usize,
    packet_ns: u64,
    cycle_ns: u64,
) -> Result<LinkBudget, BudgetError> {
    let mut frames_per_packet = usize::MAX;
    for (direction, frame) in [("output", rx_size), ("input", tx_size)] {
        if frame == 0 {
            continue;
        }
        if frame > data_size {
            return Err(BudgetError::FrameTooBig { direction, frame, data_size });
        }
        frames_per_packet = frames_per_packet.min(data_size / frame);
    }
    let budget = LinkBudget { frames_per_packet, packet_ns, cycle_ns };
    if budget.load() > MAX_LOAD { Err(BudgetError::TooSlow(budget)) } else { Ok(budget) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_bigger_than_a_packet_is_refused_naming_both_sizes() {
        let e = check(512, 1024, 8, 250_000, 1_000_000).unwrap_err();
        assert_eq!(e, BudgetError::FrameTooBig { direction: "output", frame: 1024, data_size: 512 });
        let text = e.to_string();
        assert!(text.contains("1024 bytes") && text.contains("chip.data_size"), "{text}");
        let e = check(512, 0, 600, 250_000, 1_000_000).unwrap_err();
        assert!(matches!(e, BudgetError::FrameTooBig { direction: "input", .. }));
    }

    #[test]
    fn load_is_packet_time_over_the_cycles_a_packet_carries() {
        // 128-byte frames, 512-byte packets: 4 cycles a packet, two
        // packets a call.
        let b = check(512, 128, 100, 250_000, 1_000_000).unwrap();
        assert_eq!(b.frames_per_packet, 4);
        assert!((b.load() - 0.125).abs() < 1e-9, "{}", b.load());
        assert!((b.min_exchanges_per_s() - 500.0).abs() < 1e-9, "{}", b.min_exchanges_per_s());
        // One 1 KB frame a packet of 300 us at 1 ms: allowed, above the warning.
        let b = check(1408, 1024, 0, 300_000, 1_000_000).unwrap();
        assert!(b.load() > WARN_LOAD && b.load() < MAX_LOAD);
        // 560-byte frames in 1056-byte packets of 470 us at 1 ms: 94 %,
        // which ran the RxFIFO dry every 45 ms. Refused, saying why.
        let e = check(1024, 560, 528, 470_000, 1_000_000).unwrap_err();
        assert!(e.to_string().contains("94%") && e.to_string().contains("2 packets"), "{e}");
    }

    #[test]
    fn no_process_data_costs_nothing() {
        let b = check(512, 0, 0, 250_000, 125_000).unwrap();
        assert_eq!(b.load(), 0.0);
    }
}
