//! StreamFrames benchmark: one client streams a counter to the demo IO
//! slave, one frame per DC cycle at 125 us (8 kHz), for `--secs` (default
//! 60), through the daemon (embedded) and a simulator of its own process
//! (`ecmxf-sim serve`, so the daemon's CPU figure excludes the simulated
//! chip). Run it with
//! `cargo run --release -p ecmxf-e2e --bin ecmxf-frames-bench -- --secs 60`.
//!
//! It prints, from this one run: frames per second sustained (frames sent
//! over the stream's duration), frames told with their DC cycle and paired
//! with that cycle's input frame, pairings whose looped-back value was not
//! the frame's own, underrun cycles (a frame repeated) from the daemon's
//! cycle numbers and from the simulator's record, frames the record shows
//! played once each in order, dry frames, input frames the chip dropped,
//! and the daemon's CPU (its threads' user+system time, % of one core).
#![forbid(unsafe_code)]

use std::time::{Duration, Instant};

use ecmxf_e2e::{DAEMON_THREADS, Daemon, cpu_seconds, frames};
use ecmxf_proto::v1 as pb;
use pb::master_client::MasterClient;
use pb::process_data_client::ProcessDataClient;

async fn measure(secs: u64) {
    let dir = ecmxf_e2e::temp_dir("frames-bench");
    let sim = ecmxf_e2e::Simulator::serve(&dir, &[]);
    let config = ecmxf_e2e::config_with_cycle(&sim.link(), "sync0_us = 125\n", "");
    let mut d = Daemon::with_config(&config);
    let ch = d.connect().await;
    let mut pd = ProcessDataClient::new(ch.clone());
    let mut master = MasterClient::new(ch);
    let image = pd.get_layout(pb::GetLayoutRequest {}).await.expect("layout").into_inner();
    let (_, in_at) = ecmxf_e2e::io_slave_bytes(&image);
    let lease = pd.acquire_lease(pb::AcquireLeaseRequest { slaves: vec![2], ttl_ms: 30_000 }).await.expect("lease");
    let lease = lease.into_inner().id;
    let total = secs * 8000;
    assert!(sim.ctl(&format!("record 2 {}", total + 100_000)).starts_with("ok recording"));
    let (cpu0, t0) = (cpu_seconds(&DAEMON_THREADS), Instant::now());
    let run = frames::stream_counter(&mut pd, &lease, total).await;
    let cpu = (cpu_seconds(&DAEMON_THREADS) - cpu0) / t0.elapsed().as_secs_f64() * 100.0;
    let status = master.get_status(pb::GetStatusRequest {}).await.expect("status").into_inner();
    let pairing = run.pairing(in_at as usize).expect("frames told in order");
    let started = Instant::now();
    let recorded = loop {
        let r = frames::check_record(&frames::recorded(&sim), &run).expect("the record follows the counter");
        if r.played == total || started.elapsed() > Duration::from_secs(3) {
            break r;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    d.stop();
    println!("StreamFrames, one client, 125 us cycle, {secs} s ({total} frames):");
    println!("  frames/s sustained:        {:.0}", total as f64 / run.elapsed.as_secs_f64());
    println!("  told (seq + DC cycle):     {} of {total}", pairing.told);
    println!("  paired with their inputs:  {} ({} looped back another value)", pairing.with_inputs, pairing.mismatched);
    println!(
        "  underrun cycles:           {} (daemon's numbers), {} (simulator's record)",
        pairing.late_cycles, recorded.underruns
    );
    println!(
        "  played once each in order: {} of {total} (record; cycles agree with the daemon's: {})",
        recorded.played, recorded.cycles_agree
    );
    println!("  dry frames:                {}", run.last.dry);
    println!("  inputs dropped by chip:    {}", status.counters.unwrap_or_default().inputs_dropped_by_chip);
    println!("  daemon CPU:                {cpu:.0} % of one core (engine, distributor, API; simulator excluded)");
}

fn main() {
    let mut secs = 60u64;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--secs" => secs = args.next().and_then(|v| v.parse().ok()).expect("--secs N"),
            other => panic!("unknown argument {other}; use --secs N"),
        }
    }
    // The simulator binary next to this one, as built from this tree (a
    // stale one would lack the `record` command).
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut build = std::process::Command::new(cargo);
    build.args(["build", "-q", "-p", "ecmxf-sim"]).current_dir(ecmxf_e2e::repo());
    if !cfg!(debug_assertions) {
        build.arg("--release");
    }
    assert!(build.status().is_ok_and(|s| s.success()), "building ecmxf-sim failed");
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().expect("runtime");
    rt.block_on(measure(secs));
}
