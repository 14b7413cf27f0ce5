//! Reaching the daemon: its Unix socket by default (who you are is your
//! Unix user), or TCP with TLS (`--connect`), where a bearer token or a
//! client certificate says who you are (proto/README.md, "Connecting").

use std::path::{Path, PathBuf};
use std::time::Duration;

use ecmxf_proto::v1 as pb;
use tonic::metadata::{Ascii, MetadataValue};
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Endpoint, Identity};

use crate::cli::ConnectArgs;
use crate::error::CliError;

/// Adds `authorization: Bearer <token>` to every call when a token is set.
#[derive(Debug, Clone)]
pub struct Auth(Option<MetadataValue<Ascii>>);

impl tonic::service::Interceptor for Auth {
    fn call(&mut self, mut r: tonic::Request<()>) -> Result<tonic::Request<()>, tonic::Status> {
        if let Some(t) = &self.0 {
            r.metadata_mut().insert("authorization", t.clone());
        }
        Ok(r)
    }
}

/// The channel every client uses.
pub type Chan = InterceptedService<Channel, Auth>;

/// The deadline of a call when `--timeout` is not given.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(5);

/// A connection to the daemon and the deadline for unary calls.
#[derive(Debug, Clone)]
pub struct Api {
    chan: Chan,
    timeout: Duration,
    /// `--timeout` was given: it is the deadline of every call, long
    /// operations included (a script's bound is never stretched).
    explicit: bool,
    /// Where it is connected (for messages).
    pub target: String,
}

macro_rules! clients {
    ($($name:ident => $client:ty),* $(,)?) => {
        $(
            #[doc = concat!("A `", stringify!($client), "` on this connection.")]
            pub fn $name(&self) -> $client {
                <$client>::new(self.chan.clone())
            }
        )*
    };
}

impl Api {
    clients! {
        master => pb::master_client::MasterClient<Chan>,
        slaves => pb::slaves_client::SlavesClient<Chan>,
        state => pb::state_client::StateClient<Chan>,
        sdo => pb::sdo_client::SdoClient<Chan>,
        sii => pb::sii_client::SiiClient<Chan>,
        pdo => pb::process_data_client::ProcessDataClient<Chan>,
        cia402 => pb::cia402_client::Cia402Client<Chan>,
        peripherals => pb::peripherals_client::PeripheralsClient<Chan>,
        foe => pb::foe_client::FoeClient<Chan>,
        registers => pb::registers_client::RegistersClient<Chan>,
        diagnostics => pb::diagnostics_client::DiagnosticsClient<Chan>,
    }

    /// A unary request with the call deadline.
    pub fn req<T>(&self, msg: T) -> tonic::Request<T> {
        let mut r = tonic::Request::new(msg);
        r.set_timeout(self.timeout);
        r
    }

    /// A request that may take `at_least` (an SII range, waiting for
    /// states): that long unless `--timeout` was given, which wins.
    pub fn req_for<T>(&self, msg: T, at_least: Duration) -> tonic::Request<T> {
        let mut r = tonic::Request::new(msg);
        r.set_timeout(if self.explicit { self.timeout } else { self.timeout.max(at_least) });
        r
    }

    /// A following stream (events, inputs): no deadline, it runs until
    /// stopped.
    pub fn stream<T>(&self, msg: T) -> tonic::Request<T> {
        tonic::Request::new(msg)
    }

    /// A stream that is one operation with an end (an FoE transfer and its
    /// progress): bounded by `--timeout` when given, else by nothing but
    /// the transfer itself.
    pub fn transfer<T>(&self, msg: T) -> tonic::Request<T> {
        let mut r = tonic::Request::new(msg);
        if self.explicit {
            r.set_timeout(self.timeout);
        }
        r
    }

    /// The unary deadline.
    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// How long the daemon may wait for something (a state, an axis)
    /// before answering "not reached", and the deadline of that call: by
    /// default the timeout and a second more for the answer; with
    /// `--timeout` given, both within it (the wait a tenth shorter, at
    /// most 200 ms, so the answer still arrives in time).
    pub fn wait_and_deadline(&self) -> (u32, Duration) {
        let (wait, deadline) = if self.explicit {
            (self.timeout.saturating_sub((self.timeout / 10).min(Duration::from_millis(200))), self.timeout)
        } else {
            (self.timeout, self.timeout + Duration::from_secs(1))
        };
        (wait.as_millis().min(u128::from(u32::MAX)) as u32, deadline)
    }
}

