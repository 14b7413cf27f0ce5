//! A host-side mailbox channel to one slave at a time: the
//! services the chip does not speak itself (CoE SDO Information; whatever
//! an ETG.8200 gateway client sends) go to the slave's mailboxes through
//! the chip's raw datagrams (v049 RAW_ECAT_FUNC_REQ 137 / GET 138), each
//! one a job on the blocking slot like any SDO. Decided from v049 and
//! ETG.1000.4 5.6:
//!
//! - **Write.** The whole message goes into the receive mailbox (SM0: SII
//!   words 0x18/0x19) by APWR to the slave's ring position, the area's
//!   last byte last: the ESC hands the request to the slave when its last
//!   byte is written. v049 carries at most 256 bytes per datagram, so a
//!   larger mailbox takes several, in order. A write the slave does not
//!   take (working counter 0: it still holds a request) is tried again.
//! - **Read.** APRD of the send mailbox (SM1: words 0x1A/0x1B) from its
//!   start. A read of an empty mailbox is not counted (working counter 0),
//!   so the read is the poll: no status register read first. The read
//!   that reaches the area's last byte frees it (one datagram when the
//!   mailbox is at most 256 bytes). Not RECV_MAILBOX (143): v049 gives no
//!   way to tell what it fetched or whether the mailbox was full.
//! - **Counter.** Every message the host sends is counted 0. The chip
//!   counts its own CoE requests (SDO_REQ) 1..=7 in a sequence the host
//!   cannot read, and a slave drops a request counted like the one before
//!   it; 0 is never taken for a repetition. A gateway client's counter is
//!   put back into the answer it gets.
//! - **One at a time.** The chip reads the same send mailbox for its own
//!   SDO_REQ. A host exchange holds its slave's mailbox exclusively
//!   ([`Master::mailbox_lock`]); the master's own CoE requests to that
//!   slave share it among themselves ([`Master::coe_lock`]: the blocking
//!   slot's fair queue orders them) and wait while a host exchange runs,
//!   so neither reads the other's answer.
//! - **Lost answers.** A read that freed the mailbox but never came back
//!   loses the answer: after [`REPEAT_AFTER`] with nothing read, the host
//!   toggles SM1's repeat request (0x080E bit 1) and the slave puts its
//!   last message back (ETG.1000.4 5.6.1.2), again after each such spell.
//!   A slave that had not answered yet repeats the message before, which
//!   the host did read: a message counted like the last one the host got
//!   from that slave, right after a repeat request, is that stale copy and
//!   is dropped (the counter is the slave's, 1..=7, one per message sent).
//! - **Emergencies.** A CoE emergency read while waiting is handed to the
//!   emergency path (an `Emergency` event, as the ones the chip collects)
//!   and the wait goes on.
//!
//! Polls back off from back to back to every [`POLL_MAX`]: a slave answers
//! in its own time and gives no signal, and each poll is a slot job.

/// The mailbox framing (ETG.1000.4 5.6, ETG.1000.6 5.6) that a front end
/// forwarding mailbox traffic speaks: the ETG.8200 gateway parses its
/// clients' requests with it, and answers for the master's own object
/// dictionary.
pub(crate) mod framing {
    pub(crate) use ecmxf_wire::mbx::sdo::{SdoRequest, SdoResponse};
    pub(crate) use ecmxf_wire::mbx::{HEADER_LEN, MailboxError, MailboxHeader, MailboxType, Message};
    pub(crate) use ecmxf_wire::payload::sdo::SdoAbortCode;
}

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ecmxf_wire::mbx::coe::{CoeEmergency, CoeHeader, CoeService};
use ecmxf_wire::mbx::{self, MailboxError, MailboxHeader, MailboxType, Message};
use ecmxf_wire::payload::emergency::EmergencyRecord;
use ecmxf_wire::payload::raw::{DatagramCommand, DatagramHead, RAW_MAX_DATA};

use super::per_slave::PerSlave;
use super::{Call, Master};
use crate::engine::error::EngineError;
use crate::engine::events::{Event, EventKind};

