//! The Prometheus metrics endpoint (`[metrics] listen`, off by default):
//! `GET /metrics` in the text exposition format (version 0.0.4). Read-only
//! and unauthenticated, like every exporter: bind it to localhost or a
//! management network.
//!
//! Counters are the engine's (the same numbers `Master.GetStatus` and
//! `ecmxfctl master` show); per-slave state and AL status are read from the
//! chip at each scrape (one SLV_INFO_GET transaction per slave, queued with
//! the other blocking commands). Exchanges per second is
//! `rate(ecmxf_exchanges_total[1m])`.

use std::fmt::Write as _;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;

use crate::api::Context;

/// Bucket upper bounds, seconds: SDO transfers take from a few cycles to
/// the 3 s default deadline.
const BUCKETS: [f64; 12] = [0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 3.0];

/// A latency histogram updated lock-free from any task.
#[derive(Debug, Default)]
pub struct Histogram {
    counts: [AtomicU64; BUCKETS.len()],
    over: AtomicU64,
    sum_ns: AtomicU64,
}

impl Histogram {
    /// Records one duration.
    pub fn observe(&self, d: Duration) {
        let s = d.as_secs_f64();
        match BUCKETS.iter().position(|b| s <= *b) {
            Some(i) => self.counts[i].fetch_add(1, Ordering::Relaxed),
            None => self.over.fetch_add(1, Ordering::Relaxed),
        };
        self.sum_ns.fetch_add(d.as_nanos().min(u128::from(u64::MAX)) as u64, Ordering::Relaxed);
    }

    /// Appends the `_bucket`, `_sum` and `_count` lines of `name`.
    fn render(&self, out: &mut String, name: &str, help: &str) {
        let _ = writeln!(out, "# HELP {name} {help}\n# TYPE {name} histogram");
        let mut cumulative = 0u64;
        for (b, c) in BUCKETS.iter().zip(&self.counts) {
            cumulative += c.load(Ordering::Relaxed);
            let _ = writeln!(out, "{name}_bucket{{le=\"{b}\"}} {cumulative}");
        }
        cumulative += self.over.load(Ordering::Relaxed);
        let _ = writeln!(out, "{name}_bucket{{le=\"+Inf\"}} {cumulative}");
        let _ = writeln!(out, "{name}_sum {}", self.sum_ns.load(Ordering::Relaxed) as f64 / 1e9);
        let _ = writeln!(out, "{name}_count {cumulative}");
    }
}

/// One metric with a single sample.
fn metric(out: &mut String, name: &str, kind: &str, help: &str, value: impl std::fmt::Display) {
    let _ = writeln!(out, "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {value}");
}

/// A label value escaped as the format wants (backslash, quote, newline).
fn label(v: &str) -> String {
    v.replace('\\', "\\\\").replace('"', "\\\"").replace('\n', "\\n")
}

