//! The ETG.8200 mailbox gateway (docs/mailbox.md): engineering tools (TwinCAT,
//! the EtherCAT Configurator, the TwinSAFE Loader) reach the slaves behind
//! this master over UDP port 0x88A4 (34980). A request is one datagram: a
//! 2-byte EtherCAT header (bits 0..10 length, bits 12..15 type, 5 =
//! mailbox) and one mailbox message whose header's address is the station
//! address of the slave it is for, 0 for the master itself. The answer
//! goes back the same way, from the slave's address, counted as the
//! client counted its request.
//!
//! - Slaves: the message goes through the host's mailbox channel
//!   (`master::mailbox_channel`), one transaction at a time per slave
//!   (its mailbox lock, which the master's own CoE requests share); a
//!   slave below PRE-OP, whose mailbox does not run, and a station no slave
//!   has, are answered with a mailbox error.
//! - The master (address 0): CoE SDO uploads of its object dictionary
//!   ([`master_od`]): identity, and per slave its configuration (0x8nnn)
//!   and diagnosis (0xAnnn) entries (ETG.5001.3 annex A / ETG.1510).
//! - Off unless `[gateway] listen` is set; only clients `allow` names
//!   (addresses or networks; default: this host). A datagram that is not a
//!   mailbox request is dropped and counted, and said once per client.
//!
//! A front end like the gRPC API: it reaches the engine through the master
//! only, and the engine's cycle never waits for it.

pub(crate) mod master_od;

use std::collections::HashSet;
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Duration;

use crate::master::EcatState;
use crate::master::mailbox_channel::framing::{self as mbx, MailboxError, MailboxHeader, MailboxType, Message};
use tokio::net::UdpSocket;

use crate::config::GatewayConfig;
use crate::master::{Call, Master};

/// EtherCAT header type of a mailbox (ETG.1000.4 Table 3).
const MAILBOX_FRAME: u16 = 5;
/// The largest datagram read.
const MAX_DATAGRAM: usize = 1500;
/// How long a slave may take to answer.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(5);

/// Why the gateway could not start.
#[derive(Debug)]
pub struct GatewayError {
    /// The address.
    pub listen: SocketAddr,
    /// The OS's error.
    pub source: std::io::Error,
}

impl std::fmt::Display for GatewayError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "gateway.listen {}: {}", self.listen, self.source)
    }
}

impl std::error::Error for GatewayError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.source)
    }
}

/// A request datagram read: the client's mailbox message.
fn parse(datagram: &[u8]) -> Option<Message<'_>> {
    let head = u16::from_le_bytes([*datagram.first()?, *datagram.get(1)?]);
    if head >> 12 != MAILBOX_FRAME {
        return None;
    }
    let length = usize::from(head & 0x07FF);
    let message = datagram.get(2..2 + length)?;
    Message::parse(message).ok().filter(|m| mbx::HEADER_LEN + m.body.len() == length)
}

/// An answer datagram: the EtherCAT header, then the message.
fn datagram(header: MailboxHeader, body: &[u8]) -> Vec<u8> {
    let n = mbx::HEADER_LEN + body.len();
    let mut out = vec![0u8; 2 + n];
    out[..2].copy_from_slice(&((n as u16 & 0x07FF) | MAILBOX_FRAME << 12).to_le_bytes());
    let _ = Message::write(header, body, &mut out[2..]);
    out
}

/// The answer to a request the gateway itself refuses: a mailbox error
/// from the address asked.
fn refusal(request: &MailboxHeader, error: MailboxError) -> Vec<u8> {
    let header = MailboxHeader::new(MailboxType::Error, 0, request.counter);
    datagram(MailboxHeader { address: request.address, ..header }, &error.body())
}

/// Binds `[gateway] listen`.
pub(crate) async fn bind(config: &GatewayConfig) -> Result<UdpSocket, GatewayError> {
    UdpSocket::bind(config.listen).await.map_err(|source| GatewayError { listen: config.listen, source })
}

