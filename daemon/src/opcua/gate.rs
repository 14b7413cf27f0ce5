//! The door of the OPC UA listener: the server library has a session cap
//! but no connection cap, so every connection comes in here first. Under
//! the listener's [`Gate`] (`opcua.max_connections` in all,
//! `opcua.max_connections_per_peer` from one address) a peer has
//! `opcua.hello_timeout_s` to send the first bytes of an OPC UA Hello
//! (OPC 10000-6 7.1.2.3: message type `HEL`, chunk `F`); then the
//! connection is spliced to the server, which listens on loopback only
//! (after the trusted certificates are brought up to date: a client that
//! said Hello is about to show its own, see [`super::trust`]).
//! A peer over a cap, silent past the deadline or speaking something else
//! is closed without a word.
//!
//! The cost: one more TCP hop on loopback and one copy of each byte in
//! each direction, at the rate of an OPC UA session (kilobytes a second),
//! nothing per process-data frame.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;

use crate::admission::{Gate, Ticket};

/// The first four bytes of a Hello: its message type and a final chunk.
const HELLO: &[u8; 4] = b"HELF";

/// Where a spliced connection goes: the server, once the certificates in
/// `trusted` are brought up to date.
#[derive(Clone)]
pub(super) struct Inside {
    pub(super) server: SocketAddr,
    pub(super) trusted: Arc<PathBuf>,
    /// The server's own state, whose port its endpoint descriptions give.
    pub(super) info: Arc<opcua::server::ServerInfo>,
    /// The port clients reach it on: the listener's.
    pub(super) public_port: u16,
}

/// Accepts on `public` until `stopped` changes: each connection admitted
/// by `gate` gets `hello` to begin its Hello, then is spliced `inside`.
pub(super) async fn admit_loop(
    public: TcpListener,
    gate: Gate,
    hello: Duration,
    inside: Inside,
    mut stopped: watch::Receiver<()>,
) {
    loop {
        let accepted = tokio::select! {
            a = public.accept() => a,
            _ = stopped.changed() => return,
        };
        let (peer, addr) = match accepted {
            Ok(c) => c,
            Err(e) => {
                gate.accept_failed(&e).await;
                continue;
            }
        };
        let Ok(ticket) = gate.admit(Some(addr.ip())) else { continue };
        tokio::spawn(splice(peer, ticket, hello, inside.clone()));
    }
}

/// One connection: its Hello's first bytes within `hello`, then both
/// directions copied until either side closes. The ticket frees the
/// connection's place when this ends.
async fn splice(mut peer: TcpStream, _ticket: Ticket, hello: Duration, inside: Inside) {
    let mut first = [0u8; 4];
    match tokio::time::timeout(hello, peer.read_exact(&mut first)).await {
        Ok(Ok(_)) if &first == HELLO => {}
        _ => return,
    }
    // The server gives the port it listens on in its endpoint URLs
    // (GetEndpoints, CreateSession): the inner one, which clients must not
    // use (past this gate) and cannot reach from the network. It sets it
    // once as it starts, before its first accept; set here before every
    // connection reaches it, the public port is what clients are told.
    inside.info.port.store(inside.public_port, std::sync::atomic::Ordering::Relaxed);
    let trusted = Arc::clone(&inside.trusted);
    let _ = tokio::task::spawn_blocking(move || super::trust::admit(&trusted)).await;
    let Ok(mut inner) = TcpStream::connect(inside.server).await else { return };
    let _ = peer.set_nodelay(true);
    let _ = inner.set_nodelay(true);
    if inner.write_all(&first).await.is_err() {
        return;
    }
    let _ = tokio::io::copy_bidirectional(&mut peer, &mut inner).await;
}