/// The longest wait between two polls of a send mailbox.
pub(crate) const POLL_MAX: Duration = Duration::from_millis(10);
/// How long an answer may take by default.
pub(crate) const ANSWER_TIMEOUT: Duration = Duration::from_secs(2);
/// Silence after which a lost answer is asked for again.
pub(crate) const REPEAT_AFTER: Duration = Duration::from_millis(100);
/// SM1's activate register (repeat request in bit 1).
const SM1_ACTIVATE: u16 = 0x080E;
/// Raw datagram timeout, us.
const DATAGRAM_US: u32 = 10_000;

/// Where a slave's mailboxes are (SII words 0x18..0x1B).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct MailboxGeometry {
    /// Receive mailbox (master to slave): start.
    pub rx_offset: u16,
    /// Its size.
    pub rx_size: u16,
    /// Send mailbox (slave to master): start.
    pub tx_offset: u16,
    /// Its size.
    pub tx_size: u16,
}

/// Per-slave state of the channel: geometry read once per identity, and
/// the lock host exchanges and the master's own CoE requests share.
#[derive(Debug, Default)]
pub(crate) struct MailboxChannels {
    geometry: PerSlave<MailboxGeometry>,
    locks: Mutex<HashMap<u8, Arc<tokio::sync::RwLock<()>>>>,
    /// The counter of the last message the host read from each slave.
    counters: Mutex<HashMap<u8, u8>>,
    /// Station addresses by position, read once per identity.
    stations: PerSlave<u16>,
    /// What the mailbox gateway did.
    gateway: GatewayCounters,
    /// The last emergencies the host's own reads found, newest last.
    emergencies: Mutex<std::collections::VecDeque<EmergencyRecord>>,
}

/// Emergencies kept of those the host's reads found.
const EMERGENCIES_KEPT: usize = 8;

/// What the ETG.8200 gateway did (exported as metrics).
#[derive(Debug, Default)]
pub(crate) struct GatewayCounters {
    /// Requests taken.
    pub requests: std::sync::atomic::AtomicU64,
    /// Answers sent.
    pub answered: std::sync::atomic::AtomicU64,
    /// Answers that were mailbox errors (unknown station, slave not in a
    /// mailbox state, no answer).
    pub errors: std::sync::atomic::AtomicU64,
    /// Datagrams that were no mailbox request, dropped.
    pub malformed: std::sync::atomic::AtomicU64,
    /// Datagrams from clients `gateway.allow` does not name, dropped.
    pub refused: std::sync::atomic::AtomicU64,
}

/// What a host exchange came to.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MailboxFailure {
    /// The slave has no mailbox (SII sizes 0).
    NoMailbox(u8),
    /// The message does not fit the slave's receive mailbox.
    TooLong {
        /// Bytes of the message.
        len: usize,
        /// The mailbox's size.
        size: u16,
    },
    /// The slave did not take the request, or did not answer, in time.
    NoAnswer(u8),
    /// The slave answered with a mailbox error.
    Refused(MailboxError),
}

impl std::fmt::Display for MailboxFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoMailbox(s) => write!(f, "slave {s} has no mailbox (its SII gives none)"),
            Self::TooLong { len, size } => write!(f, "{len} bytes do not fit the slave's {size}-byte mailbox"),
            Self::NoAnswer(s) => write!(f, "slave {s} did not answer in its mailbox in time"),
            Self::Refused(e) => write!(f, "the slave refused the message: {e}"),
        }
    }
}

/// What one read of a send mailbox found.
#[derive(Debug, PartialEq, Eq)]
enum Take {
    /// Nothing waits (working counter 0).
    Empty,
    /// A message, now freed.
    Message(Vec<u8>),
    /// The datagram did not come back: what it read is lost.
    Lost,
}

fn head(command: DatagramCommand, position: u8, ado: u16, length: u16) -> DatagramHead {
    // Auto-increment addressing: position n is -n.
    DatagramHead { command, length, adp: u16::from(position).wrapping_neg(), ado, logical: 0, timeout_us: DATAGRAM_US }
}

