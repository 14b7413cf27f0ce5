//! `master`: the chip and the engine (Master.GetInfo + GetStatus).

use ecmxf_proto::v1 as pb;
use schemars::JsonSchema;
use serde::Serialize;

use crate::connect::Api;
use crate::error::CliError;
use crate::output::{Fields, Report};
use crate::values::{phase_name, state_name};

/// `ecmxfctl master --json`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct MasterReport {
    /// ecmxfd's version.
    pub daemon_version: String,
    /// Chip firmware version (FW_VERSION_GET).
    pub firmware_version: u32,
    /// SPI packet size in bytes (data section + 32).
    pub packet_bytes: u32,
    /// SPI check word: FIXED, CRC8, CRC16, CRC32.
    pub check_type: String,
    /// DC SYNC0 cycle, microseconds.
    pub sync0_us: u32,
    /// RxFIFO depth and feeder marks, frames.
    pub fifo_rx_depth: u32,
    pub fifo_low: u32,
    pub fifo_high: u32,
    /// Process image sizes, bytes.
    pub output_image_bytes: u32,
    pub input_image_bytes: u32,
    pub slave_count: u32,
    /// The state bring-up drives the network to.
    pub target_state: String,
    /// Engine phase: STARTING, BRINGING_UP, RUNNING, RECOVERING, STOPPING, STOPPED.
    pub phase: String,
    /// Network state: INIT, PREOP, BOOT, SAFEOP, OP, ERROR, UNKNOWN.
    pub state: String,
    pub link_pin: bool,
    pub dc_stable: bool,
    pub rx_fifo_level: u32,
    pub tx_fifo_level: u32,
    /// Clients holding output leases.
    pub output_writers: u32,
    pub config_generation: u64,
    /// Why bring-up last failed or recovery last started ("" if never).
    pub last_error: String,
    /// Whether process data flows (the newest input frame is younger than
    /// flow_limit_us); false while no cyclic exchange runs.
    pub process_data_flowing: bool,
    /// Age of the newest input frame, microseconds.
    pub input_age_us: u64,
    /// Age beyond which process data counts as stalled, microseconds (0:
    /// no cyclic exchange).
    pub flow_limit_us: u64,
    /// The daemon's health verdict in words.
    pub health: String,
    /// The output latency budget (cycle.output_latency_us), microseconds;
    /// 0: none.
    pub output_latency_budget_us: u32,
    /// Write-to-wire latency of client output writes over the latest 512,
    /// microseconds (0 before the first write).
    pub output_latency_p50_us: u64,
    pub output_latency_p99_us: u64,
    pub counters: CountersReport,
    /// The MQTT Sparkplug B edge node; absent while none is configured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sparkplug: Option<SparkplugReport>,
}

/// The Sparkplug B edge node (see `SparkplugStatus` in proto/ecmxf/v1/master.proto).
#[derive(Debug, Serialize, JsonSchema)]
pub struct SparkplugReport {
    /// Connected to a broker, births published.
    pub connected: bool,
    /// The broker of the current or last connection ("" before the first).
    pub broker: String,
    /// The current or last connection's bdSeq.
    pub bd_seq: u64,
    /// Messages handed to the MQTT client.
    pub published: u64,
    /// Messages dropped: the client's queue was full.
    pub dropped: u64,
    /// NCMD/DCMD commands applied.
    pub commands: u64,
    /// Commands refused.
    pub refused: u64,
    /// Connections made.
    pub connects: u64,
}

impl From<pb::SparkplugStatus> for SparkplugReport {
    fn from(s: pb::SparkplugStatus) -> Self {
        Self {
            connected: s.connected,
            broker: s.broker,
            bd_seq: s.bd_seq,
            published: s.published,
            dropped: s.dropped,
            commands: s.commands,
            refused: s.refused,
            connects: s.connects,
        }
    }
}

/// Engine and chip counters (see `Counters` in proto/ecmxf/v1/master.proto).
#[derive(Debug, Serialize, JsonSchema, Default)]
pub struct CountersReport {
    pub exchanges: u64,
    pub transactions: u64,
    pub input_frames: u64,
    pub output_frames: u64,
    /// The chip's CRC and WKC error counts since the daemon started
    /// (totals accumulated from its 8-bit counters: they never wrap).
    pub crc_errors: u64,
    pub wkc_errors: u64,
    pub corrupt_answers: u64,
    pub not_ready_answers: u64,
    pub input_batches_lost: u64,
    /// Input frames dropped before any subscriber saw them.
    pub ring_overflows: u64,
    pub fifo_alarms: u64,
    pub recoveries: u64,
    pub max_fifo_gap_us: u64,
    /// Client writes that reached the wire later than the budget.
    pub output_latency_misses: u64,
    /// Input frames the chip dropped (TxFIFO full).
    pub inputs_dropped_by_chip: u64,
}

impl From<Option<pb::Counters>> for CountersReport {
    fn from(c: Option<pb::Counters>) -> Self {
        let c = c.unwrap_or_default();
        Self {
            exchanges: c.exchanges,
            transactions: c.transactions,
            input_frames: c.input_frames,
            output_frames: c.output_frames,
            crc_errors: c.crc_errors,
            wkc_errors: c.wkc_errors,
            corrupt_answers: c.corrupt_answers,
            not_ready_answers: c.not_ready_answers,
            input_batches_lost: c.input_batches_lost,
            fifo_alarms: c.fifo_alarms,
            recoveries: c.recoveries,
            max_fifo_gap_us: c.max_fifo_gap_us,
            ring_overflows: c.ring_overflows,
            output_latency_misses: c.output_latency_misses,
            inputs_dropped_by_chip: c.inputs_dropped_by_chip,
        }
    }
}

