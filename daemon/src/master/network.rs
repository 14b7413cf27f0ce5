//! Whole-network actions: re-init, warm reset, a new configuration. All go
//! through the engine's own recovery path (the full bring-up), and return
//! once the network runs again.

use std::sync::atomic::Ordering;
use std::time::Duration;

use super::{Call, Master};
use crate::config::Config;
use crate::engine::Command;
use crate::engine::error::{EngineError, NotRunning};
use crate::engine::events::EventKind;
use crate::engine::network_action::NetworkAction;
use crate::engine::telemetry::{Phase, Snapshot};

impl Master {
    /// Scans the network again and redoes the whole bring-up from the
    /// configuration (mapping, start-up SDOs, states); returns once the
    /// network runs again. Requests in flight fail with `Unavailable`.
    pub async fn reinit(&self, call: Call) -> Result<(), EngineError> {
        self.network_action(NetworkAction::Reinit, call).await
    }

    /// Warm-resets the chip (cmd 127), then redoes the bring-up; returns once
    /// the network runs again.
    pub async fn warm_reset(&self, call: Call) -> Result<(), EngineError> {
        self.network_action(NetworkAction::WarmReset, call).await
    }

    /// Brings the network up again with `config`: expected slaves, PDO
    /// mappings, start-up SDOs, axes, DC cycle, FIFO sizes, target state,
    /// recovery and output policy all take effect (ECAT_INIT, PDO_CONFIG_SET,
    /// FIFO_INIT... as at start). The link and the real-time settings belong
    /// to the running process and cannot change. Returns once the network
    /// runs with it; on a bring-up failure the engine keeps retrying the new
    /// configuration, and [`Master::last_error`] says why.
    pub async fn apply_config(&self, config: Config, call: Call) -> Result<(), EngineError> {
        config
            .validate(std::path::Path::new("(applied)"))
            .map_err(|e| EngineError::BadArgument { field: "config", reason: e.to_string() })?;
        {
            let current = self.config.lock().unwrap_or_else(|e| e.into_inner());
            if config.link != current.link {
                let reason = "the link cannot change while the daemon runs; restart it".to_string();
                return Err(EngineError::BadArgument { field: "link", reason });
            }
            if config.realtime != current.realtime {
                let reason = "real-time settings apply at start; restart the daemon".to_string();
                return Err(EngineError::BadArgument { field: "realtime", reason });
            }
        }
        if matches!(self.status().phase, Phase::Stopping | Phase::Stopped) {
            return Err(EngineError::Unavailable(NotRunning::Stopped));
        }
        let generation = self.config_generation.fetch_add(1, Ordering::AcqRel) + 1;
        let mut events = self.events();
        self.engine.send(Command::Reconfigure(generation, Box::new(config.clone())))?;
        *self.config.lock().unwrap_or_else(|e| e.into_inner()) = config;
        // The first bring-up failure with this configuration is the answer
        // (the engine goes on retrying it meanwhile).
        let failed = async {
            loop {
                match events.recv().await {
                    Ok(e) => {
                        if let EventKind::BringUpFailed(why) = e.kind {
                            if self.status().config_generation >= generation {
                                let waited_for = "bring-up with the new configuration";
                                return EngineError::NotUp { waited_for, failure: why };
                            }
                        }
                    }
                    Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => {}
                    Err(tokio::sync::broadcast::error::RecvError::Closed) => std::future::pending::<()>().await,
                }
            }
        };
        tokio::select! {
            r = self.until(call, |s| s.config_generation >= generation && s.phase == Phase::Running) => r,
            e = failed => Err(e),
        }
    }

    /// The configuration in force.
    pub fn config(&self) -> Config {
        self.config.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// `f` over the `[[axis]]` entries in force (the chip's CiA 402
    /// helper): asked on every output write, so nothing is copied.
    pub(crate) fn with_axes<R>(&self, f: impl FnOnce(&[crate::config::AxisConfig]) -> R) -> R {
        f(&self.config.lock().unwrap_or_else(|e| e.into_inner()).axes)
    }

    /// Checks that slave `slave` is on the ring a request needs: the
    /// network that runs has it. While the network is not running (coming
    /// up, recovering) the ring is not known yet, so a slave beyond it is
    /// [`EngineError::Unavailable`], which a client retries; once running,
    /// a slave that is not there is a mistake in the request, naming
    /// `field` (the chip would only answer "refused").
    pub(crate) fn check_slave(&self, slave: u8, field: &'static str) -> Result<(), EngineError> {
        let count = self.layout().slaves.len();
        if usize::from(slave) < count {
            return Ok(());
        }
        match self.status().phase {
            Phase::Running => {
                Err(EngineError::BadArgument { field, reason: format!("slave {slave} does not exist ({count} found)") })
            }
            phase => Err(EngineError::Unavailable(NotRunning::Phase { phase, last_error: self.last_error() })),
        }
    }

    fn running_or_unavailable(&self) -> Result<(), EngineError> {
        if self.status().phase != Phase::Running {
            let (phase, last_error) = (self.status().phase, self.last_error());
            return Err(EngineError::Unavailable(NotRunning::Phase { phase, last_error }));
        }
        Ok(())
    }

    async fn network_action(&self, action: NetworkAction, call: Call) -> Result<(), EngineError> {
        self.running_or_unavailable()?;
        let before = self.status().recoveries;
        self.engine.send(Command::Network(action))?;
        self.until(call, |s| s.recoveries > before && s.phase == Phase::Running).await
    }

    /// Waits until the status satisfies `done`, until `call`'s deadline
    /// (none: 30 s from now); a stopped engine ends the wait at once. Only
    /// the deadline of `call` matters here: no request is queued.
    async fn until(&self, call: Call, done: impl Fn(&Snapshot) -> bool) -> Result<(), EngineError> {
        let limit = call.or_within(Duration::from_secs(30)).left().unwrap_or_default();
        match self.wait_status(limit, |s| done(s) || s.phase == Phase::Stopped).await {
            Ok(s) if s.phase != Phase::Stopped || done(&s) => Ok(()),
            Ok(_) => Err(EngineError::Unavailable(NotRunning::Stopped)),
            Err(s) => Err(match self.last_error() {
                Some(failure) if s.phase != Phase::Running => {
                    EngineError::NotUp { waited_for: "the network is not back up yet", failure }
                }
                _ => EngineError::Timeout,
            }),
        }
    }
}
