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
//! A FIFO call is counted as two packets: guarded (see `port`), because
//! its reads take the input frames out of the chip's TxFIFO and a lost
//! answer would lose them. Pipelined calls (`cycle.fifo_reads`, the
//! default) take one on a clean link, but go guarded for a second after
//! any link error (`engine::fifo_reads`), and the plan must hold then too.
//! So a plan needs two packets per `frames per packet` cycles at least,
//! and that is the load counted here (counted as
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
/// Packets the link may carry from the moment a FIFO refill is due to the
/// moment it lands: a transaction's step already under way, the emergency
/// question that rides just before a FIFO call, and the call itself.
pub const REFILL_PACKETS: u64 = PACKETS_PER_CALL + 2;

/// The shortest output latency budget (`cycle.output_latency_us`) that
/// packets of `packet_ns` hold at a `cycle_ns` DC cycle with `host_ns` of
/// host stall allowed (`realtime.host_stall_us`), ns. For a budget the
/// RxFIFO is kept `target` frames deep (a write waits for those and one
/// cycle of the chip's own: budget = target + 1 cycles) and refilled
/// before it falls to half of that (`cyclic::Plan::levels`); what is left
/// then must outlast [`REFILL_PACKETS`] packets and the host's stall, or
/// the slaves get their last outputs again (an underrun) each time a
/// transaction's packet goes before a late refill. Without the host's
/// part this is the link's floor, which a stock kernel does not hold:
/// `ecmxf-latency-bench --rt --host-stall-us 0` (SCHED_FIFO, memory
/// locked, 60 s) ran the RxFIFO dry at 3 ms and a 1 ms cycle, and twice
/// at 2500 us and 125 us with 206 late writes, where the link alone
/// allows both.
pub fn min_output_latency_ns(packet_ns: u64, cycle_ns: u64, host_ns: u64) -> u64 {
    let cycle = cycle_ns.max(1);
    let refill_cycles = (REFILL_PACKETS * packet_ns + host_ns).div_ceil(cycle).max(1);
    (2 * refill_cycles + 1) * cycle
}

/// Why an output latency budget cannot hold, in words (`None`: it can).
pub fn latency_refusal(budget_us: u32, packet_ns: u64, cycle_ns: u64, host_ns: u64) -> Option<String> {
    let min_ns = min_output_latency_ns(packet_ns, cycle_ns, host_ns);
    if u64::from(budget_us) * 1000 >= min_ns {
        return None;
    }
    let cycle_us = cycle_ns / 1000;
    let refill_us = (REFILL_PACKETS * packet_ns).div_ceil(1000);
    Some(format!(
        "{budget_us} us cannot hold at a {cycle_us} us cycle with SPI packets of {} us: the RxFIFO is kept {} \
         frame(s) deep for it and refilled at half of that, and a refill can land {refill_us} us after it is due \
         (a FIFO call of {PACKETS_PER_CALL} packets, with a transaction's packet and the emergency question \
         before it) plus the {} us of host stall allowed (realtime.host_stall_us), so the slaves would get \
         repeated outputs; the smallest budget this link and host hold is {} us (or lengthen cycle.sync0_us, \
         raise link.spi_hz, or lower chip.data_size)",
        packet_ns.div_ceil(1000),
        (budget_us as u64 * 1000 / cycle_ns.max(1)).saturating_sub(1).max(2),
        host_ns / 1000,
        min_ns.div_ceil(1000)
    ))
}

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
    fn a_latency_budget_needs_room_for_a_refill_behind_a_transaction() {
        // The demo network's packets (512-byte data at 20 MHz and the
        // chip's 30 us): 248 us. At 125 us, four packets are 8 cycles: a
        // FIFO kept 16 deep, 17 cycles in all, for the link alone.
        let packet = clocked_ns(512, 20_000_000) + 30_000;
        assert_eq!(min_output_latency_ns(packet, 125_000, 0), 17 * 125_000);
        // With the default 1 ms of host stall: 992 + 1000 us are 16
        // cycles behind, 33 in all.
        let host = 1_000_000;
        assert_eq!(min_output_latency_ns(packet, 125_000, host), 33 * 125_000);
        for refused in [250, 1000, 2000, 2500, 4000] {
            let why = latency_refusal(refused, packet, 125_000, host).expect("refused");
            assert!(why.contains("the smallest budget this link and host hold is 4125 us"), "{why}");
            assert!(why.contains("1000 us of host stall"), "{why}");
        }
        assert_eq!(latency_refusal(4125, packet, 125_000, host), None);
        assert_eq!(latency_refusal(2125, packet, 125_000, 0), None, "an RT host that allows none");
        // At 1 ms a refill fits in a cycle, the host's stall in another: 5.
        assert_eq!(min_output_latency_ns(packet, 1_000_000, 0), 3_000_000);
        assert_eq!(min_output_latency_ns(packet, 1_000_000, host), 5_000_000);
        // Large packets at 500 us (1024-byte data at 24 MHz): 3 cycles
        // behind, 7 in all; 5 and 11 with the host's.
        assert_eq!(min_output_latency_ns(clocked_ns(1024, 24_000_000), 500_000, 0), 3_500_000);
        assert_eq!(min_output_latency_ns(clocked_ns(1024, 24_000_000), 500_000, host), 5_500_000);
    }

    #[test]
    fn no_process_data_costs_nothing() {
        let b = check(512, 0, 0, 250_000, 125_000).unwrap();
        assert_eq!(b.load(), 0.0);
    }
}
