//! The recovering phase: after a failed bring-up or a run that ended on a
//! fault or a client's action, every request is refused, the link opened
//! again when it was the link that failed, and the engine backs off
//! (doubling after each failed bring-up, up to `recovery.max_backoff_ms`)
//! before the next bring-up. A spell of recovery is said once: RECOVERING
//! at its first attempt, RECOVERED when process data flows again; the
//! attempts between are counted.

use std::sync::atomic::Ordering::Relaxed;
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use tracing::{info, warn};

use super::command::Taken;
use super::core::Core;
use super::error::{EngineError, NotRunning};
use super::events::EventKind;
use super::failure::Failure;
use super::next::Next;
use super::supervisor::RecoverCause;
use super::telemetry::Phase;
use crate::config::Config;
use crate::link::Link;

/// The back-off between bring-ups, kept across phases.
#[derive(Debug)]
pub(super) struct Recovering {
    backoff: Duration,
}

impl Recovering {
    /// The back-off starts at `recovery.backoff_ms`.
    pub(super) fn new(config: &Config) -> Self {
        Self { backoff: Duration::from_millis(config.recovery.backoff_ms) }
    }

    /// The network came up: the next recovery backs off from the start.
    pub(super) fn network_up(&mut self, config: &Config) {
        *self = Self::new(config);
    }

    /// Bring-up failed (said by the bring-up phase): waits the back-off,
    /// doubled for the next time, then brings up again.
    pub(super) fn retry<L: Link>(&mut self, core: &mut Core<L>, reopen: bool) -> Next {
        if reopen {
            reopen_link(core);
        }
        if !core.config.recovery.enabled || !pause(core, self.backoff) {
            return Next::Stop;
        }
        self.backoff = (self.backoff * 2).min(Duration::from_millis(core.config.recovery.max_backoff_ms));
        core.set_phase(Phase::Recovering);
        count_recovery(core);
        Next::BringUp
    }

    /// A run ended for `why`: said, counted, every request refused, then
    /// the back-off before bringing up again.
    pub(super) fn recover<L: Link>(&mut self, core: &mut Core<L>, why: RecoverCause) -> Next {
        if matches!(why, RecoverCause::NewConfig | RecoverCause::ReinitRequested) {
            // The client accepts the network as the bring-up finds it.
            core.telemetry.slaves_seen.store(0, Relaxed);
        }
        core.telemetry.set_error(Failure::Recovery(why.clone()));
        // Phase first: no one may see "running" while recovering.
        core.set_phase(Phase::Recovering);
        core.telemetry.forget_network();
        if core.recovery_open {
            // Still the same spell: nothing flowed since the
            // last RECOVERING. One event, attempts counted.
            warn!(reason = %why, attempt = core.telemetry.recoveries.load(Relaxed) + 1, "still recovering");
        } else {
            warn!(reason = %why, "recovering");
            core.events.emit(EventKind::Recovering(why.clone()));
            core.recovery_open = true;
        }
        count_recovery(core);
        core.fail_all(EngineError::Unavailable(NotRunning::Recovering(why.clone())));
        // The link's own fault (a restarted simulator, a device node that
        // came back): opened again before the next bring-up.
        if why.needs_reopen() {
            reopen_link(core);
        }
        if !core.config.recovery.enabled || !pause(core, self.backoff) {
            return Next::Stop;
        }
        Next::BringUp
    }
}

/// The network runs again after a fault: process data flows (the
/// first input frame), or there is none to exchange. RECOVERED is said
/// then and only then, never while nothing arrives.
pub(super) fn recovered<L>(core: &mut Core<L>) {
    if std::mem::take(&mut core.recovery_open) {
        // Logged with its event (a sentence, with axes_disabled as a field).
        let (axes, outputs) = (core.config.axes.len(), core.config.outputs.on_last_writer_gone);
        core.events.emit(EventKind::Recovered { axes_disabled: axes, outputs });
    }
}

/// A recovery started: counted, and said to waiters at once.
fn count_recovery<L: Link>(core: &mut Core<L>) {
    core.telemetry.recoveries.fetch_add(1, Relaxed);
    core.announce(Instant::now());
}

/// Opens the link again. A failure is logged; the next bring-up fails on
/// the link again and tries again after its back-off.
fn reopen_link<L: Link>(core: &mut Core<L>) {
    match core.port.link_mut().reopen() {
        Ok(()) => info!(link = %core.port.link_mut().describe(), "link opened again"),
        Err(e) => warn!(error = %e, "link could not be opened again; retrying after the back-off"),
    }
}

/// Waits `d` while refusing requests; false when told to stop. A new
/// configuration ends the wait: it is tried at once.
fn pause<L: Link>(core: &mut Core<L>, d: Duration) -> bool {
    let until = Instant::now() + d;
    while let Some(left) = until.checked_duration_since(Instant::now()) {
        if core.stop.load(Relaxed) {
            return false;
        }
        if core.take_new_config() {
            return true;
        }
        match core.commands.recv_timeout(left.min(Duration::from_millis(20))).map(|c| core.take(c)) {
            Ok(Taken::Job(j)) => {
                let _ = j.reply.send(Err(EngineError::Unavailable(NotRunning::BringingUp)));
            }
            Ok(Taken::Stop) | Err(RecvTimeoutError::Disconnected) => return false,
            Ok(Taken::Kept) | Err(RecvTimeoutError::Timeout) => {}
        }
    }
    true
}
