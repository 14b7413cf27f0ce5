//! State changes as the EtherCAT state machine allows them (ETG.1000.6
//! 6.4.1, the ESM): up one step at a time, INIT -> PRE-OP -> SAFE-OP -> OP,
//! each requested and checked (STATE_CHECK, v049 13, ends when the slaves
//! are there or refused) before the next; down in one step, which every
//! state allows; BOOT only from INIT. A slave asked to jump up refuses with
//! AL status 0x0011 (invalid requested state change), and the chip then
//! reports an error the engine must treat as a fault (`states preop;
//! states op` would fail on every network and set off a recovery). IgH and
//! SOEM walk the same way.
//!
//! A step a slave refuses ends the walk with an error naming the slave, the
//! state it is in, the one asked for and its AL status code and text.

use ecmxf_wire::EcatState;
use ecmxf_wire::payload::slave_info::{SlaveInfo, SlaveInfoCode};
pub(crate) use ecmxf_wire::payload::state::SlaveSelector;

use super::{Call, Master};
use crate::engine::error::{EngineError, WrongState};
use crate::engine::slot::SlotRequest;

/// The states the ESM goes up through, in order.
const UP: [EcatState; 4] = [EcatState::Init, EcatState::PreOp, EcatState::SafeOp, EcatState::Op];

/// Where `s` stands among [`UP`]: `None` for a state that is not on the way
/// up (none read, BOOT, or a state with the error flag: a slave that
/// reports an error takes no step up until it is acknowledged, which going
/// to INIT does).
fn rung(s: EcatState) -> Option<usize> {
    UP.iter().position(|&u| u == s)
}

/// The states to request, in order, to go from `now` to `target`: the
/// steps up one at a time, or `target` alone going down or staying. From a
/// state off the way up (an error with no state, BOOT, nothing read), the
/// walk starts at INIT, which every state may go to. BOOT is reached from
/// INIT only.
pub(crate) fn walk(now: EcatState, target: EcatState) -> Vec<EcatState> {
    if target == EcatState::Boot {
        return if now == EcatState::Init { vec![EcatState::Boot] } else { vec![EcatState::Init, EcatState::Boot] };
    }
    let Some(to) = rung(target) else { return vec![target] };
    match rung(now) {
        Some(from) if from >= to => vec![target],
        Some(from) => UP[from + 1..=to].to_vec(),
        None => UP[..=to].to_vec(),
    }
}

/// The slaves a state request or reading is for: one (by position) or,
/// for `None`, all of them.
pub(crate) fn selector(slave: Option<u8>) -> SlaveSelector {
    slave.map_or(SlaveSelector::All, SlaveSelector::One)
}

/// A slave's state and AL status, read live.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct SlaveState {
    /// Its position.
    pub position: u8,
    /// Its EtherCAT state.
    pub state: EcatState,
    /// Its AL status code.
    pub al_status: u16,
}

/// [`Master::state_report`]: the state of a slave or of the network, read
/// live.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct StateReport {
    /// The state of the slave, or of the network.
    pub state: EcatState,
    /// For one slave, its AL status code.
    pub al_status: Option<u16>,
    /// For the network, every slave's state and AL status.
    pub slaves: Vec<SlaveState>,
}

impl Master {
    /// The state `target` is in now with the AL status of the slave or,
    /// for the network, of each slave (SLV_INFO_GET, v049 15).
    pub(crate) async fn state_report(&self, target: SlaveSelector, call: Call) -> Result<StateReport, EngineError> {
        let state = self.get_state(target, call).await?;
        let mut report = StateReport { state, al_status: None, slaves: Vec::new() };
        match target {
            SlaveSelector::One(i) => {
                report.al_status = Some(self.slave_number(i, SlaveInfoCode::AlStatus, call).await? as u16)
            }
            SlaveSelector::All => {
                for position in 0..self.layout().slaves.len() as u8 {
                    let s = EcatState::from_u8(self.slave_number(position, SlaveInfoCode::State, call).await? as u8);
                    let al_status = self.slave_number(position, SlaveInfoCode::AlStatus, call).await? as u16;
                    report.slaves.push(SlaveState { position, state: s, al_status });
                }
            }
        }
        Ok(report)
    }

    /// Requests a state, walking the state machine (see the module doc);
    /// `call`'s deadline (none: the master's `default_timeout` from now)
    /// bounds the whole walk. A refused step is
    /// [`WrongState::StepRefused`], naming the slave and why.
    pub async fn set_state(&self, target: SlaveSelector, state: EcatState, call: Call) -> Result<(), EngineError> {
        if !state.is_requestable() {
            return Err(EngineError::BadArgument { field: "state", reason: format!("{state} cannot be requested") });
        }
        let call = call.or_within(self.default_timeout);
        let now = self.get_state(target, call).await?;
        for step in walk(now, state) {
            match self.request(SlotRequest::SetState { target, state: step }, call).await {
                Ok(_) => {}
                Err(EngineError::WrongState(WrongState::Refused(_))) => {
                    return Err(self.refusal(target, step, call).await);
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Why `step` was refused: the first slave of `target` not there, with
    /// its state and AL status code (read now; a slave that cannot be read
    /// is named without them).
    async fn refusal(&self, target: SlaveSelector, step: EcatState, call: Call) -> EngineError {
        let slaves: Vec<u8> = match target {
            SlaveSelector::One(s) => vec![s],
            SlaveSelector::All => (0..self.layout().slaves.len().min(usize::from(u8::MAX)) as u8).collect(),
        };
        for slave in slaves {
            let read = |item| async move {
                let d = self.request(SlotRequest::SlaveInfo { slave, item }, call).await.ok()?;
                SlaveInfo::decode(item, &d).ok()?.number()
            };
            let state = read(SlaveInfoCode::State).await.map(|v| EcatState::from_u8(v as u8));
            let code = read(SlaveInfoCode::AlStatus).await.map(|v| v as u16);
            if state.is_some_and(|s| s == step) && code.is_none_or(|c| c == 0) {
                continue;
            }
            return EngineError::WrongState(WrongState::StepRefused { slave, asked: step, state, al_status: code });
        }
        EngineError::WrongState(WrongState::Refused(step))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use EcatState::{Boot, Init, Op, PreOp, SafeOp};

    #[test]
    fn up_is_one_step_at_a_time_and_down_is_one_request() {
        assert_eq!(walk(PreOp, Op), [SafeOp, Op]);
        assert_eq!(walk(Init, Op), [PreOp, SafeOp, Op]);
        assert_eq!(walk(Init, SafeOp), [PreOp, SafeOp]);
        assert_eq!(walk(SafeOp, Op), [Op]);
        assert_eq!(walk(Op, PreOp), [PreOp]);
        assert_eq!(walk(Op, Init), [Init]);
        assert_eq!(walk(Op, Op), [Op]);
    }

    #[test]
    fn from_an_error_or_boot_the_walk_starts_at_init() {
        assert_eq!(walk(EcatState::Error, Op), [Init, PreOp, SafeOp, Op]);
        assert_eq!(walk(EcatState::None, PreOp), [Init, PreOp]);
        assert_eq!(walk(Boot, Op), [Init, PreOp, SafeOp, Op]);
        // SAFE-OP with the error flag.
        assert_eq!(walk(EcatState::Other(0x14), Op), [Init, PreOp, SafeOp, Op]);
        assert_eq!(walk(Op, Boot), [Init, Boot]);
        assert_eq!(walk(Init, Boot), [Boot]);
    }
}