impl CountersReport {
    /// The counters as aligned lines.
    pub fn add_to(&self, f: &mut Fields) {
        f.add("Exchanges", self.exchanges)
            .add("Transactions", self.transactions)
            .add("Input frames", self.input_frames)
            .add("Output frames", self.output_frames)
            .add("CRC errors", self.crc_errors)
            .add("WKC errors", self.wkc_errors)
            .add("Corrupt answers", self.corrupt_answers)
            .add("Not-ready answers", self.not_ready_answers)
            .add("Input batches lost", self.input_batches_lost)
            .add("Ring overflows", self.ring_overflows)
            .add("Inputs dropped by the chip", self.inputs_dropped_by_chip)
            .add("FIFO alarms", self.fifo_alarms)
            .add("Recoveries", self.recoveries)
            .add("Max FIFO gap", format!("{} us", self.max_fifo_gap_us))
            .add("Late writes", self.output_latency_misses);
    }
}

fn check_name(v: i32) -> &'static str {
    crate::values::enum_name(v, pb::CheckType::as_str_name, "CHECK_TYPE_")
}

impl Report for MasterReport {
    fn text(&self) -> String {
        let mut f = Fields::default();
        f.add("Daemon", format!("ecmxfd {}", self.daemon_version))
            .add("Firmware", format!("{:#04x}", self.firmware_version))
            .add("SPI packet", format!("{} bytes, {}", self.packet_bytes, self.check_type))
            .add("Cycle", format!("{} us", self.sync0_us))
            .add("RxFIFO", format!("depth {}, marks {}..{}", self.fifo_rx_depth, self.fifo_low, self.fifo_high))
            .add("Image", format!("{} bytes out, {} bytes in", self.output_image_bytes, self.input_image_bytes))
            .add("Slaves", self.slave_count)
            .add("Phase", &self.phase)
            .add("State", format!("{} (target {})", self.state, self.target_state))
            .add("Link pin", if self.link_pin { "up" } else { "down" })
            .add("DC", if self.dc_stable { "stable" } else { "not stable" })
            .add("FIFO levels", format!("rx {}, tx {}", self.rx_fifo_level, self.tx_fifo_level))
            .add("Output writers", self.output_writers)
            .add("Config generation", self.config_generation)
            .add("Health", &self.health);
        if self.flow_limit_us > 0 {
            f.add(
                "Process data",
                format!(
                    "{}: newest input {:.1} ms old (limit {:.1} ms)",
                    if self.process_data_flowing { "flowing" } else { "NOT FLOWING" },
                    self.input_age_us as f64 / 1000.0,
                    self.flow_limit_us as f64 / 1000.0
                ),
            );
        }
        let budget = match self.output_latency_budget_us {
            0 => "no budget".to_string(),
            b => format!("budget {:.1} ms", f64::from(b) / 1000.0),
        };
        let latency = if self.output_latency_p50_us == 0 {
            format!("{budget}, no write yet")
        } else {
            format!(
                "p50 {:.2} ms, p99 {:.2} ms ({budget})",
                self.output_latency_p50_us as f64 / 1000.0,
                self.output_latency_p99_us as f64 / 1000.0
            )
        };
        f.add("Output latency", latency);
        if !self.last_error.is_empty() {
            f.add("Last error", &self.last_error);
        }
        if let Some(s) = &self.sparkplug {
            let link = match (s.connected, s.broker.as_str()) {
                (true, b) => format!("connected to {b} (bdSeq {})", s.bd_seq),
                (false, "") => "not connected yet".to_string(),
                (false, b) => format!("NOT CONNECTED (last broker {b})"),
            };
            f.add("Sparkplug", link).add(
                "Sparkplug messages",
                format!(
                    "{} published, {} dropped; commands {} applied, {} refused; {} connects",
                    s.published, s.dropped, s.commands, s.refused, s.connects
                ),
            );
        }
        self.counters.add_to(&mut f);
        f.to_string()
    }
}

/// Fetches both halves.
pub async fn fetch(api: &Api) -> Result<MasterReport, CliError> {
    let mut m = api.master();
    let i = m.get_info(api.req(pb::GetInfoRequest {})).await.map_err(CliError::rpc("master info"))?.into_inner();
    let s = m.get_status(api.req(pb::GetStatusRequest {})).await.map_err(CliError::rpc("master status"))?.into_inner();
    Ok(MasterReport {
        daemon_version: i.daemon_version,
        firmware_version: i.firmware_version,
        packet_bytes: i.packet_bytes,
        check_type: check_name(i.check_type).into(),
        sync0_us: i.sync0_us,
        fifo_rx_depth: i.fifo_rx_depth,
        fifo_low: i.fifo_low,
        fifo_high: i.fifo_high,
        output_image_bytes: i.output_image_bytes,
        input_image_bytes: i.input_image_bytes,
        slave_count: i.slave_count,
        target_state: state_name(i.target_state).into(),
        phase: phase_name(s.phase).into(),
        state: state_name(s.ecat_state).into(),
        link_pin: s.link_pin,
        dc_stable: s.dc_stable,
        rx_fifo_level: s.rx_fifo_level,
        tx_fifo_level: s.tx_fifo_level,
        output_writers: s.output_writers,
        config_generation: s.config_generation,
        last_error: s.last_error,
        process_data_flowing: s.process_data_flowing,
        input_age_us: s.input_age_us,
        flow_limit_us: s.flow_limit_us,
        health: s.health,
        output_latency_budget_us: s.output_latency_budget_us,
        output_latency_p50_us: s.output_latency_p50_us,
        output_latency_p99_us: s.output_latency_p99_us,
        counters: s.counters.into(),
        sparkplug: s.sparkplug.map(Into::into),
    })
}