/// The whole exposition.
pub async fn render(ctx: &Context) -> String {
    let mut out = String::with_capacity(8192);
    let s = crate::api::master::status_pb(&ctx.master);
    let c = s.counters.unwrap_or_default();
    let phase = pb::EnginePhase::try_from(s.phase).unwrap_or_default();
    let _ = writeln!(out, "# HELP ecmxf_engine_phase The engine's phase (1 for the current one).");
    let _ = writeln!(out, "# TYPE ecmxf_engine_phase gauge");
    for p in [
        pb::EnginePhase::Starting,
        pb::EnginePhase::BringingUp,
        pb::EnginePhase::Running,
        pb::EnginePhase::Recovering,
        pb::EnginePhase::Stopping,
        pb::EnginePhase::Stopped,
    ] {
        let _ = writeln!(out, "ecmxf_engine_phase{{phase=\"{}\"}} {}", p.as_str_name(), u8::from(p == phase));
    }
    // (name, type, help, value): one sample each.
    let single: [(&str, &str, &str, String); 23] = [
        (
            "ecmxf_network_state",
            "gauge",
            "Network AL state (1 INIT, 2 PREOP, 3 BOOT, 4 SAFEOP, 8 OP, 16 ERROR).",
            s.ecat_state.to_string(),
        ),
        ("ecmxf_exchanges_total", "counter", "SPI packets exchanged with the chip.", c.exchanges.to_string()),
        (
            "ecmxf_crc_errors_total",
            "counter",
            "SPI packets the chip received with bad check words (accumulated from its 8-bit counter).",
            c.crc_errors.to_string(),
        ),
        (
            "ecmxf_wkc_errors_total",
            "counter",
            "Cycles with a wrong working counter (accumulated from the chip's 8-bit counter).",
            c.wkc_errors.to_string(),
        ),
        (
            "ecmxf_process_data_flowing",
            "gauge",
            "1 while the engine runs in the target state and input frames arrive within the limit.",
            u8::from(s.process_data_flowing).to_string(),
        ),
        (
            "ecmxf_input_age_seconds",
            "gauge",
            "Age of the newest input frame (0 while no cyclic exchange runs).",
            (s.input_age_us as f64 / 1e6).to_string(),
        ),
        (
            "ecmxf_ring_overflows_total",
            "counter",
            "Input frames dropped before any subscriber saw them (the distributor fell behind).",
            c.ring_overflows.to_string(),
        ),
        (
            "ecmxf_corrupt_answers_total",
            "counter",
            "Answers that failed validation (check word, framing).",
            c.corrupt_answers.to_string(),
        ),
        (
            "ecmxf_not_ready_answers_total",
            "counter",
            "Answers the chip marked not ready (busy).",
            c.not_ready_answers.to_string(),
        ),
        ("ecmxf_transactions_total", "counter", "Blocking-command transactions finished.", c.transactions.to_string()),
        ("ecmxf_input_frames_total", "counter", "Input frames received from the TxFIFO.", c.input_frames.to_string()),
        ("ecmxf_output_frames_total", "counter", "Output frames pushed into the RxFIFO.", c.output_frames.to_string()),
        (
            "ecmxf_input_batches_lost_total",
            "counter",
            "FIFO answers lost (corrupt): batches of input frames never received.",
            c.input_batches_lost.to_string(),
        ),
        (
            "ecmxf_fifo_underruns_total",
            "counter",
            "Times the RxFIFO ran dry (slaves got repeated outputs).",
            c.fifo_alarms.to_string(),
        ),
        ("ecmxf_recoveries_total", "counter", "Recoveries started.", c.recoveries.to_string()),
        (
            "ecmxf_max_fifo_gap_seconds",
            "gauge",
            "Longest gap between FIFO pushes seen.",
            (c.max_fifo_gap_us as f64 / 1e6).to_string(),
        ),
        ("ecmxf_rx_fifo_frames", "gauge", "Output frames waiting in the chip's RxFIFO.", s.rx_fifo_level.to_string()),
        ("ecmxf_tx_fifo_frames", "gauge", "Input frames waiting in the chip's TxFIFO.", s.tx_fifo_level.to_string()),
        (
            "ecmxf_rx_fifo_depth_frames",
            "gauge",
            "RxFIFO depth in force.",
            ctx.master.layout().fifo_rx_depth.to_string(),
        ),
        ("ecmxf_dc_stable", "gauge", "1 while the chip reports DC stable.", u8::from(s.dc_stable).to_string()),
        ("ecmxf_link_pin", "gauge", "The chip's LINK pin level.", u8::from(s.link_pin).to_string()),
        ("ecmxf_output_writers", "gauge", "Clients holding output leases.", s.output_writers.to_string()),
        (
            "ecmxf_config_generation",
            "gauge",
            "Configurations applied since the daemon started.",
            s.config_generation.to_string(),
        ),
    ];
    for (name, kind, help, value) in single {
        metric(&mut out, name, kind, help, value);
    }
    ctx.sdo_latency.render(&mut out, "ecmxf_sdo_duration_seconds", "SDO upload/download duration through the API.");
    match tokio::time::timeout(Duration::from_secs(3), crate::api::master::list_slaves(ctx, false)).await {
        Ok(Ok(list)) => {
            metric(&mut out, "ecmxf_slaves", "gauge", "Slaves found on the ring.", list.slaves.len());
            let _ =
                writeln!(out, "# HELP ecmxf_slave_state A slave's AL state (1 INIT, 2 PREOP, 3 BOOT, 4 SAFEOP, 8 OP).");
            let _ = writeln!(out, "# TYPE ecmxf_slave_state gauge");
            for sl in &list.slaves {
                let _ = writeln!(
                    out,
                    "ecmxf_slave_state{{position=\"{}\",name=\"{}\"}} {}",
                    sl.position,
                    label(&sl.name),
                    sl.state
                );
            }
            let _ = writeln!(out, "# HELP ecmxf_slave_al_status_code A slave's AL status code (0: no error).");
            let _ = writeln!(out, "# TYPE ecmxf_slave_al_status_code gauge");
            for sl in &list.slaves {
                let _ = writeln!(
                    out,
                    "ecmxf_slave_al_status_code{{position=\"{}\",name=\"{}\"}} {}",
                    sl.position,
                    label(&sl.name),
                    sl.al_status_code
                );
            }
            metric(&mut out, "ecmxf_slave_scrape_ok", "gauge", "1 when the per-slave metrics could be read.", 1);
        }
        // The engine is recovering or busy: the counters above still hold.
        _ => metric(&mut out, "ecmxf_slave_scrape_ok", "gauge", "1 when the per-slave metrics could be read.", 0),
    }
    out
}

