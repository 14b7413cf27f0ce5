//! Scale benchmark: a network of many slaves (default 128, the chip's
//! maximum: 10 TI-like 3-axis drives, the rest digital IO) served by
//! `ecmxf-sim serve` and run by the `ecmxfd` binary, at each cycle time
//! asked for (default 1000 us, then 125 us). For each round it measures:
//!
//! - **to OP**: from the daemon's start until GetStatus says RUNNING with
//!   every slave in OP;
//! - **layout after OP**: from then until GetLayout answers with the
//!   process image (the daemon builds it after OP);
//! - **`ecmxfctl slaves`**: the whole command's wall time (process start
//!   included), median of 5 runs, and that it lists every slave;
//! - **idle**, over `--secs` once settled: the simulator's and the
//!   daemon's CPU (each its own process, from /proc), SPI exchanges per
//!   second (the simulator's packet counter), FIFO alarms and input frames
//!   (the daemon's counters: frames must flow, one per cycle).
//!
//! The simulator is served with `--spin-us 0` unless `--sim-spin-us N`
//! says otherwise: it blocks for each message and sleeps through each
//! modelled wait, so its CPU is the simulation's work (what a scale bench
//! must not be limited by), not time spent polling.
//!
//! What runs where: the simulator, the daemon and each `ecmxfctl` are
//! their own processes; this one only asks and times. The daemon runs
//! without real-time settings (priority 0, memory not locked, no spinning
//! before its deadlines: `spin_us = 0`) unless `--rt` is given (needs
//! root; then the defaults: SCHED_FIFO 80, memory locked, 2 ms spin). Nothing is built: build first with
//! `cargo build --release -p ecmxfd -p ecmxfctl -p ecmxf-sim -p ecmxf-e2e --bins`,
//! then run `target/release/ecmxf-scale-bench [--slaves N] [--cycles 1000,125]
//! [--rounds 3] [--secs 5] [--rt] [--sim-spin-us N]`. Prints each round,
//! then medians.
#![forbid(unsafe_code)]

use std::process::Command;
use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, Simulator, ctl_binary, run, temp_dir};
use ecmxf_proto::v1 as pb;
use pb::master_client::MasterClient;
use pb::process_data_client::ProcessDataClient;

/// `ecmxf-sim serve --spin-us` when not given: the simulator's own.
const SIM_DEFAULT_SPIN_US: u64 = ecmxf_sim::server::SERVER_SPIN.as_micros() as u64;

/// The drives of the network; the rest are digital IO slaves.
const DRIVES: usize = 10;

struct Args {
    slaves: usize,
    cycles_us: Vec<u32>,
    rounds: usize,
    secs: u64,
    rt: bool,
    sim_spin_us: u64,
}

fn args() -> Result<Args, String> {
    let mut a = Args { slaves: 128, cycles_us: vec![1000, 125], rounds: 3, secs: 5, rt: false, sim_spin_us: 0 };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--slaves" => a.slaves = value()?.parse().map_err(|e| format!("--slaves: {e}"))?,
            "--cycles" => {
                a.cycles_us = value()?
                    .split(',')
                    .map(|c| c.parse().map_err(|e| format!("--cycles {c}: {e}")))
                    .collect::<Result<_, _>>()?
            }
            "--rounds" => a.rounds = value()?.parse().map_err(|e| format!("--rounds: {e}"))?,
            "--secs" => a.secs = value()?.parse().map_err(|e| format!("--secs: {e}"))?,
            "--rt" => a.rt = true,
            "--sim-spin-us" => a.sim_spin_us = value()?.parse().map_err(|e| format!("--sim-spin-us: {e}"))?,
            other => return Err(format!("unknown argument {other}")),
        }
    }
    if !(1..=128).contains(&a.slaves) {
        return Err(format!("--slaves {}: the chip runs 1..=128", a.slaves));
    }
    Ok(a)
}

/// One round's figures.
#[derive(Clone, Copy, Debug, Default)]
struct Round {
    to_op_ms: f64,
    layout_ms: f64,
    slaves_ms: f64,
    sim_cpu: f64,
    daemon_cpu: f64,
    exchanges_per_s: f64,
    alarms: u64,
    frames_per_cycle: f64,
}

