//! Output latency benchmark: how long a client's `WriteOutputs` takes to
//! come back through the simulated IO slave's loopback, at several
//! `cycle.output_latency_us` budgets and DC cycles. Run it with
//! `cargo run --release -p ecmxf-e2e --bin ecmxf-latency-bench` (`--secs N`
//! per configuration, default 5; `--rt` runs the engine with the daemon's
//! default real-time settings, those a configuration without `[realtime]`
//! gets: SCHED_FIFO priority 80, memory locked, 2000 us of spin before
//! each exchange; they need root or the unit's limits, without which the
//! daemon warns and runs without them; `--fifo-reads guarded|pipelined`
//! sets `cycle.fifo_reads`, unset the daemon's default; `--host-stall-us N`
//! sets `realtime.host_stall_us`, which decides the budgets refused).
//!
//! For each (cycle, budget) it checks the configuration as `ecmxfd
//! --check-config` does (a budget the link cannot hold is refused there,
//! with the smallest that can: one line, then the next budget), starts the
//! daemon (embedded, on the demo simulator), takes a lease on the IO slave, and repeatedly writes a new
//! byte to its outputs, then waits for the byte in the input image streamed
//! back (StreamInputs). It prints, from this one run:
//! - write -> loopback: from just before the WriteOutputs call to the
//!   engine receiving the input frame that carries the byte (the frame's
//!   CLOCK_MONOTONIC stamp), p50/p99/max;
//! - the daemon's own write-to-wire figure (GetStatus
//!   output_latency_p50/p99_us) and late writes;
//! - RxFIFO underruns (fifo_alarms) during the run;
//! - the daemon's CPU: its threads' user+system time over the run (the
//!   engine `ecmxf-rt`, the input distributor `ecmxf-inputs`, the API's
//!   runtime `ecmxfd-api`), in % of one core. The simulator runs inside the
//!   engine thread here (in-process link), so this includes the simulated
//!   chip.
#![forbid(unsafe_code)]

use std::time::{Duration, Instant};

use ecmxf_e2e::{DAEMON_THREADS, Daemon, cpu_seconds, percentile};
use ecmxf_proto::v1 as pb;
use ecmxfd::realtime::monotonic_ns;
use pb::master_client::MasterClient;
use pb::process_data_client::ProcessDataClient;
use tokio_stream::StreamExt;

struct Outcome {
    cpu_percent: f64,
    loopback_us: Vec<u64>,
    status: pb::MasterStatus,
    underruns: u64,
    late: u64,
}

/// What the tests' configuration says of real-time settings (none); taken
/// out (`--rt`), the daemon's defaults apply.
const NO_REALTIME: &str = "priority = 0\nlock_memory = false\nspin_us = 0\n";

/// The configuration of one run, refused as `--check-config` refuses it.
fn checked_config(
    cycle_us: u32,
    budget_us: u32,
    realtime: bool,
    reads: Option<&str>,
    host_stall_us: Option<u32>,
) -> Result<String, String> {
    let mut extra = format!("output_latency_us = {budget_us}\nsync0_us = {cycle_us}\n");
    if let Some(reads) = reads {
        extra.push_str(&format!("fifo_reads = \"{reads}\"\n"));
    }
    let mut config = ecmxf_e2e::config_with_cycle("backend = \"sim\"", &extra, "");
    if realtime {
        if !config.contains(NO_REALTIME) {
            return Err("--rt: the test configuration's [realtime] is not the one this bench takes out".into());
        }
        config = config.replace(NO_REALTIME, "");
    }
    if let Some(us) = host_stall_us {
        config = config.replace("[realtime]\n", &format!("[realtime]\nhost_stall_us = {us}\n"));
    }
    let dir = ecmxf_e2e::temp_dir("latency-check");
    let path = dir.join("ecmxfd.toml");
    std::fs::write(&path, &config).map_err(|e| e.to_string())?;
    let (mut out, mut err) = (Vec::new(), Vec::new());
    let status = ecmxfd::check_config(&path, &mut out, &mut err);
    let _ = std::fs::remove_dir_all(&dir);
    match status {
        0 => Ok(config),
        _ => Err(String::from_utf8_lossy(&err).trim().to_owned()),
    }
}

