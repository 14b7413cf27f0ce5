//! What the Sparkplug B edge node costs (docs/sparkplug.md): 64 simulated IO slaves
//! at a 1 ms cycle whose process data all change every 100 ms, published
//! at 10 Hz with deadband 0, against the same network without the node.
//!
//! What runs where: the simulator is its own process (`ecmxf-sim serve`),
//! the broker too (mosquitto, started here on a free port: $MOSQUITTO, the
//! PATH, or /usr/sbin/mosquitto); this process runs the engine, its async
//! runtime (2 workers, as ecmxfd's), the image builder, a writer that
//! changes every slave's output byte every 100 ms under a lease (the IO
//! slaves loop it back to their inputs: two changed variables per slave
//! per period), and, in the "on" phases, the Sparkplug node. Rounds
//! alternate off and on; the figures are medians of the rounds, so the
//! difference is the node's CPU on this host. Messages/s are the ones
//! handed to the MQTT client (QoS 0; the broker's queue never filled if
//! "dropped" is 0). Nothing is built.
//!
//! Run: `cargo build --release -p ecmxf-sim -p ecmxfd --bins && target/release/ecmxfd-sparkplug-bench [SECONDS] [ROUNDS]`
#![forbid(unsafe_code)]

#[path = "bench_support/mod.rs"]
mod support;

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use ecmxfd::config::SparkplugConfig;
use ecmxfd::config::sparkplug::BrokerUrl;
use support::{cpu_seconds, io_plant, median};

const SLAVES: usize = 64;

/// mosquitto on a free port, killed on drop.
struct Broker {
    child: Child,
    port: u16,
}

impl Drop for Broker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn broker(dir: &std::path::Path) -> Result<Broker, String> {
    let bin = std::env::var_os("MOSQUITTO")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("PATH")
                .and_then(|p| std::env::split_paths(&p).map(|d| d.join("mosquitto")).find(|b| b.is_file()))
        })
        .or_else(|| Some(PathBuf::from("/usr/sbin/mosquitto")).filter(|b| b.is_file()))
        .ok_or("mosquitto not found: apt-get install mosquitto, or set $MOSQUITTO")?;
    let port =
        std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map_err(|e| e.to_string())?.port();
    let conf = dir.join("mosquitto.conf");
    std::fs::write(&conf, format!("listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n"))
        .map_err(|e| e.to_string())?;
    let child = Command::new(bin)
        .arg("-c")
        .arg(&conf)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("mosquitto: {e}"))?;
    let t = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        if t.elapsed() > Duration::from_secs(10) {
            return Err("mosquitto did not listen".into());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(Broker { child, port })
}

fn main() -> Result<(), String> {
    let secs: u64 = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(5);
    let rounds: usize = std::env::args().nth(2).and_then(|s| s.parse().ok()).unwrap_or(3);
    let dir = std::env::temp_dir().join(format!("ecmxfd-spb-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let broker = broker(&dir)?;
    let (sim, master, rt) = io_plant(&dir, SLAVES, 1000)?;
    std::thread::sleep(Duration::from_secs(1));
    let sparkplug = SparkplugConfig {
        broker: vec![BrokerUrl { tls: false, host: "127.0.0.1".into(), port: broker.port }],
        group_id: "bench".into(),
        node_id: Some("gw".into()),
        primary_host_id: None,
        ca_file: None,
        client_cert: None,
        client_key: None,
        credentials_file: None,
        keep_alive_s: 30,
        data_period_ms: 100,
        data_deadband: 0.0,
        diagnostics_period_ms: 1000,
        diagnostics_deadband: 0.0,
        slaves: Vec::new(),
        variables: Vec::new(),
        metric_names: Default::default(),
        commands: ecmxfd::config::api::RoleName::None,
    };
    let alarms0 = master.status().fifo_alarms;
    let (mut off, mut on, mut rates) = (Vec::new(), Vec::new(), Vec::new());
    let window = Duration::from_secs(secs);
    let cpu_over = |w: Duration| {
        let (c0, t0) = (cpu_seconds(), Instant::now());
        std::thread::sleep(w);
        (cpu_seconds() - c0) / t0.elapsed().as_secs_f64()
    };
    for round in 0..rounds {
        let cpu_off = cpu_over(window);
        let stats = Arc::clone(master.sparkplug_state());
        let (stop, stopped) = tokio::sync::watch::channel(());
        let prepared = ecmxfd::sparkplug::prepare(&sparkplug).map_err(|e| e.to_string())?;
        let node = rt.spawn(ecmxfd::sparkplug::serve(Arc::clone(&master), prepared, Arc::clone(&stats), stopped));
        // Connected and born, then measured.
        let t = Instant::now();
        while stats.connected.load(Relaxed) == 0 && t.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(10));
        }
        std::thread::sleep(Duration::from_secs(1));
        let (p0, t0) = (stats.published.load(Relaxed), Instant::now());
        let cpu_on = cpu_over(window);
        let rate = (stats.published.load(Relaxed) - p0) as f64 / t0.elapsed().as_secs_f64();
        let _ = stop.send(());
        let _ = rt.block_on(node);
        println!(
            "round {round}: CPU without the node {:.1}%, with it {:.1}% of a core; {rate:.0} messages/s published",
            cpu_off * 100.0,
            cpu_on * 100.0
        );
        off.push(cpu_off);
        on.push(cpu_on);
        rates.push(rate);
    }
    let s = master.status();
    let dropped = master.sparkplug_state().dropped.load(Relaxed);
    println!(
        "sparkplug, {SLAVES} IO slaves at 1 ms, every variable changing at 10 Hz, deadband 0: CPU {:.1}% -> {:.1}% of a core (+{:.1} points, medians of {rounds} rounds of {secs} s), {:.0} messages/s to the broker ({} dropped), fifo alarms {}, recoveries {}",
        median(off.clone()) * 100.0,
        median(on.clone()) * 100.0,
        (median(on) - median(off)) * 100.0,
        median(rates),
        dropped,
        s.fifo_alarms - alarms0,
        s.recoveries
    );
    master.stop();
    drop(sim);
    drop(broker);
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