fn cpu_seconds_of(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let field = |n: usize| f.get(n - 3).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    (field(14) + field(15)) as f64 / 100.0
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn network(slaves: usize) -> String {
    let mut text = String::from("version = 1\n");
    for i in 0..slaves {
        let profile = if i < DRIVES.min(slaves) { "ti-3axis" } else { "digital-io" };
        text.push_str(&format!("[[slave]]\nprofile = \"{profile}\"\n"));
    }
    text
}

fn config(sim: &Simulator, cycle_us: u32, rt: bool) -> String {
    // Without real-time settings the engine also waits without spinning
    // (as the tests run it): its CPU is then its work, not its waiting.
    let realtime =
        if rt { "priority = 80\nlock_memory = true\n" } else { "priority = 0\nlock_memory = false\nspin_us = 0\n" };
    format!(
        "version = 1\n[link]\n{}\n[chip]\nready_timeout_ms = 1000\n[realtime]\n{realtime}[cycle]\nsync0_us = {cycle_us}\n",
        sim.link()
    )
}

fn packets(sim: &Simulator) -> u64 {
    sim.ctl("status")
        .split_whitespace()
        .find_map(|w| w.strip_prefix("packets="))
        .and_then(|n| n.parse().ok())
        .unwrap_or(0)
}

/// `ecmxfctl slaves` once: its wall time, ms, and the slaves it listed.
fn list_slaves(daemon: &Daemon) -> Result<(f64, usize), String> {
    let t = Instant::now();
    let out = Command::new(ctl_binary())
        .args(["--socket", &daemon.socket.display().to_string(), "--json", "slaves"])
        .output()
        .map_err(|e| format!("run ecmxfctl: {e}"))?;
    let ms = t.elapsed().as_secs_f64() * 1000.0;
    if !out.status.success() {
        return Err(format!("ecmxfctl slaves: {}", String::from_utf8_lossy(&out.stderr)));
    }
    let json: serde_json::Value =
        serde_json::from_slice(&out.stdout).map_err(|e| format!("ecmxfctl slaves --json: {e}"))?;
    let listed = json["slaves"].as_array().map_or(0, Vec::len);
    Ok((ms, listed))
}

async fn round(a: &Args, cycle_us: u32) -> Result<Round, String> {
    let dir = temp_dir("scale");
    let net = dir.join("net.toml");
    std::fs::write(&net, network(a.slaves)).map_err(|e| e.to_string())?;
    let (net, spin) = (net.display().to_string(), a.sim_spin_us.to_string());
    // The simulator's own default is not passed: a simulator built before
    // --spin-us existed can be measured too.
    let args: &[&str] = if a.sim_spin_us == SIM_DEFAULT_SPIN_US {
        &["--network", &net]
    } else {
        &["--network", &net, "--spin-us", &spin]
    };
    let sim = Simulator::serve(&dir, args);
    let start = Instant::now();
    let daemon = Daemon::binary_with_config(&config(&sim, cycle_us, a.rt));
    let mut r = Round::default();

    // To OP: polled every 5 ms (the figure's resolution).
    let channel = loop {
        if start.elapsed() > Duration::from_secs(60) {
            return Err(format!("not in OP after 60 s:\n{}", daemon.log()));
        }
        if let Ok(ch) = ecmxf_proto::connect_unix(&daemon.socket).await {
            let s = MasterClient::new(ch.clone()).get_status(pb::GetStatusRequest {}).await;
            if s.is_ok_and(|s| {
                let s = s.into_inner();
                s.phase == pb::EnginePhase::Running as i32 && s.ecat_state == pb::EcatState::Op as i32
            }) {
                break ch;
            }
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    };
    r.to_op_ms = start.elapsed().as_secs_f64() * 1000.0;

    // Layout after OP: GetLayout waits for the image (within its own
    // deadline; asked again while it is not built).
    let op = Instant::now();
    let mut pdo = ProcessDataClient::new(channel.clone());
    loop {
        match pdo.get_layout(pb::GetLayoutRequest {}).await {
            Ok(_) => break,
            Err(e) if op.elapsed() < Duration::from_secs(30) => {
                if e.code() != tonic::Code::DeadlineExceeded && e.code() != tonic::Code::Unavailable {
                    return Err(format!("GetLayout: {e}"));
                }
            }
            Err(e) => return Err(format!("no layout 30 s after OP: {e}")),
        }
    }
    r.layout_ms = op.elapsed().as_secs_f64() * 1000.0;

    let mut times = Vec::new();
    for _ in 0..5 {
        let (ms, listed) = list_slaves(&daemon)?;
        if listed != a.slaves {
            return Err(format!("ecmxfctl slaves listed {listed} of {}", a.slaves));
        }
        times.push(ms);
    }
    r.slaves_ms = median(times);

    // Idle, settled.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let mut master = MasterClient::new(channel);
    let counters = |s: pb::MasterStatus| s.counters.unwrap_or_default();
    let c0 = counters(master.get_status(pb::GetStatusRequest {}).await.map_err(|e| e.to_string())?.into_inner());
    let (p0, sim0, d0, t0) = (packets(&sim), cpu_seconds_of(sim.pid()), cpu_seconds_of(daemon.pid()), Instant::now());
    tokio::time::sleep(Duration::from_secs(a.secs)).await;
    let (p1, sim1, d1) = (packets(&sim), cpu_seconds_of(sim.pid()), cpu_seconds_of(daemon.pid()));
    let c1 = counters(master.get_status(pb::GetStatusRequest {}).await.map_err(|e| e.to_string())?.into_inner());
    let secs = t0.elapsed().as_secs_f64();
    r.sim_cpu = (sim1 - sim0) / secs * 100.0;
    r.daemon_cpu = (d1 - d0) / secs * 100.0;
    r.exchanges_per_s = (p1 - p0) as f64 / secs;
    r.alarms = c1.fifo_alarms - c0.fifo_alarms;
    r.frames_per_cycle = (c1.input_frames - c0.input_frames) as f64 / (secs * 1e6 / f64::from(cycle_us));
    drop(daemon);
    drop(sim);
    let _ = std::fs::remove_dir_all(&dir);
    Ok(r)
}

fn print(label: &str, r: &Round) {
    println!(
        "{label:<10} to OP {:>7.0} ms  layout after OP {:>6.0} ms  `ecmxfctl slaves` {:>6.0} ms  \
         idle: simulator {:>5.1} %  daemon {:>4.1} % of a core  {:>5.0} exchanges/s  \
         fifo alarms {}  input frames per cycle {:.3}",
        r.to_op_ms, r.layout_ms, r.slaves_ms, r.sim_cpu, r.daemon_cpu, r.exchanges_per_s, r.alarms, r.frames_per_cycle
    );
}

fn main() -> Result<(), String> {
    let a = args()?;
    println!(
        "{} slaves ({} TI-like 3-axis drives, the rest digital IO); {} round(s) per cycle time; idle over {} s; \
         daemon real-time settings {}; simulator spin {} us",
        a.slaves,
        DRIVES.min(a.slaves),
        a.rounds,
        a.secs,
        if a.rt { "on (SCHED_FIFO 80, memory locked, 2 ms spin)" } else { "off (no spin)" },
        a.sim_spin_us
    );
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!("load average before: {}", load.split_whitespace().take(3).collect::<Vec<_>>().join(" "));
    let mut failed = false;
    for &cycle_us in &a.cycles_us {
        println!("== cycle {cycle_us} us");
        let mut rounds = Vec::new();
        for i in 0..a.rounds {
            let mut result = Err(String::new());
            run(async { result = round(&a, cycle_us).await });
            match result {
                Ok(r) => {
                    print(&format!("round {}", i + 1), &r);
                    rounds.push(r);
                }
                Err(e) => {
                    println!("round {}: {e}", i + 1);
                    failed = true;
                }
            }
        }
        if !rounds.is_empty() {
            let m = |f: fn(&Round) -> f64| median(rounds.iter().map(f).collect());
            let medians = Round {
                to_op_ms: m(|r| r.to_op_ms),
                layout_ms: m(|r| r.layout_ms),
                slaves_ms: m(|r| r.slaves_ms),
                sim_cpu: m(|r| r.sim_cpu),
                daemon_cpu: m(|r| r.daemon_cpu),
                exchanges_per_s: m(|r| r.exchanges_per_s),
                alarms: m(|r| r.alarms as f64) as u64,
                frames_per_cycle: m(|r| r.frames_per_cycle),
            };
            print("median", &medians);
        }
    }
    if failed { Err("some rounds failed".into()) } else { Ok(()) }
}
