//! The ECM-XF chip: SPI byte stream, command execution, the blocking slot,
//! the PDO FIFOs and cyclic exchange, interrupt lines and peripherals.
//!
//! Everything happens at a time the caller passes in (nanoseconds since
//! power-up), so a test drives the chip deterministically; a real-time
//! wrapper passes the wall clock.

mod blocking;
mod cycle;
mod exec;
pub mod fifo;
pub mod periph;
pub mod spi;

use ecmxf_wire::flags::{ErrorFlags, InterruptFlags, StatusFlags};
use ecmxf_wire::framing::DATA_DEFAULT;
use ecmxf_wire::payload::cia402::{Cia402Control, Cia402State};
use ecmxf_wire::payload::ecat_init::DcTiming;
use ecmxf_wire::payload::emergency::EmergencyRecord;
use ecmxf_wire::payload::interrupt::IntConfig;
use ecmxf_wire::payload::pdo::PdoConfig;
use ecmxf_wire::payload::raw::DatagramHead;
use ecmxf_wire::{CheckType, CommandCode, EcatState, EcmStatus, ResponseHeader, encode_response};

use crate::net::Network;
pub use blocking::{BlockingOp, Timing, result_code};
use fifo::Fifos;
use periph::Peripherals;
use spi::{Boundary, SpiPort};

/// Tunable behaviour of the simulated chip.
#[derive(Clone, Debug)]
pub struct ChipConfig {
    /// Time the chip is busy after each packet it takes (INT0 inactive).
    pub processing_ns: u64,
    /// Firmware version reported by FW_VERSION_GET.
    pub firmware_version: u8,
    /// How long each blocking operation takes.
    pub timing: Timing,
    /// Time a warm reset takes before the chip answers again.
    pub warm_reset_ns: u64,
    /// Cycle used when ECAT_INIT gives no SYNC0 cycle (DC off).
    pub free_run_cycle_ns: u64,
    /// SPI clock the host runs, Hz: it times the bytes of a transfer.
    pub spi_hz: u64,
    /// Refuse (error bit7) a command whose declared data length differs
    /// from the length v049 gives its layout, instead of taking the layout
    /// and counting it: the daemon's tests turn it on.
    pub strict_lengths: bool,
}

impl Default for ChipConfig {
    fn default() -> Self {
        Self {
            processing_ns: 30_000,
            firmware_version: 0x24,
            timing: Timing::default(),
            warm_reset_ns: 50_000_000,
            free_run_cycle_ns: 1_000_000,
            spi_hz: 20_000_000,
            strict_lengths: strict_lengths_from_env(),
        }
    }
}

/// Environment variable that makes every simulated chip strict about data
/// lengths ([`ChipConfig::strict_lengths`]) when set to `1`; the
/// workspace's `.cargo/config.toml` sets it for everything cargo runs, so
/// the daemon's tests hold ecmxfd's packets to v049.
pub const STRICT_LENGTHS_ENV: &str = "ECMXF_SIM_STRICT_LENGTHS";

fn strict_lengths_from_env() -> bool {
    std::env::var(STRICT_LENGTHS_ENV).is_ok_and(|v| v == "1")
}

/// One axis of the chip's internal CiA402 helper (commands 26..30).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HelperAxis {
    /// Slave position.
    pub slave: u8,
    /// Controlword byte offset in the slave's outputs.
    pub controlword_offset: u8,
    /// Statusword byte offset in the slave's inputs.
    pub statusword_offset: u8,
    /// Control byte.
    pub control: Cia402Control,
    /// State the helper drives the axis towards.
    pub target: Cia402State,
    /// Whether the helper wrote controlword bit 7 in the last cycle (fault
    /// resets need rising edges; the host's frames carry bit 7 clear, so the
    /// helper's own last value is what the edge is made from).
    pub reset_bit: bool,
}

/// Where a slave's images sit in the FIFO frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Slot {
    /// Slave position.
    pub slave: usize,
    /// Offset in the output frame.
    pub rx_offset: usize,
    /// Output bytes.
    pub rx_len: usize,
    /// Offset in the input frame.
    pub tx_offset: usize,
    /// Input bytes.
    pub tx_len: usize,
}