impl Master {
    fn slave_lock(&self, slave: u8) -> Arc<tokio::sync::RwLock<()>> {
        let mut locks = self.channels.locks.lock().unwrap_or_else(|e| e.into_inner());
        Arc::clone(locks.entry(slave).or_default())
    }

    /// A slave's mailbox for a host exchange, alone: held for the whole
    /// exchange (all its fragments).
    pub(crate) async fn mailbox_lock(&self, slave: u8) -> tokio::sync::OwnedRwLockWriteGuard<()> {
        self.slave_lock(slave).write_owned().await
    }

    /// A slave's mailbox for one of the chip's own CoE requests: shared with
    /// the others, kept from host exchanges.
    pub(crate) async fn coe_lock(&self, slave: u8) -> tokio::sync::OwnedRwLockReadGuard<()> {
        self.slave_lock(slave).read_owned().await
    }

    /// The gateway's counters.
    pub(crate) fn gateway_counters(&self) -> &GatewayCounters {
        &self.channels.gateway
    }

    /// The configured station address of the slave at `slave` (SLV_INFO,
    /// read once per identity); `None` when it cannot be read.
    pub(crate) async fn station_address(&self, slave: u8, call: Call) -> Option<u16> {
        let identity = self.identity(slave)?;
        if let Some(a) = self.channels.stations.get(slave, identity) {
            return Some(a);
        }
        let code = ecmxf_wire::payload::slave_info::SlaveInfoCode::ConfiguredAddress;
        let a = self.slave_number(slave, code, call).await.ok()? as u16;
        self.channels.stations.put(slave, identity, a);
        Some(a)
    }

    /// The position of the slave with station address `station`.
    pub(crate) async fn slave_at_station(&self, station: u16, call: Call) -> Option<u8> {
        let count = self.layout().slaves.len().min(usize::from(u8::MAX)) as u8;
        for slave in 0..count {
            if self.station_address(slave, call).await == Some(station) {
                return Some(slave);
            }
        }
        None
    }

    /// Where `slave`'s mailboxes are, from its SII (read once per identity).
    pub(crate) async fn mailbox_geometry(&self, slave: u8, call: Call) -> Result<MailboxGeometry, EngineError> {
        self.check_slave(slave, "slave")?;
        let identity = self.identity(slave).ok_or_else(|| EngineError::BadArgument {
            field: "slave",
            reason: format!("slave {slave} does not exist"),
        })?;
        if let Some(g) = self.channels.geometry.get(slave, identity) {
            return Ok(g);
        }
        let w = self.eeprom_read_words(slave, 0x18, 4, call).await?;
        let word = |k: usize| w.get(k).copied().unwrap_or(0);
        let g = MailboxGeometry { rx_offset: word(0), rx_size: word(1), tx_offset: word(2), tx_size: word(3) };
        self.channels.geometry.put(slave, identity, g);
        Ok(g)
    }

    /// Sends one mailbox message (`kind`, `body`) to `slave` and returns the
    /// answer's header and body, given up on after `timeout` (the slave's
    /// time to answer; `call` is whose turn each datagram takes, and its
    /// deadline bounds each). The caller holds [`Master::mailbox_lock`].
    pub(crate) async fn mailbox_exchange(
        &self,
        slave: u8,
        kind: MailboxType,
        body: &[u8],
        timeout: Duration,
        call: Call,
    ) -> Result<Result<(MailboxHeader, Vec<u8>), MailboxFailure>, EngineError> {
        let g = self.mailbox_geometry(slave, call).await?;
        if g.rx_size == 0 || g.tx_size == 0 {
            return Ok(Err(MailboxFailure::NoMailbox(slave)));
        }
        let len = mbx::HEADER_LEN + body.len();
        if len > usize::from(g.rx_size) {
            return Ok(Err(MailboxFailure::TooLong { len, size: g.rx_size }));
        }
        let deadline = Instant::now() + timeout;
        // The whole area, the message first and zeros after it, so that the
        // last byte is written last.
        let mut area = vec![0u8; usize::from(g.rx_size)];
        let header = MailboxHeader::new(kind, body.len() as u16, 0);
        Message::write(header, body, &mut area)
            .map_err(|e| EngineError::BadArgument { field: "message", reason: e.to_string() })?;
        if !self.mailbox_write(slave, g, &area, deadline, call).await? {
            return Ok(Err(MailboxFailure::NoAnswer(slave)));
        }
        self.mailbox_read(slave, g, deadline, call).await
    }

