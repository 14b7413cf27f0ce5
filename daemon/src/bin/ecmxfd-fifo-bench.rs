//! FIFO reads, guarded against pipelined (`cycle.fifo_reads`), on the demo
//! network at 125 us: for each mode and each bit error rate on the
//! answers (MISO), what the link spends and what is lost:
//!
//! - exchanges/s (the simulator's packet count) against the plan's minimum
//!   (one packet per FIFO call pipelined, two guarded), the packets of
//!   those that carried a FIFO call (FIFO/s; the rest are the emergency
//!   question and status polls) and the input frames each brought (in/call;
//!   a full packet holds the minimum's frames);
//! - corrupt answers, FIFO answers lost, input frames never received
//!   (`inputs_dropped_by_chip`: chip drops and the frames lost answers
//!   carried, each numbered as a gap in the input stream);
//! - input frames received against DC cycles;
//! - the engine's CPU.
//!
//! The simulator flips one bit in a byte with the given probability; a bit
//! error rate is that over 8 (1e-6 a byte is about 1.2e-7 a bit, 8e-5
//! about 1e-5).
//!
//! What runs where: the simulator is its own process (`ecmxf-sim serve`);
//! the engine runs in this one, idle (no callers), so the CPU figure is the
//! engine's. Nothing is built.
//!
//! Run: `cargo build --release -p ecmxf-sim -p ecmxfd --bins && target/release/ecmxfd-fifo-bench [SECONDS] [guarded|pipelined]`
#![forbid(unsafe_code)]

#[path = "bench_support/mod.rs"]
mod support;

use std::time::{Duration, Instant};

use ecmxfd::config::{Config, FifoReads, LinkConfig};
use support::{cpu_seconds, packet_counts, serve, started};

/// Flip probabilities per byte, and what they are per bit.
const RATES: [(f64, &str); 3] = [(0.0, "0"), (1e-6, "1.2e-7"), (8e-5, "1e-5")];

fn main() -> Result<(), String> {
    let secs: u64 = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(10);
    println!(
        "{:<10} {:>8} {:>12} {:>8} {:>7} {:>8} {:>8} {:>8} {:>10} {:>14} {:>6}",
        "mode",
        "BER/bit",
        "exchanges/s",
        "x min",
        "FIFO/s",
        "in/call",
        "corrupt",
        "lost",
        "frames",
        "received/cyc",
        "CPU"
    );
    let only = std::env::args().nth(2);
    for mode in [FifoReads::Guarded, FifoReads::Pipelined] {
        if only.as_deref().is_some_and(|m| !format!("{mode:?}").eq_ignore_ascii_case(m)) {
            continue;
        }
        let sim = serve(None)?;
        let mut config = Config { link: LinkConfig::SimSocket { socket: sim.socket.clone() }, ..Config::simulator() };
        config.cycle.fifo_reads = mode;
        let cycle_ns = u64::from(config.cycle.sync0_us) * 1000;
        let data_size = config.chip.data_size;
        let master = started(&sim, config)?;
        let mut packets = packet_counts(&sim.socket)?;
        let mut ctl = ecmxf_sim::server::SocketClient::connect(&sim.socket).map_err(|e| e.to_string())?;
        let l = master.layout();
        let per_call = match mode {
            FifoReads::Guarded => 2.0,
            FifoReads::Pipelined => 1.0,
        };
        let frames_per_packet = [l.rx_size, l.tx_size].iter().filter(|s| **s > 0).map(|s| data_size / s).min();
        let minimum = per_call * 1e9 / (frames_per_packet.unwrap_or(1).max(1) as f64 * cycle_ns as f64);
        // Settled first: the FIFO filled, the first layout read.
        std::thread::sleep(Duration::from_secs(1));
        for (rate, per_bit) in RATES {
            ctl.control(&format!("flip miso {rate}")).map_err(|e| e.to_string())?.map_err(|e| e.to_string())?;
            let (s0, p0, t0, c0) = (master.status(), packets()?, Instant::now(), cpu_seconds());
            std::thread::sleep(Duration::from_secs(secs));
            let (s, p, wall) = (master.status(), packets()?, t0.elapsed().as_secs_f64());
            let cpu = (cpu_seconds() - c0) / wall;
            let rate_now = (p.packets - p0.packets) as f64 / wall;
            let fifo_rate = (p.fifo_packets - p0.fifo_packets) as f64 / wall;
            // Input frames a FIFO packet brought, resends counted as packets.
            let in_per_packet =
                (s.input_frames - s0.input_frames) as f64 / (p.fifo_packets - p0.fifo_packets).max(1) as f64;
            let cycles = wall * 1e9 / cycle_ns as f64;
            println!(
                "{:<10} {per_bit:>8} {rate_now:>12.0} {:>8.2} {fifo_rate:>7.0} {in_per_packet:>8.2} {:>8} {:>8} {:>10} {:>14.4} {:>5.1}%",
                format!("{mode:?}").to_lowercase(),
                rate_now / minimum,
                s.corrupt - s0.corrupt,
                s.input_batches_lost - s0.input_batches_lost,
                s.inputs_dropped_by_chip - s0.inputs_dropped_by_chip,
                (s.input_frames - s0.input_frames) as f64 / cycles,
                cpu * 100.0
            );
        }
        ctl.control("flip miso 0").map_err(|e| e.to_string())?.map_err(|e| e.to_string())?;
        master.stop();
    }
    Ok(())
}