/// Results of blocking operations, fetched with the GET commands: each
/// kind's error code (`blocking::result_code`) and data, reset when a
/// request of that kind starts.
#[derive(Clone, Debug)]
pub struct Results {
    /// Error code of the last SDO request (SDO_GET's return value).
    pub sdo: u8,
    /// Data of the last SDO read.
    pub sdo_data: Vec<u8>,
    /// Abort code of the last failed SDO.
    pub sdo_abort: u32,
    /// Error code and data of the last EEPROM operation.
    pub eeprom: (u8, Vec<u8>),
    /// The last PDO configuration read.
    pub pdo_config: PdoConfig,
    /// The last raw datagram's answer; `None` until one succeeds.
    pub raw: Option<(DatagramHead, u16, Vec<u8>)>,
    /// Error code of the last raw datagram (RAW_ECAT_FUNC_GET's return
    /// value when there is no answer).
    pub raw_error: u8,
    /// Error code of the last FoE request (FOE_FUNC_GET's return value).
    pub foe: u8,
    /// Bytes of the last FoE flash read.
    pub foe_read: Vec<u8>,
}

impl Default for Results {
    fn default() -> Self {
        use blocking::result_code::RESULT_NOT_DONE;
        Self {
            sdo: RESULT_NOT_DONE,
            sdo_data: Vec::new(),
            sdo_abort: 0,
            eeprom: (RESULT_NOT_DONE, Vec::new()),
            pdo_config: PdoConfig::default(),
            raw: None,
            raw_error: RESULT_NOT_DONE,
            foe: RESULT_NOT_DONE,
            foe_read: Vec::new(),
        }
    }
}

impl Results {
    /// Forgets the result `op` will replace, so a GET while it runs, or
    /// after it fails, never answers with an earlier request's data.
    fn forget(&mut self, op: &BlockingOp) {
        use blocking::result_code::RESULT_NOT_DONE;
        match op {
            BlockingOp::Sdo { .. } | BlockingOp::TimedOut { sdo: true } => {
                self.sdo = RESULT_NOT_DONE;
                self.sdo_data.clear();
            }
            BlockingOp::Eeprom(_) | BlockingOp::TimedOut { sdo: false } => self.eeprom = (RESULT_NOT_DONE, Vec::new()),
            BlockingOp::Raw { .. } => {
                self.raw = None;
                self.raw_error = RESULT_NOT_DONE;
            }
            BlockingOp::Foe(_) => {
                self.foe = RESULT_NOT_DONE;
                self.foe_read.clear();
            }
            _ => {}
        }
    }
}

/// The master side of the network as the chip runs it.
#[derive(Clone, Debug, Default)]
pub struct Master {
    /// ECAT_INIT has completed.
    pub inited: bool,
    /// DC settings from ECAT_INIT.
    pub dc: DcTiming,
    /// The DC cycle.
    pub cycle_ns: u64,
    /// When the next cycle runs.
    pub next_cycle_ns: u64,
    /// When DC becomes stable (after INIT_DC).
    pub dc_stable_at: Option<u64>,
    /// Frame layout.
    pub slots: Vec<Slot>,
    /// Output frame size.
    pub rx_size: usize,
    /// Input frame size.
    pub tx_size: usize,
    /// The output image sent every cycle.
    pub outputs: Vec<u8>,
    /// The latest input image.
    pub inputs: Vec<u8>,
    /// States as the chip last read them (refreshed by 57, 41, 12 and
    /// control bit1): AL status register values, 0x10 for a slave that no
    /// longer answers.
    pub cached_states: Vec<u8>,
    /// LRW enabled (142).
    pub lrw: bool,
    /// Working counter of the last cycle.
    pub wkc: u16,
    /// Consecutive cycles with a wrong working counter.
    pub wkc_streak: u8,
    /// Limit of consecutive WKC errors (255 = never).
    pub wkc_limit: u8,
    /// Exchange stopped by the WKC limit.
    pub exchange_stopped: bool,
    /// Per-slave polling of receive mailboxes (144 param 1).
    pub mailbox_polling: Vec<u8>,
    /// Receive-mailbox bytes fetched by 143 param 0.
    pub mailbox: Vec<u8>,
    /// Slaves configured by the last ECAT_INIT (the reachable ones then).
    pub configured: usize,
    /// Emergencies not yet read through RECV_MAILBOX, by slave.
    pub unread_mailbox: Vec<(u8, crate::net::slave::Emergency)>,
}

/// Fault injection.
#[derive(Clone, Debug, Default)]
pub struct Faults {
    /// Probability that a byte host->chip has one bit flipped.
    pub flip_mosi: f64,
    /// Probability that a byte chip->host has one bit flipped.
    pub flip_miso: f64,
    /// INT0 held at this level regardless of readiness.
    pub int0_stuck: Option<bool>,
    /// The TxFIFO stops taking input frames while everything else goes on
    /// (answers, state, outputs): the "OP on paper, nothing flows" fault a
    /// host must notice by itself.
    pub tx_stalled: bool,
    /// The next this many DC cycles find the RxFIFO empty (its frames are
    /// discarded): the RxFIFO runs dry as when the host falls behind,
    /// while the host itself goes on as before.
    pub rx_starved_cycles: u32,
    rng: u64,
}