/// Serves the gateway on `socket` until `stop` changes.
pub(crate) async fn serve(
    master: Arc<Master>,
    config: GatewayConfig,
    socket: UdpSocket,
    mut stop: tokio::sync::watch::Receiver<()>,
) {
    let socket = Arc::new(socket);
    let mut buf = vec![0u8; MAX_DATAGRAM];
    let mut told: HashSet<IpAddr> = HashSet::new();
    tracing::info!(listen = %config.listen, "ETG.8200 mailbox gateway");
    loop {
        let (n, from) = tokio::select! {
            r = socket.recv_from(&mut buf) => match r {
                Ok(r) => r,
                Err(e) => {
                    tracing::warn!("gateway: {e}");
                    continue;
                }
            },
            _ = stop.changed() => return,
        };
        let stats = master.gateway_counters();
        if !config.allows(from.ip()) {
            stats.refused.fetch_add(1, Relaxed);
            if told.insert(from.ip()) {
                tracing::warn!(client = %from, "gateway: a client not in gateway.allow; its datagrams are dropped");
            }
            continue;
        }
        let Some(request) = parse(&buf[..n]) else {
            stats.malformed.fetch_add(1, Relaxed);
            if told.insert(from.ip()) {
                tracing::warn!(client = %from, bytes = n, "gateway: a datagram that is no mailbox request was dropped");
            }
            continue;
        };
        stats.requests.fetch_add(1, Relaxed);
        let (header, body) = (request.header, request.body.to_vec());
        let (master, socket) = (Arc::clone(&master), Arc::clone(&socket));
        // One task per request: requests to different slaves run side by
        // side, those to one slave in turn (its mailbox lock).
        tokio::spawn(async move {
            let counters = master.gateway_counters();
            let answer = answer(&master, header, &body).await.unwrap_or_else(|refused| {
                counters.errors.fetch_add(1, Relaxed);
                refused
            });
            if socket.send_to(&answer, from).await.is_ok() {
                counters.answered.fetch_add(1, Relaxed);
            }
        });
    }
}

/// Whose turn the gateway's chip work takes: the line of work no client
/// owns (its datagrams come from peers the API does not number), each
/// request with the master's default time.
pub(crate) const GATEWAY: Call = Call::new(0, None);

/// The answer datagram to one request; a mailbox error in the slave's
/// stead (or the slave's own) is `Err`.
async fn answer(master: &Master, request: MailboxHeader, body: &[u8]) -> Result<Vec<u8>, Vec<u8>> {
    if request.address == 0 {
        let reply = master_od::answer(master, body, GATEWAY).await;
        let header = MailboxHeader::new(MailboxType::Coe, 0, request.counter);
        return reply
            .map(|r| datagram(header, &r))
            .ok_or_else(|| refusal(&request, MailboxError::SERVICE_NOT_SUPPORTED));
    }
    let Some(slave) = master.slave_at_station(request.address, GATEWAY).await else {
        return Err(refusal(&request, MailboxError::INVALID_HEADER));
    };
    let state = master.slave_number(slave, crate::master::SlaveInfoCode::State, GATEWAY).await;
    let state = state.map(|s| EcatState::from_u8(s as u8)).unwrap_or(EcatState::None);
    if !matches!(state, EcatState::PreOp | EcatState::SafeOp | EcatState::Op) {
        return Err(refusal(&request, MailboxError::SERVICE_NOT_SUPPORTED));
    }
    let exchange = async {
        let _lock = master.mailbox_lock(slave).await;
        master.mailbox_exchange(slave, request.kind, body, ANSWER_TIMEOUT, GATEWAY).await
    };
    match exchange.await {
        Ok(Ok((header, body))) => {
            let header = MailboxHeader { address: request.address, counter: request.counter, length: 0, ..header };
            Ok(datagram(header, &body))
        }
        Ok(Err(crate::master::mailbox_channel::MailboxFailure::Refused(e))) => Err(refusal(&request, e)),
        Ok(Err(e)) => {
            tracing::debug!(slave, "gateway: {e}");
            Err(refusal(&request, MailboxError::NO_MORE_MEMORY))
        }
        Err(e) => {
            tracing::debug!(slave, "gateway: {e}");
            Err(refusal(&request, MailboxError::NO_MORE_MEMORY))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_is_an_ethercat_header_and_one_mailbox_message() {
        let header = MailboxHeader { address: 0x1001, ..MailboxHeader::new(MailboxType::Coe, 0, 2) };
        let d = datagram(header, &[1, 2, 3, 4]);
        assert_eq!(&d[..2], &[10, 0x50], "10 bytes, type 5");
        let m = parse(&d).expect("parses");
        assert_eq!((m.header.address, m.header.counter, m.body), (0x1001, 2, &[1u8, 2, 3, 4][..]));
        assert!(parse(&d[..7]).is_none(), "cut short");
        let mut wrong = d.clone();
        wrong[1] = 0x10;
        assert!(parse(&wrong).is_none(), "not a mailbox frame");
        assert!(parse(&[]).is_none());
    }
}
