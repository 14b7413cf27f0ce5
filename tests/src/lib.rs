//! End-to-end tests that start the real daemon on the simulator and talk
//! to it over its Unix socket (and TCP/TLS), as any client would. This
//! library is the harness. Most tests embed the daemon in the test process
//! ([`Daemon::sim`], [`Daemon::with_config`]: `ecmxfd::run` on a thread of
//! its own, stopped through its shutdown future); tests of what only a
//! process has (signals, exit codes, its log, the CLI against the binary)
//! start the `ecmxfd` binary ([`Daemon::binary_sim`],
//! [`Daemon::binary_with_config`]) and stop it with SIGTERM.
#![forbid(unsafe_code)]

pub mod frames;
pub mod hardware;
pub mod opcua;
pub mod probe_report;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use ecmxf_proto::v1 as pb;
use tonic::transport::Channel;

/// Tests that start daemons take turns: each runs the simulator in real
/// time, and two at once on a 2-core machine would stall each other.
pub static SERIAL: Mutex<()> = Mutex::new(());

/// The workspace root.
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap_or(Path::new("..")).to_path_buf()
}

/// The `ecmxfd` binary of this build. `cargo test --workspace` builds it
/// (fresh) before any test runs; `cargo test -p ecmxf-e2e` alone does not
/// rebuild another package's binary, so run `cargo build -p ecmxfd` first
/// there (a missing binary is built here, a stale one is not noticed).
pub fn daemon_binary() -> PathBuf {
    binary("ecmxfd", "ecmxfd")
}

/// The `ecmxfctl` binary of this build (same rules as [`daemon_binary`]:
/// client/tests/binary.rs makes `cargo test --workspace` build it fresh).
pub fn ctl_binary() -> PathBuf {
    binary("ecmxfctl", "ecmxfctl")
}

fn binary(name: &str, package: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> or target/<profile>/<bin> -> target/<profile>/<name>
    let mut dir = exe.parent().expect("target directory");
    if dir.ends_with("deps") {
        dir = dir.parent().expect("target directory");
    }
    let bin = dir.join(name);
    if !bin.exists() {
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let profile: &[&str] = if cfg!(debug_assertions) { &[] } else { &["--release"] };
        let status = Command::new(cargo)
            .args(["build", "-p", package, "--bin", name])
            .args(profile)
            .current_dir(repo())
            .status()
            .expect("run cargo build");
        assert!(status.success(), "building {name} failed");
    }
    bin
}

/// The `ecmxf-sim` binary of this build (built where missing, as
/// [`daemon_binary`]).
pub fn sim_binary() -> PathBuf {
    binary("ecmxf-sim", "ecmxf-sim")
}

/// What one `ecmxfctl` run did.
#[derive(Debug)]
pub struct Ctl {
    /// The command line, for messages.
    pub args: String,
    /// Exit code (-1: killed by a signal).
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

impl Ctl {
    /// Asserts exit code 0 and returns stdout.
    pub fn ok(&self) -> &str {
        assert_eq!(self.code, 0, "ecmxfctl {} failed:\n{}{}", self.args, self.stdout, self.stderr);
        &self.stdout
    }

    /// Asserts exit code `code` and returns stderr.
    pub fn fails(&self, code: i32) -> &str {
        assert_eq!(self.code, code, "ecmxfctl {}: wanted exit {code}:\n{}{}", self.args, self.stdout, self.stderr);
        &self.stderr
    }

    /// Whether `ecmxfctl diag` found the network healthy, or degraded only
    /// by trouble that passes (the chip dropped input frames, the RxFIFO ran
    /// dry, FIFO exchanges came late): what a shared, loaded test host may
    /// cause now and then, which health reports for a while (exit 8). A
    /// test about something else accepts that, and nothing more.
    pub fn healthy_but_for_passing_trouble(&self) -> bool {
        let passing = |line: &&str| {
            ["the chip dropped", "the RxFIFO ran dry", "FIFO exchanges came later"]
                .iter()
                .any(|t| line.starts_with(&format!("PROBLEM: degraded: {t}")))
        };
        let problems: Vec<&str> = self.stdout.lines().filter(|l| l.starts_with("PROBLEM")).collect();
        self.code == 0 || self.code == 8 && !problems.is_empty() && problems.iter().all(passing)
    }