impl Faults {
    fn next(&mut self) -> f64 {
        // xorshift64*: deterministic, seedable.
        if self.rng == 0 {
            self.rng = 0x9E37_79B9_7F4A_7C15;
        }
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        (self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn maybe_flip(&mut self, b: u8, rate: f64) -> u8 {
        if rate > 0.0 && self.next() < rate { b ^ 1 << ((self.next() * 8.0) as u8 & 7) } else { b }
    }

    /// Seeds the fault generator.
    pub fn seed(&mut self, seed: u64) {
        self.rng = seed;
    }
}

/// Counters the chip keeps that tests and the socket's status can read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// Packets taken.
    pub packets: u64,
    /// Packets lost because the chip was not ready.
    pub not_ready: u64,
    /// Packets refused for a bad check word.
    pub crc_failures: u64,
    /// Commands executed (dedup repeats not counted).
    pub executed: u64,
    /// Packets taken that carried a FIFO call (PDO_DATA_FIFO_OP), repeats
    /// included: what the cyclic data costs the link, apart from the rest.
    pub fifo_packets: u64,
    /// DC cycles run.
    pub cycles: u64,
    /// Commands whose declared data length differed from their layout's
    /// (executed anyway unless [`ChipConfig::strict_lengths`]).
    pub length_mismatches: u64,
}

/// The simulated chip.
#[derive(Clone, Debug)]
pub struct Chip {
    /// Configuration.
    pub config: ChipConfig,
    /// The network.
    pub net: Network,
    /// SPI port.
    pub spi: SpiPort,
    /// Check type in force.
    pub check: CheckType,
    /// Time up to which the chip has run.
    pub now_ns: u64,
    busy_until_ns: u64,
    /// SPI CRC error counter (header 0x04).
    pub crc_errors: u8,
    /// WKC error counter (header 0x05).
    pub wkc_errors: u8,
    /// Error byte.
    pub errors: ErrorFlags,
    /// Interrupt flags.
    pub int_flags: InterruptFlags,
    /// INT polarity and masks.
    pub int_config: IntConfig,
    last_key: Option<(u8, u8)>,
    last_answer: Option<(ResponseHeader, Vec<u8>)>,
    fifo_history: [(u8, u8); 3],
    /// The blocking slot.
    pub pending: Option<(BlockingOp, u64)>,
    /// Blocking results.
    pub results: Results,
    /// Master state.
    pub master: Master,
    /// FIFOs.
    pub fifo: Fifos,
    /// CiA402 helper axes.
    pub helper: Vec<Option<HelperAxis>>,
    /// Last 8 emergencies, newest last, with their running numbers.
    pub emergencies: Vec<(u16, EmergencyRecord)>,
    emergency_count: u16,
    /// Peripherals.
    pub periph: Peripherals,
    /// PHY registers (MDIO).
    pub phy: [u16; 32],
    /// FoE staging flash.
    pub flash: Vec<u8>,
    /// Fault injection.
    pub faults: Faults,
    /// Counters.
    pub stats: Stats,
    /// Process-data length overrides (82): (slave, outputs, inputs).
    pub direct_assign: Vec<(u8, bool, Option<u16>, Option<u16>)>,
}

impl Chip {
    /// A chip at power-up (time 0) in front of `net`.
    pub fn new(net: Network, config: ChipConfig) -> Self {
        let mut chip = Self {
            config,
            net,
            spi: SpiPort::new(DATA_DEFAULT, Vec::new()),
            check: CheckType::Fixed,
            now_ns: 0,
            busy_until_ns: 0,
            crc_errors: 0,
            wkc_errors: 0,
            errors: ErrorFlags::empty(),
            int_flags: InterruptFlags::empty(),
            int_config: IntConfig::default(),
            last_key: None,
            last_answer: None,
            fifo_history: [(0, 0); 3],
            pending: None,
            results: Results::default(),
            master: Master { lrw: true, wkc_limit: 255, ..Master::default() },
            fifo: Fifos::default(),
            helper: Vec::new(),
            emergencies: Vec::new(),
            emergency_count: 0,
            periph: Peripherals::default(),
            phy: default_phy(),
            flash: vec![0xFF; 0x40000],
            faults: Faults::default(),
            stats: Stats::default(),
            direct_assign: Vec::new(),
        };
        chip.power_up_port();
        chip
    }

