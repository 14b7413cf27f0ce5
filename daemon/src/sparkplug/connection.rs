//! One MQTT connection (rumqttc): the client, and its event loop in a
//! task of its own that hands over what the node needs (CONNACK, received
//! publishes, the end of the connection) on a channel, so `poll` is never
//! cancelled mid-packet by the node's other work. What every connection
//! needs (TLS, credentials) is read once at start ([`prepare`]).

use std::sync::Arc;
use std::time::Duration;

use rumqttc::{AsyncClient, ConnectReturnCode, Event, LastWill, MqttOptions, Packet, QoS, TlsConfiguration, Transport};
use tokio::sync::mpsc;

use super::tls;
use crate::config::SparkplugConfig;
use crate::config::sparkplug::{BrokerUrl, Credentials};

/// Why the node could not start.
#[derive(Debug)]
pub enum SparkplugError {
    /// TLS material that does not load.
    Tls(String),
    /// Credentials that do not load.
    Credentials(String),
}

impl std::fmt::Display for SparkplugError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Tls(e) => write!(f, "{e}"),
            Self::Credentials(e) => write!(f, "sparkplug.credentials_file: {e}"),
        }
    }
}

impl std::error::Error for SparkplugError {}

/// What the node needs, prepared at start (files read once).
#[derive(Debug)]
pub struct Prepared {
    pub(super) config: SparkplugConfig,
    pub(super) node_id: String,
    pub(super) tls: Option<Arc<rustls::ClientConfig>>,
    pub(super) credentials: Option<Credentials>,
}

/// Reads the TLS files and credentials of `config`: an error names the
/// file, before the daemon starts serving.
pub fn prepare(config: &SparkplugConfig) -> Result<Prepared, SparkplugError> {
    let tls = tls::client_config(config).map_err(SparkplugError::Tls)?;
    let credentials =
        config.credentials_file.as_deref().map(Credentials::read).transpose().map_err(SparkplugError::Credentials)?;
    Ok(Prepared { config: config.clone(), node_id: config.node_id(), tls, credentials })
}

/// The client's queue: births of 256 devices and a period's data fit.
const QUEUE: usize = 1024;

/// What the MQTT task hands over.
#[derive(Debug)]
pub(super) enum Incoming {
    /// The CONNACK: accepted, or the refusal in words.
    Connected(Result<(), String>),
    /// A message on a subscribed topic.
    Publish {
        /// Its topic.
        topic: String,
        /// Its payload.
        payload: bytes::Bytes,
    },
    /// The connection ended: why.
    Lost(String),
}

/// A client for broker `b` and its event loop task, with `will` (topic,
/// payload) as the MQTT will.
pub(super) fn open(
    prepared: &Prepared,
    client_id: String,
    b: &BrokerUrl,
    will: (String, Vec<u8>),
) -> (AsyncClient, mpsc::Receiver<Incoming>) {
    let mut options = MqttOptions::new(client_id, b.host.clone(), b.port);
    options.set_keep_alive(Duration::from_secs(prepared.config.keep_alive_s.into()));
    // Spec 7.1: clean session, so no command queued for a dead
    // connection is acted on after a rebirth.
    options.set_clean_session(true);
    options.set_max_packet_size(1 << 20, 1 << 20);
    options.set_last_will(LastWill::new(will.0, will.1, QoS::AtLeastOnce, false));
    if let Some(creds) = &prepared.credentials {
        options.set_credentials(creds.username.clone(), creds.password.clone());
    }
    if b.tls {
        if let Some(tls) = &prepared.tls {
            options.set_transport(Transport::tls_with_config(TlsConfiguration::Rustls(Arc::clone(tls))));
        }
    }
    let (client, mut eventloop) = AsyncClient::new(options, QUEUE);
    let (tx, rx) = mpsc::channel(256);
    tokio::spawn(async move {
        loop {
            let msg = match eventloop.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(ack))) => Incoming::Connected(match ack.code {
                    ConnectReturnCode::Success => Ok(()),
                    code => Err(refused(code)),
                }),
                Ok(Event::Incoming(Packet::Publish(p))) => Incoming::Publish { topic: p.topic, payload: p.payload },
                Ok(Event::Incoming(Packet::Disconnect)) => Incoming::Lost("the broker disconnected".into()),
                Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => {
                    let _ = tx.send(Incoming::Lost("disconnected".into())).await;
                    return;
                }
                Ok(_) => continue,
                Err(rumqttc::ConnectionError::ConnectionRefused(code)) => Incoming::Lost(refused(code)),
                Err(e) => Incoming::Lost(format!("connection lost: {e}")),
            };
            let end = matches!(msg, Incoming::Lost(_));
            if tx.send(msg).await.is_err() || end {
                return;
            }
        }
    });
    (client, rx)
}

/// A CONNACK refusal in words, with what to check.
fn refused(code: ConnectReturnCode) -> String {
    let hint = match code {
        ConnectReturnCode::BadUserNamePassword | ConnectReturnCode::NotAuthorized => {
            " (check sparkplug.credentials_file, client_cert and the broker's ACL)"
        }
        ConnectReturnCode::BadClientId => " (another client uses this node's client id?)",
        _ => "",
    };
    format!("the broker refused the connection: {code:?}{hint}")
}
