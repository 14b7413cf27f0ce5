//! Benchmarks the daemon against the simulator served over its Unix socket
//! (a separate `ecmxf-sim` process, so its CPU time is not counted):
//!
//! 1. raw exchange rate of the packet port, against the simulator's modelled
//!    maximum (transfer time at its SPI clock + processing time);
//! 2. SDO round trips through the engine, one at a time and from 16 tasks,
//!    with cyclic data running at 125 us;
//! 3. RxFIFO level seen in the headers (min/max) and the longest gap between
//!    FIFO exchanges;
//! 4. the daemon process's CPU time per second of wall time;
//! 5. the link's idle rate against the minimum the plan needs (one packet
//!    per FIFO call pipelined, the daemon's default; two guarded, see
//!    `link_budget`), and the SPI exchanges each SDO adds above it, from
//!    the simulator's own packet counter;
//! 6. each demo slave's object dictionary read from the device (CoE SDO
//!    Information through the host's mailbox channel, with cyclic data at
//!    125 us), cold, then again from the daemon's memory; the SPI
//!    exchanges the cold read took above the idle rate;
//! 7. a 24-slave network (10 TI-like 3-axis drives and 14 IO slaves:
//!    404-byte frames, one a 512-byte packet) at 1 ms, idle: this
//!    process's CPU, the link's rate against the plan's minimum, FIFO
//!    alarms.
//!
//! What runs where: the simulator is its own process (`ecmxf-sim serve`,
//! one per network); the engine, its async runtime and the SDO callers run
//! in this one, so the CPU figure under load is the daemon's work plus the
//! callers'; the idle figures are taken while only the engine runs.
//! Nothing is built.
//!
//! Run: `cargo build --release -p ecmxf-sim && cargo run --release -p ecmxfd --bin ecmxfd-bench -- [SECONDS] [guarded|pipelined]`
//! (the second argument sets `cycle.fifo_reads`; unset, the daemon's default).
#![forbid(unsafe_code)]

#[path = "bench_support/mod.rs"]
mod support;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use ecmxf_wire::payload::control::InfoUpdate;
use ecmxfd::config::{Config, FifoReads, LinkConfig};
use ecmxfd::link::socket::SocketLink;
use ecmxfd::master::Call;
use ecmxfd::master::Master;
use ecmxfd::port::Port;
use support::{cpu_seconds, packet_counter, serve, started};

fn percentiles(mut v: Vec<Duration>) -> String {
    if v.is_empty() {
        return "no samples".into();
    }
    v.sort();
    let p = |q: f64| v[((v.len() as f64 * q) as usize).min(v.len() - 1)];
    format!("n={} p50={:?} p90={:?} p99={:?} max={:?}", v.len(), p(0.5), p(0.9), p(0.99), p(1.0))
}