async fn measure(config: &str, secs: u64) -> Result<Outcome, String> {
    let mut d = Daemon::with_config(config);
    let ch = d.connect().await;
    let mut pd = ProcessDataClient::new(ch.clone());
    let mut master = MasterClient::new(ch.clone());
    let layout = pd.get_layout(pb::GetLayoutRequest {}).await.map_err(|e| format!("layout: {e}"))?.into_inner();
    let (out_at, in_at) = ecmxf_e2e::io_slave_bytes(&layout);
    let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 5000 }).await;
    let lease = lease.map_err(|e| format!("lease: {e}"))?.into_inner().id;
    let mut inputs = pd
        .stream_inputs(pb::StreamInputsRequest { entries: vec![], decimation: 1, on_change: false })
        .await
        .map_err(|e| format!("stream: {e}"))?
        .into_inner();
    let counters = |s: &pb::MasterStatus| s.counters.unwrap_or_default();
    let before = master.get_status(pb::GetStatusRequest {}).await.map_err(|e| format!("status: {e}"))?.into_inner();
    let (cpu0, t0) = (cpu_seconds(&DAEMON_THREADS), Instant::now());
    let until = Instant::now() + Duration::from_secs(secs);
    let mut loopback_us = Vec::new();
    let mut value = 0u8;
    let mut k = 0u64;
    while Instant::now() < until {
        value = value % 250 + 1;
        k += 1;
        let write = pb::OutputWrite {
            target: Some(pb::output_write::Target::Offset(out_at)),
            value: Some(pb::Value { kind: Some(pb::value::Kind::Raw(vec![value])) }),
        };
        let t0 = monotonic_ns();
        pd.write_outputs(pb::WriteOutputsRequest { lease_id: lease.clone(), writes: vec![write] })
            .await
            .map_err(|e| format!("write {k}: {e}"))?;
        let deadline = Instant::now() + Duration::from_secs(2);
        loop {
            let s = tokio::time::timeout_at(deadline.into(), inputs.next()).await;
            let Ok(Some(Ok(s))) = s else {
                eprintln!("write {k}: the loopback never showed {value} within 2 s");
                break;
            };
            if s.monotonic_ns >= t0 && s.image.get(in_at as usize) == Some(&value) {
                loopback_us.push((s.monotonic_ns - t0) / 1000);
                break;
            }
        }
        // Writes at no fixed phase to the cycle.
        tokio::time::sleep(Duration::from_micros(300 + (k * 137) % 900)).await;
    }
    let status = master.get_status(pb::GetStatusRequest {}).await.map_err(|e| format!("status: {e}"))?.into_inner();
    let cpu_percent = (cpu_seconds(&DAEMON_THREADS) - cpu0) / t0.elapsed().as_secs_f64() * 100.0;
    let (b, a) = (counters(&before), counters(&status));
    drop(inputs);
    d.stop();
    loopback_us.sort_unstable();
    Ok(Outcome {
        cpu_percent,
        loopback_us,
        underruns: a.fifo_alarms - b.fifo_alarms,
        late: a.output_latency_misses - b.output_latency_misses,
        status,
    })
}

fn main() {
    let mut secs = 5u64;
    let mut only: Option<(u32, u32)> = None;
    let mut realtime = false;
    let mut reads: Option<String> = None;
    let mut host_stall_us: Option<u32> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--secs" => secs = args.next().and_then(|v| v.parse().ok()).expect("--secs N"),
            "--only" => {
                let v = args.next().expect("--only CYCLE_US:BUDGET_US");
                let (c, b) = v.split_once(':').expect("--only CYCLE_US:BUDGET_US");
                only = Some((c.parse().expect("cycle"), b.parse().expect("budget")));
            }
            "--rt" => realtime = true,
            "--host-stall-us" => host_stall_us = args.next().and_then(|v| v.parse().ok()),
            "--fifo-reads" => reads = Some(args.next().expect("--fifo-reads guarded|pipelined")),
            other => panic!(
                "unknown argument {other}; use --secs N, --only CYCLE_US:BUDGET_US, --rt, --fifo-reads guarded|pipelined, --host-stall-us N"
            ),
        }
    }
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().expect("runtime");
    println!(
        "{secs} s per configuration; engine real-time settings {}",
        if realtime { "the defaults (SCHED_FIFO 80, memory locked, 2000 us spin)" } else { "off (no spin)" }
    );
    println!(
        "{:>8} {:>9} {:>7} | {:>24} | {:>20} {:>6} {:>9} {:>7}",
        "cycle", "budget", "writes", "write->loopback p50/p99/max", "daemon wire p50/p99", "late", "underruns", "cpu %"
    );
    let all = [
        (125, 1000),
        (125, 2000),
        (125, 2500),
        (125, 4125),
        (125, 5000),
        (125, 20000),
        (1000, 2000),
        (1000, 3000),
        (1000, 5000),
        (1000, 20000),
    ];
    // `--only` runs that pair, listed or not.
    let pairs: Vec<(u32, u32)> = only.map_or_else(|| all.to_vec(), |o| vec![o]);
    for (cycle_us, budget_us) in pairs {
        let run = checked_config(cycle_us, budget_us, realtime, reads.as_deref(), host_stall_us)
            .map(|config| rt.block_on(measure(&config, secs)));
        let o = match run.and_then(|r| r) {
            Ok(o) => o,
            Err(why) => {
                println!("{cycle_us:>5} us {budget_us:>6} us   refused or failed: {why}");
                continue;
            }
        };
        let l = &o.loopback_us;
        println!(
            "{:>5} us {:>6} us {:>7} | {:>7.2} {:>7.2} {:>7.2} ms | {:>8.2} {:>8.2} ms {:>6} {:>9} {:>7.0}",
            cycle_us,
            budget_us,
            l.len(),
            percentile(l, 0.5) as f64 / 1000.0,
            percentile(l, 0.99) as f64 / 1000.0,
            l.last().copied().unwrap_or(0) as f64 / 1000.0,
            o.status.output_latency_p50_us as f64 / 1000.0,
            o.status.output_latency_p99_us as f64 / 1000.0,
            o.late,
            o.underruns,
            o.cpu_percent
        );
    }
}