/// Binds the endpoint (before the service reports ready, so a taken port
/// is a start-up error naming `metrics.listen`).
pub async fn bind(addr: SocketAddr) -> Result<TcpListener, String> {
    let l = TcpListener::bind(addr).await.map_err(|e| format!("metrics.listen {addr}: {e}"))?;
    if let Ok(a) = l.local_addr() {
        tracing::info!(address = %a, "metrics listening on http://{a}/metrics");
    }
    Ok(l)
}

/// Serves `/metrics` until `shutdown` changes.
pub async fn serve(ctx: Arc<Context>, listener: TcpListener, mut shutdown: watch::Receiver<()>) {
    loop {
        tokio::select! {
            _ = shutdown.changed() => return,
            accepted = listener.accept() => {
                let Ok((stream, _)) = accepted else { continue };
                let ctx = Arc::clone(&ctx);
                tokio::spawn(async move {
                    // A client that never finishes its request is dropped.
                    let _ = tokio::time::timeout(Duration::from_secs(10), answer(&ctx, stream)).await;
                });
            }
        }
    }
}

/// Reads one request head and answers it (then closes: no keep-alive).
async fn answer(ctx: &Context, mut stream: TcpStream) -> std::io::Result<()> {
    let mut head = Vec::with_capacity(1024);
    let mut buf = [0u8; 1024];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") {
        let n = stream.read(&mut buf).await?;
        if n == 0 {
            return Ok(());
        }
        head.extend_from_slice(&buf[..n]);
        if head.len() > 16 * 1024 {
            return respond(&mut stream, "431 Request Header Fields Too Large", "request head too large\n").await;
        }
    }
    let line = String::from_utf8_lossy(head.split(|b| *b == b'\n').next().unwrap_or_default()).into_owned();
    let mut parts = line.split_whitespace();
    let (method, path) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    let path = path.split('?').next().unwrap_or("");
    match (method, path) {
        ("GET", "/metrics") => {
            let body = render(ctx).await;
            respond_with(&mut stream, "200 OK", "text/plain; version=0.0.4; charset=utf-8", &body).await
        }
        ("GET", "/") => respond(&mut stream, "200 OK", "ecmxfd metrics: see /metrics\n").await,
        ("GET", _) => respond(&mut stream, "404 Not Found", "not found: the metrics are at /metrics\n").await,
        _ => respond(&mut stream, "405 Method Not Allowed", "only GET\n").await,
    }
}

async fn respond(stream: &mut TcpStream, status: &str, body: &str) -> std::io::Result<()> {
    respond_with(stream, status, "text/plain; charset=utf-8", body).await
}

async fn respond_with(stream: &mut TcpStream, status: &str, content_type: &str, body: &str) -> std::io::Result<()> {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes()).await?;
    stream.write_all(body.as_bytes()).await?;
    stream.shutdown().await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_buckets_are_cumulative_with_sum_and_count() {
        let h = Histogram::default();
        h.observe(Duration::from_micros(300));
        h.observe(Duration::from_millis(3));
        h.observe(Duration::from_secs(10));
        let mut out = String::new();
        h.render(&mut out, "x", "help");
        assert!(out.contains("x_bucket{le=\"0.0005\"} 1\n"), "{out}");
        assert!(out.contains("x_bucket{le=\"0.005\"} 2\n"), "{out}");
        assert!(out.contains("x_bucket{le=\"3\"} 2\n"), "{out}");
        assert!(out.contains("x_bucket{le=\"+Inf\"} 3\n"), "{out}");
        assert!(out.contains("x_count 3\n") && out.contains("x_sum 10.0033\n"), "{out}");
    }

    #[test]
    fn label_values_are_escaped() {
        assert_eq!(label("a\"b\\c\nd"), "a\\\"b\\\\c\\nd");
    }
}