    /// Reads the next message from `slave`'s send mailbox (a fragment after
    /// the first). The caller holds [`Master::mailbox_lock`].
    pub(crate) async fn mailbox_next(
        &self,
        slave: u8,
        timeout: Duration,
        call: Call,
    ) -> Result<Result<(MailboxHeader, Vec<u8>), MailboxFailure>, EngineError> {
        let g = self.mailbox_geometry(slave, call).await?;
        self.mailbox_read(slave, g, Instant::now() + timeout, call).await
    }

    /// Writes `area` into the receive mailbox, in datagrams of at most
    /// 256 bytes, in order; true once the slave took it.
    async fn mailbox_write(
        &self,
        slave: u8,
        g: MailboxGeometry,
        area: &[u8],
        deadline: Instant,
        call: Call,
    ) -> Result<bool, EngineError> {
        let mut wait = Duration::ZERO;
        loop {
            let mut taken = true;
            for (k, chunk) in area.chunks(usize::from(RAW_MAX_DATA)).enumerate() {
                let ado = g.rx_offset + (k * usize::from(RAW_MAX_DATA)) as u16;
                let h = head(DatagramCommand::Apwr, slave, ado, chunk.len() as u16);
                let a = self.raw_datagram(h, chunk.to_vec(), call).await?;
                if a.working_counter == 0 {
                    taken = false;
                    break;
                }
            }
            if taken {
                return Ok(true);
            }
            if Instant::now() >= deadline {
                return Ok(false);
            }
            wait = (wait * 2).max(Duration::from_millis(1)).min(POLL_MAX);
            tokio::time::sleep(wait).await;
        }
    }

    /// Polls the send mailbox until a message that is not an emergency
    /// comes, asking for a repeat after each [`REPEAT_AFTER`] without one.
    async fn mailbox_read(
        &self,
        slave: u8,
        g: MailboxGeometry,
        deadline: Instant,
        call: Call,
    ) -> Result<Result<(MailboxHeader, Vec<u8>), MailboxFailure>, EngineError> {
        let mut quiet_since = Instant::now();
        // The counter of the copy a repeat request may bring back that the
        // host already has.
        let mut stale: Option<u8> = None;
        let mut wait = Duration::ZERO;
        loop {
            let taken = self.mailbox_take(slave, g, call).await?;
            if taken == Take::Lost {
                // The read freed the mailbox and never came back: ask for
                // that message again at once.
                stale = self.channels.counters.lock().unwrap_or_else(|e| e.into_inner()).get(&slave).copied();
                self.mailbox_repeat(slave, call).await?;
                quiet_since = Instant::now();
                continue;
            }
            if let Take::Message(message) = taken {
                quiet_since = Instant::now();
                let Ok(m) = Message::parse(&message) else {
                    tracing::warn!(slave, "a mailbox message that does not parse was dropped");
                    continue;
                };
                if m.header.counter != 0 && stale == Some(m.header.counter) {
                    tracing::debug!(slave, counter = m.header.counter, "a repeated message already read was dropped");
                    stale = None;
                    continue;
                }
                stale = None;
                self.channels.counters.lock().unwrap_or_else(|e| e.into_inner()).insert(slave, m.header.counter);
                match m.header.kind {
                    MailboxType::Error => {
                        let e = MailboxError::decode(m.body).unwrap_or(MailboxError::SYNTAX);
                        return Ok(Err(MailboxFailure::Refused(e)));
                    }
                    MailboxType::Coe if self.emergency_handed_on(slave, m.body) => {}
                    _ => return Ok(Ok((m.header, m.body.to_vec()))),
                }
                wait = Duration::ZERO;
                continue;
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(Err(MailboxFailure::NoAnswer(slave)));
            }
            if now.duration_since(quiet_since) >= REPEAT_AFTER {
                quiet_since = now;
                stale = self.channels.counters.lock().unwrap_or_else(|e| e.into_inner()).get(&slave).copied();
                self.mailbox_repeat(slave, call).await?;
                continue;
            }
            wait = (wait * 2).max(Duration::from_micros(500)).min(POLL_MAX);
            tokio::time::sleep(wait.min(deadline - now)).await;
        }
    }

