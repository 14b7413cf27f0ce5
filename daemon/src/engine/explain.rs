//! Why a run ended, said better than its first symptom: the slaves' AL
//! status codes read when a slave may be at fault, the chip asked whether
//! it was reset when its answers stopped decoding. Only a run's end asks:
//! none of this costs anything while the bus runs.

use ecmxf_wire::flags::StatusFlags;
use tracing::{info, warn};

use super::bringup;
use super::core::Core;
use super::events::EventKind;
use super::supervisor::{RecoverCause, SlaveFault};
use crate::link::Link;

/// Reads every slave's state and AL status code (a fault is being
/// handled: the time is not the cycle's), reports the codes as events,
/// and returns them as text, e.g. "slave 2 SAFE-OP, AL status 0x001a
/// (...)". Read failures are left out.
fn al_report<L: Link>(core: &mut Core<L>, slaves: usize) -> Vec<SlaveFault> {
    let faulty: Vec<_> =
        bringup::slave_states(&mut core.port, slaves).into_iter().filter(|&(_, _, code)| code != 0).collect();
    for &(slave, state, code) in &faulty {
        core.events.emit(EventKind::AlStatus { slave, state, code });
    }
    faulty
}

/// The cause, with the slaves' AL status codes read and reported where
/// a slave is at fault. A slave that reports an AL status code is the cause of missing
/// working counters or a stopped exchange, not their symptom: the
/// cause is then `slave_error` naming it and its code. A chip that
/// stopped answering intact is asked what it is now: one back at its
/// power-up values was reset (`chip_reset`), not merely garbled.
pub(super) fn explained<L: Link>(core: &mut Core<L>, why: RecoverCause, slaves: usize) -> RecoverCause {
    match why {
        RecoverCause::SlaveError(_) | RecoverCause::WkcStreak(_) | RecoverCause::ExchangeStopped => {
            let report = al_report(core, slaves);
            match why {
                RecoverCause::SlaveError(_) if report.is_empty() => RecoverCause::SlaveError(Vec::new()),
                _ if !report.is_empty() => {
                    let slaves = bringup::describe_states(&report);
                    warn!(symptom = %why, slaves = %slaves, "AL status");
                    RecoverCause::SlaveError(report)
                }
                other => other,
            }
        }
        RecoverCause::Chip(e) if chip_was_reset(core) => {
            info!(symptom = %e, "the chip answers again with its power-up status: it was reset");
            RecoverCause::ChipReset
        }
        other => other,
    }
}

/// After a failed exchange: finds the chip's packet boundary again and
/// reads its status. True when it is back at its power-up values (a
/// NOP answer, ETHERNET_READY gone, or its packet size reset): a
/// reset, whose first symptom is answers the host cannot decode. One
/// try, within the ready timeout (a reset takes tens of ms); a chip
/// that does not answer leaves the cause as it was. Costs nothing
/// while the bus runs: only a failed exchange asks.
fn chip_was_reset<L: Link>(core: &mut Core<L>) -> bool {
    let size = core.port.data_size();
    if core.port.synchronize().is_err() {
        return false;
    }
    let h = core.port.status();
    h.is_nop() || !h.status.flags.contains(StatusFlags::ETHERNET_READY) || core.port.data_size() != size
}
