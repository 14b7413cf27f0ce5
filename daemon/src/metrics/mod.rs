//! The Prometheus metrics endpoint (`[metrics] listen`, off by default):
//! `GET /metrics` in the text exposition format (version 0.0.4). Read-only
//! and unauthenticated, like every exporter: bind it to localhost or a
//! management network.
//!
//! Counters are the engine's, read from the [`Master`] (the same numbers
//! `Master.GetStatus` and `ecmxfctl master` show); per-slave state and AL
//! status are read from the chip at each scrape (two SLV_INFO_GET
//! transactions per slave, queued with the other blocking commands).
//! Exchanges per second is `rate(ecmxf_exchanges_total[1m])`. Nothing
//! here depends on the gRPC API: the API records into the master's [`Histogram`] it
//! shares with the endpoint.

use std::fmt::Write as _;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use crate::master::EcatState;
use crate::master::SlaveInfoCode;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;

use crate::master::Master;
use crate::master::Phase;

pub(crate) use crate::master::histogram::Histogram;

/// What the endpoint reads: the engine, and the API's SDO durations.
#[derive(Debug, Clone)]
pub(crate) struct Sources {
    /// The engine.
    pub master: Arc<Master>,
    /// SDO transfer durations through the API.
    pub sdo_latency: Arc<Histogram>,
}

/// The label of each phase (the API's `EnginePhase` names, so dashboards
/// read the same words as clients).
const PHASES: [(Phase, &str); 6] = [
    (Phase::Starting, "ENGINE_PHASE_STARTING"),
    (Phase::BringUp, "ENGINE_PHASE_BRINGING_UP"),
    (Phase::Running, "ENGINE_PHASE_RUNNING"),
    (Phase::Recovering, "ENGINE_PHASE_RECOVERING"),
    (Phase::Stopping, "ENGINE_PHASE_STOPPING"),
    (Phase::Stopped, "ENGINE_PHASE_STOPPED"),
];

/// A state as the gauges show it: the AL state code, 0 when unknown.
fn state_value(s: EcatState) -> u8 {
    match s {
        EcatState::Other(_) => 0,
        s => s.to_u8(),
    }
}

