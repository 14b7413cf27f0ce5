//! When clients' outputs stop coming: a frame stream that ran dry (seen
//! as a FIFO answer tells each stream when its frames play), the last
//! output writer gone. What happens then is the
//! `outputs.on_last_writer_gone` policy: hold, zeros, or the axes
//! quick-stopped through the chip's CiA402 helper.

use ecmxf_wire::payload::cia402::{Cia402State, Cia402StateSet};
use tracing::{info, warn};

use super::core::Core;
use super::cyclic::Cyclic;
use super::events::EventKind;
use crate::config::WriterGoneAction;
use crate::link::Link;

/// The answer to a push came: when each stream frame in it plays, and
/// which streams ran dry. The answer's counts are the chip's at the
/// packet before the call (two exchanges late, see `fifo_exchange`),
/// when every frame pushed and read before the call was in: `waiting`
/// input frames were queued after the last one read before this call
/// (this call then read `read`), so the newest DC cycle then was that
/// frame's plus `waiting`; `ahead` output frames were queued then, so
/// this push's first frame plays `ahead + 1` cycles after it (the
/// cycles between that packet and this one took frames off both FIFOs
/// alike). Exact unless the RxFIFO ran dry in between (the frames then
/// play later: an underrun the record shows). Without inputs there is
/// no cycle to number.
pub(super) fn frames_played<L: Link>(core: &mut Core<L>, inputs: bool, read: usize, waiting: u8, ahead: u8) {
    let before = core.intake.inputs.seq().saturating_sub(read as u64);
    let first = before + u64::from(waiting) + u64::from(ahead) + 1;
    for i in 0..core.frames.len() {
        let f = &mut core.frames[i];
        if inputs {
            f.played(first);
        }
        if f.take_dry_start() {
            let pushed = f.pushed();
            frames_ran_dry(core, pushed);
        }
    }
}

/// A client's frame queue ran dry after `pushed` frames: said once per
/// spell; the range already holds or is zeroed (see `frames`), a
/// quick-stop policy stops the axes.
fn frames_ran_dry<L: Link>(core: &mut Core<L>, pushed: u64) {
    let action = core.config.outputs.on_last_writer_gone;
    core.events.emit(EventKind::FramesDry { pushed, action });
    if action == WriterGoneAction::QuickStop {
        quick_stop_axes(core);
    }
}

/// Every `[[axis]]` to QUICK STOP ACTIVE through the chip's CiA402
/// helper (the `quick-stop` outputs policy); failures are logged.
fn quick_stop_axes<L: Link>(core: &mut Core<L>) {
    for n in 0..core.config.axes.len() {
        let r = core.port.call(&Cia402StateSet { axis: n as u8, state: Cia402State::QuickStopActive });
        if let Err(e) = r {
            warn!("quick stop of axis {n}: {e}");
        }
    }
}

/// The last output writer went away: `outputs.on_last_writer_gone`.
pub(super) fn last_writer_gone<L: Link>(core: &mut Core<L>, cyclic: Option<&mut Cyclic>) {
    core.events.emit(EventKind::LastWriterGone(core.config.outputs.on_last_writer_gone));
    match core.config.outputs.on_last_writer_gone {
        WriterGoneAction::HoldLast => info!("last output writer gone: holding the last outputs"),
        WriterGoneAction::Zero => {
            if let Some(c) = cyclic {
                c.outputs.fill(0);
            }
            warn!("last output writer gone: outputs zeroed");
        }
        WriterGoneAction::QuickStop => {
            quick_stop_axes(core);
            warn!("last output writer gone: {} axes quick-stopped", core.config.axes.len());
        }
    }
}
