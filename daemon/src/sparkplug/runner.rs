//! The node as the daemon runs it: started from `[sparkplug]`, stopped at
//! shutdown (NDEATH before the disconnect), and replaced on SIGHUP when
//! the section changed, without touching the bus: a plant rotating broker
//! credentials or moving to another broker does not stop its machine.
//! The old node says NDEATH and disconnects before the new one connects,
//! and `bdSeq` goes on from the old node's, so a host never matches the
//! old session's death with the new session's birth.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Duration;

use tokio::sync::watch;
use tokio::task::JoinHandle;
use tracing::{info, warn};

use super::connection::{Prepared, SparkplugError, prepare};
use super::{SharedStats, session};
use crate::config::SparkplugConfig;
use crate::master::Master;

/// How long a node gets to say NDEATH and stop.
const STOP_WITHIN: Duration = Duration::from_secs(3);

/// The running node, if `[sparkplug]` asks for one.
#[derive(Debug)]
pub struct Runner {
    master: Arc<Master>,
    stats: SharedStats,
    running: Option<(watch::Sender<()>, JoinHandle<()>)>,
}

impl Runner {
    /// No node yet.
    pub fn new(master: Arc<Master>) -> Self {
        let stats = Arc::clone(master.sparkplug_state());
        Self { master, stats, running: None }
    }

    /// Starts a node with `prepared` (none may run).
    pub fn start(&mut self, prepared: Prepared) {
        let (stop, stopped) = watch::channel(());
        self.stats.enabled.store(true, Relaxed);
        let task = tokio::spawn(session::serve(Arc::clone(&self.master), prepared, Arc::clone(&self.stats), stopped));
        self.running = Some((stop, task));
    }

    /// Stops the node, if one runs: NDEATH and the disconnect, within
    /// `STOP_WITHIN`.
    pub async fn stop(&mut self) {
        if let Some((stop, mut task)) = self.running.take() {
            let _ = stop.send(());
            if tokio::time::timeout(STOP_WITHIN, &mut task).await.is_err() {
                warn!("sparkplug: the node did not stop within {} s; cut", STOP_WITHIN.as_secs());
                task.abort();
            }
        }
        self.stats.enabled.store(false, Relaxed);
        self.stats.connected.store(0, Relaxed);
    }

    /// A reloaded `[sparkplug]`: the new node's files are read first (an
    /// error keeps the old node running and is returned), then the old one
    /// stops and the new one starts.
    pub async fn replace(&mut self, config: Option<&SparkplugConfig>) -> Result<(), SparkplugError> {
        let prepared = config.map(prepare).transpose()?;
        self.stop().await;
        match prepared {
            Some(p) => {
                info!("sparkplug: node restarted with the reloaded configuration");
                self.start(p);
            }
            None => info!("sparkplug: node stopped ([sparkplug] removed)"),
        }
        Ok(())
    }
}
