//! The daemon as a foreground process: SIGINT and SIGTERM stop it safely,
//! SIGHUP reads the configuration file again and hands it to the running
//! daemon ([`crate::lifecycle::Options::reloads`]).

use std::path::PathBuf;
use std::time::Duration;

use tokio::signal::unix::SignalKind;
use tracing::{error, info, warn};

use crate::config::Config;
use crate::lifecycle::{DaemonError, Options};
use crate::service::{Logging, Notifier};

/// Runs the daemon ([`crate::run_with`]) until SIGINT or SIGTERM, reloading
/// `config_path` on SIGHUP (kept as it is when the file has a mistake);
/// a status line every `status_every` (`None`: never).
pub async fn run_until_signalled(
    config: Config,
    config_path: Option<PathBuf>,
    status_every: Option<Duration>,
    logging: Logging,
) -> Result<(), DaemonError> {
    let signal = |k| tokio::signal::unix::signal(k).map_err(DaemonError::Signals);
    let mut sigterm = signal(SignalKind::terminate())?;
    let mut sighup = signal(SignalKind::hangup())?;
    let (reload_tx, reloads) = tokio::sync::mpsc::channel(1);
    let options =
        Options { status_every, notifier: Some(Notifier::from_env()), logging: Some(logging), reloads: Some(reloads) };
    let shutdown = async {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => info!("SIGINT"),
            _ = sigterm.recv() => info!("SIGTERM"),
        }
    };
    let reloader = async {
        while sighup.recv().await.is_some() {
            let Some(path) = &config_path else {
                warn!("SIGHUP: started without --config, nothing to reload");
                continue;
            };
            match Config::load(path) {
                Ok(c) => {
                    info!(file = %path.display(), "SIGHUP: configuration read again");
                    if reload_tx.send(c).await.is_err() {
                        return;
                    }
                }
                Err(e) => error!("SIGHUP: {e}; keeping the running configuration"),
            }
        }
    };
    tokio::select! {
        r = crate::run_with(config, options, shutdown) => r,
        () = reloader => std::future::pending().await,
    }
}