/// A slave's state and AL status code, read from the chip.
async fn slave_state(master: &Master, slave: u8) -> Option<(EcatState, u16)> {
    // No client's: a scrape's requests share the line of work no client
    // owns, each with the master's default time.
    let call = crate::master::Call::anonymous(None);
    let state = master.slave_number(slave, SlaveInfoCode::State, call).await.ok()?;
    let code = master.slave_number(slave, SlaveInfoCode::AlStatus, call).await.ok()?;
    Some((EcatState::from_u8(state as u8), code as u16))
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
pub(crate) async fn render(sources: &Sources) -> String {
    let master = &sources.master;
    let mut out = String::with_capacity(8192);
    let s = master.status();
    let verdict = master.verdict(&s);
    // What runs: the daemon's version and the chip's firmware (0 before
    // the first bring-up read it), one sample of 1 as Prometheus' *_info.
    let _ = writeln!(
        out,
        "# HELP ecmxf_build_info The daemon's version and the chip's firmware.\n# TYPE ecmxf_build_info gauge\n\
         ecmxf_build_info{{version=\"{}\",firmware=\"{:#04x}\"}} 1",
        env!("CARGO_PKG_VERSION"),
        master.layout().firmware
    );
    let _ = writeln!(out, "# HELP ecmxf_engine_phase The engine's phase (1 for the current one).");
    let _ = writeln!(out, "# TYPE ecmxf_engine_phase gauge");
    for (p, name) in PHASES {
        let _ = writeln!(out, "ecmxf_engine_phase{{phase=\"{name}\"}} {}", u8::from(p == s.phase));
    }
    // (name, type, help, value): one sample each.
    let single: [(&str, &str, &str, String); 27] = [
        (
            "ecmxf_network_state",
            "gauge",
            "Network AL state (1 INIT, 2 PREOP, 3 BOOT, 4 SAFEOP, 8 OP, 16 ERROR).",
            state_value(s.ecat_state).to_string(),
        ),
        ("ecmxf_exchanges_total", "counter", "SPI packets exchanged with the chip.", s.exchanges.to_string()),
        (
            "ecmxf_crc_errors_total",
            "counter",
            "SPI packets the chip received with bad check words (accumulated from its 8-bit counter).",
            s.crc_errors.to_string(),
        ),
        (
            "ecmxf_wkc_errors_total",
            "counter",
            "Cycles with a wrong working counter (accumulated from the chip's 8-bit counter).",
            s.wkc_errors.to_string(),
        ),
        (
            "ecmxf_process_data_flowing",
            "gauge",
            "1 while the engine runs in the target state and input frames arrive within the limit.",
            u8::from(verdict.flowing()).to_string(),
        ),
        (
            "ecmxf_input_age_seconds",
            "gauge",
            "Age of the newest input frame (0 while no cyclic exchange runs).",
            verdict.input_age.map_or(0.0, |(a, _)| a.as_secs_f64()).to_string(),
        ),
        (
            "ecmxf_ring_overflows_total",
            "counter",
            "Input frames dropped before any subscriber saw them (the distributor fell behind).",
            s.ring_overflows.to_string(),
        ),
        (
            "ecmxf_corrupt_answers_total",
            "counter",
            "Answers that failed validation (check word, framing).",
            s.corrupt.to_string(),
        ),
        (
            "ecmxf_not_ready_answers_total",
            "counter",
            "Answers the chip marked not ready (busy).",
            s.not_ready.to_string(),
        ),
        ("ecmxf_transactions_total", "counter", "Blocking-command transactions finished.", s.transactions.to_string()),
        ("ecmxf_input_frames_total", "counter", "Input frames received from the TxFIFO.", s.input_frames.to_string()),
        ("ecmxf_output_frames_total", "counter", "Output frames pushed into the RxFIFO.", s.output_frames.to_string()),
        (
            "ecmxf_input_batches_lost_total",
            "counter",
            "FIFO answers lost for good with their input frames; stays 0 (a corrupt FIFO answer is asked again).",
            s.input_batches_lost.to_string(),
        ),
        (
            "ecmxf_fifo_alarms_total",
            "counter",
            "Times the RxFIFO ran dry (slaves got repeated outputs); the API's fifo_alarms.",
            s.fifo_alarms.to_string(),
        ),
        (
            "ecmxf_fifo_underruns_total",
            "counter",
            "Old name of ecmxf_fifo_alarms_total (the same count), kept for existing dashboards.",
            s.fifo_alarms.to_string(),
        ),
        ("ecmxf_recoveries_total", "counter", "Recoveries started.", s.recoveries.to_string()),
        (
            "ecmxf_max_fifo_gap_seconds",
            "gauge",
            "Longest gap between FIFO pushes seen.",
            (s.max_fifo_gap_us as f64 / 1e6).to_string(),
        ),
        ("ecmxf_rx_fifo_frames", "gauge", "Output frames waiting in the chip's RxFIFO.", s.rx_fifo.to_string()),
        ("ecmxf_tx_fifo_frames", "gauge", "Input frames waiting in the chip's TxFIFO.", s.tx_fifo.to_string()),
        ("ecmxf_rx_fifo_depth_frames", "gauge", "RxFIFO depth in force.", master.layout().fifo_rx_depth.to_string()),
        (
            "ecmxf_dc_stable",
            "gauge",
            "1 while the chip reports DC stable.",
            u8::from(s.status_flags().contains(crate::master::diagnostics::StatusFlags::DC_STABLE)).to_string(),
        ),
        (
            "ecmxf_link_pin",
            "gauge",
            "The chip's LINK pin level.",
            u8::from(s.error_flags().contains(crate::master::diagnostics::ErrorFlags::LINK_PIN)).to_string(),
        ),
        ("ecmxf_output_writers", "gauge", "Clients holding output leases.", master.output_writers().to_string()),
        (
            "ecmxf_output_latency_budget_seconds",
            "gauge",
            "The output latency budget in force (cycle.output_latency_us; 0: none).",
            (f64::from(master.output_latency_budget_us().unwrap_or(0)) / 1e6).to_string(),
        ),
        (
            "ecmxf_output_latency_misses_total",
            "counter",
            "Client output writes that reached the wire later than the budget.",
            s.output_latency_misses.to_string(),
        ),
        (
            "ecmxf_inputs_dropped_by_chip_total",
            "counter",
            "Input frames the chip dropped with its TxFIFO full (the host was away too long).",
            s.inputs_dropped_by_chip.to_string(),
        ),
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
    let g = master.gateway_counters();
    for (name, help, counter) in [
        ("ecmxf_gateway_requests_total", "Mailbox gateway (ETG.8200) requests taken.", &g.requests),
        ("ecmxf_gateway_answers_total", "Mailbox gateway answers sent.", &g.answered),
        ("ecmxf_gateway_errors_total", "Mailbox gateway answers that were mailbox errors.", &g.errors),
        ("ecmxf_gateway_malformed_total", "Mailbox gateway datagrams that were no mailbox request.", &g.malformed),
        (
            "ecmxf_gateway_refused_total",
            "Mailbox gateway datagrams from clients gateway.allow does not name.",
            &g.refused,
        ),
    ] {
        metric(&mut out, name, "counter", help, counter.load(std::sync::atomic::Ordering::Relaxed));
    }
    let s = master.sparkplug_state();
    if s.enabled.load(std::sync::atomic::Ordering::Relaxed) {
        use std::sync::atomic::Ordering::Relaxed;
        metric(
            &mut out,
            "ecmxf_sparkplug_connected",
            "gauge",
            "1 while the Sparkplug node is connected and born.",
            s.connected.load(Relaxed),
        );
        for (name, help, counter) in [
            ("ecmxf_sparkplug_published_total", "Sparkplug messages handed to the MQTT client.", &s.published),
            (
                "ecmxf_sparkplug_dropped_total",
                "Sparkplug messages dropped: the MQTT client's queue was full.",
                &s.dropped,
            ),
            ("ecmxf_sparkplug_commands_total", "Sparkplug NCMD/DCMD commands applied.", &s.commands),
            (
                "ecmxf_sparkplug_refused_total",
                "Sparkplug commands refused (disabled, role, metric, value).",
                &s.refused,
            ),
            ("ecmxf_sparkplug_connects_total", "Sparkplug connections made to a broker.", &s.connects),
        ] {
            metric(&mut out, name, "counter", help, counter.load(Relaxed));
        }
    }
    let o = master.opcua_state();
    if o.enabled.load(std::sync::atomic::Ordering::Relaxed) {
        use std::sync::atomic::Ordering::Relaxed;
        for (name, help, gauge) in [
            ("ecmxf_opcua_sessions", "OPC UA sessions open.", &o.sessions),
            ("ecmxf_opcua_monitored_items", "OPC UA monitored items on the daemon's variables.", &o.monitored_items),
        ] {
            metric(&mut out, name, "gauge", help, gauge.load(Relaxed));
        }
        for (name, help, counter) in [
            ("ecmxf_opcua_samples_total", "Values sampled for OPC UA monitored items.", &o.samples),
            ("ecmxf_opcua_writes_total", "OPC UA output writes done.", &o.writes),
            ("ecmxf_opcua_calls_total", "OPC UA method calls done.", &o.calls),
            ("ecmxf_opcua_refused_total", "OPC UA writes and calls refused (role, lease, value).", &o.refused),
        ] {
            metric(&mut out, name, "counter", help, counter.load(Relaxed));
        }
    }
    if let Some(l) = master.output_latency() {
        let name = "ecmxf_output_latency_seconds";
        let _ = writeln!(
            out,
            "# HELP {name} Write-to-wire latency of client output writes over the latest {} writes.\n# TYPE {name} summary",
            l.samples
        );
        let _ = writeln!(out, "{name}{{quantile=\"0.5\"}} {}", f64::from(l.p50_us) / 1e6);
        let _ = writeln!(out, "{name}{{quantile=\"0.99\"}} {}", f64::from(l.p99_us) / 1e6);
    }
    sources.sdo_latency.render(&mut out, "ecmxf_sdo_duration_seconds", "SDO upload/download duration through the API.");
    let slaves = master.layout().slaves;
    let read_all = async {
        let mut states = Vec::with_capacity(slaves.len());
        for (i, _) in slaves.iter().enumerate() {
            states.push(slave_state(master, i as u8).await?);
        }
        Some(states)
    };
    match tokio::time::timeout(Duration::from_secs(3), read_all).await {
        Ok(Some(states)) => {
            metric(&mut out, "ecmxf_slaves", "gauge", "Slaves found on the ring.", slaves.len());
            let _ =
                writeln!(out, "# HELP ecmxf_slave_state A slave's AL state (1 INIT, 2 PREOP, 3 BOOT, 4 SAFEOP, 8 OP).");
            let _ = writeln!(out, "# TYPE ecmxf_slave_state gauge");
            for (i, (sl, (state, _))) in slaves.iter().zip(&states).enumerate() {
                let _ = writeln!(
                    out,
                    "ecmxf_slave_state{{position=\"{i}\",name=\"{}\"}} {}",
                    label(&sl.name),
                    state_value(*state)
                );
            }
            let _ = writeln!(out, "# HELP ecmxf_slave_al_status_code A slave's AL status code (0: no error).");
            let _ = writeln!(out, "# TYPE ecmxf_slave_al_status_code gauge");
            for (i, (sl, (_, code))) in slaves.iter().zip(&states).enumerate() {
                let _ =
                    writeln!(out, "ecmxf_slave_al_status_code{{position=\"{i}\",name=\"{}\"}} {code}", label(&sl.name));
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
pub(crate) async fn bind(addr: SocketAddr) -> std::io::Result<TcpListener> {
    let l = TcpListener::bind(addr).await?;
    if let Ok(a) = l.local_addr() {
        tracing::info!(address = %a, "metrics listening on http://{a}/metrics");
    }
    Ok(l)
}

/// Connections the endpoint holds at once: a scraper needs one, a few
/// people with curl a few more.
pub(crate) const MAX_CONNECTIONS: usize = 32;

/// Connections one peer address holds at once.
const MAX_PER_PEER: usize = 8;

/// Time a client has to send its request head.
const HEAD_DEADLINE: Duration = Duration::from_secs(5);

/// Serves `/metrics` until `shutdown` changes. Connections are admitted
/// as the API's are (daemon/src/admission.rs), with caps of their own.
pub(crate) async fn serve(sources: Sources, listener: TcpListener, mut shutdown: watch::Receiver<()>) {
    use crate::admission::{Cap, Gate};
    let gate = Gate::new(
        "metrics",
        Cap { limit: MAX_CONNECTIONS, key: "the metrics endpoint's connection cap" },
        Some(Cap { limit: MAX_PER_PEER, key: "the metrics endpoint's per-peer cap" }),
    );
    loop {
        tokio::select! {
            _ = shutdown.changed() => return,
            accepted = listener.accept() => {
                let (stream, peer) = match accepted {
                    Ok(c) => c,
                    Err(e) => {
                        gate.accept_failed(&e).await;
                        continue;
                    }
                };
                let Ok(ticket) = gate.admit(Some(peer.ip())) else { continue };
                let sources = sources.clone();
                tokio::spawn(async move {
                    let _ticket = ticket;
                    // A client that never finishes its request is dropped.
                    let _ = tokio::time::timeout(Duration::from_secs(10), answer(&sources, stream)).await;
                });
            }
        }
    }
}

/// Reads one request head and answers it (then closes: no keep-alive).
async fn answer(sources: &Sources, mut stream: TcpStream) -> std::io::Result<()> {
    let mut head = Vec::with_capacity(1024);
    let mut buf = [0u8; 1024];
    let by = tokio::time::Instant::now() + HEAD_DEADLINE;
    while !head.windows(4).any(|w| w == b"\r\n\r\n") {
        let n = match tokio::time::timeout_at(by, stream.read(&mut buf)).await {
            Ok(n) => n?,
            Err(_) => return Ok(()),
        };
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
            let body = render(sources).await;
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
    fn label_values_are_escaped() {
        assert_eq!(label("a\"b\\c\nd"), "a\\\"b\\\\c\\nd");
    }
}
