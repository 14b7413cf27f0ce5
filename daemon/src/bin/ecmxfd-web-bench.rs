//! What the dashboard costs (docs/web.md): 64 simulated IO slaves at the
//! 125 us cycle whose outputs (looped back to their inputs) all change
//! every 100 ms, with SESSIONS browsers on the plots page (each holds the
//! live feed and a plot of 8 inputs open, the streams the page opens),
//! against the same network without the dashboard.
//!
//! What runs where: the simulator is its own process (`ecmxf-sim serve`);
//! the browsers' streams are one process of their own (Python's standard
//! library, `tests/python/web_check.py load`: $ECMXF_PYTHON or the venv
//! `target/py-venv` that `.ci/run` makes; a browser's rendering runs on
//! the operator's machine, not the gateway); this process runs the engine,
//! its async runtime (2 workers, as ecmxfd's), the image builder, a writer
//! that changes every output byte every 100 ms under a lease, and in the
//! "on" phases the dashboard with its streams open. Rounds alternate off
//! and on; the figures are medians of the rounds, so the difference is the
//! dashboard's CPU (this process only; the clients' is printed apart).
//! Nothing is built.
//!
//! Run: `cargo build --release -p ecmxf-sim -p ecmxfd --bins && target/release/ecmxfd-web-bench [SECONDS] [ROUNDS] [SESSIONS]`
#![forbid(unsafe_code)]

#[path = "bench_support/mod.rs"]
mod support;

use std::sync::Arc;
use std::time::Duration;

use ecmxfd::config::WebConfig;
use support::{cpu_over, io_plant, median, python_load, python_with, repo_with};

const SLAVES: usize = 64;

fn main() -> Result<(), String> {
    let arg = |n: usize, default: u64| std::env::args().nth(n).and_then(|s| s.parse().ok()).unwrap_or(default);
    let (secs, rounds, sessions) = (arg(1, 5), arg(2, 3) as usize, arg(3, 10));
    let repo = repo_with("tests/python/web_check.py")?;
    let python = python_with(&repo, "selenium")?;
    let dir = std::env::temp_dir().join(format!("ecmxfd-web-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let (sim, master, rt) = io_plant(&dir, SLAVES, 125)?;
    std::thread::sleep(Duration::from_secs(1));
    let (mut alarms_off, mut alarms_on) = (0, 0);
    let alarms = || master.status().fifo_alarms;
    let (mut off, mut on, mut rates, mut client_cpu) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let window = Duration::from_secs(secs);
    for round in 0..rounds {
        let a0 = alarms();
        let (cpu_off, _) = cpu_over(window, None);
        alarms_off += alarms() - a0;
        let port =
            std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map_err(|e| e.to_string())?;
        // Every stream comes from 127.0.0.1 here: the per-peer cap as
        // large as the listener's.
        let web = WebConfig { listen: port, max_connections_per_peer: 64, ..WebConfig::loopback() };
        let listener = rt.block_on(ecmxfd::web::bind(&web)).map_err(|e| e.to_string())?;
        let (stop, stopped) = tokio::sync::watch::channel(());
        let server = rt.spawn(ecmxfd::web::serve(Arc::clone(&master), web, Vec::new(), Vec::new(), listener, stopped));
        let url = format!("http://{port}/");
        let load_secs = (secs + 1).to_string();
        let script = repo.join("tests/python/web_check.py");
        let loaded = python_load(
            &master,
            &python,
            &script,
            &["load", url.as_str(), &sessions.to_string(), &load_secs],
            window,
            "streams",
        )?;
        alarms_on += loaded.alarms;
        let (cpu_on, cpu_clients, counted) = (loaded.cpu, loaded.client_cpu, loaded.counted);
        let rate = counted["per_second"].as_f64().unwrap_or(0.0);
        let _ = stop.send(());
        let _ = rt.block_on(server);
        println!(
            "round {round}: CPU without the dashboard {:.1}%, with it {:.1}% of a core; clients {:.1}% in their \
             process; {rate:.0} messages/s over {} streams",
            cpu_off * 100.0,
            cpu_on * 100.0,
            cpu_clients * 100.0,
            counted["streams"]
        );
        off.push(cpu_off);
        on.push(cpu_on);
        rates.push(rate);
        client_cpu.push(cpu_clients);
    }
    let s = master.status();
    println!(
        "web, {SLAVES} IO slaves at 125 us, outputs changing at 10 Hz, {sessions} plots pages (live feed and a plot \
         of 8 inputs each): CPU {:.1}% -> {:.1}% of a core (+{:.1} points, medians of {rounds} rounds of {secs} s), \
         {:.0} messages/s delivered, clients {:.1}% of a core in their own process; fifo alarms {alarms_off} \
         without the dashboard, {alarms_on} with it; recoveries {}",
        median(off.clone()) * 100.0,
        median(on.clone()) * 100.0,
        (median(on) - median(off)) * 100.0,
        median(rates),
        median(client_cpu) * 100.0,
        s.recoveries
    );
    rt.shutdown_background();
    master.stop();
    drop(sim);
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
