//! What the bench binaries share: a simulator in its own process, the
//! engine started on it, the simulator's packet counter, this process's
//! CPU time.

use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

use ecmxfd::config::Config;
use ecmxfd::link::socket::SocketLink;
use ecmxfd::master::Master;
use ecmxfd::master::Phase;

/// A simulator process, killed on drop.
pub struct Sim {
    child: Child,
    /// Its socket.
    pub socket: PathBuf,
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_file(&self.socket);
    }
}

/// Serves the demo network, or the network file `network`.
pub fn serve(network: Option<&Path>) -> Result<Sim, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let bin = exe.with_file_name("ecmxf-sim");
    if !bin.exists() {
        return Err(format!("{} not found: build it first (cargo build --release -p ecmxf-sim)", bin.display()));
    }
    let tag = if network.is_some() { "net" } else { "demo" };
    let socket = std::env::temp_dir().join(format!("ecmxfd-bench-{}-{tag}.sock", std::process::id()));
    let mut command = Command::new(&bin);
    command.arg("serve").arg("--socket").arg(&socket);
    if let Some(n) = network {
        command.arg("--network").arg(n);
    }
    let child = command.spawn().map_err(|e| e.to_string())?;
    let t = Instant::now();
    while SocketLink::connect(&socket).is_err() {
        if t.elapsed() > Duration::from_secs(10) {
            return Err("the simulator did not start".into());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(Sim { child, socket })
}

/// The simulator's own count of packets clocked: what the link carried,
/// whichever side of the daemon sent it.
#[allow(dead_code)] // not every bench reads the link
pub fn packet_counter(socket: &Path) -> Result<impl FnMut() -> Result<u64, String> + use<>, String> {
    let mut ctl = ecmxf_sim::server::SocketClient::connect(socket).map_err(|e| e.to_string())?;
    Ok(move || -> Result<u64, String> {
        let text = ctl.control("status").map_err(|e| e.to_string())?.map_err(|e| e.to_string())?;
        text.split_whitespace()
            .find_map(|w| w.strip_prefix("packets="))
            .and_then(|n| n.parse().ok())
            .ok_or_else(|| format!("no packet count in {text:?}"))
    })
}

/// The engine on `sim`, once its network runs.
pub fn started(sim: &Sim, config: Config) -> Result<Master, String> {
    let master = Master::start(SocketLink::connect(&sim.socket).map_err(|e| e.to_string())?, config);
    let t = Instant::now();
    while master.status().phase != Phase::Running {
        if t.elapsed() > Duration::from_secs(60) {
            return Err(format!("engine not running: {:?}", master.last_error()));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(master)
}

/// This process's CPU time (user + system), s.
pub fn cpu_seconds() -> f64 {
    let u = nix::sys::resource::getrusage(nix::sys::resource::UsageWho::RUSAGE_SELF);
    u.map_or(0.0, |u| {
        let t = |tv: nix::sys::time::TimeVal| tv.tv_sec() as f64 + tv.tv_usec() as f64 / 1e6;
        t(u.user_time()) + t(u.system_time())
    })
}
