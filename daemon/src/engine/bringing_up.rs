//! The bring-up phase: runs the procedure ([`bringup`]) with the stop flag
//! as its abort, and turns the result into the next phase. A stop during
//! bring-up sends the slaves back to INIT.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use ecmxf_wire::EcatState;
use ecmxf_wire::payload::state::{SlaveSelector, StateCheck};
use tracing::{error, info, warn};

use super::bringup::{self, BringUpError};
use super::core::Core;
use super::events::EventKind;
use super::failure::Failure;
use super::next::Next;
use super::telemetry::Phase;
use crate::config::WriterGoneAction;
use crate::link::Link;
use crate::port::PortError;

/// Brings the network up; `first` is the engine's first try (after it,
/// every bring-up is a recovery's).
pub(super) fn bring_up<L: Link>(core: &mut Core<L>, first: bool) -> Next {
    core.set_phase(if first { Phase::BringUp } else { Phase::Recovering });
    core.telemetry.forget_network();
    core.events.rebase();
    core.crc_errors.rebase();
    core.wkc_errors.rebase();
    // After a fault the outputs are what the policy says: the image
    // the lease holders last wrote (hold-last, quick-stop: the axes
    // come up disabled anyway), or zeros.
    if !first && core.config.outputs.on_last_writer_gone == WriterGoneAction::Zero {
        core.held.clear();
    }
    // A stop during bring-up ends its waits at once (Port::set_abort).
    core.port.set_abort(Some(Arc::clone(&core.stop)));
    let seen = core.telemetry.slaves_seen.load(Relaxed) as usize;
    let result = bringup::bring_up(&mut core.port, &core.config, &core.held, seen);
    core.port.set_abort(None);
    if core.stop.load(Relaxed) {
        abandon(core, result.is_ok());
        return Next::Stop;
    }
    core.publish_status(Instant::now());
    match result {
        Ok(layout) => Next::Run(layout),
        Err(e) => {
            // The header of a failed bring-up says nothing about the network.
            core.telemetry.forget_network();
            if !e.is_permanent() {
                // A permanent one is said once, by the daemon as it exits.
                error!(error = %e, "bring-up failed");
            }
            let permanent = e.is_permanent();
            let reopen = matches!(&e, BringUpError::Port(PortError::Link(_)));
            let failure = Failure::BringUp(Arc::new(e));
            core.telemetry.set_error(failure.clone());
            core.events.emit(EventKind::BringUpFailed(failure));
            if permanent {
                core.telemetry.refused.store(true, Relaxed);
                return Next::Stop;
            }
            Next::Retry { reopen }
        }
    }
}

/// Told to stop during bring-up: the slaves go back to INIT if the chip
/// answers (bounded, so the daemon still stops within a second).
fn abandon<L: Link>(core: &mut Core<L>, reached: bool) {
    core.set_phase(Phase::Stopping);
    info!(reached, "stop during bring-up");
    core.port.set_ready_timeout(core.config.ready_timeout().min(Duration::from_millis(200)));
    let init = StateCheck { target: SlaveSelector::All, state: EcatState::Init };
    if let Err(e) = bringup::blocking(&mut core.port, &init, Duration::from_millis(500)) {
        warn!(error = %e, "stop during bring-up: slaves not brought to INIT");
    }
}
