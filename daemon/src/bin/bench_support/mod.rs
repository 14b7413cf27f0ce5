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
    let mut counts = packet_counts(socket)?;
    Ok(move || counts().map(|c| c.packets))
}

/// Packets the simulator clocked, in all and those carrying a FIFO call.
#[allow(dead_code)] // not every bench reads the link
#[derive(Clone, Copy, Debug)]
pub struct PacketCounts {
    pub packets: u64,
    pub fifo_packets: u64,
}

/// The simulator's packet counts (see [`PacketCounts`]), read from its status.
#[allow(dead_code)] // not every bench reads the link
pub fn packet_counts(socket: &Path) -> Result<impl FnMut() -> Result<PacketCounts, String> + use<>, String> {
    let mut ctl = ecmxf_sim::server::SocketClient::connect(socket).map_err(|e| e.to_string())?;
    Ok(move || -> Result<PacketCounts, String> {
        let text = ctl.control("status").map_err(|e| e.to_string())?.map_err(|e| e.to_string())?;
        let field = |name: &str| -> Result<u64, String> {
            text.split_whitespace()
                .find_map(|w| w.strip_prefix(name)?.strip_prefix('='))
                .and_then(|n| n.parse().ok())
                .ok_or_else(|| format!("no {name} in {text:?}"))
        };
        Ok(PacketCounts { packets: field("packets")?, fifo_packets: field("fifo_packets")? })
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

/// CPU time (user + system) of process `pid`, s (/proc, USER_HZ = 100).
#[allow(dead_code)] // the benches with clients in their own process only
pub fn cpu_seconds_of(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let field = |n: usize| f.get(n - 3).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    (field(14) + field(15)) as f64 / 100.0
}

/// This process's CPU time (user + system), s.
pub fn cpu_seconds() -> f64 {
    let u = nix::sys::resource::getrusage(nix::sys::resource::UsageWho::RUSAGE_SELF);
    u.map_or(0.0, |u| {
        let t = |tv: nix::sys::time::TimeVal| tv.tv_sec() as f64 + tv.tv_usec() as f64 / 1e6;
        t(u.user_time()) + t(u.system_time())
    })
}

/// A plant for the front-end benches: `slaves` simulated IO slaves (the
/// network file written in `dir`) run by the engine at `cycle_us` in this
/// process, with a tokio runtime (2 workers, as ecmxfd's) that keeps the
/// image built and runs the plant's application: every output byte
/// changes every 100 ms under a lease (the IO slaves loop it back to their
/// inputs). Drop the runtime before stopping the master.
#[allow(dead_code)] // the front-end benches only
pub fn io_plant(
    dir: &Path,
    slaves: usize,
    cycle_us: u32,
) -> Result<(Sim, std::sync::Arc<Master>, tokio::runtime::Runtime), String> {
    use std::sync::Arc;
    let network = dir.join(format!("net{slaves}.toml"));
    let list: String = (0..slaves).map(|_| "[[slave]]\nprofile = \"digital-io\"\n").collect();
    std::fs::write(&network, format!("version = 1\n{list}")).map_err(|e| e.to_string())?;
    let sim = serve(Some(&network))?;
    let mut config =
        Config { link: ecmxfd::config::LinkConfig::SimSocket { socket: sim.socket.clone() }, ..Config::simulator() };
    config.cycle.sync0_us = cycle_us;
    let master = Arc::new(started(&sim, config)?);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| e.to_string())?;
    rt.spawn(Arc::clone(&master).keep_image_built());
    let image = rt.block_on(master.image(ecmxfd::master::Call::anonymous(None))).map_err(|e| e.to_string())?;
    let outputs: Vec<usize> =
        image.entries.iter().enumerate().filter(|(_, e)| e.output && e.index == 0x7000).map(|(i, _)| i).collect();
    let lease = master.acquire_lease(&[], Some(Duration::from_secs(5)), "bench").map_err(|e| e.to_string())?;
    rt.spawn({
        let (master, image) = (Arc::clone(&master), Arc::clone(&image));
        async move {
            let mut tick = tokio::time::interval(Duration::from_millis(100));
            for n in 0u64.. {
                tick.tick().await;
                let mut staging = ecmxfd::master::entry_writes::Staging::new(&master, &image);
                for &i in &outputs {
                    let _ = staging.entry(&image.entries[i], &[(n % 255) as u8 + 1]);
                }
                if let Err(e) = staging.commit(master.leases(), &lease.id, "bench") {
                    eprintln!("writer: {e}");
                }
            }
        }
    });
    Ok((sim, master, rt))
}

/// The median of `v` (not empty).
#[allow(dead_code)] // the front-end benches only
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The repository holding `file` (a client script the bench runs), from
/// this binary's place in target/<profile>/.
#[allow(dead_code)] // the benches with Python clients only
pub fn repo_with(file: &str) -> Result<PathBuf, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    exe.ancestors()
        .find(|d| d.join(file).is_file())
        .map(PathBuf::from)
        .ok_or_else(|| format!("{file} not found above this binary"))
}

/// The Python the client scripts run on ($ECMXF_PYTHON, else the venv
/// `.ci/run` makes), if it imports `module`.
#[allow(dead_code)] // the benches with Python clients only
pub fn python_with(repo: &Path, module: &str) -> Result<PathBuf, String> {
    let p =
        std::env::var_os("ECMXF_PYTHON").map(PathBuf::from).unwrap_or_else(|| repo.join("target/py-venv/bin/python"));
    let ok = Command::new(&p).args(["-c", &format!("import {module}")]).output().is_ok_and(|o| o.status.success());
    if ok {
        Ok(p)
    } else {
        Err(format!(
            "{} cannot import {module}: python3 -m venv target/py-venv && target/py-venv/bin/pip install -r \
             tests/python/requirements.txt (or set $ECMXF_PYTHON)",
            p.display()
        ))
    }
}

/// This process's CPU, and the `client` process's if given, in cores over
/// `window` (slept through).
#[allow(dead_code)] // the benches with Python clients only
pub fn cpu_over(window: Duration, client: Option<u32>) -> (f64, f64) {
    let (c0, k0, t0) = (cpu_seconds(), client.map_or(0.0, cpu_seconds_of), Instant::now());
    std::thread::sleep(window);
    let wall = t0.elapsed().as_secs_f64();
    ((cpu_seconds() - c0) / wall, client.map_or(0.0, |p| (cpu_seconds_of(p) - k0) / wall))
}

/// What a load client measured against a front end.
#[allow(dead_code)] // the benches with Python clients only
pub struct Loaded {
    /// This process's CPU while the clients ran, in cores.
    pub cpu: f64,
    /// The clients' CPU, in cores.
    pub client_cpu: f64,
    /// FIFO alarms meanwhile.
    pub alarms: u64,
    /// The clients' closing JSON line (their counts).
    pub counted: serde_json::Value,
}

/// Runs a Python load client (`script` with `args`, from `repo`): waits for
/// its first line to say "subscribed", measures over `window`, then reads
/// its counts from its last line. `what` names its streams in errors.
#[allow(dead_code)] // the benches with Python clients only
pub fn python_load(
    master: &Master,
    python: &Path,
    script: &Path,
    args: &[&str],
    window: Duration,
    what: &str,
) -> Result<Loaded, String> {
    use std::io::{BufRead, BufReader, Read};
    use std::process::Stdio;
    let mut clients = Command::new(python)
        .arg(script)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("python: {e}"))?;
    let mut out = BufReader::new(clients.stdout.take().ok_or("no client output")?);
    let mut line = String::new();
    out.read_line(&mut line).map_err(|e| e.to_string())?;
    if line.trim() != "subscribed" {
        let _ = clients.kill();
        return Err(format!("the clients did not open their {what}: {line:?}"));
    }
    let a0 = master.status().fifo_alarms;
    let (cpu, client_cpu) = cpu_over(window, Some(clients.id()));
    let alarms = master.status().fifo_alarms - a0;
    let mut rest = String::new();
    out.read_to_string(&mut rest).map_err(|e| e.to_string())?;
    let _ = clients.wait();
    let counted = serde_json::from_str(rest.lines().last().unwrap_or("")).unwrap_or_default();
    Ok(Loaded { cpu, client_cpu, alarms, counted })
}
