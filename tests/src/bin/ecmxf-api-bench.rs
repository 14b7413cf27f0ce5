//! API benchmark: starts the `ecmxfd` binary next to this one with `--sim`,
//! as its own process (build both first: `cargo build --release -p ecmxfd
//! -p ecmxf-e2e --bins`; this bench builds nothing and replaces no binary),
//! and measures over its Unix socket:
//! - unary SDO upload latency, one client, then 16 concurrent clients
//!   (each on its own connection);
//! - input streaming to 16 concurrent subscribers: samples/s and the
//!   frame-to-subscriber latency (host CLOCK_MONOTONIC when the sample
//!   arrives minus when the engine received the frame);
//! - both at once.
//!
//! What runs where: the daemon (engine and in-process simulator) in its own
//! process, the clients in this one; each process's CPU comes from its own
//! /proc entry. A frame-to-subscriber latency below zero (the clocks
//! disagree) is not clamped: such samples are counted and said as an error.
//! Prints medians, p99 and max from this one run. `--secs N` sets each
//! phase's length (default 5).
//!
//! `--soak N` runs instead, for N seconds: 4 subscribers taking every
//! input frame plus 16 SDO clients each writing a value of its own and
//! reading it back (clients that share an object take turns on it), and
//! reports wrong values, FIFO alarms per minute, lost samples and the
//! daemon's CPU (a five-minute soak, the length that once showed slow
//! drifts: `--soak 300`).
#![forbid(unsafe_code)]

use std::time::{Duration, Instant};

use ecmxf_e2e::{Daemon, percentile};
use ecmxf_proto::v1 as pb;
use ecmxfd::realtime::monotonic_ns;
use pb::process_data_client::ProcessDataClient;
use pb::sdo_client::SdoClient;
use tokio_stream::StreamExt;
use tonic::transport::Channel;

const CLIENTS: usize = 16;

fn report(name: &str, mut us: Vec<u64>, secs: f64) {
    us.sort_unstable();
    println!(
        "{name:<44} n={:>7} {:>8.0}/s  p50={:>6} us  p99={:>6} us  max={:>6} us",
        us.len(),
        us.len() as f64 / secs,
        percentile(&us, 0.5),
        percentile(&us, 0.99),
        us.last().copied().unwrap_or(0)
    );
}

async fn sdo_load(ch: Channel, until: Instant) -> Vec<u64> {
    let mut sdo = SdoClient::new(ch);
    let req = pb::SdoUploadRequest { slave: 1, index: 0x1018, subindex: 1, complete_access: false, data_type: 0 };
    let mut out = Vec::new();
    while Instant::now() < until {
        let t = Instant::now();
        sdo.upload(req).await.expect("SDO upload");
        out.push(t.elapsed().as_micros() as u64);
    }
    out
}

/// (frame-to-subscriber latencies in us, frames lost, samples whose
/// latency came out negative).
async fn subscriber(ch: Channel, until: Instant) -> (Vec<u64>, u64, u64) {
    let mut pd = ProcessDataClient::new(ch);
    let mut s = pd
        .stream_inputs(pb::StreamInputsRequest { entries: vec![], decimation: 1, on_change: false })
        .await
        .expect("stream")
        .into_inner();
    let mut lat = Vec::new();
    let (mut lost, mut negative) = (0, 0);
    while let Some(m) = s.next().await {
        let m = m.expect("sample");
        match monotonic_ns().checked_sub(m.monotonic_ns) {
            Some(ns) => lat.push(ns / 1000),
            None => negative += 1,
        }
        lost += m.lost;
        if Instant::now() >= until {
            break;
        }
    }
    (lat, lost, negative)
}

async fn channels(d: &Daemon, n: usize) -> Vec<Channel> {
    let mut v = Vec::new();
    for _ in 0..n {
        v.push(ecmxf_proto::connect_unix(&d.socket).await.expect("connect"));
    }
    v
}

