//! The daemon as a foreground process: SIGINT and SIGTERM stop it safely,
//! SIGHUP reads the configuration file again and hands it to the running
//! daemon ([`crate::lifecycle::Options::reloads`]). Started without a
//! configuration file (`ecmxfd --sim` in a terminal) there is nothing to
//! read again, and SIGHUP means what it means to any foreground program:
//! the terminal is gone, so the daemon stops safely, as on SIGTERM, rather
//! than live on holding its socket.

use std::path::PathBuf;
use std::time::Duration;

use tokio::signal::unix::SignalKind;
use tracing::{error, info, warn};

use crate::config::Config;
use crate::lifecycle::{DaemonError, Options};
use crate::service::{Logging, Notifier};

/// Runs the daemon ([`crate::run_with`]) until SIGINT or SIGTERM, reloading
/// `config_path` on SIGHUP (kept as it is when the file has a mistake;
/// without one SIGHUP stops it too); a status line every `status_every`
/// (`None`: never).
pub async fn run_until_signalled(
    config: Config,
    config_path: Option<PathBuf>,
    status_every: Option<Duration>,
    logging: Logging,
) -> Result<(), DaemonError> {
    // Started under `nohup` (SIGHUP ignored): a hang-up is not for it. Read
    // before the handler below replaces the disposition.
    let nohup = sighup_ignored();
    let signal = |k| tokio::signal::unix::signal(k).map_err(DaemonError::Signals);
    let mut sigterm = signal(SignalKind::terminate())?;
    let mut sighup = signal(SignalKind::hangup())?;
    let (reload_tx, reloads) = tokio::sync::mpsc::channel(1);
    let options =
        Options { status_every, notifier: Some(Notifier::from_env()), logging: Some(logging), reloads: Some(reloads) };
    let hung_up = tokio::sync::Notify::new();
    let shutdown = async {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => info!("SIGINT"),
            _ = sigterm.recv() => info!("SIGTERM"),
            () = hung_up.notified() => {}
        }
    };
    let reloader = async {
        while sighup.recv().await.is_some() {
            let Some(path) = &config_path else {
                if nohup {
                    warn!("SIGHUP: started without --config, nothing to reload (ignored under nohup)");
                    continue;
                }
                info!("SIGHUP: started without --config, nothing to reload: stopping (the terminal hung up)");
                hung_up.notify_one();
                // The daemon stops through `shutdown`; ending here would
                // drop it mid-run (the select below).
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

/// Whether SIGHUP is ignored by this process (its `SigIgn` mask in
/// /proc/self/status, bit 0 being signal 1), as `nohup` leaves it.
fn sighup_ignored() -> bool {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigIgn:"))
        .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        .is_some_and(|mask| mask & 1 != 0)
}
