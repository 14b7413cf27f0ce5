//! What one simulated DC cycle costs the simulator, by network size: the
//! chip's cycle over every slave (outputs into each slave's dictionary,
//! the devices' own step, inputs out of it, the FIFO frames), the work a
//! `ecmxf-sim serve` process does 8000 times a second at 125 us whatever
//! its host does. Everything runs in this one process: the chip is brought
//! to OP through its packets by the test host (sim/tests/common), then only
//! time advances (the RxFIFO runs dry and the last outputs repeat, as the
//! cycle does in every case).
//!
//! `cargo bench -p ecmxf-sim --bench network_cycle` prints, per network,
//! the median over 7 runs of the CPU one simulated second takes, as a share
//! of a core at 125 us and at 1 ms. The networks are the scale bench's
//! (ecmxf-scale-bench: 10 TI-like 3-axis drives, the rest digital IO) at
//! 24, 64 and 128 slaves, and the demo network.

use std::time::Instant;

use ecmxf_sim::Network;
use ecmxf_sim::net::profiles;

#[path = "../tests/common/mod.rs"]
mod common;

/// Drives first, then IO slaves, as the scale bench builds its network.
fn network(slaves: usize) -> Network {
    const DRIVES: usize = 10;
    let list = (0..slaves)
        .map(|i| {
            let serial = 1000 + i as u32;
            if i < DRIVES.min(slaves) {
                profiles::ti_three_axis(serial, i as u16 + 1)
            } else {
                profiles::digital_io(serial, i as u16 + 1)
            }
        })
        .collect();
    Network::new(list)
}

/// Seconds of CPU (wall, one thread) per simulated second at 125 us.
fn cost(net: Network) -> f64 {
    let mut h = common::Host::new(net);
    common::bring_up_to_op(&mut h, 0);
    const SIMULATED_NS: u64 = 250_000_000;
    let start = h.chip.now_ns;
    let began = Instant::now();
    h.chip.advance_to(start + SIMULATED_NS);
    began.elapsed().as_secs_f64() / (SIMULATED_NS as f64 / 1e9)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    // `cargo test --benches` runs this with `--bench` absent: one short
    // pass proves it works without taking the time of a measurement.
    let measuring = std::env::args().any(|a| a == "--bench");
    let runs = if measuring { 7 } else { 1 };
    println!("simulator CPU per simulated second (median of {runs}), one thread, this process");
    for (name, make) in [
        ("demo (3 slaves)", Box::new(Network::demo) as Box<dyn Fn() -> Network>),
        ("24 slaves", Box::new(|| network(24))),
        ("64 slaves", Box::new(|| network(64))),
        ("128 slaves", Box::new(|| network(128))),
    ] {
        let share = median((0..runs).map(|_| cost(make())).collect());
        // The chip's cycle runs at 125 us here: 1 ms does an eighth of the
        // cycles for the same simulated second.
        println!("{name:>16}: {:6.1} % of a core at 125 us, {:5.1} % at 1 ms", share * 100.0, share * 100.0 / 8.0);
    }
}