async fn streams(d: &Daemon, clients: usize, secs: u64, label: &str) {
    let until = Instant::now() + Duration::from_secs(secs);
    let tasks: Vec<_> = channels(d, clients).await.into_iter().map(|c| tokio::spawn(subscriber(c, until))).collect();
    let mut all = Vec::new();
    let (mut lost, mut negative) = (0, 0);
    let mut per = Vec::new();
    for t in tasks {
        let (l, k, n) = t.await.expect("task");
        per.push(l.len());
        all.extend(l);
        lost += k;
        negative += n;
    }
    if negative > 0 {
        println!(
            "ERROR: {negative} samples arrived before the engine received their frame (clocks disagree); left out"
        );
    }
    report(&format!("stream, {clients} subscriber(s){label}: frame->subscriber"), all, secs as f64);
    println!(
        "{:<44} per subscriber min {} max {} samples, lost {lost}",
        "",
        per.iter().min().unwrap_or(&0),
        per.iter().max().unwrap_or(&0)
    );
}

/// Writable CiA 402 objects of the demo's drives (slave, index), checked
/// to answer before the soak uses them.
const SOAK_OBJECTS: [(u32, u32); 8] =
    [(1, 0x6083), (1, 0x6084), (1, 0x6085), (1, 0x6081), (1, 0x6883), (1, 0x6884), (1, 0x7083), (1, 0x7084)];

/// One client of the soak: writes `client`-tagged values to its object and
/// reads each back; (pairs done, wrong read-backs, errors).
async fn write_read_back(
    ch: Channel,
    client: u32,
    object: (u32, u32),
    turn: std::sync::Arc<tokio::sync::Mutex<()>>,
    until: Instant,
) -> (u64, u64, u64) {
    let mut sdo = SdoClient::new(ch);
    let (mut pairs, mut wrong, mut errors) = (0u64, 0u64, 0u64);
    let mut n = 0u32;
    while Instant::now() < until {
        n = n.wrapping_add(1);
        let value = (client << 24) | (n & 0x00FF_FFFF);
        let _mine = turn.lock().await;
        let w = pb::SdoDownloadRequest {
            slave: object.0,
            index: object.1,
            subindex: 0,
            complete_access: false,
            data_type: 0,
            value: Some(pb::Value { kind: Some(pb::value::Kind::Raw(value.to_le_bytes().to_vec())) }),
        };
        if sdo.download(w).await.is_err() {
            errors += 1;
            continue;
        }
        let r = pb::SdoUploadRequest {
            slave: object.0,
            index: object.1,
            subindex: 0,
            complete_access: false,
            data_type: 0,
        };
        match sdo.upload(r).await {
            Ok(a) if a.get_ref().raw == value.to_le_bytes() => pairs += 1,
            Ok(_) => wrong += 1,
            Err(_) => errors += 1,
        }
    }
    (pairs, wrong, errors)
}

async fn soak(d: &Daemon, ch: Channel, secs: u64) {
    let mut sdo = SdoClient::new(ch.clone());
    let mut objects = Vec::new();
    for o in SOAK_OBJECTS {
        let r = pb::SdoUploadRequest { slave: o.0, index: o.1, subindex: 0, complete_access: false, data_type: 0 };
        if sdo.upload(r).await.is_ok_and(|a| a.get_ref().raw.len() == 4) {
            objects.push((o, std::sync::Arc::new(tokio::sync::Mutex::new(()))));
        }
    }
    assert!(!objects.is_empty(), "no writable 32-bit object answered");
    let master = || pb::master_client::MasterClient::new(ch.clone());
    let before = master().get_status(pb::GetStatusRequest {}).await.unwrap().into_inner().counters.unwrap();
    let cpu0 = cpu_seconds(d.pid());
    let until = Instant::now() + Duration::from_secs(secs);
    let t = Instant::now();
    let subs: Vec<_> = channels(d, 4).await.into_iter().map(|c| tokio::spawn(subscriber(c, until))).collect();
    let clients: Vec<_> = channels(d, CLIENTS)
        .await
        .into_iter()
        .enumerate()
        .map(|(i, c)| {
            let (o, turn) = objects[i % objects.len()].clone();
            tokio::spawn(write_read_back(c, i as u32 + 1, o, turn, until))
        })
        .collect();
    let (mut pairs, mut wrong, mut errors) = (0, 0, 0);
    for c in clients {
        let (p, w, e) = c.await.expect("client");
        (pairs, wrong, errors) = (pairs + p, wrong + w, errors + e);
    }
    let (mut samples, mut lost) = (0, 0);
    for s in subs {
        let (l, k, _) = s.await.expect("subscriber");
        samples += l.len();
        lost += k;
    }
    let wall = t.elapsed().as_secs_f64();
    let after = master().get_status(pb::GetStatusRequest {}).await.unwrap().into_inner().counters.unwrap();
    let alarms = after.fifo_alarms - before.fifo_alarms;
    println!(
        "soak {wall:.0} s: {pairs} SDO write/read-back pairs on {} objects, {wrong} wrong values, {errors} errors",
        objects.len()
    );
    println!(
        "soak: 4 subscribers {samples} samples, {lost} lost; FIFO alarms {alarms} ({:.2}/min); inputs dropped by the chip {}",
        alarms as f64 * 60.0 / wall,
        after.inputs_dropped_by_chip - before.inputs_dropped_by_chip
    );
    println!("soak: daemon process CPU {:.1} % of one core", (cpu_seconds(d.pid()) - cpu0) * 100.0 / wall);
}

fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let f: Vec<&str> = stat.rsplit(')').next().unwrap_or("").split_whitespace().collect();
    let ticks: f64 =
        f.get(11).and_then(|v| v.parse().ok()).unwrap_or(0.0) + f.get(12).and_then(|v| v.parse().ok()).unwrap_or(0.0);
    ticks / 100.0
}

fn main() {
    let soak_secs: Option<u64> = std::env::args().skip_while(|a| a != "--soak").nth(1).and_then(|v| v.parse().ok());
    let secs: u64 = std::env::args().skip_while(|a| a != "--secs").nth(1).and_then(|v| v.parse().ok()).unwrap_or(5);
    let daemon = ecmxf_e2e::daemon_binary();
    if !daemon.exists() {
        eprintln!(
            "{} not found: build it first (cargo build --release -p ecmxfd -p ecmxf-e2e --bins)",
            daemon.display()
        );
        std::process::exit(2);
    }
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build().expect("runtime");
    rt.block_on(async {
        let started = Instant::now();
        let mut d = Daemon::binary_sim();
        let ch = d.connect().await;
        let info = pb::master_client::MasterClient::new(ch.clone()).get_info(pb::GetInfoRequest {}).await.unwrap().into_inner();
        println!(
            "{} --sim (pid {}), {} us cycle, {} B in / {} B out per frame, {} s per phase",
            daemon.display(),
            d.pid(),
            info.sync0_us,
            info.input_image_bytes,
            info.output_image_bytes,
            secs
        );
        // Warm-up.
        sdo_load(ch.clone(), Instant::now() + Duration::from_millis(300)).await;
        if let Some(n) = soak_secs {
            soak(&d, ch, n).await;
            d.stop();
            return;
        }

        let t = Instant::now();
        let one = sdo_load(ch.clone(), Instant::now() + Duration::from_secs(secs)).await;
        report("SDO upload, 1 client", one, t.elapsed().as_secs_f64());

        let until = Instant::now() + Duration::from_secs(secs);
        let t = Instant::now();
        let tasks: Vec<_> = channels(&d, CLIENTS).await.into_iter().map(|c| tokio::spawn(sdo_load(c, until))).collect();
        let mut all = Vec::new();
        for task in tasks {
            all.extend(task.await.expect("task"));
        }
        report(&format!("SDO upload, {CLIENTS} clients"), all, t.elapsed().as_secs_f64());

        streams(&d, 1, secs, "").await;
        streams(&d, CLIENTS, secs, "").await;

        let until = Instant::now() + Duration::from_secs(secs);
        let load: Vec<_> = channels(&d, CLIENTS).await.into_iter().map(|c| tokio::spawn(sdo_load(c, until))).collect();
        streams(&d, CLIENTS, secs, " + 16 SDO clients").await;
        let mut all = Vec::new();
        for task in load {
            all.extend(task.await.expect("task"));
        }
        report(&format!("SDO upload, {CLIENTS} clients, during streaming"), all, secs as f64);

        let status = pb::master_client::MasterClient::new(ch).get_status(pb::GetStatusRequest {}).await.unwrap().into_inner();
        let c = status.counters.unwrap();
        println!(
            "engine: fifo_alarms={} input_batches_lost={} max_fifo_gap_us={} (the longest the engine thread itself stalled)",
            c.fifo_alarms, c.input_batches_lost, c.max_fifo_gap_us
        );
        let cpu = cpu_seconds;
        println!(
            "cpu seconds: daemon process {:.1}, bench clients (this process) {:.1}, wall {:.1} s on {} cores",
            cpu(d.pid()),
            cpu(std::process::id()),
            started.elapsed().as_secs_f64(),
            std::thread::available_parallelism().map_or(0, |n| n.get())
        );
        d.stop();
    });
}
