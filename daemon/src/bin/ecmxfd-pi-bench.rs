//! The "Pi budget": the daemon on a core like the target's. A Raspberry Pi
//! has one slow core for everything; this 2-core VM stands for it by
//! limiting the daemon to a third of one core with a CPU quota (1000 us of
//! CPU per 3000 us, cgroup v2 `cpu.max` or v1 `cpu.cfs_quota_us`), then
//! runs the demo network at 125 us idle and reports what the plan needs to
//! hold: FIFO alarms (the RxFIFO ran dry), input frames against cycles,
//! input frames the chip dropped, and the CPU used.
//!
//! What runs where: the simulator is its own process, started before the
//! limit and outside it; the engine runs in this process, which moves
//! itself into the limited group (and back out at the end). Needs a
//! writable cgroup hierarchy (root here); says so and skips otherwise.
//! Nothing is built.
//!
//! Run: `cargo build --release -p ecmxf-sim -p ecmxfd --bins && target/release/ecmxfd-pi-bench [SECONDS] [unlimited]`
//! (`unlimited`: the same run without the limit, for comparison).
#![forbid(unsafe_code)]

#[path = "bench_support/mod.rs"]
mod support;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use ecmxfd::config::{Config, LinkConfig};
use support::{cpu_seconds, packet_counter, serve, started};

/// CPU time allowed per period, us.
const QUOTA_US: u64 = 1000;
/// The period, us.
const PERIOD_US: u64 = 3000;

/// This process in a CPU-limited cgroup; back in its old group on drop.
struct CpuLimit {
    group: PathBuf,
    parent: PathBuf,
}

impl CpuLimit {
    /// Moves this process into a new group limited to `QUOTA_US` per
    /// `PERIOD_US`: cgroup v2 where the unified hierarchy has the cpu
    /// controller, else v1's cpu controller. `Err`: why it cannot.
    fn apply() -> Result<Self, String> {
        let name = format!("ecmxfd-pi-bench-{}", std::process::id());
        let write = |p: &Path, v: &str| std::fs::write(p, v).map_err(|e| format!("{}: {e}", p.display()));
        let v2 = Path::new("/sys/fs/cgroup");
        let v2_cpu = std::fs::read_to_string(v2.join("cgroup.controllers")).is_ok_and(|c| c.contains("cpu"));
        let (parent, limit): (PathBuf, Vec<(&str, String)>) = if v2_cpu {
            (v2.to_path_buf(), vec![("cpu.max", format!("{QUOTA_US} {PERIOD_US}"))])
        } else if Path::new("/sys/fs/cgroup/cpu/cpu.cfs_quota_us").exists() {
            let v1 = PathBuf::from("/sys/fs/cgroup/cpu");
            (v1, vec![("cpu.cfs_period_us", PERIOD_US.to_string()), ("cpu.cfs_quota_us", QUOTA_US.to_string())])
        } else {
            return Err("no cgroup cpu controller (v2 cpu.max or v1 cpu.cfs_quota_us) on this machine".into());
        };
        let group = parent.join(name);
        std::fs::create_dir(&group).map_err(|e| format!("{}: {e} (needs root)", group.display()))?;
        let this = Self { group, parent };
        for (file, value) in limit {
            write(&this.group.join(file), &value)?;
        }
        write(&this.group.join("cgroup.procs"), &std::process::id().to_string())?;
        Ok(this)
    }
}

impl Drop for CpuLimit {
    fn drop(&mut self) {
        let _ = std::fs::write(self.parent.join("cgroup.procs"), std::process::id().to_string());
        let _ = std::fs::remove_dir(&self.group);
    }
}

fn main() -> Result<(), String> {
    let secs: u64 = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(60);
    let unlimited = std::env::args().nth(2).is_some_and(|a| a == "unlimited");
    let sim = serve(None)?;
    let mut packets = packet_counter(&sim.socket)?;
    let limit = if unlimited {
        None
    } else {
        match CpuLimit::apply() {
            Ok(l) => Some(l),
            Err(why) => {
                println!("pi budget: skipped: {why}");
                return Ok(());
            }
        }
    };
    let what = if limit.is_some() { format!("{QUOTA_US} us of CPU per {PERIOD_US} us") } else { "unlimited".into() };
    let config = Config { link: LinkConfig::SimSocket { socket: sim.socket.clone() }, ..Config::simulator() };
    let cycle_us = config.cycle.sync0_us;
    let master = started(&sim, config)?;
    // Settled first (the RxFIFO filled to its level), then the window.
    std::thread::sleep(Duration::from_secs(1));
    let (s0, p0, t0, c0) = (master.status(), packets()?, Instant::now(), cpu_seconds());
    std::thread::sleep(Duration::from_secs(secs));
    let (s, p, wall) = (master.status(), packets()?, t0.elapsed());
    let cpu = (cpu_seconds() - c0) / wall.as_secs_f64();
    let cycles = (wall.as_secs_f64() * 1e6 / f64::from(cycle_us)) as u64;
    println!(
        "pi budget ({what}; demo network at {cycle_us} us, idle, {:.0} s): \
         fifo alarms {}, input frames {} in {cycles} cycles, dropped by the chip {}, CPU {:.1}% of a core, \
         {:.0} exchanges/s, recoveries {}",
        wall.as_secs_f64(),
        s.fifo_alarms - s0.fifo_alarms,
        s.input_frames - s0.input_frames,
        s.inputs_dropped_by_chip - s0.inputs_dropped_by_chip,
        cpu * 100.0,
        (p - p0) as f64 / wall.as_secs_f64(),
        s.recoveries - s0.recoveries
    );
    master.stop();
    drop(limit);
    drop(sim);
    Ok(())
}