    fn power_up_port(&mut self) {
        let mut status = self.status();
        status.flags |= StatusFlags::NOP;
        let header = ResponseHeader { status, ..self.snapshot(0, CommandCode::InfoUpdate, 0, 0) };
        let nop = self.encode(&header, &[]);
        self.spi.reset(DATA_DEFAULT, nop);
    }

    /// Whether the chip takes a packet starting at `now_ns`.
    pub fn ready(&self, now_ns: u64) -> bool {
        now_ns >= self.busy_until_ns
    }

    /// When the chip will next be ready.
    pub fn ready_at(&self) -> u64 {
        self.busy_until_ns
    }

    /// When something happens next without the host: the next DC cycle
    /// or the end of the running blocking command, if any.
    pub fn next_event_at(&self) -> Option<u64> {
        let cycle = self.master.inited.then_some(self.master.next_cycle_ns);
        let done = self.pending.as_ref().map(|(_, t)| *t);
        cycle.into_iter().chain(done).min()
    }

    /// INT0's electrical level at `now_ns` (polarity from command 58;
    /// active-high after power-up).
    pub fn int0_level(&self, now_ns: u64) -> bool {
        if let Some(level) = self.faults.int0_stuck {
            return level;
        }
        let active_high =
            self.int_config.polarity.contains(ecmxf_wire::payload::interrupt::IntPolarity::INT0_ACTIVE_HIGH);
        self.ready(now_ns) == active_high
    }

    /// Whether INT1 is active: (interrupt flags & enable mask) != 0, GPIO
    /// and peripheral sources included (v049 ECM-XF中斷).
    pub fn int1_active(&self) -> bool {
        let c = &self.int_config;
        !(self.int_flags & c.mask).is_empty()
            || self.periph.int_flags & u32::from(c.gpio) != 0
            || (self.periph.int_flags >> 8) & u32::from(c.peripheral.bits() & 0x0F) != 0
    }

    /// INT1's electrical level (active-low after power-up).
    pub fn int1_level(&self) -> bool {
        let active_high =
            self.int_config.polarity.contains(ecmxf_wire::payload::interrupt::IntPolarity::INT1_ACTIVE_HIGH);
        self.int1_active() == active_high
    }

    /// Time one byte takes on the wire.
    pub fn byte_ns(&self) -> u64 {
        8_000_000_000 / self.config.spi_hz.max(1)
    }

    /// One full-duplex SPI transfer starting at `start_ns`: `mosi` in,
    /// `miso` out (up to `mosi.len()` bytes), each byte [`Chip::byte_ns`]
    /// after the previous. Readiness is judged when a packet's first byte
    /// arrives; processing starts when its last byte has.
    pub fn transfer(&mut self, start_ns: u64, mosi: &[u8], miso: &mut [u8]) {
        let byte_ns = self.byte_ns();
        for (i, &byte) in mosi.iter().enumerate() {
            self.advance_to(start_ns + (i as u64 + 1) * byte_ns);
            let first_byte_at = self.now_ns - byte_ns;
            let byte = {
                let rate = self.faults.flip_mosi;
                self.faults.maybe_flip(byte, rate)
            };
            let ready = self.ready(first_byte_at);
            let (out, boundary) = self.spi.exchange(byte, ready);
            if let Some(slot) = miso.get_mut(i) {
                let rate = self.faults.flip_miso;
                *slot = self.faults.maybe_flip(out, rate);
            }
            match boundary {
                Some(Boundary::Taken(packet)) => {
                    self.stats.packets += 1;
                    let answer = self.take_packet(&packet);
                    self.spi.pending = answer;
                    self.busy_until_ns = self.busy_until_ns.max(self.now_ns + self.config.processing_ns);
                }
                Some(Boundary::Lost) => self.stats.not_ready += 1,
                None => {}
            }
        }
    }

    /// Runs DC cycles and blocking completions up to `now_ns`.
    pub fn advance_to(&mut self, now_ns: u64) {
        while self.now_ns < now_ns {
            let cycle_at = if self.master.inited { Some(self.master.next_cycle_ns) } else { None };
            let done_at = self.pending.as_ref().map(|(_, t)| *t);
            let next = [cycle_at, done_at].into_iter().flatten().filter(|t| *t <= now_ns).min();
            let Some(t) = next else {
                self.now_ns = now_ns;
                break;
            };
            self.now_ns = self.now_ns.max(t);
            if done_at == Some(t) {
                if let Some((op, _)) = self.pending.take() {
                    self.finish_blocking(op);
                }
            } else {
                self.run_cycle();
                self.master.next_cycle_ns += self.master.cycle_ns.max(1);
            }
        }
        self.periph.advance(self.now_ns);
    }