fn main() -> Result<(), String> {
    let secs: u64 = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(10);
    let reads = fifo_reads()?;
    let sim = serve(None)?;
    let mut config = Config { link: LinkConfig::SimSocket { socket: sim.socket.clone() }, ..Config::simulator() };
    config.cycle.fifo_reads = reads;
    let sim_config = ecmxf_sim::ChipConfig::default();
    let data_size = config.chip.data_size;
    let modelled_ns = ecmxfd::master::link_budget::clocked_ns(data_size, sim_config.spi_hz) + sim_config.processing_ns;
    let modelled_rate = 1e9 / modelled_ns as f64;

    // 1. Raw port rate: guarded INFO_UPDATEs back to back.
    {
        let mut port = Port::new(SocketLink::connect(&sim.socket).map_err(|e| e.to_string())?);
        port.synchronize().map_err(|e| e.to_string())?;
        port.resize(data_size).map_err(|e| e.to_string())?;
        let before = port.stats().exchanges;
        let t = Instant::now();
        while t.elapsed() < Duration::from_secs(secs.min(5)) {
            port.call(&InfoUpdate).map_err(|e| e.to_string())?;
        }
        let rate = (port.stats().exchanges - before) as f64 / t.elapsed().as_secs_f64();
        println!(
            "port exchange rate     : {rate:.0}/s of a modelled {modelled_rate:.0}/s ({:.1}%) at {data_size}-byte data, {} Hz SPI, {} us processing",
            100.0 * rate / modelled_rate,
            sim_config.spi_hz,
            sim_config.processing_ns / 1000
        );
    }

    // 2.-4. The engine with cyclic data.
    let master = Arc::new(started(&sim, config)?);
    let mut packets = packet_counter(&sim.socket)?;
    // Idle first, before the async runtime and the level sampler exist:
    // cyclic data only, nothing else in this process.
    let (p0, t0, c0) = (packets()?, Instant::now(), cpu_seconds());
    std::thread::sleep(Duration::from_secs(3));
    let idle_cpu = (cpu_seconds() - c0) / t0.elapsed().as_secs_f64();
    let idle_rate = (packets()? - p0) as f64 / t0.elapsed().as_secs_f64();
    let plan_minimum = plan_minimum(&master, data_size, modelled_ns);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| e.to_string())?;
    let levels = Arc::new(std::sync::Mutex::new((u8::MAX, 0u8)));
    let sampling = Arc::new(AtomicBool::new(true));
    let sampler = {
        let (m, l, s) = (Arc::clone(&master), Arc::clone(&levels), Arc::clone(&sampling));
        std::thread::spawn(move || {
            while s.load(Ordering::Relaxed) {
                let lvl = m.status().rx_fifo;
                let mut g = l.lock().unwrap_or_else(|e| e.into_inner());
                *g = (g.0.min(lvl), g.1.max(lvl));
                drop(g);
                std::thread::sleep(Duration::from_millis(1));
            }
        })
    };
    let cpu0 = cpu_seconds();
    let wall0 = Instant::now();
    let inputs0 = master.status().input_frames;
    let (p1, t1) = (packets()?, Instant::now());
    let mut single_window = (0u64, Duration::ZERO);
    let (single, loaded, exchanges) = rt.block_on(async {
        let mut single = Vec::new();
        let end = Instant::now() + Duration::from_secs(secs / 2);
        while Instant::now() < end {
            let t = Instant::now();
            master.sdo_read(1, 0x1018, 1, false, Call::anonymous(None)).await.map_err(|e| e.to_string())?;
            single.push(t.elapsed());
        }
        single_window = (packets()? - p1, t1.elapsed());
        let ex0 = master.status().exchanges;
        let t0 = Instant::now();
        let end = Instant::now() + Duration::from_secs(secs - secs / 2);
        let mut tasks = Vec::new();
        for n in 0..16u16 {
            let m = Arc::clone(&master);
            tasks.push(tokio::spawn(async move {
                let mut v = Vec::new();
                while Instant::now() < end {
                    let t = Instant::now();
                    m.sdo_read((n % 3) as u8, 0x1018, 1 + (n % 4) as u8, false, Call::anonymous(None))
                        .await
                        .map_err(|e| e.to_string())?;
                    v.push(t.elapsed());
                }
                Ok::<_, String>(v)
            }));
        }
        let mut loaded = Vec::new();
        for t in tasks {
            loaded.extend(t.await.map_err(|e| e.to_string())??);
        }
        let rate = (master.status().exchanges - ex0) as f64 / t0.elapsed().as_secs_f64();
        Ok::<_, String>((single, loaded, rate))
    })?;
    let cpu = (cpu_seconds() - cpu0) / wall0.elapsed().as_secs_f64();
    sampling.store(false, Ordering::Relaxed);
    let _ = sampler.join();
    let s = master.status();
    let (lmin, lmax) = *levels.lock().unwrap_or_else(|e| e.into_inner());
    let (window_packets, window) = single_window;
    let above_idle = window_packets as f64 - idle_rate * window.as_secs_f64();
    println!(
        "idle exchanges         : {idle_rate:.0}/s (simulator's packet count, cyclic data only, 3 s, cycle.fifo_reads = {:?}); the plan needs {:.0}/s pipelined ({:.2}x), {plan_minimum:.0}/s guarded ({:.2}x)",
        master.config().cycle.fifo_reads,
        plan_minimum / 2.0,
        idle_rate / (plan_minimum / 2.0).max(1.0),
        idle_rate / plan_minimum.max(1.0)
    );
    println!(
        "idle daemon CPU        : {:.1}% of a core (this process while only the engine runs: cyclic data at 125 us, no callers)",
        idle_cpu * 100.0
    );
    println!(
        "SPI exchanges per SDO  : {:.2} above the idle rate ({} SDO reads one at a time)",
        above_idle / single.len().max(1) as f64,
        single.len()
    );
    println!("SDO read, one at a time: {}", percentiles(single));
    println!("SDO read, 16 tasks     : {}", percentiles(loaded));
    println!("engine exchange rate   : {exchanges:.0}/s under SDO load with cyclic data");
    println!(
        "RxFIFO level (header)  : min {lmin} max {lmax} frames (target {}..{}), longest FIFO gap {} us, fifo alarms {}",
        master.layout().fifo_low,
        master.layout().fifo_high,
        s.max_fifo_gap_us,
        s.fifo_alarms
    );
    println!(
        "input frames           : {} in the SDO windows ({} cycles of 125 us in {:.1} s)",
        s.input_frames - inputs0,
        (wall0.elapsed().as_secs_f64() * 8000.0) as u64,
        wall0.elapsed().as_secs_f64()
    );
    println!(
        "daemon CPU time        : {cpu:.2} s per s (engine, input distributor, async runtime; simulator excluded)"
    );
    println!(
        "recoveries             : {}{}",
        s.recoveries,
        master.last_error().map(|e| format!(" (last: {e})")).unwrap_or_default()
    );
    // 6. Dictionaries the devices describe (no state_dir: read cold).
    for slave in 0..master.layout().slaves.len() as u8 {
        let (p0, t0) = (packets()?, Instant::now());
        let d = rt.block_on(master.device_dictionary(slave, Call::anonymous(None))).map_err(|e| e.to_string())?;
        let cold = t0.elapsed();
        let extra = packets()? as f64 - p0 as f64 - idle_rate * cold.as_secs_f64();
        let t1 = Instant::now();
        rt.block_on(master.device_dictionary(slave, Call::anonymous(None))).map_err(|e| e.to_string())?;
        let cached = t1.elapsed();
        let entries: usize = d.objects.iter().map(|o| o.entries.len()).sum();
        println!(
            "device dictionary      : slave {slave}: {} objects, {entries} entries read from the device in {:.0} ms ({:.0} SPI exchanges above idle, {:.1} per entry); again from memory in {:.0?}",
            d.objects.len(),
            cold.as_secs_f64() * 1e3,
            extra,
            extra / (entries + d.objects.len()).max(1) as f64,
            cached
        );
    }
    master.stop();
    drop(sim);
    many_slaves_idle(data_size, modelled_ns)?;
    Ok(())
}