/// Connects as the arguments say.
pub async fn connect(args: &ConnectArgs, timeout: Option<Duration>) -> Result<Api, CliError> {
    let (explicit, timeout) = (timeout.is_some(), timeout.unwrap_or(DEFAULT_TIMEOUT));
    let token = token(args)?;
    let (channel, target) = match &args.tcp() {
        Some(url) => tcp(args, url).await?,
        None => {
            let path = args.socket_path();
            (unix(&path).await?, path.display().to_string())
        }
    };
    Ok(Api { chan: InterceptedService::new(channel, Auth(token)), timeout, explicit, target })
}

fn token(args: &ConnectArgs) -> Result<Option<MetadataValue<Ascii>>, CliError> {
    let text = match (&args.token, &args.token_file) {
        (Some(t), _) => t.clone(),
        (None, Some(p)) => read(p).map(|b| String::from_utf8_lossy(&b).trim().to_owned())?,
        (None, None) => return Ok(None),
    };
    format!("Bearer {text}")
        .parse()
        .map(Some)
        .map_err(|_| CliError::Usage("the token has characters a gRPC header cannot carry".into()))
}

fn read(p: &Path) -> Result<Vec<u8>, CliError> {
    std::fs::read(p).map_err(CliError::file(p))
}

async fn unix(path: &PathBuf) -> Result<Channel, CliError> {
    ecmxf_proto::connect_unix(path)
        .await
        .map_err(|e| CliError::Unreachable { target: path.display().to_string(), reason: unix_reason(&e) })
}

/// What a user needs to hear about a failed socket connection: the OS's
/// reason (tonic's own text is only "transport error").
fn unix_reason(e: &(dyn std::error::Error + 'static)) -> String {
    let mut cur = Some(e);
    while let Some(c) = cur {
        if let Some(io) = c.downcast_ref::<std::io::Error>() {
            return match io.kind() {
                std::io::ErrorKind::NotFound => "no socket there".to_owned(),
                std::io::ErrorKind::ConnectionRefused => "nothing listens on the socket (stale file)".to_owned(),
                std::io::ErrorKind::PermissionDenied => {
                    "permission denied on the socket (be in its group, see api.socket_group)".to_owned()
                }
                _ => io.to_string(),
            };
        }
        cur = c.source();
    }
    chain(e)
}

async fn tcp(args: &ConnectArgs, url: &str) -> Result<(Channel, String), CliError> {
    let url = if url.contains("://") { url.to_owned() } else { format!("https://{url}") };
    if url.starts_with("http://") {
        return Err(CliError::Usage(format!(
            "--connect {url}: ecmxfd serves TCP only with TLS; use https:// (or host:port)"
        )));
    }
    let endpoint = Endpoint::from_shared(url.clone())
        .map_err(|e| CliError::Usage(format!("--connect {url}: not a URL: {e}")))?
        .connect_timeout(Duration::from_secs(5));
    let mut tls = ClientTlsConfig::new();
    tls = match &args.ca_file() {
        Some(ca) => tls.ca_certificate(Certificate::from_pem(read(ca)?)),
        None => tls.with_enabled_roots(),
    };
    if let (Some(cert), Some(key)) = (&args.cert, &args.key) {
        tls = tls.identity(Identity::from_pem(read(cert)?, read(key)?));
    }
    if let Some(d) = &args.tls_domain {
        tls = tls.domain_name(d.clone());
    }
    let endpoint = endpoint.tls_config(tls).map_err(|e| CliError::Usage(format!("--connect {url}: {}", chain(&e))))?;
    let ch = endpoint.connect().await.map_err(|e| CliError::Unreachable { target: url.clone(), reason: chain(&e) })?;
    Ok((ch, url))
}

/// An error and its causes on one line (tonic's top-level text is often
/// only "transport error").
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    while let Some(c) = cur {
        let t = c.to_string();
        if !s.contains(&t) {
            s.push_str(": ");
            s.push_str(&t);
        }
        cur = c.source();
    }
    s
}