    /// One read of the send mailbox. The read that reaches the last byte
    /// frees it.
    async fn mailbox_take(&self, slave: u8, g: MailboxGeometry, call: Call) -> Result<Take, EngineError> {
        let size = usize::from(g.tx_size);
        let first = size.min(usize::from(RAW_MAX_DATA));
        let a = match self
            .raw_datagram(head(DatagramCommand::Aprd, slave, g.tx_offset, first as u16), Vec::new(), call)
            .await
        {
            Ok(a) => a,
            // The chip says the datagram failed: it did not come back.
            Err(EngineError::Failed(_)) => return Ok(Take::Lost),
            Err(e) => return Err(e),
        };
        if a.working_counter == 0 {
            return Ok(Take::Empty);
        }
        let mut message = a.data;
        if first < size {
            // The rest of the message, then the last byte, which frees it.
            let want = MailboxHeader::decode(&message)
                .map_or(first, |h| mbx::HEADER_LEN + usize::from(h.length))
                .clamp(first, size - 1);
            let mut at = first;
            while at < want {
                let n = (want - at).min(usize::from(RAW_MAX_DATA));
                let h = head(DatagramCommand::Aprd, slave, g.tx_offset + at as u16, n as u16);
                message.extend(self.raw_datagram(h, Vec::new(), call).await?.data);
                at += n;
            }
            let last = head(DatagramCommand::Aprd, slave, g.tx_offset + (size - 1) as u16, 1);
            self.raw_datagram(last, Vec::new(), call).await?;
        }
        Ok(Take::Message(message))
    }

    /// Toggles SM1's repeat request: the slave puts its last answer back.
    async fn mailbox_repeat(&self, slave: u8, call: Call) -> Result<(), EngineError> {
        let now = self.raw_datagram(head(DatagramCommand::Aprd, slave, SM1_ACTIVATE, 1), Vec::new(), call).await?;
        let toggled = now.data.first().copied().unwrap_or(0) ^ 0x02;
        tracing::debug!(slave, "mailbox repeat request");
        self.raw_datagram(head(DatagramCommand::Apwr, slave, SM1_ACTIVATE, 1), vec![toggled], call).await?;
        Ok(())
    }

    /// A CoE emergency in the mailbox is an event like those the chip
    /// collects; true when `body` was one.
    fn emergency_handed_on(&self, slave: u8, body: &[u8]) -> bool {
        if CoeHeader::decode(body).map(|h| h.service) != Ok(CoeService::Emergency) {
            return false;
        }
        let Ok(e) = CoeEmergency::decode(body) else { return true };
        let record = EmergencyRecord {
            slot: 0,
            slave,
            number: 0,
            error_code: e.error_code,
            error_register: e.error_register,
            data: e.data,
        };
        {
            let mut kept = self.channels.emergencies.lock().unwrap_or_else(|e| e.into_inner());
            if kept.len() == EMERGENCIES_KEPT {
                kept.pop_front();
            }
            kept.push_back(record);
        }
        self.engine.publish_event(Event { time_ns: self.now_ns(), kind: EventKind::Emergency(record) });
        true
    }

    /// The last emergencies the host's own mailbox reads found (the chip
    /// never saw them: they are not in its history), newest first.
    pub(crate) fn mailbox_emergencies(&self) -> Vec<EmergencyRecord> {
        self.channels.emergencies.lock().unwrap_or_else(|e| e.into_inner()).iter().rev().copied().collect()
    }
}
