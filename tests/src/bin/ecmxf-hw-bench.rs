//! Hardware-link benchmark: what one SPI exchange costs the daemon through
//! the hardware link (`backend = "spidev"`: spidev ioctls, GPIO v2 level
//! reads and INT0 edge events) next to the simulator's socket link, on the
//! demo network idle in OP at a 125 us and a 1 ms cycle.
//!
//! What runs where: `ecmxf-sim serve` in its own process; `ecmxfd` (the
//! binary next to this one) in its own, on the socket link or on devices
//! emulated by the preload library (sim/hw-emu) in front of that
//! simulator; this process only measures. It builds nothing and replaces
//! no binary: build first with `cargo build --release -p ecmxfd -p
//! ecmxf-sim -p ecmxf-hw-emu -p ecmxf-e2e --bins --lib` (exit 2 when a
//! piece is missing).
//!
//! `ecmxf-hw-bench [SECONDS] [--daemon PATH]... [--rounds N]`: with more than
//! one `--daemon` (a before/after comparison), every configuration runs
//! each daemon in turn, N rounds (default 1), so the builds share the
//! machine's noise; each row names its daemon.
//!
//! Per run, over SECONDS (default 6) after a second of warm-up: exchanges
//! per second (the daemon's counter), the daemon's user+system CPU from
//! /proc (per exchange and as % of one core), and for the hardware link
//! the device calls per exchange the emulation counted (SPI messages, GPIO
//! value reads, polls, event reads): each is one system call on a Pi. With
//! strace installed, a further 2 s window counts every system call of the
//! daemon's process per exchange (ptrace slows the process: counts only);
//! on the hardware link those are the emulation's socket calls standing in
//! for the ioctls. The emulation's own round trip to the simulator is in
//! the hardware link's CPU figure, as the socket link's is in its own.
#![forbid(unsafe_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use ecmxf_e2e::hardware::rpi_link;
use ecmxf_e2e::{Daemon, Simulator, config_with_cycle, temp_dir};
use ecmxf_proto::v1 as pb;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Wire {
    Socket,
    Hardware,
}

/// User+system CPU seconds of process `pid`.
fn cpu(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let field = |n: usize| f.get(n - 3).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    (field(14) + field(15)) as f64 / 100.0
}

async fn exchanges(ch: &tonic::transport::Channel) -> u64 {
    let mut m = pb::master_client::MasterClient::new(ch.clone());
    let s = m.get_status(pb::GetStatusRequest {}).await.expect("GetStatus").into_inner();
    s.counters.map_or(0, |c| c.exchanges)
}

/// `name value` lines.
fn counters(path: &Path) -> BTreeMap<String, u64> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .filter_map(|l| l.split_once(' '))
        .filter_map(|(k, v)| Some((k.to_string(), v.trim().parse().ok()?)))
        .collect()
}

/// strace's `-c` summary: (calls per syscall, total calls).
fn strace_summary(path: &Path) -> (Vec<(String, u64)>, u64) {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let mut rows = Vec::new();
    let mut total = 0;
    for line in text.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        // % time, seconds, usecs/call, calls, [errors], syscall
        if w.len() >= 5 && w[0].parse::<f64>().is_ok() {
            let calls = w[3].parse().unwrap_or(0);
            let name = w.last().copied().unwrap_or("?").to_string();
            if name == "total" {
                total = calls;
            } else {
                rows.push((name, calls));
            }
        }
    }
    rows.sort_by_key(|r| std::cmp::Reverse(r.1));
    (rows, total)
}

struct Figures {
    per_s: f64,
    cpu_pct: f64,
    cpu_us_per_exchange: f64,
    device_calls: Option<(f64, String)>,
    strace: Option<(f64, String)>,
}