    /// Parses stdout as one JSON value.
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_str(self.ok())
            .unwrap_or_else(|e| panic!("ecmxfctl {}: not JSON ({e}):\n{}", self.args, self.stdout))
    }
}

/// Runs `ecmxfctl` with `args` (no daemon chosen: add `--socket`), with
/// none of the user's ECMXF_* variables.
pub fn ctl(args: &[&str]) -> Ctl {
    let out = Command::new(ctl_binary())
        .args(args)
        .env_remove("ECMXF_SOCKET")
        .env_remove("ECMXF_CONNECT")
        .env_remove("ECMXF_TOKEN")
        .env_remove("ECMXF_CA")
        .stdin(Stdio::null())
        .output()
        .expect("run ecmxfctl");
    Ctl {
        args: args.join(" "),
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// The published schema of `command`'s --json output
/// (docs/ecmxfctl-json-schema.json).
pub fn json_schema(command: &str) -> serde_json::Value {
    let path = repo().join("docs/ecmxfctl-json-schema.json");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("read the published schema")).expect("schema JSON");
    doc["commands"].get(command).cloned().unwrap_or_else(|| panic!("no published schema for {command:?}"))
}

/// Asserts that `value` matches the published schema of `command`.
pub fn assert_schema(command: &str, value: &serde_json::Value) {
    let schema = json_schema(command);
    let v = jsonschema::validator_for(&schema).unwrap_or_else(|e| panic!("schema of {command:?} invalid: {e}"));
    let errors: Vec<String> = v.iter_errors(value).map(|e| format!("{} at {}", e, e.instance_path())).collect();
    assert!(errors.is_empty(), "{command} --json does not match its schema: {errors:?}\n{value:#}");
}

/// `ecmxf-sim serve` as its own process, for a daemon with
/// `backend = "sim-socket"`: faults are injected with `ecmxf-sim ctl`, and
/// the simulator can be killed and started again on the same socket.
#[derive(Debug)]
pub struct Simulator {
    child: Child,
    bin: PathBuf,
    /// Its socket.
    pub socket: PathBuf,
    args: Vec<String>,
}

impl Simulator {
    /// Serves the demo network on `dir/sim.sock`, with `args` added to
    /// `serve` (e.g. `["--seed", "7"]`).
    pub fn serve(dir: &Path, args: &[&str]) -> Self {
        let bin = sim_binary();
        let socket = dir.join("sim.sock");
        let args: Vec<String> = args.iter().map(|a| a.to_string()).collect();
        let child = Self::spawn(&bin, &socket, &args);
        Self { child, bin, socket, args }
    }

    fn spawn(bin: &Path, socket: &Path, args: &[String]) -> Child {
        let _ = std::fs::remove_file(socket);
        let child = Command::new(bin)
            .args(["serve", "--socket"])
            .arg(socket)
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start ecmxf-sim");
        let start = Instant::now();
        while !socket.exists() {
            assert!(start.elapsed() < Duration::from_secs(10), "ecmxf-sim did not create its socket");
            std::thread::sleep(Duration::from_millis(10));
        }
        child
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The daemon's `[link]` lines for this simulator.
    pub fn link(&self) -> String {
        format!("backend = \"sim-socket\"\nsocket = \"{}\"", self.socket.display())
    }

    /// `ecmxf-sim ctl WORDS...`; its answer (panics if refused).
    pub fn ctl(&self, words: &str) -> String {
        let out = Command::new(&self.bin)
            .args(["ctl", "--socket"])
            .arg(&self.socket)
            .args(words.split(' '))
            .output()
            .expect("run ecmxf-sim ctl");
        assert!(out.status.success(), "ctl {words}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// Kills the simulator (SIGKILL: no goodbye to its clients).
    pub fn kill(&mut self) {
        // A frozen process dies of SIGKILL too; thawed first, it is reaped
        // at once.
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGCONT);
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Freezes the simulator (SIGSTOP): the chip stops answering, as a
    /// hung link does, its socket still open.
    pub fn freeze(&self) {
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGSTOP).expect("SIGSTOP ecmxf-sim");
    }

    /// Lets a frozen simulator go on (SIGCONT).
    pub fn thaw(&self) {
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGCONT).expect("SIGCONT ecmxf-sim");
    }

    /// Starts a fresh simulator (a chip at power-up) on the same socket.
    pub fn restart(&mut self) {
        self.kill();
        self.child = Self::spawn(&self.bin, &self.socket, &self.args);
    }
}

impl Drop for Simulator {
    fn drop(&mut self) {
        self.kill();
    }
}

/// A file of ../shared/fixtures, if there; without it the caller skips
/// (and says so), unless ECMXF_REQUIRE_FIXTURES is set (CI), where a
/// missing fixture fails the test.
pub fn fixture(name: &str) -> Option<PathBuf> {
    present(fixtures_dir()?.join(name))
}

/// A simulator network file `dir/net.toml` of `slaves` (`[[slave]]`
/// tables), and the daemon's `[link]` lines that run it in process.
pub fn sim_network(dir: &Path, slaves: &str) -> String {
    let net = dir.join("net.toml");
    std::fs::write(&net, format!("version = 1\n{slaves}")).expect("write the network file");
    format!("backend = \"sim\"\nnetwork = \"{}\"", net.display())
}

/// The network the TwinCAT fixture (eni_twincat_elmo4_imu.xml) was made
/// for, as a simulator network file in `dir` ([`sim_network`]): its IMU,
/// known only from the ENI, then four Elmo Gold drives from their ESI. The
/// ENI's path and the `[link]` lines; `None` (skipped) without the
/// fixtures.
pub fn twincat_network(dir: &Path) -> Option<(PathBuf, String)> {
    let eni = fixture("eni_twincat_elmo4_imu.xml")?;
    let elmo = fixture("esi_elmo_gold_Elmo_ECAT_00010420_V11.xml")?;
    let mut slaves = format!("[[slave]]\neni = \"{}\"\neni_slave = \"Imu\"\n", eni.display());
    for _ in 0..4 {
        slaves.push_str(&format!(
            "[[slave]]\nesi = \"{}\"\nproduct_code = 0x30924\nrevision = 0x10420\n",
            elmo.display()
        ));
    }
    Some((eni, sim_network(dir, &slaves)))
}

/// A simulated network of these catalogue devices (the simulator's network
/// file in `dir`) and the daemon's `[[slave]]` entries for it, each naming
/// its device's ESI file where it has one (so the daemon names and types
/// its objects as the file does): the `[link]` lines and the entries.
pub fn catalog_network(dir: &Path, devices: &[&ecmxf_devices::catalog::CatalogDevice]) -> (String, String) {
    use ecmxf_devices::config_file::toml_path;
    let tables: String = devices.iter().map(|d| ecmxf_sim::config::SlaveSection::table_for(d)).collect();
    let network = dir.join("net.toml");
    std::fs::write(&network, format!("version = 1\n{tables}")).expect("write the network file");
    let slaves = devices
        .iter()
        .map(|d| match d.origin.esi() {
            Some(f) => format!("[[slave]]\nesi = {}\n", toml_path(f)),
            None => "[[slave]]\n".to_string(),
        })
        .collect();
    (format!("backend = \"sim\"\nnetwork = {}", toml_path(&network)), slaves)
}

/// ../shared/fixtures itself, if there (else as [`fixture`]).
pub fn fixtures_dir() -> Option<PathBuf> {
    present(repo().join("../shared/fixtures"))
}

fn present(path: PathBuf) -> Option<PathBuf> {
    if path.exists() {
        return Some(path);
    }
    assert!(std::env::var_os("ECMXF_REQUIRE_FIXTURES").is_none(), "{} missing", path.display());
    eprintln!("skipped: {} missing", path.display());
    None
}

/// How a daemon of the tests runs.
#[derive(Debug)]
enum Running {
    /// The `ecmxfd` binary, logging into a file.
    Process(Child),
    /// `ecmxfd::run` on a thread of the test process; the sender ends it.
    Embedded {
        stop: Option<tokio::sync::oneshot::Sender<()>>,
        thread: Option<std::thread::JoinHandle<Result<(), String>>>,
    },
}

/// A running daemon.
#[derive(Debug)]
pub struct Daemon {
    running: Running,
    /// Its socket.
    pub socket: PathBuf,
    /// A folder for this daemon's files, removed on drop.
    pub dir: PathBuf,
    log: PathBuf,
}

/// A daemon configuration for tests: `[link]` lines (e.g. `backend =
/// "sim"`), the simulator-friendly real-time and cycle settings of
/// `config/ecmxfd-sim.toml`, then `extra` (more sections).
pub fn config(link: &str, extra: &str) -> String {
    config_with_cycle(link, "", extra)
}

/// [`config`] with more `[cycle]` keys (e.g. `"sync0_us = 125\n"`).
pub fn config_with_cycle(link: &str, cycle: &str, extra: &str) -> String {
    format!(
        "version = 1\n[link]\n{link}\n[chip]\nready_timeout_ms = 1000\n[realtime]\npriority = 0\nlock_memory = false\nspin_us = 0\n\
         [cycle]\n{cycle}fifo_rx_depth = 255\nfifo_tx_depth = 40\nfifo_low = 128\nfifo_high = 240\n{extra}"
    )
}

/// The `[[axis]]` of the TI-like drive's first axis, as the tests use it.
pub const TI_AXIS: &str = "[[axis]]\nslave = 1\ncontrolword_offset = 0\nstatusword_offset = 0\n";

/// `msg` with `authorization: Bearer <token>`.
pub fn with_token<T>(msg: T, token: &str) -> tonic::Request<T> {
    let mut r = tonic::Request::new(msg);
    r.metadata_mut().insert("authorization", format!("Bearer {token}").parse().expect("ASCII token"));
    r
}

/// A write of `kind` to the named process-image entry.
pub fn by_entry(name: &str, kind: pb::value::Kind) -> pb::OutputWrite {
    pb::OutputWrite {
        target: Some(pb::output_write::Target::Entry(name.into())),
        value: Some(pb::Value { kind: Some(kind) }),
    }
}

/// A harmless SDO write (the TI drive's quick stop option code := 2).
pub fn sdo_write() -> pb::SdoDownloadRequest {
    pb::SdoDownloadRequest {
        slave: 1,
        index: 0x605A,
        subindex: 0,
        complete_access: false,
        data_type: 0,
        value: Some(pb::Value { kind: Some(pb::value::Kind::Integer(2)) }),
    }
}

/// A fresh temporary folder.
pub fn temp_dir(tag: &str) -> PathBuf {
    static N: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let n = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("ecmxf-e2e-{tag}-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create temp dir");
    dir
}

/// A configuration file for a test daemon: `{dir}` in the text is
/// replaced by the daemon's folder, `{repo}` by the workspace root.
fn write_config(dir: &Path, text: &str) -> PathBuf {
    let text = text.replace("{dir}", &dir.display().to_string()).replace("{repo}", &repo().display().to_string());
    let path = dir.join("ecmxfd.toml");
    std::fs::write(&path, text).expect("write config");
    path
}

impl Daemon {
    /// For a daemon whose engine never runs (bring-up fails for good):
    /// waits for its API, then for the engine's last error in its status
    /// (up to 10 s); the status as it last read.
    pub async fn status_with_an_error(&self) -> pb::MasterStatus {
        let mut status = pb::MasterStatus::default();
        for _ in 0..500 {
            if let Ok(ch) = ecmxf_proto::connect_unix(&self.socket).await {
                if let Ok(s) = pb::master_client::MasterClient::new(ch).get_status(pb::GetStatusRequest {}).await {
                    status = s.into_inner();
                    if !status.last_error.is_empty() {
                        break;
                    }
                }
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        status
    }

    /// The daemon embedded, on the demo simulator (as `ecmxfd --sim`), with
    /// a private socket.
    pub fn sim() -> Self {
        let mut config = ecmxfd::config::Config::simulator();
        config.link = ecmxfd::config::LinkConfig::Sim { network: None };
        Self::embed(temp_dir("sim"), config)
    }

    /// The daemon embedded, configured by `text` (see [`config`]; `{dir}`
    /// and `{repo}` are replaced by the daemon's folder and the workspace).
    pub fn with_config(text: &str) -> Self {
        let dir = temp_dir("cfg");
        let path = write_config(&dir, text);
        let config = ecmxfd::config::Config::load(&path).unwrap_or_else(|e| panic!("{e}"));
        Self::embed(dir, config)
    }

    /// The `ecmxfd --sim` binary with a private socket.
    pub fn binary_sim() -> Self {
        Self::binary_sim_with(&[])
    }

    /// The `ecmxfd --sim` binary with more arguments.
    pub fn binary_sim_with(args: &[&str]) -> Self {
        let mut all = vec!["--sim"];
        all.extend_from_slice(args);
        Self::spawn(temp_dir("sim"), &all)
    }

    /// The `ecmxfd --config <text written to a file>` binary.
    pub fn binary_with_config(text: &str) -> Self {
        Self::binary_with_config_on(&daemon_binary(), text, &[])
    }

    /// `binary --config <text written to a file>` with `env` added to its
    /// environment (the emulated hardware: [`hardware::emulation`]).
    pub fn binary_with_config_on(binary: &Path, text: &str, env: &[(String, std::ffi::OsString)]) -> Self {
        let dir = temp_dir("cfg");
        let path = write_config(&dir, text).display().to_string();
        Self::spawn_with(binary, env, dir, &["--config", &path])
    }

    fn embed(dir: PathBuf, mut config: ecmxfd::config::Config) -> Self {
        let socket = dir.join("ecmxfd.sock");
        config.api.socket = Some(socket.clone());
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let thread = std::thread::Builder::new()
            .name("ecmxfd-embedded".into())
            .spawn(move || {
                // Named, so a benchmark can tell the daemon's threads
                // (these, ecmxf-rt, ecmxf-inputs) from its own.
                let rt = tokio::runtime::Builder::new_multi_thread()
                    .worker_threads(2)
                    .thread_name("ecmxfd-api")
                    .enable_all()
                    .build()
                    .map_err(|e| e.to_string())?;
                let result = rt.block_on(ecmxfd::run(config, async {
                    let _ = stopped.await;
                }));
                rt.shutdown_timeout(Duration::from_millis(100));
                result.map_err(|e| e.to_string())
            })
            .expect("start the embedded daemon");
        let running = Running::Embedded { stop: Some(stop), thread: Some(thread) };
        Self { running, socket, log: dir.join("ecmxfd.log"), dir }
    }

    fn spawn(dir: PathBuf, args: &[&str]) -> Self {
        Self::spawn_with(&daemon_binary(), &[], dir, args)
    }

    fn spawn_with(binary: &Path, env: &[(String, std::ffi::OsString)], dir: PathBuf, args: &[&str]) -> Self {
        let socket = dir.join("ecmxfd.sock");
        let log = dir.join("ecmxfd.log");
        let child = Command::new(binary)
            .envs(env.iter().map(|(k, v)| (k, v)))
            .args(args)
            .args(["--socket", &socket.display().to_string(), "--status-every", "0"])
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).expect("log file"))
            .spawn()
            .expect("start ecmxfd");
        Self { running: Running::Process(child), socket, dir, log }
    }

    /// Whether it ended (and how), without waiting.
    fn ended(&mut self) -> Option<String> {
        match &mut self.running {
            Running::Process(child) => child.try_wait().ok().flatten().map(|s| format!("exited with {s}")),
            Running::Embedded { thread, .. } => {
                if !thread.as_ref().is_some_and(|t| t.is_finished()) {
                    return None;
                }
                let r = thread.take().map(|t| t.join());
                Some(match r {
                    Some(Ok(Ok(()))) => "ended".into(),
                    Some(Ok(Err(e))) => format!("failed: {e}"),
                    Some(Err(_)) => "panicked".into(),
                    None => "ended before".into(),
                })
            }
        }
    }

    /// Runs `ecmxfctl --socket <this daemon's socket> args...`.
    pub fn ctl(&self, args: &[&str]) -> Ctl {
        let socket = self.socket.display().to_string();
        let mut all = vec!["--socket", socket.as_str()];
        all.extend_from_slice(args);
        ctl(&all)
    }

    /// Its process id (the test's own when embedded).
    pub fn pid(&self) -> u32 {
        match &self.running {
            Running::Process(child) => child.id(),
            Running::Embedded { .. } => std::process::id(),
        }
    }

    /// What the daemon logged so far (a binary's log file; an embedded
    /// daemon logs to the test's own subscriber, none by default).
    pub fn log(&self) -> String {
        match &self.running {
            Running::Process(_) => std::fs::read_to_string(&self.log).unwrap_or_default(),
            Running::Embedded { .. } => "(embedded daemon: its log is not captured)".into(),
        }
    }

    /// Whether the daemon's log says `text` within `within` (a spawned
    /// daemon's; an embedded one's log is not captured: false). For work
    /// the daemon does on its own after it runs, that no call waits for.
    pub async fn logged(&self, text: &str, within: std::time::Duration) -> bool {
        let end = std::time::Instant::now() + within;
        loop {
            if self.log().contains(text) {
                return true;
            }
            if std::time::Instant::now() > end {
                return false;
            }
            tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        }
    }

    /// Connects, and waits until the engine runs (GetStatus says RUNNING).
    pub async fn connect(&mut self) -> Channel {
        let start = Instant::now();
        loop {
            if let Some(how) = self.ended() {
                panic!("ecmxfd {how}:\n{}", self.log());
            }
            if let Ok(ch) = ecmxf_proto::connect_unix(&self.socket).await {
                let mut m = pb::master_client::MasterClient::new(ch.clone());
                if let Ok(s) = m.get_status(pb::GetStatusRequest {}).await {
                    if s.get_ref().phase == pb::EnginePhase::Running as i32 {
                        return ch;
                    }
                }
            }
            assert!(start.elapsed() < Duration::from_secs(30), "ecmxfd not running after 30 s:\n{}", self.log());
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Stops it: a binary with SIGTERM (killed after 10 s), an embedded
    /// daemon through its shutdown future. The exit code: 0 when it
    /// stopped cleanly, 1 when it failed, `None` when it had to be killed
    /// or had already ended.
    pub fn stop(&mut self) -> Option<i32> {
        match &mut self.running {
            Running::Process(child) => {
                let pid = nix::unistd::Pid::from_raw(child.id() as i32);
                let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
                let start = Instant::now();
                while start.elapsed() < Duration::from_secs(10) {
                    if let Ok(Some(s)) = child.try_wait() {
                        return s.code();
                    }
                    std::thread::sleep(Duration::from_millis(20));
                }
                let _ = child.kill();
                let _ = child.wait();
                None
            }
            Running::Embedded { stop, thread } => {
                if let Some(stop) = stop.take() {
                    let _ = stop.send(());
                }
                match thread.take()?.join() {
                    Ok(Ok(())) => Some(0),
                    Ok(Err(e)) => {
                        eprintln!("embedded ecmxfd: {e}");
                        Some(1)
                    }
                    Err(_) => Some(101),
                }
            }
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if self.ended().is_none() {
            self.stop();
        }
        let _ = std::fs::remove_dir_all(&self.dir);
        // Every error an embedded daemon answered in this test binary was
        // words a user can read, not Rust Debug output: the API's error layer
        // records any that was not.
        if matches!(self.running, Running::Embedded { .. }) && !std::thread::panicking() {
            let debug = ecmxfd::debug_looking_messages();
            assert!(debug.is_empty(), "error messages that read like Rust Debug output: {debug:#?}");
        }
    }
}

/// Runs an async test body on a runtime of its own, holding [`SERIAL`].
pub fn run<F: std::future::Future<Output = ()>>(body: F) {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().expect("runtime").block_on(body);
}

/// The demo network's digital-IO slave (position 2, its outputs looped back
/// to its inputs): the byte offsets of its outputs and inputs in the
/// process image.
pub fn io_slave_bytes(image: &pb::ProcessImage) -> (u32, u32) {
    let first = |dir: pb::Direction| {
        image
            .entries
            .iter()
            .filter(|e| e.slave == 2 && e.direction == dir as i32)
            .map(|e| e.bit_offset / 8)
            .min()
            .expect("the demo network's IO slave")
    };
    (first(pb::Direction::Output), first(pb::Direction::Input))
}

/// The `p` quantile (0..=1) of `sorted`, nearest rank; 0 for none.
pub fn percentile(sorted: &[u64], p: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// The daemon's threads when it runs embedded in this process: the engine,
/// the input distributor, the API's runtime.
pub const DAEMON_THREADS: [&str; 3] = ["ecmxf-rt", "ecmxf-inputs", "ecmxfd-api"];

/// CPU time of this process' threads with these names, seconds, from
/// /proc/self/task/*/stat (utime + stime, in USER_HZ = 100 ticks per
/// second on Linux).
pub fn cpu_seconds(names: &[&str]) -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else { return 0.0 };
    let mut ticks = 0u64;
    for t in tasks.flatten() {
        let comm = std::fs::read_to_string(t.path().join("comm")).unwrap_or_default();
        if !names.contains(&comm.trim()) {
            continue;
        }
        let stat = std::fs::read_to_string(t.path().join("stat")).unwrap_or_default();
        // Fields after the ")" that ends the name: state is field 3, utime 14, stime 15.
        let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
        let f: Vec<&str> = rest.split_whitespace().collect();
        let field = |n: usize| f.get(n - 3).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
        ticks += field(14) + field(15);
    }
    ticks as f64 / 100.0
}

/// Checks the details every daemon error carries and returns their
/// `ErrorInfo` reason: a `google.rpc.Status` whose code and message are
/// the status's own (grpc-go, grpcurl and buf take the status from there,
/// not from `grpc-status`), in the domain "ecmxf".
pub fn full_status(e: &tonic::Status) -> String {
    use prost::Message;
    use tonic_types::StatusExt;
    let details = tonic_types::pb::Status::decode(e.details())
        .unwrap_or_else(|why| panic!("details of {e:?} are not a google.rpc.Status: {why}"));
    assert_eq!(details.code, e.code() as i32, "the details' code: {e:?}");
    assert_eq!(details.message, e.message(), "the details' message: {e:?}");
    let info = e.get_details_error_info().unwrap_or_else(|| panic!("no ErrorInfo in {e:?}"));
    assert_eq!(info.domain, "ecmxf", "{info:?}");
    info.reason
}

/// A program `.ci/run` installs from a registry: `$var`, else `default`
/// (relative to the repository), if it exists and `usable` says so. `None`
/// (and a note saying `install`) without one, unless `$require` is set
/// (CI), where it is missing is a failure.
pub fn installed_tool(
    var: &str,
    default: &str,
    usable: impl Fn(&Path) -> bool,
    require: &str,
    install: &str,
) -> Option<PathBuf> {
    let tool = std::env::var_os(var).map(PathBuf::from).unwrap_or_else(|| repo().join(default));
    if tool.exists() && usable(&tool) {
        return Some(tool);
    }
    assert!(
        std::env::var_os(require).is_none(),
        "{require} is set but {} is missing or unusable ({install}; bash .ci/run does)",
        tool.display()
    );
    eprintln!("skipped: {} is missing or unusable ({install}; bash .ci/run does)", tool.display());
    None
}

/// Graphviz's `dot` (`$ECMXF_DOT`, else /usr/bin/dot, which `.ci/run`
/// installs from Debian): what `ecmxfctl graph` writes for; required where
/// `ECMXF_REQUIRE_DOT` is set.
pub fn dot_binary() -> Option<PathBuf> {
    installed_tool("ECMXF_DOT", "/usr/bin/dot", |_| true, "ECMXF_REQUIRE_DOT", "apt-get install graphviz")
}

/// The node_modules folder `.ci/run` installs tests/node's packages into
/// (`$ECMXF_NODE_MODULES`, else target/node/node_modules), if `node` loads
/// `module` from it; required where `ECMXF_REQUIRE_NODE` is set.
pub fn node_modules(module: &str) -> Option<PathBuf> {
    let loads = |modules: &Path| {
        Command::new("node")
            .env("NODE_PATH", modules)
            .args(["-e", &format!("require('{module}')")])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    let install = "mkdir -p target/node; cp tests/node/package.json tests/node/package-lock.json target/node; \
                   npm ci --prefix target/node";
    installed_tool("ECMXF_NODE_MODULES", "target/node/node_modules", loads, "ECMXF_REQUIRE_NODE", install)
}

/// `buf` (the Buf CLI, written in Go: its `buf curl` is a gRPC client
/// built on connect-go, which like grpc-go reads the status from the error
/// details): `$ECMXF_BUF`, else the copy `.ci/run` installs from the npm
/// registry into `target/buf`; required where `ECMXF_REQUIRE_BUF` is set.
pub fn buf_binary() -> Option<PathBuf> {
    installed_tool(
        "ECMXF_BUF",
        "target/buf/node_modules/.bin/buf",
        |_| true,
        "ECMXF_REQUIRE_BUF",
        "npm install --prefix target/buf @bufbuild/buf",
    )
}

/// A TCP connection to 127.0.0.1:`port` from address `from` (127.0.0.0/8
/// is all loopback), so caps per peer address can be filled and passed.
pub async fn connect_from(from: std::net::Ipv4Addr, port: u16) -> std::io::Result<tokio::net::TcpStream> {
    let s = tokio::net::TcpSocket::new_v4()?;
    s.bind(std::net::SocketAddr::new(from.into(), 0))?;
    s.connect(std::net::SocketAddr::from(([127, 0, 0, 1], port))).await
}

/// How long until the peer closed `s` (EOF or reset), reading and dropping
/// whatever it sends; `None` when it is still open after `limit`.
pub async fn closed_within(mut s: tokio::net::TcpStream, limit: std::time::Duration) -> Option<std::time::Duration> {
    use tokio::io::AsyncReadExt;
    let start = std::time::Instant::now();
    let mut buf = [0u8; 64];
    loop {
        match tokio::time::timeout(limit.saturating_sub(start.elapsed()), s.read(&mut buf)).await {
            Ok(Ok(0)) | Ok(Err(_)) => return Some(start.elapsed()),
            Ok(Ok(_)) => continue,
            Err(_) => return None,
        }
    }
}

/// An input stream's sequence numbers as a subscriber checks them: each
/// jump must be told, as `lost` (this subscriber fell behind) or `gap`
/// (cycles the daemon never received), and numbers never go back.
#[derive(Debug, Default)]
pub struct SeqCheck {
    /// Samples received.
    pub samples: u64,
    /// The newest sequence number.
    pub seq: u64,
    /// Samples whose number did not rise.
    pub backwards: u64,
    /// Cycles told as never received.
    pub gaps: u64,
    /// Frames this subscriber was told it lost.
    pub lost: u64,
    /// Jumps neither `lost` nor `gap` explain: (previous, seq, lost, gap).
    pub unexplained: Vec<(u64, u64, u64, u64)>,
}

impl SeqCheck {
    /// Notes the next sample.
    pub fn note(&mut self, sample: &pb::InputSample) {
        self.samples += 1;
        if sample.seq <= self.seq {
            self.backwards += 1;
        }
        let jump = sample.seq.saturating_sub(self.seq + 1);
        if self.samples > 1 && jump != sample.lost + sample.gap {
            self.unexplained.push((self.seq, sample.seq, sample.lost, sample.gap));
        }
        self.seq = sample.seq;
        self.gaps += sample.gap;
        self.lost += sample.lost;
    }
}