/// `cycle.fifo_reads` as the second argument says.
fn fifo_reads() -> Result<FifoReads, String> {
    match std::env::args().nth(2).as_deref() {
        None => Ok(FifoReads::default()),
        Some("guarded") => Ok(FifoReads::Guarded),
        Some("pipelined") => Ok(FifoReads::Pipelined),
        Some(other) => Err(format!("{other:?}: the second argument is guarded or pipelined")),
    }
}

/// The exchanges per second the plan needs at least (see `link_budget`)
/// for the master's network, with the modelled packet time.
fn plan_minimum(master: &Master, data_size: usize, packet_ns: u64) -> f64 {
    let l = master.layout();
    let cycle_ns = u64::from(master.config().cycle.sync0_us) * 1000;
    ecmxfd::master::link_budget::check(data_size, l.rx_size, l.tx_size, packet_ns, cycle_ns)
        .map_or(f64::NAN, |b| b.min_exchanges_per_s())
}

/// 6.: a 24-slave network at 1 ms, idle.
fn many_slaves_idle(data_size: usize, packet_ns: u64) -> Result<(), String> {
    let dir = std::env::temp_dir().join(format!("ecmxfd-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let network = dir.join("net24.toml");
    let slaves: String = (0..24)
        .map(|i| format!("[[slave]]\nprofile = \"{}\"\n", if i < 10 { "ti-3axis" } else { "digital-io" }))
        .collect();
    std::fs::write(&network, format!("version = 1\n{slaves}")).map_err(|e| e.to_string())?;
    let sim = serve(Some(&network))?;
    let mut config = Config { link: LinkConfig::SimSocket { socket: sim.socket.clone() }, ..Config::simulator() };
    config.cycle.sync0_us = 1000;
    config.cycle.fifo_reads = fifo_reads()?;
    let master = started(&sim, config)?;
    let mut packets = packet_counter(&sim.socket)?;
    // Settled first (the FIFO filled), then 3 s idle.
    std::thread::sleep(Duration::from_secs(1));
    let (s0, p0, t0, c0) = (master.status(), packets()?, Instant::now(), cpu_seconds());
    std::thread::sleep(Duration::from_secs(3));
    let cpu = (cpu_seconds() - c0) / t0.elapsed().as_secs_f64();
    let rate = (packets()? - p0) as f64 / t0.elapsed().as_secs_f64();
    let s = master.status();
    let l = master.layout();
    let minimum = plan_minimum(&master, data_size, packet_ns);
    println!(
        "24 slaves at 1 ms, idle: CPU {:.1}% of a core, {rate:.0} exchanges/s (the plan needs {minimum:.0}/s: {}-byte output and {}-byte input frames), fifo alarms {}, input frames {} in {} cycles",
        cpu * 100.0,
        l.rx_size,
        l.tx_size,
        s.fifo_alarms - s0.fifo_alarms,
        s.input_frames - s0.input_frames,
        (t0.elapsed().as_secs_f64() * 1000.0) as u64
    );
    master.stop();
    drop(sim);
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