fn run(wire: Wire, cycle_us: u32, secs: u64, daemon: &Path, library: &Path) -> Figures {
    let dir = temp_dir("hw-bench");
    let sim = Simulator::serve(&dir, &[]);
    let stats = dir.join("emu-stats");
    let (link, env) = match wire {
        Wire::Socket => (sim.link(), vec![]),
        Wire::Hardware => (
            rpi_link(),
            vec![
                ("LD_PRELOAD".to_string(), library.as_os_str().to_owned()),
                ("ECMXF_SIM_SOCKET".to_string(), sim.socket.clone().into_os_string()),
                ("ECMXF_EMU_STATS".to_string(), stats.clone().into_os_string()),
            ],
        ),
    };
    let text = config_with_cycle(&link, &format!("sync0_us = {cycle_us}\n"), "");
    let mut d = Daemon::binary_with_config_on(daemon, &text, &env);
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().expect("runtime");
    let ch = rt.block_on(d.connect());
    std::thread::sleep(Duration::from_secs(1));
    let pid = d.pid();
    let (x0, c0, t0) = (rt.block_on(exchanges(&ch)), cpu(pid), Instant::now());
    std::thread::sleep(Duration::from_secs(secs));
    let (x1, c1, dt) = (rt.block_on(exchanges(&ch)), cpu(pid), t0.elapsed().as_secs_f64());
    let n = (x1 - x0).max(1) as f64;

    let strace = Command::new("strace").arg("-V").output().ok().filter(|o| o.status.success()).and_then(|_| {
        let out = dir.join("strace.txt");
        let x0 = rt.block_on(exchanges(&ch));
        let mut tracer = Command::new("strace")
            .args(["-c", "-f", "-o"])
            .arg(&out)
            .args(["-p", &pid.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .ok()?;
        std::thread::sleep(Duration::from_secs(2));
        let x1 = rt.block_on(exchanges(&ch));
        let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(tracer.id() as i32), nix::sys::signal::SIGINT);
        let _ = tracer.wait();
        let (rows, total) = strace_summary(&out);
        let n = (x1 - x0).max(1) as f64;
        let top = rows.iter().take(4).map(|(s, c)| format!("{s} {:.2}", *c as f64 / n)).collect::<Vec<_>>();
        Some((total as f64 / n, top.join(", ")))
    });

    let total = rt.block_on(exchanges(&ch)).max(1) as f64;
    d.stop();
    let device_calls = (wire == Wire::Hardware).then(|| {
        let c = counters(&stats);
        let get = |k: &str| c.get(k).copied().unwrap_or(0) as f64;
        let calls = get("spi_messages") + get("gpio_get_values") + get("gpio_polls") + get("gpio_reads");
        let detail = format!(
            "SPI {:.2}, GPIO values {:.2}, polls {:.3}, event reads {:.3}",
            get("spi_messages") / total,
            get("gpio_get_values") / total,
            get("gpio_polls") / total,
            get("gpio_reads") / total
        );
        (calls / total, detail)
    });
    let _ = std::fs::remove_dir_all(&dir);
    let busy = c1 - c0;
    Figures { per_s: n / dt, cpu_pct: 100.0 * busy / dt, cpu_us_per_exchange: busy * 1e6 / n, device_calls, strace }
}

fn main() {
    let mut secs: u64 = 6;
    let mut daemons: Vec<PathBuf> = Vec::new();
    let mut rounds = 1;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--daemon" => daemons.push(args.next().map(PathBuf::from).unwrap_or_default()),
            "--rounds" => rounds = args.next().and_then(|v| v.parse().ok()).unwrap_or(1),
            n => {
                secs = n
                    .parse()
                    .unwrap_or_else(|_| panic!("usage: ecmxf-hw-bench [SECONDS] [--daemon PATH]... [--rounds N]"))
            }
        }
    }
    let exe = std::env::current_exe().expect("this executable");
    let dir = exe.parent().expect("its folder").to_path_buf();
    if daemons.is_empty() {
        daemons.push(dir.join("ecmxfd"));
    }
    let library =
        [dir.join("libecmxf_hw_emu.so"), dir.join("deps/libecmxf_hw_emu.so")].into_iter().find(|p| p.exists());
    let missing: Vec<PathBuf> = daemons
        .iter()
        .cloned()
        .chain([dir.join("ecmxf-sim")])
        .filter(|p| !p.exists())
        .chain(library.is_none().then(|| dir.join("libecmxf_hw_emu.so")))
        .collect();
    if !missing.is_empty() {
        eprintln!(
            "ecmxf-hw-bench: missing {missing:?}; build first: cargo build --release -p ecmxfd -p ecmxf-sim \
             -p ecmxf-hw-emu -p ecmxf-e2e --bins --lib"
        );
        std::process::exit(2);
    }
    let library = library.unwrap_or_default();
    println!("ecmxf-hw-bench: {secs} s per run, demo network idle in OP");
    for (i, d) in daemons.iter().enumerate() {
        println!("daemon {i}: {}", d.display());
    }
    println!(
        "{:<8} {:<7} {:<3} {:>11} {:>7} {:>12} {:>18}  strace: syscalls/exch (top)",
        "cycle", "link", "d", "exchanges/s", "CPU %", "CPU us/exch", "device calls/exch"
    );
    for cycle in [125, 1000] {
        for wire in [Wire::Socket, Wire::Hardware] {
            for _ in 0..rounds {
                for (i, daemon) in daemons.iter().enumerate() {
                    let f = run(wire, cycle, secs, daemon, &library);
                    let name = match wire {
                        Wire::Socket => "socket",
                        Wire::Hardware => "spidev",
                    };
                    let calls = f.device_calls.as_ref().map_or("-".into(), |(n, _)| format!("{n:.2}"));
                    let strace = f.strace.as_ref().map_or("(no strace)".into(), |(n, top)| format!("{n:.1} ({top})"));
                    println!(
                        "{:<8} {name:<7} {i:<3} {:>11.0} {:>7.1} {:>12.1} {calls:>18}  {strace}",
                        format!("{cycle} us"),
                        f.per_s,
                        f.cpu_pct,
                        f.cpu_us_per_exchange
                    );
                    if let Some((_, detail)) = f.device_calls {
                        println!("{:<20} device calls per exchange: {detail}", "");
                    }
                }
            }
        }
    }
}