    /// The ECM status byte now.
    pub fn status(&self) -> EcmStatus {
        let mut flags = StatusFlags::empty();
        let running = self.master.inited && !self.master.exchange_stopped;
        flags.set(StatusFlags::ETHERNET_READY, self.master.inited);
        flags.set(StatusFlags::PDO_CONFIGURED, running && !self.master.slots.is_empty());
        flags.set(StatusFlags::FIFO_ENABLED, running && self.fifo.enabled);
        flags.set(StatusFlags::BLOCKING_BUSY, self.pending.is_some());
        flags.set(StatusFlags::DC_STABLE, self.master.dc_stable_at.is_some_and(|t| self.now_ns >= t));
        EcmStatus { check_type: self.check, flags }
    }

    /// The ECAT state byte: the lowest state the chip has read, or ERROR when
    /// a slave reported an error.
    pub fn ecat_state(&self) -> EcatState {
        if !self.master.inited {
            return EcatState::None;
        }
        let states = &self.master.cached_states;
        if states.iter().any(|s| s & 0x10 != 0) {
            return EcatState::Error;
        }
        states.iter().map(|s| s & 0x0F).min().map_or(EcatState::None, EcatState::from_u8)
    }

    fn snapshot(&self, index: u8, code: CommandCode, value: u8, data_len: u16) -> ResponseHeader {
        // The answer goes out with the next exchange, so a host sees the
        // level as it was two exchanges before it reads it.
        let (tx, rx) = self.fifo_history[1];
        let mut errors = self.errors;
        errors.set(ErrorFlags::LINK_PIN, self.net.reachable() > 0);
        errors.set(ErrorFlags::PHY_LINK_AT_INIT, self.master.inited);
        ResponseHeader {
            crc_errors: self.crc_errors,
            wkc_errors: self.wkc_errors,
            tx_fifo_count: tx,
            rx_fifo_count: rx,
            ecat_state: self.ecat_state(),
            errors,
            status: self.status(),
            index,
            code,
            return_value: value,
            data_len,
            int_flags: self.int_flags,
            gpio_int_flags: self.periph.int_flags as u16,
            gpio_inputs: self.periph.input_value() as u16,
        }
    }

    fn encode(&self, header: &ResponseHeader, data: &[u8]) -> Vec<u8> {
        let mut buf = vec![0u8; self.spi.packet_len()];
        let n = data.len().min(self.spi.data_size);
        let mut h = *header;
        h.data_len = n as u16;
        // The buffer has the port's length and the data is cut to fit, so
        // this cannot fail.
        let _ = encode_response(&h, &data[..n], self.check, &mut buf);
        buf
    }

    /// Records FIFO levels at each packet taken; an answer reports the value
    /// from the packet before, and reaches the host one exchange later: the
    /// counts the host reads lag by two exchanges (the vendor driver's
    /// comment).
    fn note_fifo_levels(&mut self) {
        self.fifo_history.rotate_right(1);
        let clamp = |n: usize| n.min(255) as u8;
        self.fifo_history[0] = (clamp(self.fifo.tx.len()), clamp(self.fifo.rx.len()));
    }

    /// Stores an emergency in the 8-deep history.
    fn record_emergency(&mut self, slave: u8, e: crate::net::slave::Emergency) {
        self.emergency_count = self.emergency_count.wrapping_add(1);
        let rec = EmergencyRecord {
            slot: 0,
            slave,
            number: self.emergency_count,
            error_code: e.error_code,
            error_register: e.error_register,
            data: e.data,
        };
        self.emergencies.push((self.emergency_count, rec));
        if self.emergencies.len() > 8 {
            self.emergencies.remove(0);
        }
    }

    /// Warm reset: everything back to power-up, busy while it initialises.
    /// The network keeps running on its own (slaves time out).
    pub fn warm_reset(&mut self) {
        let net = std::mem::take(&mut self.net);
        let config = self.config.clone();
        let faults = std::mem::take(&mut self.faults);
        let now = self.now_ns;
        let stats = self.stats;
        *self = Chip::new(net, config);
        self.faults = faults;
        self.stats = stats;
        self.now_ns = now;
        self.busy_until_ns = now + self.config.warm_reset_ns;
    }
}

fn default_phy() -> [u16; 32] {
    let mut r = [0u16; 32];
    r[0] = 0x3100; // control: 100 Mbit/s, autonegotiation
    r[1] = 0x786D; // status: link up, autonegotiation complete
    r[2] = 0x0007; // PHY id
    r[3] = 0xC0F1;
    r
}
